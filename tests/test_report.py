"""report.md and run.log of a real short run (the session's ``short_run``): figures that are real
images showing the run, a unit in every metric row, no raw ``nan``/``inf``, notes only when
something is wrong, and the run's summary in Hydra's job log."""

from __future__ import annotations

import math
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from simlan_data.evaluation.metric_units import UNITS, format_metric, unit_of
from simlan_data.evaluation.replay import ReplayContext
from simlan_data.evaluation.report_figures import (
    AGENT_COLOURS,
    DPI,
    ERROR_FILENAME,
    FIGURE_SIZES,
    TIMELINE_FILENAME,
    TIMELINE_ROW_IN,
    TRAJECTORIES_FILENAME,
    write_figures,
)
from simlan_data.evaluation.report_series import floor_plan, read_series
from simlan_data.evaluation.run_notes import run_notes
from simlan_data.metrics_io import load_metrics
from simlan_data.recording.reader import RecordingReader

FIGURES = (TRAJECTORIES_FILENAME, ERROR_FILENAME, TIMELINE_FILENAME)


def _section(report: str, title: str) -> str:
    """The text of ``## title`` up to the next ``## `` heading."""
    start = report.index(f"## {title}\n")
    end = report.find("\n## ", start + 1)
    return report[start : end if end > 0 else None]


def _colour_pixels(image_bgr: np.ndarray, hex_rgb: str, tol: int = 40) -> int:
    r, g, b = (int(hex_rgb[i : i + 2], 16) for i in (1, 3, 5))
    diff = np.abs(image_bgr.astype(int) - np.array([b, g, r])).sum(axis=2)
    return int((diff <= tol).sum())


def test_every_metric_of_a_real_run_has_a_unit(short_run: Path) -> None:
    metrics = load_metrics(short_run / "metrics.json")
    assert len(metrics) > 50
    assert [name for name in metrics if unit_of(name) is None] == []


def test_metrics_are_shown_for_people() -> None:
    assert format_metric("recording.bytes", 54_966_700.0) == ("52.4", "MiB")
    assert format_metric("localization.ate_xy_rmse_m", 0.00804405) == ("0.804", "cm")
    assert format_metric("localization.robot_agent_1.ate_xy_rmse_m", math.nan) == (
        "n/a: never observed",
        "cm",
    )
    assert format_metric("safety.min_clearance_zone_m", math.inf) == ("none: no zone applies", "m")
    assert format_metric("localization.availability", 1.0) == ("100", "%")
    assert format_metric("sim.physics_steps", 14400.0) == ("14,400", "count")
    assert format_metric("run.stopped_early", 0.0) == ("no", "yes/no")
    assert format_metric("job.gl_threads", -1.0) == ("Mesa's default", "threads")
    assert format_metric("localization.camera_163.disagreement_m", 0.0123) == ("1.23", "cm")
    assert format_metric("no.such_metric", 2.0) == ("2", "?")
    assert all(u.unit and u.what for u in UNITS.values())


def test_the_report_has_a_unit_in_every_row_and_no_raw_nan_or_inf(short_run: Path) -> None:
    report = (short_run / "report.md").read_text()
    metrics = load_metrics(short_run / "metrics.json")
    rows = [ln for ln in _section(report, "All metrics").splitlines() if ln.startswith("| `")]
    assert len(rows) == len(metrics)
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert len(cells) == 4 and cells[1] and cells[2] not in ("", "?"), row
    headline = report[: report.index("## Figures")]
    assert "| position error (ATE xy RMSE) |" in headline and "| cm |" in headline
    tables = "\n".join(ln for ln in report.splitlines() if ln.startswith("|"))
    words = re.findall(r"\b(nan|NaN|inf|Infinity|null|None)\b", tables)
    assert words == [], words
    size = next(r for r in rows if r.startswith("| `recording.bytes`"))
    assert f"| {metrics['recording.bytes'] / 2**20:.3g} | MiB |" in size, size


def test_the_report_links_figures_that_are_real_images_of_the_run(short_run: Path) -> None:
    report = (short_run / "report.md").read_text()
    metrics = load_metrics(short_run / "metrics.json")
    moving = 1  # the default scenario: one pallet truck
    for name in FIGURES:
        assert f"]({name})" in report, name
        image = cv2.imread(str(short_run / name), cv2.IMREAD_COLOR)
        assert image is not None, name
        width, height = FIGURE_SIZES[name]
        if name == TIMELINE_FILENAME:
            height += TIMELINE_ROW_IN * moving
        assert image.shape[:2] == (round(height * DPI), round(width * DPI)), name
        assert image.std() > 20, name  # not a blank canvas
    trajectories = cv2.imread(str(short_run / TRAJECTORIES_FILENAME), cv2.IMREAD_COLOR)
    assert _colour_pixels(trajectories, AGENT_COLOURS[0]) > 300  # the truck's truth line is drawn
    error = cv2.imread(str(short_run / ERROR_FILENAME), cv2.IMREAD_COLOR)
    assert metrics["localization.robot_agent_1.ticks_valid"] > 0
    assert _colour_pixels(error, AGENT_COLOURS[0]) > 200  # its error curves


