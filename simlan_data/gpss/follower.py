"""Follow a route of waypoints with a differential-drive robot (pure pursuit on a polyline).

Pure algorithm: poses in, twist out. No simulator, no file format.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FollowerParams:
    speed_mps: float = 1.0
    lookahead_m: float = 1.2
    goal_tolerance_m: float = 0.25
    max_yaw_rate_rps: float = 0.8
    turn_in_place_rad: float = 0.9
    accel_mps2: float = 0.5
    slowdown_radius_m: float = 1.5


@dataclass(frozen=True)
class Command:
    linear_mps: float
    angular_rps: float
    goal_index: int
    done: bool


class WaypointFollower:
    """Pure pursuit along the segments between waypoints; turns in place on sharp corners."""

    def __init__(
        self, waypoints: Sequence[Sequence[float]], params: FollowerParams, *, loop: bool = False
    ) -> None:
        self.points = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        self.params, self.loop = params, loop
        self.index = 0  # next waypoint to reach
        self.reached = 0
        self._speed = 0.0
        self._turning = False

    @property
    def done(self) -> bool:
        return len(self.points) == 0 or (not self.loop and self.index >= len(self.points))

    def step(self, x: float, y: float, yaw: float, dt_s: float) -> Command:
        """Twist for the robot at (x, y, yaw) for the next ``dt_s`` seconds."""
        p = self.params
        if self.done:
            self._speed = 0.0
            return Command(0.0, 0.0, self.index, True)
        pos = np.array([x, y])
        target = self.points[self.index]
        if np.linalg.norm(target - pos) < p.goal_tolerance_m:
            self.reached += 1
            self.index += 1
            if self.loop and self.index >= len(self.points):
                self.index = 0
            if self.done:
                self._speed = 0.0
                return Command(0.0, 0.0, self.index, True)
            target = self.points[self.index]
        carrot = self._carrot(pos, target)
        dx, dy = carrot - pos
        heading_error = float((np.arctan2(dy, dx) - yaw + np.pi) % (2 * np.pi) - np.pi)
        # hysteresis: start turning in place above the threshold, drive again below half of it
        if abs(heading_error) > p.turn_in_place_rad or (
            self._turning and abs(heading_error) > 0.5 * p.turn_in_place_rad
        ):
            self._turning = True
            self._speed = 0.0
            w = float(np.clip(1.5 * heading_error, -p.max_yaw_rate_rps, p.max_yaw_rate_rps))
            return Command(0.0, w, self.index, False)
        self._turning = False
        last = not self.loop and self.index == len(self.points) - 1
        dist_goal = float(np.linalg.norm(target - pos))
        v_goal = p.speed_mps * min(1.0, dist_goal / p.slowdown_radius_m) if last else p.speed_mps
        v_target = max(0.1, v_goal) * max(0.2, np.cos(heading_error))
        self._speed = float(min(v_target, self._speed + p.accel_mps2 * dt_s))
        dist = max(float(np.hypot(dx, dy)), 1e-6)
        curvature = 2.0 * np.sin(heading_error) / dist
        w = float(np.clip(self._speed * curvature, -p.max_yaw_rate_rps, p.max_yaw_rate_rps))
        return Command(self._speed, w, self.index, False)

    def _carrot(self, pos: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The point ``lookahead_m`` ahead on the segment leading to ``target`` (or the target)."""
        if self.index == 0 and not self.loop:
            return target
        start = self.points[self.index - 1]
        seg = target - start
        length = float(np.linalg.norm(seg))
        if length < 1e-9:
            return target
        u = seg / length
        along = float(np.clip((pos - start) @ u, 0.0, length))
        ahead = min(length, along + self.params.lookahead_m)
        return start + u * ahead
