"""SIMLAN's collision families: a pallet truck and a Jackal set up to collide.

SIMLAN's ``collision_action_server`` teleports the two robots so that, driving straight at
constant speed for ``experiment_time``, they meet at a collision point, for an ``angle`` (the
Jackal's heading relative to the truck's), a truck speed and a ``collision_type``:

- 0 HEAD_ON: the fronts meet (front corners at crossing angles; front centres at 180 degrees);
- 1 PALLET_TRUCK_SIDE: the Jackal's front hits the pallet truck's side;
- 2 JACKAL_SIDE: the pallet truck's front hits the Jackal's side;

and at 0 degrees (catch-up) the faster robot's front meets the slower one's back. Here both
robots are GPSS robots steered by the cameras through a goal beyond the collision point; they
set off together and accelerate as the path follower does, so each start lies the distance it
covers in ``time_s`` (with that acceleration) before its pose at the moment of contact. At that
moment the striking front is ``overlap_m`` past the contact point (half of it each, head-on), so
that small timing errors still end in a collision when nothing stops them (SIMLAN's points
touch exactly).

Pure numpy: the config resolver ``${collision_setup:KEY}`` turns the ``collision`` section into
agent poses and goals, so the recorded config holds the resolved numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simlan_data.errors import ConfigError
from simlan_data.world.agent_types import AGENT_TYPES

HEAD_ON, PALLET_TRUCK_SIDE, JACKAL_SIDE = 0, 1, 2
TRUCK_NS, JACKAL_NS = "robot_agent_1", "robot_agent_2"
GUARDED = ("both", "jackal", "truck", "none")
FOLLOWER_ACCEL_MPS2 = 0.6  # PursuitParams.accel_mps2: how the GPSS path follower speeds up
RUN_ON_M = 5.0  # each goal lies this far past the meeting point


@dataclass(frozen=True)
class CollisionSetup:
    truck_pose: tuple[float, float, float]
    truck_goal: tuple[float, float]
    jackal_pose: tuple[float, float, float]
    jackal_goal: tuple[float, float]
    contact_truck: tuple[float, float, float]  # poses at the moment of contact (by design)
    contact_jackal: tuple[float, float, float]
    closing: bool  # False when nothing brings them together (catch-up at equal speed)


def travel_m(speed_mps: float, time_s: float, accel_mps2: float = FOLLOWER_ACCEL_MPS2) -> float:
    """Distance covered from standstill in ``time_s``, accelerating at ``accel_mps2`` to ``speed_mps``."""
    ramp_s = speed_mps / accel_mps2
    if time_s <= ramp_s:
        return 0.5 * accel_mps2 * time_s**2
    return speed_mps * time_s - speed_mps**2 / (2 * accel_mps2)


def _place(point: np.ndarray, yaw: float, local: tuple[float, float]) -> tuple[float, float, float]:
    """The pose whose base_link-frame point ``local`` lies on ``point``."""
    c, s = np.cos(yaw), np.sin(yaw)
    x = point[0] - (c * local[0] - s * local[1])
    y = point[1] - (s * local[0] + c * local[1])
    return float(x), float(y), float(yaw)


def collision_setup(
    angle_deg: float,
    truck_speed_mps: float,
    collision_type: int,
    *,
    jackal_speed_mps: float = 1.0,
    point_xy: tuple[float, float] = (5.5, 1.0),
    time_s: float = 3.0,
    overlap_m: float = 0.1,
    run_on_m: float = RUN_ON_M,
) -> CollisionSetup:
    """Start poses and goals of the truck and the Jackal for one collision case."""
    tx0, tx1, _, ty1 = AGENT_TYPES["pallet_truck"].footprint_m
    jx0, jx1, _, jy1 = AGENT_TYPES["jackal"].footprint_m
    point = np.asarray(point_xy, dtype=float)
    a = float(np.radians(angle_deg % 360.0))
    truck_yaw, jackal_yaw = 0.0, a
    sin_a = float(np.sin(a))
    closing = True
    if abs(sin_a) < 1e-6 and np.cos(a) < 0:  # 180: head-on along one line, front centres meet
        t_local, j_local = (tx1 - overlap_m / 2, 0.0), (jx1 - overlap_m / 2, 0.0)
    elif abs(sin_a) < 1e-6:  # 0: catch-up, the faster front meets the slower back
        if truck_speed_mps > jackal_speed_mps:
            t_local, j_local = (tx1 - overlap_m, 0.0), (jx0, 0.0)
        elif truck_speed_mps < jackal_speed_mps:
            t_local, j_local = (tx0, 0.0), (jx1 - overlap_m, 0.0)
        else:  # same speed: they never close in; the Jackal drives 1 m ahead of the truck
            t_local, j_local = (tx1, 0.0), (jx0 - 1.0, 0.0)
            closing = False
    else:
        side_t = -1.0 if sin_a > 0 else 1.0  # the Jackal comes from the truck's right (or left)
        side_j = 1.0 if sin_a > 0 else -1.0  # the Jackal's side that faces the oncoming truck
        if collision_type == HEAD_ON:
            t_local = (tx1 - overlap_m / 2, side_t * ty1)
            j_local = (jx1 - overlap_m / 2, side_j * jy1)
        elif collision_type == PALLET_TRUCK_SIDE:
            t_local = (0.5 * (tx0 + tx1), side_t * ty1)
            j_local = (jx1 - overlap_m, 0.0)
        elif collision_type == JACKAL_SIDE:
            t_local = (tx1 - overlap_m, 0.0)
            j_local = (0.5 * (jx0 + jx1), side_j * jy1)
        else:
            raise ValueError(f"unknown collision_type {collision_type}")
    truck_at = _place(point, truck_yaw, t_local)
    jackal_at = _place(point, jackal_yaw, j_local)

    def start_and_goal(at: tuple[float, float, float], speed: float) -> tuple[tuple, tuple]:
        x, y, yaw = at
        d = travel_m(speed, time_s)
        c, s = float(np.cos(yaw)), float(np.sin(yaw))
        start = (round(x - d * c, 4), round(y - d * s, 4), round(yaw, 6))
        goal = (round(x + run_on_m * c, 4), round(y + run_on_m * s, 4))
        return start, goal

    truck_start, truck_goal = start_and_goal(truck_at, truck_speed_mps)
    jackal_start, jackal_goal = start_and_goal(jackal_at, jackal_speed_mps)
    return CollisionSetup(truck_start, truck_goal, jackal_start, jackal_goal, truck_at, jackal_at, closing)


def resolve(key: str, section: dict) -> object:
    """Value of ``${collision_setup:KEY}`` for a config's ``collision`` section."""
    setup = collision_setup(
        float(section["angle"]),
        float(section["truck_speed_mps"]),
        int(section["collision_type"]),
        jackal_speed_mps=float(section.get("jackal_speed_mps", 1.0)),
        point_xy=(float(section.get("point", (5.5, 1.0))[0]), float(section.get("point", (5.5, 1.0))[1])),
        time_s=float(section.get("time_s", 3.0)),
        overlap_m=float(section.get("overlap_m", 0.1)),
    )
    guarded = str(section.get("guarded", "both"))
    slowest = min(float(section["truck_speed_mps"]), float(section.get("jackal_speed_mps", 1.0)))
    # long enough for the slower robot to drive on to its goal past the meeting point: a robot the
    # safety layer stopped short of it may still be hit by an unguarded one, later
    duration = float(section.get("time_s", 3.0)) + min(RUN_ON_M / slowest, 20.0) + 1.0
    values: dict[str, object] = {
        "duration_s": round(duration, 3),
        "truck_pose": list(setup.truck_pose),
        "truck_goals": [list(setup.truck_goal)],
        "jackal_pose": list(setup.jackal_pose),
        "jackal_goals": [list(setup.jackal_goal)],
        "safety_enabled": guarded != "none",
        "safety_namespaces": {"both": [], "jackal": [JACKAL_NS], "truck": [TRUCK_NS], "none": []}.get(
            guarded, []
        ),
    }
    if key not in values:
        raise KeyError(f"unknown collision_setup key {key!r}; known: {', '.join(values)}")
    return values[key]


