"""Navigation of one robot to its goals: plan on the grid, follow with pure pursuit, on estimates.

Pure numpy: inputs are the robot's estimated pose and the coordinator's decision, the output is a
velocity command. It never sees ground truth.

A goal the robot does not reach fails for one of :data:`FAILURE_REASONS`:

- ``unreachable``: the planner found no path to it (given up at once, the next goal follows);
- ``blocked``: the run ended while the robot had made no progress towards it (moved less than
  :data:`PROGRESS_M` on its estimated pose) for at least :data:`BLOCKED_AFTER_S`: stopped by the
  safety layer, by the coordinator, behind another robot, or without a pose estimate;
- ``timeout``: the run ended first (the robot was still making progress, or had not started on
  the goal yet).

The state of the status that records a failure is ``failed_<reason>`` (:func:`failure_reason`
reads it back), so the reason travels in the navigation status message without a new field.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.coordinator import Decision, Intent
from simlan_data.algorithms.follower import PathFollower, PursuitParams
from simlan_data.algorithms.planner import GridPlanner, Plan, PlanningError
from simlan_data.constants import NS_PER_S

DETOUR_MAX_FACTOR = 1.5
DETOUR_MAX_EXTRA_M = 6.0
FAILURE_REASONS = ("unreachable", "blocked", "timeout")
FAILED_STATE_PREFIX = "failed_"
BLOCKED_AFTER_S = 10.0  # no progress for this long when the run ends: blocked, not timeout
PROGRESS_M = 0.1  # the estimated position moved at least this far: progress


def failure_reason(state: str) -> str | None:
    """The reason a status with ``state`` records a failed goal for, or None (not a failure)."""
    if state.startswith(FAILED_STATE_PREFIX):
        return state[len(FAILED_STATE_PREFIX) :]
    return None


@dataclass
class NavigationStatus:
    goals_total: int
    goals_reached: int = 0
    goals_failed: int = 0
    # idle | waiting_localization | waiting | following | safety_stop | done | failed_<reason>
    state: str = "idle"
    planned_length_m: float = 0.0  # sum of the first plan's length of every goal
    plans: int = 0
    failures: list[str] = field(default_factory=list)  # why, one line per failed goal
    failed_by_reason: dict[str, int] = field(default_factory=lambda: dict.fromkeys(FAILURE_REASONS, 0))

    def fail(self, reason: str, count: int, why: str) -> None:
        """Count ``count`` goals failed for ``reason`` (one of FAILURE_REASONS)."""
        self.goals_failed += count
        self.failed_by_reason[reason] += count
        self.failures += [why] * count
        self.state = FAILED_STATE_PREFIX + reason


class Navigator:
    """Drive through ``goals`` in order (or in a loop)."""

    def __init__(
        self,
        namespace: str,
        goals: list[list[float]],
        planner: GridPlanner,
        pursuit: PursuitParams,
        *,
        loop: bool = False,
    ) -> None:
        self.namespace = namespace
        self.goals = [np.asarray(g, dtype=float) for g in goals]
        self.planner, self.pursuit, self.loop = planner, pursuit, loop
        self.index = 0
        self.follower: PathFollower | None = None
        self.plan: Plan | None = None
        self.new_plan = False  # set when a plan was made; the caller publishes and clears it
        self.status = NavigationStatus(len(self.goals))
        self._goal_first_plan = True
        self._pose: tuple[float, float] | None = None  # the newest estimated position given
        self._anchor: tuple[float, float] | None = None  # where progress was last seen ...
        self._progress_ns: int | None = None  # ... and when (None: not yet clocked on this goal)
        self.aside: PathFollower | None = None  # with every goal done: a way out of others' way

    @property
    def goal(self) -> NDArray[np.float64] | None:
        if self.index >= len(self.goals):
            return None
        return self.goals[self.index]

    def _make_plan(self, x: float, y: float) -> None:
        goal = self.goal
        assert goal is not None
        try:
            plan = self.planner.plan((x, y), (float(goal[0]), float(goal[1])))
        except PlanningError as err:
            self.status.fail("unreachable", 1, str(err))
            self._advance()
            return
        self._adopt(plan)

    def detour(self, x: float, y: float, blocked: NDArray[np.bool_]) -> Plan | None:
        """A path to the current goal that avoids ``blocked`` cells, or None if there is none that
        is not much longer than the rest of the current path (a long way round, maybe out of
        camera coverage: rather wait). The caller checks it and ``adopt``s it."""
        goal = self.goal
        if goal is None:
            return None
        remaining = (
            self.follower.remaining_m()
            if self.follower is not None
            else float(np.hypot(goal[0] - x, goal[1] - y))
        )
        try:
            return self.planner.plan(
                (x, y),
                (float(goal[0]), float(goal[1])),
                blocked=blocked,
                max_length_m=DETOUR_MAX_FACTOR * remaining + DETOUR_MAX_EXTRA_M,
            )
        except PlanningError:
            return None

    def adopt(self, plan: Plan) -> None:
        """Follow ``plan`` (a detour) from now on."""
        self._adopt(plan)

    def _adopt(self, plan: Plan) -> None:
        self.plan = plan
        self.follower = PathFollower(plan.points_xy, self.pursuit, plan.reverse, plan.stops)
        self.status.plans += 1
        if self._goal_first_plan:
            self.status.planned_length_m += plan.length_m
            self._goal_first_plan = False
        self.new_plan = True

    def move_aside(
        self,
        path_xy: NDArray[np.float64],
        reverse: tuple[bool, ...] | None = None,
        stops: tuple[int, ...] | None = None,
    ) -> None:
        """With every goal done, drive ``path_xy`` (a fleet coordinator moves an idle robot out of
        the others' way; ``reverse``: its segments driven backwards; ``stops``: vertices where it
        turns on the spot); it counts as no goal. A path equal to the one driven is kept."""
        if self.goal is not None or (
            self.aside is not None
            and np.array_equal(self.aside.path, path_xy)
            and self.aside.reverse == (tuple(reverse) if reverse is not None else None)
            and self.aside.stops == (tuple(sorted(stops)) if stops else None)
        ):
            return
        self.aside = PathFollower(path_xy, self.pursuit, reverse, stops)

    def ahead(self) -> tuple[NDArray[np.float64] | None, bool]:
        """The path ahead as the safety layer reads it, and whether it is driven backwards: the
        plan, or for a route with reversing the rest of the part driven now (a route that turns
        back on itself is not projected onto the wrong part)."""
        follower = self.follower if self.goal is not None else self.aside
        if follower is None or (follower.reverse is None and follower.stops is None):
            return (self.plan.points_xy if self.plan is not None else None), False
        return follower.ahead_xy(), follower.reversing

    def cancel(self) -> None:
        """Drop the current plan: the safety layer stopped the robot. The goal stays; a new plan
        is made from wherever the robot stands once it may drive again."""
        self.follower, self.plan = None, None
        self.status.state = "safety_stop"

    def _advance(self) -> None:
        self.index += 1
        if self.loop and self.index >= len(self.goals):
            self.index = 0
        self.follower, self.plan = None, None
        self._goal_first_plan = True
        self._anchor = self._progress_ns = None

    def clock(self, t_ns: int) -> None:
        """Note the time of a control tick: progress is the estimated position moving
        :data:`PROGRESS_M` from where it was when progress was last seen (or the goal began)."""
        if self.goal is None:
            return
        if self._progress_ns is None:  # the goal's first tick
            self._anchor, self._progress_ns = self._pose, t_ns
        elif self._pose is None:  # no estimate yet: no progress
            return
        elif self._anchor is None:  # the first estimate: where progress is measured from
            self._anchor = self._pose
        elif np.hypot(*np.subtract(self._pose, self._anchor)) >= PROGRESS_M:
            self._anchor, self._progress_ns = self._pose, t_ns

    def finish(self, t_ns: int) -> list[tuple[str, int]]:
        """The run ends at ``t_ns``: fail the goals left (none on a loop), the current one
        ``blocked`` if the robot made no progress for :data:`BLOCKED_AFTER_S`, the rest ``timeout``.

        Returns (reason, count) in the order they were counted (each one status to publish).
        """
        if self.loop or self.goal is None:
            return []
        out: list[tuple[str, int]] = []
        left = len(self.goals) - self.index
        stalled_s = None if self._progress_ns is None else (t_ns - self._progress_ns) / NS_PER_S
        if stalled_s is not None and stalled_s >= BLOCKED_AFTER_S:
            self.status.fail("blocked", 1, f"no progress for {stalled_s:.1f} s when the run ended")
            out.append(("blocked", 1))
            left -= 1
        if left:
            self.status.fail("timeout", left, "the run ended first")
            out.append(("timeout", left))
        self.index = len(self.goals)
        self.follower, self.plan = None, None
        return out

    def intent(
        self,
        pose_xyyaw: tuple[float, float, float] | None,
        priority: int,
        footprint_m: tuple[float, float, float, float],
    ) -> Intent | None:
        if pose_xyyaw is None:
            return None
        self._pose = (pose_xyyaw[0], pose_xyyaw[1])
        ahead = None
        if self.follower is not None and not self.follower.done:
            f = self.follower
            start = f.remaining_m()
            s0 = f.length_m - start
            samples = np.arange(s0, min(f.length_m, s0 + 4.0) + 1e-9, 0.25)
            ahead = np.vstack([[pose_xyyaw[0], pose_xyyaw[1]], f.points_at(samples)])
        return Intent(self.namespace, priority, pose_xyyaw, footprint_m, ahead)

    def step(
        self,
        pose_xyyaw: tuple[float, float, float] | None,
        dt_s: float,
        decision: Decision | None = None,
    ) -> tuple[float, float]:
        """Twist for the next ``dt_s`` given the estimated pose (None: no valid estimate)."""
        if self.goal is None:
            self.status.state = "done"
            return self._step_aside(pose_xyyaw, dt_s, decision)
        if pose_xyyaw is None:
            self.status.state = "waiting_localization"
            return 0.0, 0.0
        x, y, yaw = pose_xyyaw
        self._pose = (x, y)
        if self.follower is None:
            self._make_plan(x, y)
            if self.follower is None:
                return 0.0, 0.0
        limit = None if decision is None else decision.speed_limit_mps
        assert self.follower is not None
        v, w = _held(decision, *self.follower.step(x, y, yaw, dt_s, speed_limit_mps=limit))
        self.status.state = "waiting" if limit == 0.0 else "following"
        if self.follower.done and not self._ends_at_goal(self.follower):
            self.status.state = "waiting"  # a coordinator's route that stops short (a window, a queue)
            return 0.0, 0.0
        if self.follower.done:
            self.status.goals_reached += 1
            self._advance()
            if self.goal is None:
                self.status.state = "done"
        return v, w

    def _ends_at_goal(self, follower: PathFollower) -> bool:
        """Whether the path followed ends at the goal (a coordinator's windowed or queued route
        ends before it: done with it, the robot waits for the next one)."""
        goal = self.goal
        end = follower.path[-1]
        return (
            goal is None
            or float(np.hypot(end[0] - goal[0], end[1] - goal[1])) <= 2 * self.pursuit.goal_tolerance_m
        )

    def _step_aside(
        self, pose_xyyaw: tuple[float, float, float] | None, dt_s: float, decision: Decision | None
    ) -> tuple[float, float]:
        """Done: stand, or follow the way aside the coordinator gave, at its speed limit."""
        if self.aside is None or self.aside.done or pose_xyyaw is None:
            return 0.0, 0.0
        limit = None if decision is None else decision.speed_limit_mps
        x, y, yaw = pose_xyyaw
        return _held(decision, *self.aside.step(x, y, yaw, dt_s, speed_limit_mps=limit))


def _held(decision: Decision | None, v: float, w: float) -> tuple[float, float]:
    """The follower's twist, without a turn in place where the decision holds the robot at speed 0
    and forbids it (``Decision.turn_in_place``): a forklift held by a fleet plan turned towards its
    path and swept its forks into a pallet truck (docs/fleet.md)."""
    if decision is not None and decision.speed_limit_mps == 0.0 and not decision.turn_in_place and v == 0.0:
        return 0.0, 0.0
    return v, w
