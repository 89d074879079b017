"""Navigation dry run: the GPSS stack driving ideal unicycles on ground truth, no simulator.

Seconds instead of minutes to check that a set of routes is drivable and that the coordinator
resolves its conflicts (waits, detours, deadlocks) before paying for physics and cameras. Robots
move exactly as commanded (with the robot type's acceleration limit); there are no cameras, so
localization is ground truth (``source=ground_truth``).

Pure numpy/shapely.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from simlan_data.algorithms.coordinator import footprint_polygon
from simlan_data.algorithms.occupancy import OccupancyGrid
from simlan_data.algorithms.roles import CoordinatorContext
from simlan_data.algorithms.safety import SafetyEvent, SafetyLayer, TreesConfig
from simlan_data.algorithms.stack import AgentPlan, GpssStack, NavigationParams
from simlan_data.constants import NS_PER_S
from simlan_data.geometry.rotations import wrap_angle


@dataclass
class DryRunResult:
    duration_s: float
    goals_reached: dict[str, int]
    goals_total: dict[str, int]
    finished_s: dict[str, float | None]  # when each robot reached its last goal
    min_gap_m: float  # smallest distance between any two footprints over the run
    min_gap_pair: tuple[str, str] | None
    waits_s: dict[str, float]
    trajectories: dict[str, np.ndarray] = field(default_factory=dict)  # (N, 4): t, x, y, yaw
    safety_events: list[SafetyEvent] = field(default_factory=list)

    @property
    def all_goals_reached(self) -> bool:
        return all(self.goals_reached[ns] == self.goals_total[ns] for ns in self.goals_total)


def dry_run(
    agents: list[AgentPlan],
    grid: OccupancyGrid,
    nav: NavigationParams,
    *,
    duration_s: float,
    control_hz: float = 20.0,
    accel_mps2: float = 1.0,
    safety: TreesConfig | None = None,
    coordinator: Callable[[CoordinatorContext], Any] | None = None,
) -> DryRunResult:
    """Drive ``agents`` (diff-drive robots and walkers) for ``duration_s`` with the GPSS stack
    (and its safety layer, on ground truth, if ``safety`` is given; ``coordinator``: another
    coordinator than the built-in ``gpss``, built from its context as ``GpssStack`` builds it)."""
    dt = 1.0 / control_hz
    stack = GpssStack(
        agents,
        {},
        grid,
        nav=nav,
        source="ground_truth",
        coordinator=coordinator,
        safety=None if safety is None else (lambda ctx: SafetyLayer(safety, ctx)),
        control_period_s=dt,
    )
    poses = {a.namespace: np.array(a.pose, dtype=float) for a in agents}
    speeds = {a.namespace: 0.0 for a in agents}
    traj: dict[str, list[tuple[float, float, float, float]]] = {a.namespace: [] for a in agents}
    finished: dict[str, float | None] = dict.fromkeys(stack.navigators)
    min_gap, min_pair = np.inf, None
    kinds = {a.namespace: a.kind for a in agents}
    steps = round(duration_s * control_hz)
    for k in range(steps):
        t = k * dt
        truth = {ns: (float(p[0]), float(p[1]), float(p[2])) for ns, p in poses.items()}
        out = stack.control(round(t * NS_PER_S), dt, truth)
        for ns, (v_cmd, w) in out.commands.items():
            dv = float(np.clip(v_cmd - speeds[ns], -accel_mps2 * dt, accel_mps2 * dt))
            speeds[ns] += dv
            x, y, yaw = poses[ns]
            v = speeds[ns]
            poses[ns] = np.array(
                [x + v * np.cos(yaw) * dt, y + v * np.sin(yaw) * dt, wrap_angle(yaw + w * dt)]
            )
            px, py, pyaw = (float(v) for v in poses[ns])
            traj[ns].append((t, px, py, pyaw))
        for ns, navigator in stack.navigators.items():
            if finished[ns] is None and navigator.goal is None:
                finished[ns] = t
        shapes = {
            ns: footprint_polygon(tuple(map(float, p)), kinds[ns].footprint_m)  # type: ignore[arg-type]
            for ns, p in poses.items()
        }
        names = sorted(shapes)
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                gap = shapes[a].distance(shapes[b])
                if gap < min_gap:
                    min_gap, min_pair = gap, (a, b)
    return DryRunResult(
        duration_s,
        {ns: n.status.goals_reached for ns, n in stack.navigators.items()},
        {ns: n.status.goals_total for ns, n in stack.navigators.items()},
        finished,
        float(min_gap),
        min_pair,
        {ns: getattr(stack.coordinator, "waits", {}).get(ns, 0) * dt for ns in stack.navigators},
        {ns: np.array(v) for ns, v in traj.items()},
        list(stack.safety_events),
    )
