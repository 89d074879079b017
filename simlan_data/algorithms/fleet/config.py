"""The fleet coordinator's parameters (``algorithms.coordinator.*`` with ``algorithms/coordinator=fleet``)."""

from __future__ import annotations

from dataclasses import dataclass

from simlan_data.errors import ConfigError

_KEY = "algorithms.coordinator."


def _within(
    name: str, value: float, low: float, high: float, unit: str, default: float, *, zero_ok: bool = False
) -> None:
    """Refuse ``value`` outside (low, high] ([low, high] with ``zero_ok``), naming the key."""
    if not (low <= value <= high if zero_ok else low < value <= high):
        raise ConfigError.invalid(
            _KEY + name, value, f"must be within {low}..{high} {unit}".rstrip(), f"use {default}"
        )


@dataclass(frozen=True)
class FleetConfig:
    """Route graph, timing and execution of the fleet coordinator (see docs/fleet.md)."""

    spacing_m: float = 1.0  # route graph block size: node spacing on open floor, one plan step of travel
    lane_clearance_m: float = 0.25  # a robot's lanes keep its own half width plus this from obstacles
    speed_mps: float = 0.5  # planning speed (a step lasts spacing_m / speed_mps)
    horizon_s: float = 90.0  # reservation horizon: how far ahead plans are reserved
    safety_m: float = (
        0.0  # extra distance between two robots' footprint regions (on top of the run's safety distance)
    )
    tracking_m: float = 0.15  # footprints grow by this on every side: how far a robot strays from its route
    reach_m: float = 0.35  # a robot within this of a route vertex has reached it
    brake_m: float = 1.0  # below this distance to the last vertex it may enter, the speed limit tapers
    stall_s: float = 3.0  # allowed to move but not moving for this long: stopped (an obstacle, replan)
    deadlock_after_s: float = 10.0  # deadlock bound: a robot waiting this long on a robot that does not move
    replan_s: float = 5.0  # least time between replans for a spent window, a queue, a stop, a failure
    unseen_cost: float = 25.0  # camera steering: route guide's extra length per metre no camera sees (0: off)
    unseen_limit: float = 1.0  # camera steering: arcs more than this share unseen (driven that way) are not driven (1: no limit)
    reverse_ratio: float = 0.0  # planned reversing speed / speed_mps (0: never reverse; opt-in)
    start_back_ratio: float = 0.0  # backing off its start: this share of speed_mps (0: never, docs/fleet.md)
    shelters: bool = False  # a robot in another's way goes to a shelter first (opt-in, docs/fleet.md)
    soft_waiting: bool = True  # the route guide counts 3 m more per arc where robots not planned yet stand
    # (both off by default: in the closed loop they reached fewer goals than without, and a
    # reversing truck backed into a shelf before its tail was checked: docs/fleet.md)

    def __post_init__(self) -> None:
        _within("spacing_m", self.spacing_m, 0.2, 5.0, "m", 1.0)
        _within("lane_clearance_m", self.lane_clearance_m, 0.0, 2.0, "m", 0.25, zero_ok=True)
        _within("speed_mps", self.speed_mps, 0.0, 5.0, "m/s", 0.5)
        _within("horizon_s", self.horizon_s, 0.0, 1800.0, "s", 90.0)
        _within("safety_m", self.safety_m, 0.0, 5.0, "m", 0.0, zero_ok=True)
        _within("tracking_m", self.tracking_m, 0.0, 2.0, "m", 0.15, zero_ok=True)
        _within("reach_m", self.reach_m, 0.0, 2.0, "m", 0.35)
        _within("brake_m", self.brake_m, 0.0, 10.0, "m", 1.0)
        _within("stall_s", self.stall_s, 0.0, 600.0, "s", 3.0)
        _within("deadlock_after_s", self.deadlock_after_s, 0.0, 600.0, "s", 10.0)
        _within("replan_s", self.replan_s, 0.0, 600.0, "s", 5.0)
        _within("unseen_cost", self.unseen_cost, 0.0, 1000.0, "", 25.0, zero_ok=True)
        _within("unseen_limit", self.unseen_limit, 0.0, 1.0, "", 1.0, zero_ok=True)
        _within("reverse_ratio", self.reverse_ratio, 0.0, 1.0, "", 0.0, zero_ok=True)
        _within("start_back_ratio", self.start_back_ratio, 0.0, 1.0, "", 0.0, zero_ok=True)

    @property
    def step_s(self) -> float:
        return self.spacing_m / self.speed_mps

    @property
    def horizon_steps(self) -> int:
        return max(4, round(self.horizon_s / self.step_s))
