"""Write a run's ``report.md``: what went wrong, the headline figures, plots, every metric with
its unit, what the recording holds.

    notes (only when something is wrong) -> headline table -> figures -> agents -> run
    -> all metrics by area (unit in every row) -> recording -> cameras' last frames -> details

The figures and the notes come from the recording and the metrics (``report_series``,
``run_notes``), so a report can be rebuilt from a run directory.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from simlan_data.constants import NS_PER_S, REPORT_FILENAME
from simlan_data.evaluation.metric_units import AREAS, area_of, format_metric, unit_of
from simlan_data.evaluation.run_notes import run_notes
from simlan_data.imaging.image_files import write_image
from simlan_data.recording.codecs import decode_compressed, decode_raw
from simlan_data.recording.reader import RecordingReader

if TYPE_CHECKING:
    from simlan_data.config.schema import Config
    from simlan_data.evaluation.report_series import RunSeries
    from simlan_data.sim.simulation import RunStats

log = logging.getLogger(__name__)

MOSAIC_FILENAME = "report_cameras.png"


COLOUR_TOPIC = re.compile(r"^/camera_[^/]+/image_raw(/compressed)?$")

# (label, metric) of the headline table, in this order; a metric the run lacks is left out
HEADLINE = (
    ("goals reached", "navigation.goals_reached"),
    ("position error (ATE xy RMSE)", "localization.ate_xy_rmse_m"),
    ("heading error (yaw RMSE)", "localization.yaw_rmse_deg"),
    ("localization availability", "localization.availability"),
    ("collisions", "agents.collisions"),
    ("safety stops", "safety.stops"),
    ("safety violations", "safety.violations"),
    ("real-time factor", "sim.rtf"),
    ("recording size", "recording.bytes"),
)


def last_images(reader: RecordingReader) -> dict[str, np.ndarray]:
    """The last colour image of every camera (decoded), by camera name."""
    topics = [t for t in reader.topics if COLOUR_TOPIC.match(t)]
    if not topics:
        return {}
    start = max(reader.start_ns, reader.end_ns - NS_PER_S)
    out: dict[str, np.ndarray] = {}
    for m in reader.messages(topics, start_ns=start):
        name = m.topic.split("/")[1]
        if m.msgtype.endswith("CompressedImage"):
            out[name] = decode_compressed(m.msg.format, m.msg.data)
        else:
            out[name] = decode_raw(m.msg.encoding, m.msg.height, m.msg.width, m.msg.step, m.msg.data)
    return dict(sorted(out.items()))


def camera_mosaic(
    images: dict[str, np.ndarray], *, columns: int = 4, tile_width: int = 480
) -> np.ndarray | None:
    """Tile labelled camera images into one RGB image."""
    if not images:
        return None
    tiles = []
    for name, img in images.items():
        h, w = img.shape[:2]
        tile = cv2.resize(img, (tile_width, round(h * tile_width / w)), interpolation=cv2.INTER_AREA)
        tile = np.ascontiguousarray(tile)
        cv2.putText(tile, name, (8, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 40, 40), 2, cv2.LINE_AA)
        tiles.append(tile)
    th = max(t.shape[0] for t in tiles)
    blank = np.zeros((th, tile_width, 3), dtype=np.uint8)
    tiles += [blank] * ((-len(tiles)) % columns)
    rows = [np.hstack(tiles[i : i + columns]) for i in range(0, len(tiles), columns)]
    return np.vstack(rows)


# ----------------------------------------------------------------------------------- tables
def cell(name: str, metrics: Mapping[str, float]) -> str:
    """A metric's value for a table cell (``-`` when the run lacks it)."""
    return format_metric(name, metrics[name])[0] if name in metrics else "-"


def headline_table(metrics: Mapping[str, float]) -> list[str]:
    lines = ["| | value | unit |", "| --- | --- | --- |"]
    for label, name in HEADLINE:
        if name not in metrics:
            continue
        value, unit = format_metric(name, metrics[name])
        if name == "navigation.goals_reached" and "navigation.goals_total" in metrics:
            value = f"{value} of {cell('navigation.goals_total', metrics)}"
        lines.append(f"| {label} | {value} | {unit} |")
    return lines


