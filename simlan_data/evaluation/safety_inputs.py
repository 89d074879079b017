"""Read what the safety layer saw, and what really happened, from a recording.

One pass over the bag gives, per control tick: every robot's estimate (pose, velocity, fix age),
collision sensor reading, plan and navigation state, the people detections, the commands the
robots got and their recorded safety state; and ground truth at the same ticks. The metrics
(``safety_metrics.py``) and the counterfactual replay (``safety_replay.py``) both start here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms import registry
from simlan_data.algorithms.roles import SafetyContext
from simlan_data.algorithms.safety import (
    DRIVE,
    RobotEstimate,
    RobotSpec,
    SafetyEvent,
    TreeParams,
    TreesConfig,
    mover_of,
)
from simlan_data.config.legacy import with_algorithms
from simlan_data.constants import NS_PER_S
from simlan_data.errors import RecordingInputError
from simlan_data.evaluation.metrics import _yaw, ground_truth
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.agent_types import agent_type

DRIVE_KINDS = {"diff": "robot", "walker": "person", "static": "static"}


@dataclass
class Truth:
    """Ground truth of one agent at the control ticks."""

    pose: NDArray[np.float64]  # (N, 3) x, y, yaw
    speed_mps: NDArray[np.float64]  # signed, along the heading
    yaw_rate_rps: NDArray[np.float64]

    def at(self, i: int) -> tuple[float, float, float]:
        x, y, yaw = self.pose[i]
        return float(x), float(y), float(yaw)


@dataclass
class SafetyRecording:
    """Per-tick inputs and outcomes of a run (index i <-> ``ticks[i]``)."""

    config: dict[str, Any]
    specs: dict[str, RobotSpec]  # every agent
    robots: list[str]  # marker robots steered by GPSS
    goals: dict[str, int]
    spawn: dict[str, tuple[float, float, float]]
    ticks: NDArray[np.int64]
    camera_ticks: NDArray[np.int64]
    truth: dict[str, Truth]
    commands: dict[str, NDArray[np.float64]]  # (N, 2) v, w the robot got
    estimates: dict[str, list[RobotEstimate]]
    contacts: dict[str, list[tuple[float, tuple[str, ...]]]]
    plans: dict[str, list[NDArray[np.float64] | None]]  # plan messages at the tick (None: no new one)
    nav_states: dict[str, list[str | None]]  # navigation state published at the tick (None: no change)
    people: list[tuple[int, list[tuple[float, float]]]]  # (stamp, fused positions)
    states: dict[str, list[str]]  # recorded safety state per tick (robots with a tree)
    events: list[SafetyEvent]
    detections: dict[str, NDArray[np.int64]] = field(default_factory=dict)  # stamps a camera found the marker
    zones_topic: bool = False
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def control_period_s(self) -> float:
        return 1.0 / float(self.config.get("control_rate_hz", 20.0))

    @property
    def camera_period_s(self) -> float:
        return 1.0 / float((self.config.get("cameras") or {}).get("rate_hz", 5.0))

    def index(self, stamp_ns: int) -> int:
        """Index of the first tick at or after ``stamp_ns``."""
        return min(int(np.searchsorted(self.ticks, stamp_ns)), len(self.ticks) - 1)


def selected_safety(
    config: dict[str, Any], options: dict[str, Any] | None = None, *, where: str = "replay --set"
) -> tuple[registry.AlgorithmSpec, Any]:
    """The safety monitor and its config: the recording's, or ``options["safety"]`` (a registered
    name or module:Class); the other options are its config's dotted keys (``ttc.enabled``),
    applied over the recorded values (over none when another monitor is selected).

    Raises:
        ConfigError: an unknown name or key, a value its config rejects.
        RecordingInputError: a dotted key through a value that is not a section.
    """
    options = dict(options or {})
    name = options.pop("safety", None)
    recorded_name, values = registry.selection(with_algorithms(config), "safety")
    if name is not None and str(name) != recorded_name:
        values = {}
    spec = registry.resolve("safety", recorded_name if name is None else str(name), where=where)
    section: dict[str, Any] = {k: (dict(v) if isinstance(v, dict) else v) for k, v in values.items()}
    for key, value in options.items():
        parts = key.split(".")
        node = section
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise RecordingInputError(
                    f"invalid --set {key}", where, f"{p} is not a section", "check the key"
                )
        node[parts[-1]] = value
    safety_config = spec.make_config(section, where=where)
    check = getattr(safety_config, "check_namespaces", None)
    if callable(check):
        check(sorted(config.get("agents") or {}))
    return spec, safety_config


def processing_delay_s(config: dict[str, Any]) -> float:
    """The localizer's processing delay of a recorded run (``algorithms.localizer``; recordings
    made before the localizer was an algorithm kept it under ``localization``)."""
    localizer = with_algorithms(config)["algorithms"].get("localizer") or {}
    return float(localizer.get("processing_delay_s", 0.0))  # (0 for a localizer without one)


def safety_context(
    config: dict[str, Any], specs: dict[str, RobotSpec], spawn: dict[str, Any]
) -> SafetyContext:
    """What the live safety monitor was built with, from a recorded run's config."""
    static = [
        m
        for ns, spec in specs.items()
        if spec.kind == "static" and (m := mover_of(spec, RobotEstimate(spawn[ns]))) is not None
    ]
    return SafetyContext(
        list(specs.values()),
        static,
        1.0 / float(config.get("control_rate_hz", 20.0)),
        1.0 / float((config.get("cameras") or {}).get("rate_hz", 5.0)),
        processing_delay_s(config),
        bool((config.get("navigation") or {}).get("coordination", True)),
    )


