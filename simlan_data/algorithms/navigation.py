"""Navigation of one robot to its goals: plan on the grid, follow with pure pursuit, on estimates.

Pure numpy: inputs are the robot's estimated pose and the coordinator's decision, the output is a
velocity command. It never sees ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.coordinator import Decision, Intent
from simlan_data.algorithms.follower import PathFollower, PursuitParams
from simlan_data.algorithms.planner import GridPlanner, Plan, PlanningError

DETOUR_MAX_FACTOR = 1.5
DETOUR_MAX_EXTRA_M = 6.0


@dataclass
class NavigationStatus:
    goals_total: int
    goals_reached: int = 0
    goals_failed: int = 0
    state: str = "idle"  # idle | waiting_localization | waiting | following | safety_stop | done
    planned_length_m: float = 0.0  # sum of the first plan's length of every goal
    plans: int = 0
    failures: list[str] = field(default_factory=list)


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
            self.status.failures.append(str(err))
            self.status.goals_failed += 1
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
        self.follower = PathFollower(plan.points_xy, self.pursuit)
        self.status.plans += 1
        if self._goal_first_plan:
            self.status.planned_length_m += plan.length_m
            self._goal_first_plan = False
        self.new_plan = True

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

    def intent(
        self,
        pose_xyyaw: tuple[float, float, float] | None,
        priority: int,
        footprint_m: tuple[float, float, float, float],
    ) -> Intent | None:
        if pose_xyyaw is None:
            return None
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
            return 0.0, 0.0
        if pose_xyyaw is None:
            self.status.state = "waiting_localization"
            return 0.0, 0.0
        x, y, yaw = pose_xyyaw
        if self.follower is None:
            self._make_plan(x, y)
            if self.follower is None:
                return 0.0, 0.0
        limit = None if decision is None else decision.speed_limit_mps
        assert self.follower is not None
        v, w = self.follower.step(x, y, yaw, dt_s, speed_limit_mps=limit)
        self.status.state = "waiting" if limit == 0.0 else "following"
        if self.follower.done:
            self.status.goals_reached += 1
            self._advance()
            if self.goal is None:
                self.status.state = "done"
        return v, w
