"""A kinematic fleet: robots that drive a coordinator's routes exactly, without physics or cameras.

It runs a coordinator (any object with the role's ``decide(t_ns, intents)``) at algorithm level:
each robot follows the path of its ``Decision`` (``path_xy``) at its speed under the decision's
speed limit, faces where it drives, and records where it was. A robot whose goals are done drives
only a way aside it is given. Fast enough for hundreds of seeded missions a minute per core, so the
coordinator's own behaviour (goals reached, clearance, deadlocks) can be measured apart from the
simulator's (tests/test_fleet_coordinator.py, benchmarks/fleet_kinematic.py).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import polars as pl
from numpy.typing import NDArray

from simlan_data.algorithms.coordinator import Intent
from simlan_data.algorithms.coverage import robot_floors, seen_by_all
from simlan_data.algorithms.fleet import FleetConfig, FleetCoordinator
from simlan_data.algorithms.occupancy import grid_from_world
from simlan_data.algorithms.roles import CoordinatorContext
from simlan_data.algorithms.safety.geometry import Footprint, footprint_polygon
from simlan_data.config.missions import MissionsConfig, generate_missions
from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.fleet_metrics import Status, fleet_metrics
from simlan_data.geometry.camera import CameraModel
from simlan_data.world.agent_types import AGENT_TYPES, AgentType
from simlan_data.world.layout import load_layout

CLEARANCE_M = 0.4  # navigation.clearance_m's default (the smallest planner radius's margin)


@dataclass
class _Robot:
    pose: list[float]
    goals: list[tuple[float, float]]
    fp: Footprint
    speed_mps: float
    path: NDArray[np.float64] | None = None
    reverse: tuple[bool, ...] | None = None  # per segment of ``path``: driven backwards
    s: float = 0.0  # metres along ``path``
    dwell_until_s: float | None = None  # at a goal until then (served at a dock), then on
    reached: int = 0


@dataclass
class KinematicFleet:
    """Robots (name -> (pose x, y, yaw), goals, footprint[, speed]) driven by ``coordinator``."""

    coordinator: Any
    robots: dict[str, tuple]
    stopped: tuple[str, ...] = ()  # robots that never move (a fault): others must go round
    dwell_s: float = 0.0
    speed_mps: float = 0.5
    t_s: float = 0.0
    trace: list[dict[str, tuple[float, float, float]]] = field(default_factory=list)
    times_s: list[float] = field(default_factory=list)  # the time of each ``trace`` entry
    arrivals: list[tuple[float, str, tuple[float, float]]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._r = {
            n: _Robot(
                list(spec[0]),
                [tuple(g) for g in spec[1]],
                spec[2],
                float(spec[3]) if len(spec) > 3 else self.speed_mps,
            )
            for n, spec in self.robots.items()
        }

    def intents(self) -> list[Intent]:
        return [
            Intent(n, k + 1, tuple(r.pose), r.fp, None, goal_xy=r.goals[0] if r.goals else None)  # type: ignore[arg-type]
            for k, (n, r) in enumerate(sorted(self._r.items()))
        ]

    def step(self, dt: float = 0.1) -> None:
        """One control tick: the coordinator decides, every robot drives ``dt``."""
        decisions = self.coordinator.decide(round(self.t_s * NS_PER_S), self.intents())
        for n, r in self._r.items():
            d = decisions.get(n)
            if n in self.stopped or d is None or self._dwelling(r):
                continue
            if d.path_xy is not None and (r.path is None or not np.array_equal(r.path, d.path_xy)):
                r.path = np.asarray(d.path_xy, dtype=float)
                r.s = _along(r.path, np.asarray(r.pose[:2]))
            if d.path_xy is not None:
                r.reverse = d.path_reverse
            if r.path is None:
                continue
            self._drive(
                n, r, dt, r.speed_mps if d.speed_limit_mps is None else min(r.speed_mps, d.speed_limit_mps)
            )
        self.t_s += dt
        self.trace.append({n: (r.pose[0], r.pose[1], r.pose[2]) for n, r in self._r.items()})
        self.times_s.append(self.t_s)

    def _drive(self, name: str, r: _Robot, dt: float, v: float) -> None:
        assert r.path is not None
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(r.path, axis=0), axis=1))])
        r.s = min(cum[-1], r.s + v * dt)
        xy = np.array([np.interp(r.s, cum, r.path[:, i]) for i in (0, 1)])
        step = xy - np.asarray(r.pose[:2])
        yaw = float(np.arctan2(step[1], step[0])) if np.hypot(*step) > 1e-6 else r.pose[2]
        k = min(int(np.searchsorted(cum, r.s, side="left")) - 1, len(cum) - 2)
        if np.hypot(*step) > 1e-6 and r.reverse is not None and r.reverse[max(k, 0)]:
            yaw = float(np.arctan2(-step[1], -step[0]))  # it faces away from where it drives
        r.pose = [float(xy[0]), float(xy[1]), yaw]  # it faces where it drives (or reverses)
        if r.goals and r.s >= cum[-1] - 1e-9 and np.hypot(*(xy - np.asarray(r.goals[0]))) < 0.3:
            self.arrivals.append((self.t_s, name, r.goals[0]))
            r.dwell_until_s, r.path = self.t_s + self.dwell_s, None

    def _dwelling(self, r: _Robot) -> bool:
        """At a goal for dwell_s, then on to the next goal."""
        if r.dwell_until_s is None:
            return False
        if self.t_s < r.dwell_until_s:
            return True
        r.dwell_until_s = None
        r.goals.pop(0)
        r.reached += 1
        return False

    def run(self, seconds: float, dt: float = 0.1) -> None:
        """Step until every robot that can move has no goal left, or ``seconds`` pass."""
        for _ in range(round(seconds / dt)):
            self.step(dt)
            if all(not r.goals or n in self.stopped for n, r in self._r.items()):
                return

    def done(self, name: str) -> bool:
        return not self._r[name].goals

    def pose(self, name: str) -> list[float]:
        return list(self._r[name].pose)

    def goals_left(self) -> int:
        return sum(len(r.goals) for n, r in self._r.items() if n not in self.stopped)

    def path(self, name: str) -> NDArray[np.float64]:
        return np.array([snap[name][:2] for snap in self.trace])

    def metrics(self, kinds: Mapping[str, AgentType]) -> dict[str, float]:
        """The ``fleet.*`` metrics of a recording (:func:`fleet_metrics`: deadlocks, waits, clearance,
        tasks) computed on this run, so the coordinator alone is judged by the same definitions as
        a simulated run. ``kinds``: each robot's agent type (its footprint)."""
        stamps = np.round(np.asarray([0.0, *self.times_s]) * NS_PER_S).astype(np.int64)
        truth, status = {}, {}
        for n in self._r:
            poses = np.asarray([self.robots[n][0]] + [snap[n] for snap in self.trace], dtype=float)
            truth[n] = pl.DataFrame(
                {"stamp_ns": stamps, "x": poses[:, 0], "y": poses[:, 1], "yaw": poses[:, 2]}
            )
            total = len(self.robots[n][1])
            history: list[Status] = [(0, total, 0, 0, ())]
            reached = [t for t, name, _ in self.arrivals if name == n]
            history += [(round(t * NS_PER_S), total, k + 1, 0, ()) for k, t in enumerate(reached)]
            status[n] = history
        return fleet_metrics(truth, status, kinds)

    def min_gap_m(self, every: int = 1) -> float:
        """The smallest distance between two robots' footprints over the run (every n-th tick)."""
        names = sorted(self._r)
        gaps = [
            footprint_polygon(snap[a], self._r[a].fp).distance(footprint_polygon(snap[b], self._r[b].fp))
            for snap in self.trace[::every]
            for i, a in enumerate(names)
            for b in names[i + 1 :]
        ]
        return float(min(gaps)) if gaps else float("inf")


