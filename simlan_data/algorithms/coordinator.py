"""Central multi-robot coordination: who may drive on, who waits, who detours.

Every control tick each robot states its intent: its footprint now and the region its footprint
will sweep along its planned path over the next few metres (its *claim*). In priority order
(robot_agent_1 first), a robot is allowed on if its claim touches neither the footprint of another
agent (it would drive into it) nor the claim of a robot already allowed on (it would cut it off);
otherwise it waits. A robot blocked for longer than ``deadlock_after_s`` by a robot that does not
drive on either (head-on meetings, a robot parked in the way) is told to replan around the others.

Pure shapely/numpy over estimated poses (never ground truth).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from simlan_data.constants import NS_PER_S


@dataclass(frozen=True)
class Intent:
    """What one agent is doing, as the coordinator sees it."""

    namespace: str
    priority: int  # lower drives first
    pose_xyyaw: tuple[float, float, float]
    footprint_m: tuple[float, float, float, float]  # x0, x1, y0, y1 in base_link
    path_ahead_xy: NDArray[np.float64] | None = None  # (N, 2) from the current position; None: not navigating
    yields: bool = True  # False for people and fixed robots: others must go around them
    goal_xy: tuple[float, float] | None = None  # where it is navigating to (None: no goal)


def _footprint_rings(
    poses_xyyaw: NDArray[np.float64], footprint_m: tuple[float, float, float, float], grow_m: float
) -> NDArray[np.float64]:
    """Closed corner rings (N, 5, 2) of the footprint at N poses (x, y, yaw), in the map frame."""
    x0, x1, y0, y1 = footprint_m
    g = grow_m
    # shapely's box(x0, y0, x1, y1) ring order, counter-clockwise
    local = np.array(
        [[x1 + g, y0 - g], [x1 + g, y1 + g], [x0 - g, y1 + g], [x0 - g, y0 - g], [x1 + g, y0 - g]]
    )
    c, s = np.cos(poses_xyyaw[:, 2])[:, None], np.sin(poses_xyyaw[:, 2])[:, None]
    x = c * local[:, 0] - s * local[:, 1] + poses_xyyaw[:, :1]
    y = s * local[:, 0] + c * local[:, 1] + poses_xyyaw[:, 1:2]
    return np.stack([x, y], axis=-1)


def footprint_polygon(
    pose_xyyaw: tuple[float, float, float],
    footprint_m: tuple[float, float, float, float],
    *,
    grow_m: float = 0.0,
) -> Polygon:
    ring = _footprint_rings(np.array([pose_xyyaw], dtype=float), footprint_m, grow_m)[0]
    return shapely.polygons(ring)


def swept_claim(
    intent: Intent, *, horizon_m: float, grow_m: float, step_m: float = 0.3, heading_window_m: float = 0.6
) -> Polygon:
    """Union of the footprint at poses along the path ahead.

    The heading at a pose is that of the path's chord over ``heading_window_m`` around it: a
    path follower cuts the small zigzags of a grid path, so the robot does not turn on each.
    (Vectorized: the footprints are built as one array and merged by one ``union_all``.)
    """
    poses = [np.asarray(intent.pose_xyyaw, dtype=float)[None, :]]
    path = intent.path_ahead_xy
    if path is not None and len(path) >= 2:
        lengths = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(lengths)])
        if cum[-1] < 1e-9:
            return footprint_polygon(intent.pose_xyyaw, intent.footprint_m, grow_m=grow_m)

        def at(s: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.stack([np.interp(s, cum, path[:, 0]), np.interp(s, cum, path[:, 1])], axis=-1)

        half = 0.5 * heading_window_m
        s = np.arange(step_m, min(horizon_m, cum[-1]) + 1e-9, step_m)
        if len(s):
            d = at(np.minimum(s + half, cum[-1])) - at(np.maximum(s - half, 0.0))
            poses.append(np.column_stack([at(s), np.arctan2(d[:, 1], d[:, 0])]))
    rings = _footprint_rings(np.concatenate(poses), intent.footprint_m, grow_m)
    if len(rings) == 1:
        return shapely.polygons(rings[0])
    return shapely.union_all(shapely.polygons(rings))


@dataclass
class Decision:
    speed_limit_mps: float | None  # 0 = wait, None = free
    blocked_by: tuple[str, ...] = ()
    replan: bool = False  # look for a way around the others (see Coordinator)
    path_xy: NDArray[np.float64] | None = None  # follow this path to the goal (a fleet coordinator's route)
    # per segment of path_xy: driven backwards (None: every segment forwards). A robot reverses
    # out of a corridor or a dead end where it cannot turn (the fleet coordinator's plans)
    path_reverse: tuple[bool, ...] | None = None
    # vertices of path_xy where the robot stops and turns on the spot (a fleet plan reserves a
    # turn's swept circle there only): it drives to the vertex before it turns (None: none)
    path_stops: tuple[int, ...] | None = None
    # held at speed 0, may it still turn in place towards its path? (False: its whole footprint
    # stands still; a fleet plan reserves a turn's swept circle only where it plans the turn)
    turn_in_place: bool = True


@dataclass
class Coordinator:
    """Decide per control tick which robots drive, wait or replan."""

    safety_distance_m: float = 0.6
    horizon_m: float = 3.0
    deadlock_after_s: float = 3.0
    _waiting_since: dict[str, int] = field(default_factory=dict)
    waits: dict[str, int] = field(default_factory=dict)  # ticks spent waiting, per robot
    granted: set[str] = field(default_factory=set)  # robots allowed on at the last decision

    def decide(self, t_ns: int, intents: list[Intent]) -> dict[str, Decision]:
        grow = 0.5 * self.safety_distance_m
        now = {i.namespace: footprint_polygon(i.pose_xyyaw, i.footprint_m, grow_m=grow) for i in intents}
        claims = {
            i.namespace: swept_claim(i, horizon_m=self.horizon_m, grow_m=grow)
            for i in intents
            if i.path_ahead_xy is not None
        }
        priority = {i.namespace: i.priority for i in intents}
        granted: dict[str, Polygon] = {}
        out: dict[str, Decision] = {}
        for intent in sorted(intents, key=lambda i: i.priority):
            ns = intent.namespace
            if ns not in claims:
                continue
            claim = claims[ns]
            blockers = [o for o, shape in now.items() if o != ns and claim.intersects(shape)]
            blockers += [o for o, shape in granted.items() if o not in blockers and claim.intersects(shape)]
            if not blockers:
                granted[ns] = claim
                self._waiting_since.pop(ns, None)
                out[ns] = Decision(None)
                continue
            self._waiting_since.setdefault(ns, t_ns)
            self.waits[ns] = self.waits.get(ns, 0) + 1
            out[ns] = Decision(0.0, tuple(sorted(blockers)))
        self.granted = set(granted)
        # Who looks for a way round: a robot that has waited deadlock_after_s for a robot that is
        # not driving on (waiting as well, parked, a person, unlocalized). In a mutual wait the one
        # of lower priority goes first; if it found no way round, after twice the time the other
        # one tries too.
        limit = self.deadlock_after_s * NS_PER_S
        for ns, decision in out.items():
            if decision.speed_limit_mps != 0.0:
                continue
            waited = t_ns - self._waiting_since[ns]
            stuck = [b for b in decision.blocked_by if b not in granted]
            if not stuck or waited < limit:
                continue
            yields_first = all(
                priority[ns] > priority[b] for b in stuck if b in out and out[b].speed_limit_mps == 0.0
            )
            if yields_first or waited >= 2 * limit:
                decision.replan = True
                self._waiting_since[ns] = t_ns  # give the new plan time before asking again
        return out