def judging_params(config: dict[str, Any], safety_config: Any, context: SafetyContext) -> TreeParams:
    """The trees' params the metrics judge hazards by: the selected config where it is the trees',
    else the recording's trees config (or the trees' defaults) for another monitor."""
    if not isinstance(safety_config, TreesConfig):
        name, values = registry.selection(with_algorithms(config), "safety")
        safety_config = TreesConfig(**values) if name == registry.DEFAULTS["safety"] else TreesConfig()
    return TreeParams.of(safety_config, context)


def safety_params(
    config: dict[str, Any], options: dict[str, Any] | None = None, *, where: str = "replay --set"
) -> TreeParams:
    """The trees' params a recorded run is judged by (with ``options`` as in :func:`selected_safety`);
    without options the recorded monitor is not loaded (a plug-in need not be importable here)."""
    specs, spawn = agent_specs(config)
    safety_config = selected_safety(config, options, where=where)[1] if options else None
    return judging_params(config, safety_config, safety_context(config, specs, spawn))


def agent_specs(config: dict[str, Any]) -> tuple[dict[str, RobotSpec], dict[str, tuple[float, float, float]]]:
    specs, spawn = {}, {}
    for ns, a in (config.get("agents") or {}).items():
        kind = agent_type(a.get("type", "pallet_truck"))
        speed = float(a.get("speed_mps", kind.default_speed_mps))
        specs[ns] = RobotSpec(
            ns, kind.footprint_m, min(speed, kind.max_speed_mps), DRIVE_KINDS.get(kind.drive, "static")
        )
        x, y, yaw = (float(v) for v in a.get("pose", (0.0, 0.0, 0.0)))
        spawn[ns] = (x, y, yaw)
    return specs, spawn


def _truth_at(table: Any, ticks: NDArray[np.int64]) -> Truth:
    t = table["stamp_ns"].to_numpy()
    x, y, yaw = (table[c].to_numpy() for c in ("x", "y", "yaw"))
    ts = t / NS_PER_S
    vx, vy = np.gradient(x, ts), np.gradient(y, ts)
    w = np.gradient(np.unwrap(yaw), ts)
    speed = vx * np.cos(yaw) + vy * np.sin(yaw)
    idx = np.clip(np.searchsorted(t, ticks), 0, len(t) - 1)
    return Truth(np.stack([x[idx], y[idx], yaw[idx]], axis=1), speed[idx], w[idx])


