"""Safety metrics from ground truth: did the safety layer stop the robots when it had to?

The hazards are the tree's own conditions evaluated on ground truth instead of estimates (true
pose and speed, true contact, true camera visibility, other agents' true motion), at the control
ticks. Definitions (per robot, summed over robots; ``budget`` = one control period + one camera
period):

- ``safety.violations``: real zone entries (the true footprint inside a zone that applies to the
  robot), real collisions (contact episodes with a force above the threshold) and real unobserved
  intervals (no camera could see the marker for longer than the timeout);
- ``safety.missed``: violations with no stop in time: every zone entry; a collision after which
  the robot was not stopped within the budget; an unobserved interval in which the robot was
  still commanded to move one budget after the timeout ran out;
- ``safety.stops`` (transitions to stop), ``safety.false_stops``: stops whose cause was not a
  hazard in ground truth within one budget of the stop (an ``unobserved`` stop also counts as
  justified when no camera had found the marker for longer than the timeout, a detector dropout
  while the marker was in view: ``safety.stops_while_visible`` counts those);
- ``safety.max_latency_s``: over hazard onsets (ground truth) at which the robot was moving, the
  time to the robot's stop command (0 if it stopped earlier: the estimate saw it first);
- ``safety.max_stop_distance_m``: distance the robot really travelled from a stop command to
  standstill; ``safety.min_clearance_m``: smallest true distance between a robot's footprint and
  a zone that applies to it or another agent's footprint;
- ``safety.collisions_static``: collisions with the layout (a shelf, a wall, a pallet: no other
  agent among the bodies touched at the onset), whether the robot drove or turned into it;
  ``safety.collisions_moving`` / ``_standing``: collisions with another agent in which the robot
  was moving (driving or turning in place) / standing (hit by the other agent). The three add up
  to ``safety.violations.collisions``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from shapely.geometry import Polygon

from simlan_data.algorithms.safety import (
    CAUSES,
    DRIVE,
    STOP,
    RobotEstimate,
    SafetyDecision,
    SafetyEvent,
    TreeParams,
)
from simlan_data.algorithms.safety.conditions import (
    SafetyContext,
    contact,
    enters_zone,
    unobserved,
    worst_approach,
)
from simlan_data.algorithms.safety.geometry import Zone, footprint_polygon
from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.metrics import Visibility
from simlan_data.evaluation.safety_inputs import (
    SafetyRecording,
    Truth,
    agent_specs,
    read_safety_recording,
    safety_params,
    truth_movers,
)
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.agent_types import agent_type

MOVING_MPS = 0.05
TURNING_RPS = 0.05  # an in-place turn at more than this is moving (it sweeps the footprint)
STANDSTILL_MPS = 0.02


@dataclass(frozen=True)
class Violation:
    namespace: str
    kind: str  # zone_entry | collision | unobserved
    onset_ns: int
    other: str
    moving: bool  # the robot was driving when it happened
    stopped_in_time: bool


@dataclass(frozen=True)
class Hazard:
    namespace: str
    cause: str
    onset_ns: int
    latency_s: float | None  # None: no stop followed


def _edges(flags: NDArray[np.bool_], *, merge: int = 0) -> list[int]:
    """Indices where ``flags`` becomes true; an onset within ``merge`` ticks of the end of the
    previous episode continues it (contacts flicker while two bodies push each other)."""
    f = np.asarray(flags, dtype=bool)
    onsets = np.flatnonzero(f & ~np.concatenate([[False], f[:-1]]))
    ends = np.flatnonzero(f & ~np.concatenate([f[1:], [False]]))
    out: list[int] = []
    for k, i in enumerate(onsets):
        if out and k > 0 and i - ends[k - 1] <= merge:
            continue
        out.append(int(i))
    return out


def truth_ages(rec: SafetyRecording, ns: str, cameras: dict[str, CameraModel]) -> NDArray[np.float64]:
    """Per tick: time since a camera last could see the robot's marker (ground truth); -1: never."""
    kind = agent_type(rec.config["agents"][ns].get("type", "pallet_truck"))
    ages = np.full(len(rec.ticks), -1.0)
    if kind.marker_xyz is None:
        return ages
    vis = Visibility(cameras, kind)
    tr = rec.truth[ns]
    last: int | None = None
    cam = set(rec.camera_ticks.tolist())
    for i, t in enumerate(rec.ticks):
        if int(t) in cam and vis.in_view(*tr.at(i)):
            last = int(t)
        ages[i] = -1.0 if last is None else (int(t) - last) / NS_PER_S
    return ages


