"""The GPSS algorithms: markers, localization, planning, following, coordination, safety, bird's-eye."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.algorithms` stays light and free of pybullet.
# roles and registry: see simlan_data.algorithms.roles / .registry
_EXPORTS: dict[str, str] = {
    "BirdseyeStitcher": "birdseye",
    "CanvasSpec": "birdseye",
    "SimlanBirdseye": "birdseye_simlan",
    "Coordinator": "coordinator",
    "Decision": "coordinator",
    "Intent": "coordinator",
    "DryRunResult": "dryrun",
    "dry_run": "dryrun",
    "FollowerParams": "follower",
    "PathFollower": "follower",
    "PursuitParams": "follower",
    "WaypointFollower": "follower",
    "Detection": "markers",
    "MarkerDetector": "markers",
    "MarkerMount": "markers",
    "MarkerObservation": "markers",
    "NavigationStatus": "navigation",
    "Navigator": "navigation",
    "OccupancyGrid": "occupancy",
    "grid_from_nav2_map": "occupancy",
    "grid_from_world": "occupancy",
    "PeopleParams": "people",
    "PersonDetection": "people",
    "PersonDetector": "people",
    "PersonTracker": "people",
    "GridPlanner": "planner",
    "Plan": "planner",
    "PlanningError": "planner",
}

__all__ = [
    "BirdseyeStitcher",
    "CanvasSpec",
    "Coordinator",
    "Decision",
    "Detection",
    "DryRunResult",
    "FollowerParams",
    "GridPlanner",
    "Intent",
    "MarkerDetector",
    "MarkerMount",
    "MarkerObservation",
    "NavigationStatus",
    "Navigator",
    "OccupancyGrid",
    "PathFollower",
    "PeopleParams",
    "PersonDetection",
    "PersonDetector",
    "PersonTracker",
    "Plan",
    "PlanningError",
    "PursuitParams",
    "SimlanBirdseye",
    "WaypointFollower",
    "dry_run",
    "grid_from_nav2_map",
    "grid_from_world",
]


def __getattr__(name: str) -> Any:
    """Import the defining module on first use of a public name (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