def event_of(m: Any) -> SafetyEvent:
    e = m.msg
    pose = (e.pose.position.x, e.pose.position.y, _yaw(e.pose.orientation))
    return SafetyEvent(
        m.stamp_ns, e.robot, e.cause, e.action, pose, e.speed_mps, e.detail, e.other, e.pose_valid
    )


def read_safety_recording(reader: RecordingReader, config: dict[str, Any]) -> SafetyRecording:
    """Everything the safety metrics and the counterfactual replay need, at the control ticks."""
    specs, spawn = agent_specs(config)
    robots = [ns for ns, s in specs.items() if s.kind == "robot"]
    if not robots:
        raise RecordingInputError(
            "no robots", str(reader.path), "the run has no GPSS robot", "record a run with robots"
        )
    topics = {ns: schema.agent_topics(ns) for ns in specs}
    ticks = _control_ticks(reader, topics[robots[0]])
    n = len(ticks)
    pos = {int(t): i for i, t in enumerate(ticks)}
    truth_tables = ground_truth(reader)
    truth = {ns: _truth_at(truth_tables[ns], ticks) for ns in specs if ns in truth_tables}
    rows = {ns: _robot_rows(reader, topics[ns], pos, n) for ns in robots}
    estimates: dict[str, list[RobotEstimate]] = {}
    if (config.get("localization") or {}).get("source", "camera") == "camera":
        estimates = {ns: _estimates(reader, topics[ns], pos, n, spawn[ns]) for ns in robots}
    people = [
        (m.stamp_ns, [(p.position.x, p.position.y) for p in m.msg.poses])
        for m in reader.messages([schema.PEOPLE_DETECTIONS])
    ]
    events = [event_of(m) for m in reader.messages([schema.SAFETY_EVENTS])]
    detections = _marker_detections(reader, config, robots)
    cam_rate = float((config.get("cameras") or {}).get("rate_hz", 5.0))
    camera_ns = round(NS_PER_S / cam_rate)
    camera_ticks = ticks[ticks % camera_ns == 0]
    goals = {ns: len((config.get("agents") or {}).get(ns, {}).get("goals") or []) for ns in robots}
    return SafetyRecording(
        config,
        specs,
        robots,
        goals,
        spawn,
        ticks,
        camera_ticks,
        truth,
        {ns: r.commands for ns, r in rows.items()},
        estimates,
        {ns: r.contacts for ns, r in rows.items()},
        {ns: r.plans for ns, r in rows.items()},
        {ns: r.nav_states for ns, r in rows.items()},
        people,
        {ns: r.states for ns, r in rows.items() if r.states is not None},
        events,
        detections=detections,
        zones_topic=schema.SAFETY_ZONES in reader.topics,
    )


def _control_ticks(reader: RecordingReader, tp: dict[str, Any]) -> NDArray[np.int64]:
    """Find the control ticks: the stamps of the first robot's commands."""
    ticks = np.array(sorted({m.stamp_ns for m in reader.messages([tp["cmd_vel"].name])}), dtype=np.int64)
    if len(ticks) == 0:
        raise RecordingInputError(
            "no commands", str(reader.path), "no /<ns>/cmd_vel messages", "record a GPSS run"
        )
    return ticks


@dataclass
class _RobotRows:
    """One robot's recorded topics at the control ticks."""

    commands: NDArray[np.float64]
    contacts: list[tuple[float, tuple[str, ...]]]
    plans: list[NDArray[np.float64] | None]
    nav_states: list[str | None]
    states: list[str] | None  # None: no safety state recorded


