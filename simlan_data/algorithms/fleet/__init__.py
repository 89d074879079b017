"""Fleet coordination: a route graph of the layout, prioritized planning in space and time with a
reservation table, and robust execution of the plan (see docs/fleet.md)."""

from __future__ import annotations

from simlan_data.algorithms.fleet.config import FleetConfig
from simlan_data.algorithms.fleet.coordinator import FleetCoordinator, FleetState
from simlan_data.algorithms.fleet.graph import RouteGraph, build_route_graph
from simlan_data.algorithms.fleet.schedule import FleetPlan, Obstacle, Request, Timing, plan_fleet

__all__ = [
    "FleetConfig",
    "FleetCoordinator",
    "FleetPlan",
    "FleetState",
    "Obstacle",
    "Request",
    "RouteGraph",
    "Timing",
    "build_route_graph",
    "plan_fleet",
]
