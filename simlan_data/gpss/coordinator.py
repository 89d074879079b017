"""Central multi-robot coordination: who may drive on, who waits, who detours.

Every control tick each robot states its intent: its footprint now and the region its footprint
will sweep along its planned path over the next few metres (its *claim*). In priority order
(robot_agent_1 first), a robot is allowed on if its claim touches neither the footprint of another
agent (it would drive into it) nor the claim of a robot already allowed on (it would cut it off);
otherwise it waits. A robot blocked by a waiting robot for longer than ``deadlock_after_s`` is
told to replan around the others (head-on meetings, a robot parked in the way).

Pure shapely/numpy over estimated poses (never ground truth).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from shapely import affinity
from shapely.geometry import Polygon, box
from shapely.ops import unary_union

from ..constants import NS_PER_S


@dataclass(frozen=True)
class Intent:
    """What one agent is doing, as the coordinator sees it."""

    namespace: str
    priority: int  # lower drives first
    pose_xyyaw: tuple[float, float, float]
    footprint_m: tuple[float, float, float, float]  # x0, x1, y0, y1 in base_link
    path_ahead_xy: NDArray[np.float64] | None = None  # (N, 2) from the current position; None: not navigating
    yields: bool = True  # False for people and fixed robots: others must go around them


def footprint_polygon(
    pose_xyyaw: tuple[float, float, float],
    footprint_m: tuple[float, float, float, float],
    *,
    grow_m: float = 0.0,
) -> Polygon:
    x, y, yaw = pose_xyyaw
    x0, x1, y0, y1 = footprint_m
    rect = box(x0 - grow_m, y0 - grow_m, x1 + grow_m, y1 + grow_m)
    return affinity.translate(affinity.rotate(rect, yaw, origin=(0, 0), use_radians=True), x, y)


def swept_claim(intent: Intent, *, horizon_m: float, grow_m: float, step_m: float = 0.3) -> Polygon:
    """Union of the footprint at poses along the path ahead (heading along the path)."""
    shapes = [footprint_polygon(intent.pose_xyyaw, intent.footprint_m, grow_m=grow_m)]
    path = intent.path_ahead_xy
    if path is not None and len(path) >= 2:
        seg = np.diff(path, axis=0)
        lengths = np.linalg.norm(seg, axis=1)
        cum = np.concatenate([[0.0], np.cumsum(lengths)])
        for s in np.arange(step_m, min(horizon_m, cum[-1]) + 1e-9, step_m):
            i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(lengths) - 1))
            if lengths[i] < 1e-9:
                continue
            t = (s - cum[i]) / lengths[i]
            p = path[i] + t * seg[i]
            yaw = float(np.arctan2(seg[i][1], seg[i][0]))
            shapes.append(
                footprint_polygon((float(p[0]), float(p[1]), yaw), intent.footprint_m, grow_m=grow_m)
            )
    return unary_union(shapes)


@dataclass
class Decision:
    speed_limit_mps: float | None  # 0 = wait, None = free
    blocked_by: tuple[str, ...] = ()
    replan: bool = False


@dataclass
class Coordinator:
    """Decide per control tick which robots drive, wait or replan."""

    safety_distance_m: float = 0.6
    horizon_m: float = 3.0
    deadlock_after_s: float = 3.0
    _waiting_since: dict[str, int] = field(default_factory=dict)
    waits: dict[str, int] = field(default_factory=dict)  # ticks spent waiting, per robot

    def decide(self, t_ns: int, intents: list[Intent]) -> dict[str, Decision]:
        grow = 0.5 * self.safety_distance_m
        now = {i.namespace: footprint_polygon(i.pose_xyyaw, i.footprint_m, grow_m=grow) for i in intents}
        claims = {
            i.namespace: swept_claim(i, horizon_m=self.horizon_m, grow_m=grow)
            for i in intents
            if i.path_ahead_xy is not None
        }
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
            since = self._waiting_since.setdefault(ns, t_ns)
            self.waits[ns] = self.waits.get(ns, 0) + 1
            replan = (t_ns - since) >= self.deadlock_after_s * NS_PER_S
            if replan:
                self._waiting_since[ns] = t_ns  # give the new plan time before asking again
            out[ns] = Decision(0.0, tuple(sorted(blockers)), replan)
        return out