def truth_hazards(
    rec: SafetyRecording,
    params: TreeParams,
    states: dict[str, list[str]],
    cameras: dict[str, CameraModel],
) -> dict[str, dict[str, NDArray[np.bool_]]]:
    """Per robot and cause: the tree's condition on ground truth at every tick.

    The truth context is held (looks at the motion the robot would make if released) exactly
    when the recorded tree was, so a stop and its truth hazard are judged by the same rule.
    """
    out: dict[str, dict[str, NDArray[np.bool_]]] = {}
    for ns in rec.robots:
        if ns not in rec.truth:
            continue
        spec = rec.specs[ns]
        zones = tuple(z for z in params.zones if z.applies_to(ns))
        ctx = SafetyContext(spec, params, zones)
        ages = truth_ages(rec, ns, cameras)
        flags = {c: np.zeros(len(rec.ticks), dtype=bool) for c in CAUSES}
        st = states.get(ns, [DRIVE] * len(rec.ticks))
        navigating = rec.goals.get(ns, 0) > 0
        tr = rec.truth[ns]
        for i, t in enumerate(rec.ticks):
            ctx.stamp_ns = int(t)
            pose = tr.at(i)
            ctx.estimate = RobotEstimate(
                pose, float(tr.speed_mps[i]), float(tr.yaw_rate_rps[i]), 0.0, ages[i], pose
            )
            ctx.contact = rec.contacts[ns][i]
            ctx.others = truth_movers(rec, i, ns, robots=params.ttc_against_robots())
            ctx.held = SafetyDecision(st[i - 1] if i > 0 else DRIVE)
            if i > 0 and rec.plans[ns][i - 1] is not None:
                ctx.plan = rec.plans[ns][i - 1]
            if i > 0 and rec.nav_states[ns][i - 1] is not None:
                navigating = rec.nav_states[ns][i - 1] != "done"
            ctx.navigating = navigating
            flags["collision"][i] = contact(ctx) is not None
            flags["unobserved"][i] = unobserved(ctx) is not None
            flags["restricted_area"][i] = bool(zones) and enters_zone(ctx) is not None
            flags["ttc"][i] = worst_approach(ctx, STOP) is not None
        out[ns] = flags
    return out


@dataclass(frozen=True)
class _Robot:
    """One robot's ground truth at the control ticks, as every check of :func:`evaluate` reads it."""

    ns: str
    tr: Truth
    n: int
    stopped: NDArray[np.bool_]  # the run (recorded or counterfactual) commanded a stop
    cmd_v: NDArray[np.float64]  # |commanded linear speed|
    moving: NDArray[np.bool_]  # driving (true speed) or commanded to
    flags: dict[str, NDArray[np.bool_]]  # truth hazards per cause
    zones: list[Zone]  # the zones that apply to it
    shapes: list[Polygon]  # its true footprint per tick