def test_the_figures_are_rebuilt_from_the_run_directory_alone(short_run: Path, tmp_path: Path) -> None:
    """The figures read the recording and metrics.json, nothing of the live process: drawn again
    from the run directory they are the same pixels."""
    metrics = load_metrics(short_run / "metrics.json")
    with RecordingReader(short_run / "recording") as reader:
        ctx = ReplayContext(reader, tmp_path)
        series = read_series(reader, ctx.config, ctx.cameras, metrics)
    assert series.agents["robot_agent_1"].truth.shape[0] > 10
    write_figures(tmp_path, series, floor_plan(series.config))
    for name in FIGURES:
        again = cv2.imread(str(tmp_path / name), cv2.IMREAD_COLOR)
        live = cv2.imread(str(short_run / name), cv2.IMREAD_COLOR)
        assert again.shape == live.shape and np.array_equal(again, live), name


def test_notes_only_when_something_is_wrong(short_run: Path) -> None:
    clean = {
        "navigation.robot_agent_1.goals_reached": 4.0,
        "navigation.robot_agent_1.goals_total": 4.0,
        "localization.robot_agent_1.availability": 1.0,
        "agents.robot_agent_1.collisions": 0.0,
        "safety.violations": 0.0,
        "sim.rtf": 2.0,
    }
    assert run_notes(clean, ["robot_agent_1"], config={"live": {"realtime": True}}) == []
    wrong = clean | {
        "navigation.robot_agent_1.goals_reached": 1.0,
        "localization.robot_agent_1.availability": 0.0,
        "agents.robot_agent_1.collisions": 2.0,
        "safety.violations": 1.0,
        "safety.violations.zone_entries": 1.0,
        "sim.rtf": 0.5,
    }
    texts = [n.text for n in run_notes(wrong, ["robot_agent_1"], config={"live": {"realtime": True}})]
    assert [t.split(" ")[0] for t in texts] == [
        "never",
        "robot_agent_1",
        "robot_agent_1",
        "safety:",
        "realtime",
    ]
    held = clean | {
        "navigation.robot_agent_1.goals_reached": 0.0,
        "navigation.robot_agent_1.goals_failed": 4.0,
        "navigation.robot_agent_1.goals_failed.blocked": 4.0,
        "safety.robot_agent_1.stopped_at_end": 1.0,
        "safety.robot_agent_1.stopped_at_end.restricted_area": 1.0,
    }
    (note,) = run_notes(held, ["robot_agent_1"])
    assert note.in_summary and note.text.endswith(
        "4 blocked (no progress for 10 s at the end); a safety stop held it at the end "
        "(restricted_area; see the safety events)"
    ), note.text
    # the short run (3 s) reaches none of its four goals: the report says so at the top
    report = (short_run / "report.md").read_text()
    top = report[: report.index("| | value | unit |")]
    assert "**Notes**" in top and "robot_agent_1 reached 0 of 4 goals in 3 s simulated" in top
    assert "calibration" not in top  # the packaged calibrations' known fields: no note


def test_run_log_holds_the_runs_messages(short_run: Path) -> None:
    log = (short_run / "run.log").read_text()
    assert "[simlan_data.apps.run][DEBUG] - scenario 'default' starting: 3 s simulated" in log
    assert "simulated 3.0 of 3 s" in log
    assert "[simlan_data.apps.run][INFO] - simlan_data: scenario 'default' finished" in log
    assert f"  run directory  {short_run}" in log
    assert f"  next           python -m simlan_data.replay {short_run / 'recording'} --info" in log
    assert "report figures:" in log  # the figures' timings
    # the console shows the same summary as plain lines (as when the run printed it)
    console = (short_run.parent / "default_short.stdout").read_text().splitlines()
    assert console[0] == "simlan_data: scenario 'default' finished" and console[-1].startswith("  next")
    assert "\n".join(console) in log


@pytest.mark.parametrize("name", FIGURES)
def test_figure_names_are_in_the_docs(name: str) -> None:
    docs = (Path(__file__).resolve().parents[1] / "docs" / "running.md").read_text()
    assert name in docs