def mission_fleet(
    robots: int,
    seed: int,
    *,
    tasks: int = 3,
    dwell_s: float = 2.0,
    safety_m: float = 0.6,
    cameras: Sequence[CameraModel] = (),
    types: Sequence[str] | None = None,
    config: FleetConfig | None = None,
) -> tuple[KinematicFleet, dict[str, AgentType]]:
    """The seeded missions of ``scenario=fleet`` (same generator and seed as a run) on the real
    layout's occupancy grid, driven by ``algorithms/coordinator=fleet``: the kinematic fleet and each
    robot's agent type. ``safety_m``: navigation.safety_distance_m (its default). With ``cameras``
    (robots that steer on them, as in a run): missions on the floor they see, and the coordinator
    given that floor as the run's stack gives it (``CoordinatorContext.seen``). ``config``: the
    coordinator's (default: ``FleetConfig()``)."""
    spec_cfg = MissionsConfig(robots=robots, tasks=tasks)
    if types is not None:
        spec_cfg = MissionsConfig(robots=robots, tasks=tasks, types=list(types))
    missions = generate_missions(spec_cfg, seed=seed, cameras=tuple(cameras))
    grid = grid_from_world(load_layout("warehouse_layout.csv", "default"), resolution_m=0.1)
    kinds = {n: AGENT_TYPES[a["type"]] for n, a in missions.agents.items()}
    seen = None
    floors = robot_floors(grid, cameras, kinds.values(), clearance_m=CLEARANCE_M) if cameras else {}
    if floors:
        seen = seen_by_all(floors.values()).by_heading
    coordinator = FleetCoordinator(config or FleetConfig(), CoordinatorContext(safety_m, grid, seen))
    spec = {
        n: (tuple(a["pose"]), [tuple(g) for g in a["goals"]], kinds[n].footprint_m, a["speed_mps"])
        for n, a in missions.agents.items()
    }
    return KinematicFleet(coordinator, spec, dwell_s=dwell_s), kinds


def _along(path: NDArray[np.float64], xy: NDArray[np.float64]) -> float:
    """Arc length of the point of ``path`` nearest to ``xy`` (a new path is joined where it is)."""
    a, b = path[:-1], path[1:]
    seg = b - a
    den = np.maximum(np.sum(seg * seg, axis=1), 1e-18)
    t = np.clip(np.sum((xy - a) * seg, axis=1) / den, 0.0, 1.0)
    k = int(np.argmin(np.linalg.norm(a + t[:, None] * seg - xy, axis=1))) if len(seg) else 0
    cum = np.concatenate([[0.0], np.cumsum(np.sqrt(den))])
    return float(cum[k] + t[k] * np.sqrt(den[k])) if len(seg) else 0.0