@dataclass
class _Tally:
    """What :func:`evaluate` sums over robots; :meth:`metrics` turns it into the run's ``{prefix}.*``."""

    violations: list[Violation] = field(default_factory=list)
    hazards: list[Hazard] = field(default_factory=list)
    tot: dict[str, float] = field(
        default_factory=lambda: dict.fromkeys(
            ("stops", "slows", "false_stops", "unanswered", "moving", "standing", "static", "visible"), 0.0
        )
    )
    stops_by_cause: dict[str, float] = field(default_factory=lambda: dict.fromkeys(CAUSES, 0.0))
    latencies: list[float] = field(default_factory=list)
    stop_dists: list[float] = field(default_factory=list)
    clearances: list[float] = field(default_factory=list)
    zone_clear: list[float] = field(default_factory=list)

    def metrics(self, prefix: str, budget_s: float) -> dict[str, float]:
        """Sum the robots' violations, stops, latencies and clearances into the run's metrics."""
        violations, tot, latencies, stop_dists = self.violations, self.tot, self.latencies, self.stop_dists
        clearances, zone_clear = self.clearances, self.zone_clear
        out: dict[str, float] = {}
        kinds = {
            k: sum(1 for v in violations if v.kind == k) for k in ("zone_entry", "collision", "unobserved")
        }
        out[f"{prefix}.violations"] = float(len(violations))
        out[f"{prefix}.violations.zone_entries"] = float(kinds["zone_entry"])
        out[f"{prefix}.violations.collisions"] = float(kinds["collision"])
        out[f"{prefix}.violations.unobserved"] = float(kinds["unobserved"])
        out[f"{prefix}.missed"] = float(
            sum(1 for v in violations if v.kind == "zone_entry" or not v.stopped_in_time)
        )
        out[f"{prefix}.stops"] = tot["stops"]
        for cause, count in self.stops_by_cause.items():
            out[f"{prefix}.stops.{cause}"] = count
        out[f"{prefix}.slows"] = tot["slows"]
        out[f"{prefix}.false_stops"] = tot["false_stops"]
        out[f"{prefix}.stops_while_visible"] = tot["visible"]
        out[f"{prefix}.hazards"] = float(len(self.hazards))
        out[f"{prefix}.hazards_unanswered"] = tot["unanswered"]
        out[f"{prefix}.max_latency_s"] = max(latencies) if latencies else float("nan")
        out[f"{prefix}.latency_budget_s"] = budget_s
        out[f"{prefix}.max_stop_distance_m"] = max(stop_dists) if stop_dists else 0.0
        out[f"{prefix}.min_clearance_m"] = min(clearances + zone_clear, default=float("inf"))
        out[f"{prefix}.min_clearance_zone_m"] = min(zone_clear, default=float("inf"))
        out[f"{prefix}.min_clearance_agents_m"] = min(clearances, default=float("inf"))
        out[f"{prefix}.collisions_moving"] = tot["moving"]
        out[f"{prefix}.collisions_standing"] = tot["standing"]
        out[f"{prefix}.collisions_static"] = tot["static"]
        return out


def _robot(
    rec: SafetyRecording,
    ns: str,
    params: TreeParams,
    states: dict[str, list[str]],
    flags: dict[str, NDArray[np.bool_]],
) -> _Robot:
    """Gather one robot's truth, commands, stops and footprints at the control ticks."""
    tr = rec.truth[ns]
    n = len(rec.ticks)
    st = np.array(states.get(ns, [DRIVE] * n))
    stopped = st == STOP
    cmd_v = np.abs(rec.commands[ns][:, 0])
    moving = (np.abs(tr.speed_mps) > MOVING_MPS) | (cmd_v > 0.01)
    zones = [z for z in params.zones if z.applies_to(ns)]
    shapes = [footprint_polygon(tr.at(i), rec.specs[ns].footprint) for i in range(n)]
    return _Robot(ns, tr, n, stopped, cmd_v, moving, flags, zones, shapes)


def _zone_entries(rec: SafetyRecording, r: _Robot, tally: _Tally) -> list[Violation]:
    """Find the true footprint's entries into the zones that apply (never stopped in time)."""
    v_ns: list[Violation] = []
    for z in r.zones:
        inside = np.array([s.intersects(z.polygon) for s in r.shapes])
        for i in _edges(inside):
            v_ns.append(Violation(r.ns, "zone_entry", int(rec.ticks[i]), z.name, bool(r.moving[i]), False))
        tally.zone_clear.append(min(float(s.distance(z.polygon)) for s in r.shapes))
    return v_ns


