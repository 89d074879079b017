"""Follow a route of waypoints with a differential-drive robot (pure pursuit on a polyline).

Pure algorithm: poses in, twist out. No simulator, no file format.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


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


@dataclass(frozen=True)
class PursuitParams:
    """Regulated pure pursuit (after Nav2's RPP)."""

    max_speed_mps: float = 1.0
    min_lookahead_m: float = 0.8
    max_lookahead_m: float = 2.0
    lookahead_time_s: float = 1.2
    accel_mps2: float = 0.6
    decel_mps2: float = 1.0
    max_yaw_rate_rps: float = 0.8
    rotate_in_place_rad: float = 0.8  # turn on the spot when the path is this far off heading
    regulated_radius_m: float = 2.0  # slow down on curves tighter than this
    min_regulated_speed_mps: float = 0.25
    approach_distance_m: float = 1.2  # slow down this close to the goal
    goal_tolerance_m: float = 0.3
    # a section that ends before the path does (a turn on the spot, a change of direction) ends only
    # this close along the path to its end vertex: the plan reserved the turn there (a pallet truck
    # that turned 0.28 m short of its turn vertex swept its tail into a shelf end)
    stop_tolerance_m: float = 0.05


class PathFollower:
    """Follow a planned polyline to its end with regulated pure pursuit.

    Speed is limited by curvature, by the distance to the goal and by an external limit (the
    multi-robot coordinator, the safety layer); acceleration is bounded.

    ``reverse`` (per segment of the path, optional): segments driven backwards. The path is cut
    into sections where the direction changes; the robot drives each section to its end, stops
    there and drives the next. Backwards it pursues the path with its tail (the mirrored unicycle:
    heading + pi, the linear speed negated). A path that turns back on itself at a cusp is thus
    never projected onto the wrong part. ``stops`` (vertex indices, optional): sections end there
    too, so the robot reaches such a vertex before it turns towards the next section (a fleet
    plan's turn on the spot; pursued across the corner, it turned before the vertex, where the
    plan had reserved no turn, and swept into a shelf).
    """

    def __init__(
        self,
        path_xy: NDArray[np.float64],
        params: PursuitParams,
        reverse: Sequence[bool] | None = None,
        stops: Sequence[int] | None = None,
    ) -> None:
        self.path = np.asarray(path_xy, dtype=float).reshape(-1, 2)
        self.params = params
        seg = np.diff(self.path, axis=0)
        self._seg_len = np.linalg.norm(seg, axis=1)
        self._cum = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        self.length_m = float(self._cum[-1])
        self.reverse = tuple(bool(b) for b in reverse) if reverse is not None else None
        if self.reverse is not None and len(self.reverse) != len(self._seg_len):
            raise ValueError(f"reverse has {len(self.reverse)} flags for {len(self._seg_len)} segments")
        self.stops = tuple(sorted(int(k) for k in stops)) if stops else None
        self._ends, self._backs = self._sections()
        self.section = 0  # the section driven now
        self._progress_m = 0.0
        self._speed = 0.0
        self._rotating = False
        self.done = self.length_m < 1e-6

    def _sections(self) -> tuple[list[float], list[bool]]:
        """Arc length at the end of each section (a run of segments driven one way, up to a stop)
        and its way."""
        n = len(self._seg_len)
        way = self.reverse if self.reverse is not None else (False,) * n
        stops = set(self.stops or ())
        ends, backs = [], [bool(way[0])] if n else [False]
        for i in range(1, n):
            if way[i] != way[i - 1] or i in stops:
                ends.append(float(self._cum[i]))
                backs.append(bool(way[i]))
        ends.append(self.length_m)
        return ends, backs

    @property
    def reversing(self) -> bool:
        """Whether the section driven now is driven backwards."""
        return self._backs[self.section]

    def ahead_xy(self) -> NDArray[np.float64]:
        """The rest of the section driven now, from the progress so far (N >= 1, 2)."""
        end = self._ends[self.section]
        inner = self.path[(self._cum > self._progress_m) & (self._cum < end)]
        return np.vstack([self.point_at(self._progress_m), inner, self.point_at(end)])

    def _project(self, p: NDArray[np.float64]) -> float:
        """Arc length of the closest path point to ``p``, searched forward of the progress so far,
        within the section driven now."""
        best_s, best_d = self._progress_m, np.inf
        end = self._ends[self.section]
        start = self._ends[self.section - 1] if self.section else 0.0
        for i in range(len(self._seg_len)):
            if self._cum[i] >= end - 1e-9:
                break
            if self._cum[i + 1] < self._progress_m - 0.5 or self._cum[i + 1] <= start + 1e-9:
                continue
            a, L = self.path[i], self._seg_len[i]
            if L < 1e-9:
                continue
            u = (self.path[i + 1] - a) / L
            t = float(np.clip((p - a) @ u, 0.0, L))
            d = float(np.linalg.norm(a + t * u - p))
            if d < best_d:
                best_d, best_s = d, self._cum[i] + t
            if self._cum[i] > self._progress_m + 5.0:
                break
        return max(best_s, self._progress_m)

    def point_at(self, s: float) -> NDArray[np.float64]:
        s = float(np.clip(s, 0.0, self.length_m))
        i = int(np.clip(np.searchsorted(self._cum, s, side="right") - 1, 0, len(self._seg_len) - 1))
        L = self._seg_len[i]
        t = 0.0 if L < 1e-9 else (s - self._cum[i]) / L
        return self.path[i] + t * (self.path[i + 1] - self.path[i])

    def points_at(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`point_at` for an array of arc lengths (N,) -> (N, 2), the same numbers."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length_m)
        i = np.clip(np.searchsorted(self._cum, s, side="right") - 1, 0, len(self._seg_len) - 1)
        L = self._seg_len[i]
        safe = np.where(L < 1e-9, 1.0, L)
        t = np.where(L < 1e-9, 0.0, (s - self._cum[i]) / safe)
        return self.path[i] + t[:, None] * (self.path[i + 1] - self.path[i])

    def remaining_m(self) -> float:
        return self.length_m - self._progress_m

    def step(
        self, x: float, y: float, yaw: float, dt_s: float, *, speed_limit_mps: float | None = None
    ) -> tuple[float, float]:
        """Twist (v, w) for the next ``dt_s``; sets ``done`` at the goal."""
        p = self.params
        if self.done:
            self._speed = 0.0
            return 0.0, 0.0
        pos = np.array([x, y])
        while True:  # the section driven now: at its end, on to the next
            end = self._ends[self.section]
            self._progress_m = min(self._project(pos), end)
            goal = self.point_at(end)
            dist_goal = float(np.linalg.norm(goal - pos))
            if self.section < len(self._ends) - 1:  # a stop on the way: reached along the path
                reached = end - self._progress_m < p.stop_tolerance_m and dist_goal < p.goal_tolerance_m
            else:
                reached = dist_goal < p.goal_tolerance_m or (
                    end - self._progress_m < p.goal_tolerance_m and dist_goal < 2 * p.goal_tolerance_m
                )
            if not reached:
                break
            self._speed = 0.0
            if self.section == len(self._ends) - 1:
                self.done = True
                return 0.0, 0.0
            self.section += 1
            self._progress_m = end
        back = self._backs[self.section]
        if back:
            yaw = yaw + np.pi  # its tail leads
        lookahead = float(np.clip(self._speed * p.lookahead_time_s, p.min_lookahead_m, p.max_lookahead_m))
        carrot = self.point_at(min(self._progress_m + lookahead, end))
        if np.linalg.norm(carrot - pos) < 1e-6:
            carrot = goal
        dx, dy = carrot - pos
        alpha = float((np.arctan2(dy, dx) - yaw + np.pi) % (2 * np.pi) - np.pi)
        if abs(alpha) > p.rotate_in_place_rad or (
            self._rotating and abs(alpha) > 0.25 * p.rotate_in_place_rad
        ):
            self._rotating = True
            self._speed = 0.0
            return 0.0, float(np.clip(1.5 * alpha, -p.max_yaw_rate_rps, p.max_yaw_rate_rps))
        self._rotating = False
        dist = max(float(np.hypot(dx, dy)), 1e-6)
        curvature = 2.0 * np.sin(alpha) / dist
        v = p.max_speed_mps
        if abs(curvature) > 1e-9 and 1.0 / abs(curvature) < p.regulated_radius_m:
            v = max(p.min_regulated_speed_mps, v * (1.0 / abs(curvature)) / p.regulated_radius_m)
        v = min(v, max(0.15, p.max_speed_mps * dist_goal / p.approach_distance_m))
        if speed_limit_mps is not None:
            v = min(v, speed_limit_mps)
        if v < self._speed:
            self._speed = max(v, self._speed - p.decel_mps2 * dt_s)
        else:
            self._speed = min(v, self._speed + p.accel_mps2 * dt_s)
        w = float(np.clip(self._speed * curvature, -p.max_yaw_rate_rps, p.max_yaw_rate_rps))
        return (-self._speed if back else self._speed), w