def metrics_tables(metrics: Mapping[str, float]) -> list[str]:
    """Every metric, a table per area (in ``AREAS`` order), unit and meaning in every row."""
    order = {title: k for k, title in enumerate(AREAS.values())}
    by_area: dict[str, list[str]] = {}
    for name in sorted(metrics):
        by_area.setdefault(area_of(name), []).append(name)
    lines: list[str] = []
    for area in sorted(by_area, key=lambda a: (order.get(a, len(order)), a)):
        lines += [f"### {area}", "", "| metric | value | unit | what |", "| --- | --- | --- | --- |"]
        for name in by_area[area]:
            value, unit = format_metric(name, metrics[name])
            entry = unit_of(name)
            lines.append(f"| `{name}` | {value} | {unit} | {entry.what if entry else ''} |")
        lines.append("")
    return lines


def agents_table(cfg: Config, stats: RunStats, metrics: Mapping[str, float]) -> list[str]:
    lines = [
        "| agent | type | goals reached | collisions | driven (m) | ATE xy RMSE (cm) | yaw RMSE (deg) | availability (%) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for ns in sorted(stats.collisions):
        goals = f"{cell(f'navigation.{ns}.goals_reached', metrics)} of {cell(f'navigation.{ns}.goals_total', metrics)}"
        lines.append(
            f"| {ns} | {cfg.agents[ns].type} | {goals} | {stats.collisions[ns]} | {stats.distance_m.get(ns, 0.0):.3g} | "
            f"{cell(f'localization.{ns}.ate_xy_rmse_m', metrics)} | {cell(f'localization.{ns}.yaw_rmse_deg', metrics)} | "
            f"{cell(f'localization.{ns}.availability', metrics)} |"
        )
    return lines


def run_table(
    cfg: Config, stats: RunStats, metrics: Mapping[str, float], reader: RecordingReader
) -> list[str]:
    return [
        "| | |",
        "| --- | --- |",
        f"| seed | {cfg.seed} |",
        f"| simulated | {metrics['sim.duration_s']:.2f} s |",
        f"| wall clock | {metrics['sim.wall_s']:.2f} s |",
        f"| cameras | {', '.join(str(c) for c in cfg.cameras.ids)} at {cfg.cameras.rate_hz:g} Hz, {cfg.cameras.width}x{cfg.cameras.height}, {'+'.join(cfg.cameras.streams)}, distortion {'on' if cfg.cameras.distortion else 'off'} |",
        f"| renderer | {stats.renderer} ({'layered' if cfg.render.layered else 'full'}) |",
        f"| world | {cfg.world.layout}, fidelity {cfg.world.fidelity}, physics {cfg.world.physics_hz} Hz |",
        f"| recording | `recording/` ({stats.recording_bytes / 2**20:.1f} MiB, {reader.message_count} messages) |",
    ]


# ---------------------------------------------------------------------------------- figures
FIGURE_CAPTIONS = {  # file name -> (alt text, caption, why it may be missing)
    "report_trajectories.png": (
        "trajectories",
        "Trajectories on the floor plan: ground truth, camera estimates, goals, restricted zones, cameras.",
        "no agent moved",
    ),
    "report_error.png": (
        "localization error",
        "Localization error of the camera estimates over time.",
        "no camera-based estimates in this run (localization.source, or no robot with a marker)",
    ),
    "report_timeline.png": (
        "speed and events",
        "Speed (commanded, true, estimated) with safety stops and slow-downs, goals reached and collisions.",
        "no agent drove",
    ),
}


def figures_section(run_dir: Path, series: RunSeries, floor: Any | None = None) -> list[str]:
    """Draw the figures (over ``floor``, an occupancy grid, else the one of the recorded
    config's layout); their links and captions (or why one is missing)."""
    from simlan_data.evaluation.report_figures import write_figures
    from simlan_data.evaluation.report_series import floor_plan

    t0 = time.perf_counter()
    floor = floor if floor is not None else floor_plan(series.config)
    floor_s = time.perf_counter() - t0
    timings = write_figures(run_dir, series, floor)
    log.debug(
        "report figures: floor plan %.2f s, %s",
        floor_s,
        ", ".join(f"{name} {seconds:.2f} s" for name, seconds in timings.items()),
    )
    lines = ["## Figures", ""]
    for name, (alt, caption, missing) in FIGURE_CAPTIONS.items():
        if (run_dir / name).is_file():
            lines += [f"![{alt}]({name})", "", f"*{caption}*", ""]
        else:
            lines += [f"*{caption.split(':')[0].rstrip('.')}: not drawn, {missing}.*", ""]
    return lines


# ----------------------------------------------------------------------------------- report
def write_report(
    run_dir: Path,
    cfg: Config,
    stats: RunStats,
    metrics: dict[str, float],
    reader: RecordingReader,
    *,
    config: Mapping[str, Any] | None = None,
    cameras: Mapping[str, Any] | None = None,
    floor: Any | None = None,
) -> Path:
    """Write ``report.md`` and its figures into ``run_dir``; ``config`` and ``cameras`` are the
    recording's (its /simlan/config as a dict, its cameras), read from ``reader`` if not given;
    ``floor``: the run's occupancy grid (built from the recorded config's layout if not given)."""
    from simlan_data.evaluation.report_series import read_series

    t0 = time.perf_counter()
    if config is None or cameras is None:
        from simlan_data.evaluation.replay import ReplayContext

        ctx = ReplayContext(reader, run_dir)
        config, cameras = ctx.config, ctx.cameras
    series = read_series(reader, config, cameras, metrics)
    log.debug("report series read in %.2f s", time.perf_counter() - t0)
    mosaic = camera_mosaic(last_images(reader))
    if mosaic is not None:
        write_image(run_dir / MOSAIC_FILENAME, cv2.cvtColor(mosaic, cv2.COLOR_RGB2BGR))  # OSError if not
    notes = run_notes(
        metrics,
        stats.collisions,
        config=config,
        calibration_issues=len(stats.calibration_issues),
        user_calibration=bool(cfg.cameras.calibration_dir),
        goals_failed={ns: len(a.goals_failed_s) for ns, a in series.agents.items()},
    )
    lines = [f"# Run report: {cfg.scenario.name}", "", cfg.scenario.description or "", ""]
    if metrics.get("run.stopped_early"):
        lines += [
            f"**Stopped early** at {metrics['sim.duration_s']:.2f} s of {cfg.duration_s:g} s simulated "
            "(a signal: see `INTERRUPTED`); everything below is what ran.",
            "",
        ]
    if notes:
        lines += ["**Notes**", "", *[f"- {n.text}" for n in notes], ""]
    lines += headline_table(metrics) + [""]
    lines += figures_section(run_dir, series, floor)
    lines += ["## Agents", "", *agents_table(cfg, stats, metrics), ""]
    lines += ["## Run", "", *run_table(cfg, stats, metrics, reader), ""]
    lines += ["## All metrics", "", "Raw values (SI units, `null` for n/a) are in `metrics.json`.", ""]
    lines += metrics_tables(metrics)
    lines += ["## Recording", "", "```", reader.summary(), "```", ""]
    if mosaic is not None:
        lines += ["## Cameras (last frame)", "", f"![cameras]({MOSAIC_FILENAME})", ""]
    if stats.calibration_issues:
        lines += ["## Calibration notes", "", "Fields that disagree with K, R, t (K, R, t are used):", ""]
        lines += [f"- {issue}" for issue in stats.calibration_issues]
        lines.append("")
    if stats.layout_notes:
        lines += ["## Layout notes", "", "Where SIMLAN's layout and this twin's geometry disagree:", ""]
        lines += [f"- {note}" for note in stats.layout_notes]
        lines.append("")
    path = run_dir / REPORT_FILENAME
    path.write_text("\n".join(lines))
    log.debug("report written in %.2f s: %s", time.perf_counter() - t0, path)
    return path


def missing_units(metrics: Mapping[str, float]) -> list[str]:
    """The metrics the unit table does not know (the report shows ``?`` for their unit)."""
    return sorted(name for name in metrics if unit_of(name) is None)