def _collisions(
    rec: SafetyRecording, r: _Robot, params: TreeParams, tol: int, tally: _Tally
) -> list[Violation]:
    """Find the contact episodes over the force threshold and whether the robot stopped within the budget."""
    dt = params.control_period_s
    tr, n, stopped, moving = r.tr, r.n, r.stopped, r.moving
    v_ns: list[Violation] = []
    # the recorded collision sensor is ground truth
    force = np.array([c[0] for c in rec.contacts[r.ns]])
    touching = (force >= params.config.collision.force_threshold_n) & (force > 0)
    for i in _edges(touching, merge=round(1.0 / dt)):
        lo = max(0, i - 5)
        was_moving = bool(
            (np.abs(tr.speed_mps[lo : i + 1]) > MOVING_MPS).any()
            or (np.abs(tr.yaw_rate_rps[lo : i + 1]) > TURNING_RPS).any()
        )
        j = min(n - 1, i + tol)
        ok = bool(stopped[i : j + 1].any()) or not bool(moving[j])
        touched = rec.contacts[r.ns][i][1]
        v_ns.append(Violation(r.ns, "collision", int(rec.ticks[i]), ", ".join(touched), was_moving, ok))
        tally.tot[_collision_kind(rec, r.ns, touched, moving=was_moving)] += 1
    return v_ns


def _collision_kind(rec: SafetyRecording, ns: str, touched: tuple[str, ...], *, moving: bool) -> str:
    """``static`` (only layout bodies touched), else ``moving`` / ``standing`` (another agent)."""
    if not any(o in rec.specs and o != ns for o in touched):
        return "static"
    return "moving" if moving else "standing"


def _unobserved_intervals(rec: SafetyRecording, r: _Robot, tol: int) -> list[Violation]:
    """Find the true unobserved intervals and whether the robot was stopped one budget after the timeout."""
    v_ns: list[Violation] = []
    for i in _edges(r.flags["unobserved"]):
        j = min(r.n - 1, i + tol)
        ok = bool(r.stopped[j]) or r.cmd_v[j] <= 0.01
        v_ns.append(Violation(r.ns, "unobserved", int(rec.ticks[i]), "", bool(r.moving[i]), ok))
    return v_ns


def _latencies(rec: SafetyRecording, r: _Robot, params: TreeParams, tol: int, tally: _Tally) -> list[float]:
    """Time each truth hazard's onset (while moving) to the robot's stop command; unanswered ones count."""
    lat_ns: list[float] = []
    for cause in CAUSES:
        if not params.config.applies(r.ns, cause):
            continue
        for i in _edges(r.flags[cause]):
            if not r.moving[i] and not r.stopped[i]:
                continue  # standing still: nothing to stop
            first = np.flatnonzero(r.stopped[max(0, i - tol) :])
            if len(first) == 0:
                tally.hazards.append(Hazard(r.ns, cause, int(rec.ticks[i]), None))
                tally.tot["unanswered"] += 1
                continue
            j = max(0, i - tol) + int(first[0])
            lat = max(0.0, (int(rec.ticks[j]) - int(rec.ticks[i])) / NS_PER_S)
            tally.hazards.append(Hazard(r.ns, cause, int(rec.ticks[i]), lat))
            lat_ns.append(lat)
    return lat_ns


def _stops(
    rec: SafetyRecording,
    r: _Robot,
    params: TreeParams,
    stops: list[SafetyEvent],
    tol: int,
    tally: _Tally,
) -> tuple[int, list[float]]:
    """Check each stop against the truth hazard of its cause and measure its distance to standstill.

    Returns the number of false stops and the stop distances.
    """
    dt = params.control_period_s
    tr, n, flags = r.tr, r.n, r.flags
    false = 0
    dists = []
    found = rec.detections.get(r.ns, np.zeros(0, dtype=np.int64))
    for e in stops:
        i = rec.index(e.stamp_ns)
        justified = e.cause not in flags or bool(flags[e.cause][max(0, i - tol) : i + tol + 1].any())
        if e.cause == "unobserved" and not justified:
            k = int(np.searchsorted(found, e.stamp_ns, side="right"))
            dropout_s = (e.stamp_ns - int(found[k - 1])) / NS_PER_S if k > 0 else float("inf")
            justified = dropout_s > params.config.observability.timeout_s
            tally.tot["visible"] += 1
        if not justified:
            false += 1
        tally.stops_by_cause[e.cause] = tally.stops_by_cause.get(e.cause, 0.0) + 1
        j = i
        end = min(n - 1, i + round(5.0 / dt))
        while j < end and abs(tr.speed_mps[j]) > STANDSTILL_MPS:
            j += 1
        dists.append(float(np.sum(np.hypot(*np.diff(tr.pose[i : j + 1, :2], axis=0).T))) if j > i else 0.0)
    return false, dists