def _robot_rows(reader: RecordingReader, tp: dict[str, Any], pos: dict[int, int], n: int) -> _RobotRows:
    """Read one robot's commands, contacts, plans, navigation and safety states at the ticks."""
    rows = _RobotRows(np.zeros((n, 2)), [(0.0, ())] * n, [None] * n, [None] * n, None)
    for m in reader.messages([tp["cmd_vel"].name]):
        rows.commands[pos[m.stamp_ns]] = (m.msg.twist.linear.x, m.msg.twist.angular.z)
    for m in reader.messages([tp["collision"].name]):
        if m.stamp_ns in pos:
            rows.contacts[pos[m.stamp_ns]] = (float(m.msg.max_normal_force_n), tuple(m.msg.other_bodies))
    for m in reader.messages([tp["plan"].name]):
        if m.stamp_ns in pos:
            rows.plans[pos[m.stamp_ns]] = np.array(
                [[p.pose.position.x, p.pose.position.y] for p in m.msg.poses]
            )
    for m in reader.messages([tp["navigation"].name]):
        if m.stamp_ns in pos:
            rows.nav_states[pos[m.stamp_ns]] = m.msg.state
    st = [DRIVE] * n
    seen = False
    for m in reader.messages([tp["safety_state"].name]):
        if m.stamp_ns in pos:
            st[pos[m.stamp_ns]] = m.msg.state
            seen = True
    if seen:
        rows.states = st
    return rows


def _marker_detections(
    reader: RecordingReader, config: dict[str, Any], robots: list[str]
) -> dict[str, NDArray[np.int64]]:
    """Collect, per robot, the stamps at which a camera found its marker."""
    marker_of = {
        ns: int(a.get("marker_id") if a.get("marker_id") is not None else ns.rsplit("_", 1)[-1])
        for ns, a in (config.get("agents") or {}).items()
        if ns in robots
    }
    found: dict[str, set[int]] = {ns: set() for ns in robots}
    det_topics = [t for t in reader.topics if t.endswith("/marker_detections")]
    for m in reader.messages(det_topics):
        for marker in {int(v) for v in m.msg.ids}:
            for ns, mid in marker_of.items():
                if mid == marker:
                    found[ns].add(m.stamp_ns)
    return {ns: np.array(sorted(v), dtype=np.int64) for ns, v in found.items()}


def _estimates(
    reader: RecordingReader,
    tp: dict[str, Any],
    pos: dict[int, int],
    n: int,
    spawn: tuple[float, float, float],
) -> list[RobotEstimate]:
    """The localizer's output at every tick, as the live stack handed it to the safety layer."""
    poses: dict[int, tuple[tuple[float, float, float], float]] = {}
    for m in reader.messages([tp["pose_estimate"].name]):
        p = m.msg.pose.pose
        cov = np.asarray(m.msg.pose.covariance, dtype=float)
        poses[m.stamp_ns] = (
            (p.position.x, p.position.y, _yaw(p.orientation)),
            float(np.sqrt(max(cov[0], cov[7]))),
        )
    twists = {
        m.stamp_ns: (m.msg.twist.linear.x, m.msg.twist.angular.z)
        for m in reader.messages([tp["velocity_estimate"].name])
    }
    out: list[RobotEstimate] = [RobotEstimate(None, last_pose=spawn)] * n
    last = spawn
    for m in reader.messages([tp["localization"].name]):
        i = pos.get(m.stamp_ns)
        if i is None:
            continue
        st = m.msg
        if st.fix_age_s < 0 and not st.valid:
            out[i] = RobotEstimate(None, last_pose=last)
            continue
        pose_sigma = poses.get(m.stamp_ns) if st.valid else None
        v, w = twists.get(m.stamp_ns, (0.0, 0.0))
        if pose_sigma is not None:
            last = pose_sigma[0]
            out[i] = RobotEstimate(pose_sigma[0], v, w, pose_sigma[1], float(st.fix_age_s), last)
        else:
            out[i] = RobotEstimate(None, fix_age_s=float(st.fix_age_s), last_pose=last)
    return out


def truth_movers(rec: SafetyRecording, i: int, exclude: str, *, robots: bool = True) -> list[Any]:
    """Every other agent at tick ``i`` as ground truth has it (for the truth-side conditions);
    other robots only if ``robots``."""
    out = []
    for ns, spec in rec.specs.items():
        if ns == exclude or ns not in rec.truth or (spec.kind == "robot" and not robots):
            continue
        tr = rec.truth[ns]
        est = RobotEstimate(tr.at(i), float(tr.speed_mps[i]), float(tr.yaw_rate_rps[i]), 0.0, 0.0, tr.at(i))
        m = mover_of(spec, est)
        if m is not None:
            out.append(m)
    return out
