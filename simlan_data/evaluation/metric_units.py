"""The unit and meaning of every metric a run writes: one table, read by the report.

``metrics.json`` keeps raw SI values (metres, seconds, bytes, fractions; ``null`` where a value
is not a number, see :mod:`simlan_data.metrics_io`). The report shows them for people: in the
unit of :data:`UNITS` (centimetres for localization errors, MiB for the recording, per cent for
shares), three significant digits, and a NaN or an infinity as what it means for that metric
("n/a: never in view", "none: no zone"). A metric missing here shows its raw value with unit
``?`` (tests/test_report.py fails on one).

Keys are metric names; ``*`` stands for one dotted part of a name (an agent's namespace, a cause).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import cache

from simlan_data.algorithms.navigation import BLOCKED_AFTER_S
from simlan_data.evaluation.fleet_metrics import DEADLOCK_MOVE_M, DEADLOCK_S, MIN_WAIT_S

__all__ = ["AREAS", "UNITS", "MetricUnit", "area_of", "format_metric", "format_number", "unit_of"]


@dataclass(frozen=True)
class MetricUnit:
    """How the report shows one metric."""

    unit: str  # the unit of the shown value: cm, deg, s, m/s, MiB, count, %, x, yes/no ...
    what: str  # one line: what it measures
    scale: float = 1.0  # shown value = raw value x scale (m -> cm: 100)
    nan: str = "n/a"  # what a NaN (JSON null) means here
    inf: str = "none"  # what an infinity means here
    labels: tuple[tuple[float, str], ...] = ()  # raw values shown as words (-1 threads: the default)


def _per_agent(area: str, name: str, entry: MetricUnit) -> dict[str, MetricUnit]:
    """The same unit for the run's aggregate ``area.name`` and each agent's ``area.*.name``."""
    return {f"{area}.{name}": entry, f"{area}.*.{name}": entry}


_COUNT = "count"
NEVER_OBSERVED = "n/a: never observed"

UNITS: dict[str, MetricUnit] = {
    # --------------------------------------------------------------------------------- fleet
    "fleet.robots": MetricUnit(_COUNT, "robots with goals"),
    "fleet.tasks_total": MetricUnit(_COUNT, "tasks given (two goals each; a last odd goal is home)"),
    "fleet.tasks_completed": MetricUnit(_COUNT, "tasks whose two goals were reached"),
    "fleet.missions_done": MetricUnit("yes/no", "every goal of every robot reached"),
    "fleet.makespan_s": MetricUnit("s", "start to the last goal reached (the run's length if not all were)"),
    "fleet.tasks_per_hour": MetricUnit("1/h", "tasks completed per hour of makespan", nan="n/a: no time"),
    "fleet.wait_s_mean": MetricUnit("s", f"mean stand of a robot with a pending goal (>= {MIN_WAIT_S:g} s)"),
    "fleet.wait_s_max": MetricUnit("s", "longest stand of a robot with a pending goal"),
    "fleet.wait_share": MetricUnit("%", "share of pending robot-time spent standing", 100.0),
    "fleet.min_clearance_m": MetricUnit(
        "cm", "smallest footprint-to-footprint distance between two robots", 100.0, inf="none: one robot"
    ),
    "fleet.deadlocks": MetricUnit(
        _COUNT,
        f"deadlocks: >= 2 linked robots with pending goals, none moving {DEADLOCK_MOVE_M:g} m in {DEADLOCK_S:g} s",
    ),
    "fleet.deadlock_s": MetricUnit("s", "time with a deadlock"),
    # ---------------------------------------------------------------------------- navigation
    **_per_agent("navigation", "goals_reached", MetricUnit(_COUNT, "goals reached")),
    **_per_agent("navigation", "goals_total", MetricUnit(_COUNT, "goals given")),
    **_per_agent("navigation", "goals_failed", MetricUnit(_COUNT, "goals not reached (every reason)")),
    **_per_agent("navigation", "goals_failed.unreachable", MetricUnit(_COUNT, "goals failed: no path")),
    **_per_agent(
        "navigation",
        "goals_failed.blocked",
        MetricUnit(_COUNT, f"goals failed: no progress for {BLOCKED_AFTER_S:g} s when the run ended"),
    ),
    **_per_agent(
        "navigation", "goals_failed.timeout", MetricUnit(_COUNT, "goals failed: the run ended first")
    ),
    **_per_agent("navigation", "collisions", MetricUnit(_COUNT, "collisions (collision sensor, onsets)")),
    "navigation.*.driven_m": MetricUnit("m", "distance driven (ground truth)"),
    **_per_agent(
        "navigation",
        "path_length_ratio",
        MetricUnit("ratio", "distance driven / first planned path length (all goals reached)"),
    ),
    # -------------------------------------------------------------------------- localization
    **_per_agent(
        "localization",
        "ate_xy_rmse_m",
        MetricUnit("cm", "position error RMSE (xy, valid estimates)", 100.0, NEVER_OBSERVED),
    ),
    **_per_agent(
        "localization", "ate_xy_max_m", MetricUnit("cm", "largest position error (xy)", 100.0, NEVER_OBSERVED)
    ),
    **_per_agent("localization", "yaw_rmse_deg", MetricUnit("deg", "heading error RMSE", nan=NEVER_OBSERVED)),
    **_per_agent(
        "localization",
        "availability",
        MetricUnit(
            "%", "ticks with a fresh fix among ticks with the marker in view", 100.0, "n/a: never in view"
        ),
    ),
    **_per_agent(
        "localization", "latency_s", MetricUnit("ms", "mean age of the newest fix", 1000.0, NEVER_OBSERVED)
    ),
    "localization.*.ticks_in_view": MetricUnit(_COUNT, "control ticks with the marker in some camera's view"),
    "localization.*.ticks_valid": MetricUnit(_COUNT, "control ticks with a valid estimate"),
    "localization.cameras_detecting": MetricUnit(_COUNT, "cameras that found a marker at least once"),
    "localization.camera_*.disagreement_m": MetricUnit(
        "cm", "RMS distance of this camera's fixes to the other cameras' (same marker, same frame)", 100.0
    ),
    "localization.camera_disagreement_max_m": MetricUnit("cm", "largest camera disagreement", 100.0),
    # -------------------------------------------------------------------------------- safety
    **_per_agent("safety", "stops", MetricUnit(_COUNT, "safety stops")),
    "safety.stops.*": MetricUnit(_COUNT, "safety stops of this cause"),
    "safety.slows": MetricUnit(_COUNT, "slow-downs"),
    "safety.*.stopped_at_end": MetricUnit(_COUNT, "1: a safety stop still held the robot when the run ended"),
    "safety.*.stopped_at_end.*": MetricUnit(
        _COUNT, "1: the cause of the stop that held the robot at the end"
    ),
    **_per_agent("safety", "violations", MetricUnit(_COUNT, "safety violations (judged on ground truth)")),
    "safety.violations.zone_entries": MetricUnit(_COUNT, "entries into a restricted zone"),
    "safety.violations.collisions": MetricUnit(_COUNT, "collisions judged as violations"),
    "safety.violations.unobserved": MetricUnit(_COUNT, "drives on without a fix for longer than allowed"),
    **_per_agent("safety", "missed", MetricUnit(_COUNT, "violations not stopped in time")),
    **_per_agent("safety", "false_stops", MetricUnit(_COUNT, "stops without a hazard")),
    "safety.stops_while_visible": MetricUnit(_COUNT, "unobserved-stops while a camera saw the marker"),
    "safety.hazards": MetricUnit(_COUNT, "hazards in ground truth"),
    "safety.hazards_unanswered": MetricUnit(_COUNT, "hazards the robot did not react to in time"),
    **_per_agent(
        "safety", "max_latency_s", MetricUnit("s", "slowest reaction to a hazard", nan="n/a: no hazard")
    ),
    "safety.latency_budget_s": MetricUnit("s", "allowed reaction time (control + camera period)"),
    **_per_agent(
        "safety", "max_stop_distance_m", MetricUnit("m", "longest distance to stand still after a stop")
    ),
    **_per_agent(
        "safety",
        "min_clearance_m",
        MetricUnit("m", "smallest clearance to a zone or another agent", inf="none: no zone or other agent"),
    ),
    "safety.min_clearance_zone_m": MetricUnit(
        "m", "smallest clearance to a restricted zone", inf="none: no zone applies"
    ),
    "safety.min_clearance_agents_m": MetricUnit(
        "m", "smallest clearance to another agent", inf="none: no other agent"
    ),
    "safety.collisions_moving": MetricUnit(_COUNT, "collisions with another agent while the robot moved"),
    "safety.collisions_standing": MetricUnit(_COUNT, "collisions with another agent while the robot stood"),
    "safety.collisions_static": MetricUnit(_COUNT, "collisions with the layout (shelf, wall, pallet)"),
    # ------------------------------------------------------------------- agents (simulator)
    "agents.collisions": MetricUnit(_COUNT, "contact onsets with anything but the floor (all agents)"),
    "agents.*.collisions": MetricUnit(_COUNT, "contact onsets with anything but the floor"),
    "agents.*.distance_m": MetricUnit("m", "distance travelled (simulator)"),
    # ---------------------------------------------------------------------------- simulation
    "sim.rtf": MetricUnit("x real time", "real-time factor: simulated time / wall time"),
    "sim.duration_s": MetricUnit("s", "simulated time"),
    "sim.wall_s": MetricUnit("s", "wall time of the simulation loop"),
    "sim.cpu_s": MetricUnit("s", "CPU time of the process during the loop (all threads)"),
    "sim.main_thread_cpu_s": MetricUnit("s", "CPU time of the simulation thread"),
    "sim.cameras": MetricUnit(_COUNT, "cameras"),
    "sim.physics_steps": MetricUnit(_COUNT, "physics steps"),
    "sim.camera_frames": MetricUnit(_COUNT, "camera frames rendered"),
    "sim.camera_frames_changed": MetricUnit(_COUNT, "camera frames whose image changed"),
    "sim.camera_frames_dropped": MetricUnit(
        _COUNT, "camera frames lost by the camera stage (sensors.timing.drop_rate)"
    ),
    "sim.camera_subframes": MetricUnit(
        _COUNT, "renders of all cameras per tick, summed (motion blur sub-frames)"
    ),
    "sim.render_wall_s": MetricUnit("s", "wall time spent rendering"),
    "sim.localize_wall_s": MetricUnit("s", "wall time spent localizing"),
    # ----------------------------------------------------------------------------- recording
    "recording.bytes": MetricUnit("MiB", "size of the recording", 1.0 / 2**20),
    "recording.messages": MetricUnit(_COUNT, "messages recorded"),
    # ------------------------------------------------------------------------------ the job
    "job.opencv_threads": MetricUnit("threads", "OpenCV's thread pool"),
    "job.encode_threads": MetricUnit("threads", "image encoder threads (0: on the simulation thread)"),
    "job.gl_threads": MetricUnit(
        "threads", "Mesa's rasterizer threads (LP_NUM_THREADS)", labels=((-1.0, "Mesa's default"),)
    ),
    "run.stopped_early": MetricUnit("yes/no", "stopped by a signal before duration_s"),
    # ------------------------------------------------------------------------- pose mapping
    "posemap.drive.frames": MetricUnit(_COUNT, "frames the pose mapper estimated"),
    "posemap.drive.predict_ms_per_frame": MetricUnit("ms", "pose mapper time per frame"),
    "posemap.drive.mae_rad": MetricUnit("deg", "mean absolute joint-angle error", 180.0 / math.pi),
    "posemap.drive.mpjpe_m": MetricUnit("cm", "mean per-joint position error", 100.0),
}

# the report's sections, in this order; a name's area is its first dotted part
AREAS: dict[str, str] = {
    "fleet": "Fleet",
    "navigation": "Navigation",
    "localization": "Localization",
    "safety": "Safety",
    "agents": "Agents (simulator)",
    "sim": "Simulation",
    "recording": "Recording",
    "job": "Job",
    "run": "Run",
    "posemap": "Pose mapping",
}


@cache
def _patterns() -> list[tuple[re.Pattern[str], MetricUnit]]:
    return [
        (re.compile("^" + re.escape(key).replace(r"\*", "[^.]+") + "$"), u)
        for key, u in UNITS.items()
        if "*" in key
    ]


def unit_of(name: str) -> MetricUnit | None:
    """The entry of metric ``name``: its own, else the first pattern that matches; None if unknown."""
    if name in UNITS:
        return UNITS[name]
    return next((u for pattern, u in _patterns() if pattern.match(name)), None)


def area_of(name: str) -> str:
    """The report section of metric ``name``."""
    head = name.split(".", 1)[0]
    return AREAS.get(head, head)


def format_number(value: float, unit: str = "") -> str:
    """A finite value for people: integers for counts, else three significant digits (no exponent
    from 1e-4 to 1e15; thousands separated)."""
    if unit == _COUNT and float(value).is_integer():
        return f"{int(value):,}"
    if value == 0:
        return "0"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    return f"{value:.3g}"


def format_metric(name: str, value: float) -> tuple[str, str]:
    """(shown value, unit) of one metric for the report; NaN and infinities as what they mean."""
    entry = unit_of(name)
    if entry is None:
        return (format_number(value) if math.isfinite(value) else str(value), "?")
    if math.isnan(value):
        return entry.nan, entry.unit
    if math.isinf(value):
        return entry.inf, entry.unit
    for raw, label in entry.labels:
        if value == raw:
            return label, entry.unit
    if entry.unit == "yes/no":
        return ("yes" if value else "no"), entry.unit
    return format_number(value * entry.scale, entry.unit), entry.unit