def _agent_clearance(rec: SafetyRecording, r: _Robot) -> float:
    """Smallest true distance between the robot's footprint and another agent's, over the run."""
    others = [o for o in rec.specs if o != r.ns and o in rec.truth]
    return min(
        (
            float(r.shapes[i].distance(footprint_polygon(rec.truth[o].at(i), rec.specs[o].footprint)))
            for o in others
            for i in range(r.n)
        ),
        default=float("inf"),
    )


def evaluate(
    rec: SafetyRecording,
    params: TreeParams,
    events: list[SafetyEvent],
    states: dict[str, list[str]],
    cameras: dict[str, CameraModel],
    *,
    prefix: str = "safety",
) -> tuple[dict[str, float], list[Violation], list[Hazard]]:
    """Metrics of a run (recorded or counterfactual events and states) against ground truth."""
    budget_s = params.control_period_s + params.camera_period_s
    dt = params.control_period_s
    tol = int(np.ceil(budget_s / dt - 1e-9))
    hazards_truth = truth_hazards(rec, params, states, cameras)
    tally = _Tally()
    out: dict[str, float] = {}
    for ns in rec.robots:
        if ns not in rec.truth:
            continue
        r = _robot(rec, ns, params, states, hazards_truth[ns])
        mine = [e for e in events if e.namespace == ns]
        v_ns = _zone_entries(rec, r, tally)
        v_ns += _collisions(rec, r, params, tol, tally)
        v_ns += _unobserved_intervals(rec, r, tol)
        tally.violations += v_ns
        lat_ns = _latencies(rec, r, params, tol, tally) if params.config.applies(ns) else []
        tally.latencies += lat_ns
        stops = [e for e in mine if e.action == STOP]
        false, dists = _stops(rec, r, params, stops, tol, tally)
        tally.stop_dists += dists
        tally.tot["stops"] += len(stops)
        tally.tot["slows"] += sum(1 for e in mine if e.action == "slow")
        tally.tot["false_stops"] += false
        agent_gap = _agent_clearance(rec, r)
        tally.clearances.append(agent_gap)
        zgap = min(
            (min(float(s.distance(z.polygon)) for s in r.shapes) for z in r.zones), default=float("inf")
        )
        p = f"{prefix}.{ns}."
        out[p + "stops"] = float(len(stops))
        out[p + "violations"] = float(len(v_ns))
        out[p + "missed"] = float(sum(1 for v in v_ns if v.kind == "zone_entry" or not v.stopped_in_time))
        out[p + "false_stops"] = float(false)
        out[p + "max_latency_s"] = max(lat_ns) if lat_ns else float("nan")
        out[p + "max_stop_distance_m"] = max(dists) if dists else 0.0
        out[p + "min_clearance_m"] = min(agent_gap, zgap)
        held = mine[-1] if mine and mine[-1].action == STOP else None  # still stopped when the run ended
        out[p + "stopped_at_end"] = float(held is not None)
        if held is not None:
            out[f"{p}stopped_at_end.{held.cause}"] = 1.0
    out.update(tally.metrics(prefix, budget_s))
    return out, tally.violations, tally.hazards


def recording_safety_metrics(
    reader: RecordingReader, config: dict[str, Any], cameras: dict[str, CameraModel]
) -> dict[str, float]:
    """``safety.*`` of a live run, from its recording (recorded events and states); none without robots."""
    specs, _ = agent_specs(config)
    if not any(s.kind == "robot" for s in specs.values()):
        return {}
    rec = read_safety_recording(reader, config)
    params = safety_params(config)
    metrics, _, _ = evaluate(rec, params, rec.events, rec.states, cameras)
    return metrics