_bad = ConfigError.invalid  # invalid KEY=VALUE in config: WHY; FIX


@dataclass
class CollisionScenarioConfig:
    """SIMLAN's collision families (scenario=collision): the ``collision`` section (scenario data)."""

    angle: float = 90.0  # the Jackal's heading relative to the truck's, degrees (0: catch-up, 180: head-on)
    truck_speed_mps: float = 1.0
    collision_type: int = 0  # 0 head-on, 1 pallet-truck side, 2 Jackal side (SIMLAN's CollisionType)
    jackal_speed_mps: float = 1.0
    point: list[float] = field(default_factory=lambda: [5.5, 1.0])  # where they meet (map)
    time_s: float = 3.0  # from the start to the contact, if nothing stops them
    overlap_m: float = 0.1
    guarded: str = "both"  # robots with a safety tree: both | jackal (SIMLAN's setup) | truck | none

    def __post_init__(self) -> None:
        if self.guarded not in GUARDED:
            raise _bad(
                "collision.guarded",
                self.guarded,
                f"expected one of {', '.join(GUARDED)}",
                "use both",
            )
        if self.collision_type not in (0, 1, 2):
            raise _bad(
                "collision.collision_type",
                self.collision_type,
                "0 head-on, 1 pallet-truck side, 2 Jackal side",
                "use 0, 1 or 2",
            )
        for name in ("truck_speed_mps", "jackal_speed_mps"):
            if not 0 < getattr(self, name) <= 2.0:
                raise _bad(
                    f"collision.{name}", getattr(self, name), "must be within (0, 2] m/s", "use e.g. 1.0"
                )
        if not 1.0 <= self.time_s <= 30.0:
            raise _bad("collision.time_s", self.time_s, "must be within 1..30 s", "use 3.0")
        if len(self.point) != 2:
            raise _bad("collision.point", list(self.point), "expected [x_m, y_m]", "use [5.5, 1.0]")
