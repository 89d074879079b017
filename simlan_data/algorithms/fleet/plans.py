"""What the fleet planner is asked and what it answers: requests, obstacles, timed routes, timing.

The planner itself is ``schedule.py`` (the order, the reservation table) and ``search.py`` (one
robot's space-time search); ``execution.py`` runs its answer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from simlan_data.algorithms.fleet import footprint as fp
from simlan_data.algorithms.fleet.footprint import Region, Shape


@dataclass(frozen=True)
class Request:
    """What one robot asks of the fleet plan."""

    name: str
    start: int  # node it is snapped to
    goal: int | None  # node; None: the goal is off the graph
    shape: Shape
    start_xy: tuple[float, float]
    heading_rad: float | None = None  # None: may leave the start in any direction
    goal_xy: tuple[float, float] | None = None  # the real goal, driven to from the goal node
    start_turnable: bool = True  # it may turn in place where it stands
    idle: bool = False  # every goal done: its goal is where it parks; it moves aside, never goes first
    lane_radius_m: float = 0.0  # its half width plus the lane clearance: the edges it drives (0: all)


@dataclass(frozen=True)
class Obstacle:
    """Something that does not take part in the plan (stopped, unlocalized, a person)."""

    xy: tuple[float, float]
    radius_m: float
    yaw_rad: float | None = None  # with ``shape``: its footprint at this heading, else a circle
    shape: Shape | None = None

    def region(self) -> Region:
        if self.shape is not None and self.yaw_rad is not None:
            return fp.pose(self.shape, np.asarray(self.xy), self.yaw_rad)
        c = np.asarray([self.xy], dtype=float)
        return c, c.copy(), np.array([self.radius_m])


@dataclass
class Vertex:
    """A place on a robot's route: the node, when it arrives and leaves, what it holds meanwhile."""

    node: int
    arrive: int  # step it arrives (0: the start)
    depart: int | None  # step it starts for the next vertex (None: it stays)
    occ: Region  # what it holds from leaving the vertex before until arriving at the one after
    loose: bool = False  # where it stands now, or its way off it: kept off others, not the safety distance
    back: bool = False  # it drives here from the vertex before reversing
    turn: bool = False  # it may turn in place here (after arriving)


@dataclass
class RobotPlan:
    """One robot's timed route."""

    name: str
    vertices: list[Vertex]
    target: int  # where it ends: its goal, or a queue node outside a held goal
    queued: bool = False  # waits outside its goal (held by a robot planned before it)
    complete: bool = True  # reaches the target within the horizon

    @property
    def nodes(self) -> list[int]:
        """Node of the last vertex reached, per step, up to the arrival at the last one."""
        out: list[int] = []
        for a, b in zip(self.vertices, self.vertices[1:] + [None]):
            out.extend([a.node] * ((b.arrive if b is not None else a.arrive + 1) - a.arrive))
        return out


@dataclass
class FleetPlan:
    plans: dict[str, RobotPlan] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)  # name -> unreachable | blocked
    order: list[str] = field(default_factory=list)  # the priority order that was used
    # robot -> robots planned after it whose standing place keeps it from its goal
    blockers: dict[str, list[str]] = field(default_factory=dict)
    # (robot, its blocker) -> the nearest node where the blocker would stand clear of the robot's
    # way to its goal (None: there is none)
    shelters: dict[tuple[str, str], int | None] = field(default_factory=dict)
    sheltered: dict[str, int] = field(default_factory=dict)  # robot -> the node it was sent to instead


@dataclass(frozen=True)
class Timing:
    """How the plan's clock relates to the graph."""

    spacing_m: float
    horizon: int  # steps
    safety_m: float  # distance kept between two robots' regions
    turn_tolerance_rad: float = math.radians(50.0)  # larger heading changes need a turn in place
    # where a robot changes between driving forwards and backwards it stands: a larger heading
    # change there is a turn on the spot (the path follower's), which the plan has not reserved
    cusp_tolerance_rad: float = math.radians(20.0)
    # planned reversing speed as a share of the forward speed (an arc driven backwards takes
    # 1 / reverse_ratio as many steps); 0: it never reverses
    reverse_ratio: float = 0.0
    # a robot that never reverses may still back off its start onto a node nearly behind it, at
    # this share of the forward speed (0: it may not): a robot parked facing a shelf, or stopped
    # across a lane where it cannot turn, has no other way out
    start_back_ratio: float = 0.0
    soft_waiting: bool = True  # the guide passes by where robots not planned yet stand (schedule.py)
    shelters: bool = False  # a robot in another's way may be sent to a shelter first (schedule.py)
    unseen_limit: float = 1.0  # arcs more than this share unseen driven that way are not driven

    def steps(self, length_m: float) -> int:
        return max(1, math.ceil(length_m / self.spacing_m - 1e-6))


def start_region(r: Request, *, turn: bool) -> Region:
    xy = np.asarray(r.start_xy, dtype=float)
    if r.heading_rad is None:
        return fp.circle(r.shape, xy)
    here = fp.pose(r.shape, xy, r.heading_rad)
    return fp.region(here, fp.circle(r.shape, xy)) if turn else here
