"""What the report's figures show, read from a recording (so a report can be rebuilt from one).

One raw pass over the small topics (served from the reader's cache after the metrics read them),
then decoding only what a figure needs: every message would cost about 45 us each (a 60 s run of
one robot holds ~11,000 of them: 0.5 s), so the control-rate topics and ground truth are decoded
at no more than :data:`MAX_POINTS` ticks per series; rare topics (navigation status, safety
events, zones, collisions of an agent that collided) are decoded whole.

    recording --raw pass--> by topic --kept ticks--> decode --> RunSeries --> report_figures
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.metrics import RecordedRows, _yaw
from simlan_data.recording import schema
from simlan_data.recording.reader import Message, RecordingReader

MAX_POINTS = 400  # samples per series: a figure 1,000 px wide shows no more
FOOTPRINT_SAMPLES = 12  # image-border points per side for a camera's floor footprint
FLOOR_RESOLUTION_M = 0.1

F64 = NDArray[np.float64]


@dataclass
class AgentSeries:
    """One agent over time (simulated seconds)."""

    namespace: str
    kind: str
    truth: F64  # (N, 4) t, x, y, yaw
    estimate: F64  # (M, 5) t, x, y, yaw, valid (1/0); rows without a pose estimate are left out
    commanded: F64  # (K, 2) t, forward speed commanded (m/s)
    estimated_speed: F64  # (K, 2) t, forward speed estimated (m/s)
    goals: F64  # (G, 2) x, y
    goals_reached_s: list[float] = field(default_factory=list)
    goals_failed_s: list[float] = field(default_factory=list)
    collisions_s: list[float] = field(default_factory=list)

    def true_speed(self) -> F64:
        """(N, 2) t, forward speed from ground truth (signed along the heading)."""
        t, x, y, yaw = self.truth.T if len(self.truth) else (np.zeros(0),) * 4
        if len(t) < 2:
            return np.zeros((0, 2))
        vx, vy = np.gradient(x, t), np.gradient(y, t)
        return np.stack([t, vx * np.cos(yaw) + vy * np.sin(yaw)], axis=1)

    def errors(self) -> F64:
        """(M, 3) t, xy error (m), |yaw error| (deg) of the valid estimates against ground truth
        at the same ticks (interpolated where ground truth has no sample at a tick)."""
        est = self.estimate[self.estimate[:, 4] > 0] if len(self.estimate) else self.estimate
        if len(est) == 0 or len(self.truth) < 2:
            return np.zeros((0, 3))
        t = self.truth[:, 0]
        gx, gy = np.interp(est[:, 0], t, self.truth[:, 1]), np.interp(est[:, 0], t, self.truth[:, 2])
        gyaw = np.interp(est[:, 0], t, np.unwrap(self.truth[:, 3]))
        dyaw = (est[:, 3] - gyaw + np.pi) % (2 * np.pi) - np.pi
        return np.stack(
            [est[:, 0], np.hypot(est[:, 1] - gx, est[:, 2] - gy), np.degrees(np.abs(dyaw))], axis=1
        )


@dataclass(frozen=True)
class Event:
    """A safety event: a robot stopped, slowed or drove on."""

    t_s: float
    namespace: str
    cause: str
    action: str  # stop | slow | resume
    detail: str


@dataclass
class RunSeries:
    """Everything the figures draw."""

    duration_s: float
    agents: dict[str, AgentSeries]
    events: list[Event]
    zones: list[tuple[str, F64]]  # name, (P, 2) polygon
    cameras: dict[str, tuple[F64, F64 | None]]  # id: position (3,), floor footprint (P, 2)
    config: dict[str, Any]


def _seconds(stamp_ns: int) -> float:
    return stamp_ns / NS_PER_S


def _stride(n: int) -> int:
    return max(1, math.ceil(n / MAX_POINTS))


def kept_ticks(stamps: Iterable[int]) -> set[int]:
    """At most :data:`MAX_POINTS` of the control ticks, evenly spread (every k-th)."""
    ticks = sorted(set(stamps))
    return set(ticks[:: _stride(len(ticks))])


def read_series(
    reader: RecordingReader,
    config: Mapping[str, Any],
    cameras: Mapping[str, Any],
    metrics: Mapping[str, float],
) -> RunSeries:
    """The figures' data from a recording (``config``: its /simlan/config; ``cameras``: its
    cameras; ``metrics``: says which agents collided, so only their collision topic is read whole)."""
    agents = dict(config.get("agents") or {})
    topics = {ns: schema.agent_topics(ns) for ns in agents}
    control = ("pose_estimate", "localization", "cmd_vel", "velocity_estimate")
    rare = ("navigation", "collision")
    wanted = [schema.GROUND_TRUTH_POSES, schema.SAFETY_EVENTS, schema.SAFETY_ZONES]
    wanted += [topics[ns][k].name for ns in agents for k in (*control, *rare)]
    raw: dict[str, list[Message]] = defaultdict(list)
    for m in reader.messages([t for t in wanted if t in reader.topics], raw=True):
        raw[m.topic].append(m)
    ticks = kept_ticks(m.stamp_ns for ns in agents for k in control for m in raw[topics[ns][k].name])

    def decoded(topic: str, *, sampled: bool = False, every: int = 0) -> list[Message]:
        """All of ``topic``; or (``sampled``) those at the kept ticks, and every ``every``-th."""
        msgs = raw.get(topic, [])
        if sampled:
            msgs = [m for i, m in enumerate(msgs) if m.stamp_ns in ticks or (every and i % every == 0)]
        return [reader.deserialize(m) for m in msgs]

    truth_rows = RecordedRows()
    truth_every = _stride(len(raw[schema.GROUND_TRUTH_POSES]))
    for m in decoded(schema.GROUND_TRUTH_POSES, sampled=True, every=truth_every):
        truth_rows.add(m)
    out: dict[str, AgentSeries] = {}
    for ns, agent in agents.items():
        tp = topics[ns]
        collided = metrics.get(f"agents.{ns}.collisions", 0.0) or metrics.get(
            f"navigation.{ns}.collisions", 0.0
        )
        series = AgentSeries(
            ns,
            str(agent.get("type", "")),
            _pose_rows(truth_rows.truth.get(ns, [])),
            _estimate_rows(
                decoded(tp["pose_estimate"].name, sampled=True),
                decoded(tp["localization"].name, sampled=True),
            ),
            _speed_rows(decoded(tp["cmd_vel"].name, sampled=True)),
            _speed_rows(decoded(tp["velocity_estimate"].name, sampled=True)),
            np.asarray(agent.get("goals") or [], dtype=float).reshape(-1, 2),
        )
        _navigation_times(series, decoded(tp["navigation"].name))
        if collided:
            series.collisions_s = _collision_onsets(decoded(tp["collision"].name))
        out[ns] = series
    events = [
        Event(_seconds(m.stamp_ns), m.msg.robot, m.msg.cause, m.msg.action, m.msg.detail)
        for m in decoded(schema.SAFETY_EVENTS)
    ]
    return RunSeries(
        duration_s=float(metrics.get("sim.duration_s", _seconds(reader.duration_ns))),
        agents=out,
        events=events,
        zones=_zones(decoded(schema.SAFETY_ZONES)),
        cameras={
            cid: (np.asarray(cam.position, dtype=float), floor_footprint(cam)) for cid, cam in cameras.items()
        },
        config=dict(config),
    )


def _pose_rows(rows: list[tuple]) -> F64:
    if not rows:
        return np.zeros((0, 4))
    a = np.asarray(rows, dtype=float)
    a[:, 0] /= NS_PER_S
    return a


def _estimate_rows(estimates: list[Message], statuses: list[Message]) -> F64:
    valid = {m.stamp_ns: bool(m.msg.valid) for m in statuses}
    rows: list[tuple] = []
    for m in estimates:
        p = m.msg.pose.pose
        valid_at = float(valid.get(m.stamp_ns, True))
        rows.append((_seconds(m.stamp_ns), p.position.x, p.position.y, _yaw(p.orientation), valid_at))
    return np.asarray(rows, dtype=float).reshape(-1, 5)


def _speed_rows(messages: list[Message]) -> F64:
    return np.asarray([(_seconds(m.stamp_ns), m.msg.twist.linear.x) for m in messages], dtype=float).reshape(
        -1, 2
    )


def _navigation_times(series: AgentSeries, statuses: list[Message]) -> None:
    """When each goal was reached or given up (the status changes)."""
    reached = failed = 0
    for m in statuses:
        t = _seconds(m.stamp_ns)
        series.goals_reached_s += [t] * max(0, int(m.msg.goals_reached) - reached)
        series.goals_failed_s += [t] * max(0, int(m.msg.goals_failed) - failed)
        reached, failed = max(reached, int(m.msg.goals_reached)), max(failed, int(m.msg.goals_failed))


def _collision_onsets(states: list[Message]) -> list[float]:
    out, before = [], False
    for m in states:
        hit = bool(m.msg.in_collision)
        if hit and not before:
            out.append(_seconds(m.stamp_ns))
        before = hit
    return out


def _zones(messages: list[Message]) -> list[tuple[str, F64]]:
    """Restricted zones from /safety/zones: each a closed line strip, then its name (a text marker)."""
    if not messages:
        return []
    strips: list[F64] = []
    names: list[str] = []
    for marker in messages[-1].msg.markers:
        if marker.points:
            strips.append(np.array([(p.x, p.y) for p in marker.points], dtype=float))
        elif marker.text:
            names.append(str(marker.text))
    names += [f"zone {i + 1}" for i in range(len(names), len(strips))]
    return list(zip(names, strips, strict=False))


def floor_footprint(camera: Any) -> F64 | None:
    """The floor area a camera's image covers: its image border cast onto z = 0 (where it
    meets the floor), as a polygon; None if too little of the border does."""
    w, h = camera.width - 1, camera.height - 1
    s = np.linspace(0.0, 1.0, FOOTPRINT_SAMPLES, endpoint=False)
    border = np.concatenate(
        [
            np.stack([s * w, np.zeros_like(s)], 1),
            np.stack([np.full_like(s, w), s * h], 1),
            np.stack([(1 - s) * w, np.full_like(s, h)], 1),
            np.stack([np.zeros_like(s), (1 - s) * h], 1),
        ]
    )
    try:
        points, ok = camera.intersect_plane_z(border, 0.0)
    except (ValueError, np.linalg.LinAlgError):
        return None
    if ok.sum() < 3:
        return None
    return np.asarray(points[ok][:, :2], dtype=float)


def floor_plan(config: Mapping[str, Any]) -> Any | None:
    """The run's obstacles as an occupancy grid (its layout at its fidelity), None if unreadable."""
    from simlan_data.algorithms.occupancy import grid_from_world
    from simlan_data.errors import SimlanError
    from simlan_data.world.layout import load_layout

    world = config.get("world") or {}
    try:
        placements = load_layout(
            world.get("layout", "warehouse_layout.csv"), world.get("fidelity", "default")
        )
    except SimlanError:
        return None  # (a report is still written; the map just has no floor plan)
    return grid_from_world(placements, resolution_m=FLOOR_RESOLUTION_M)
