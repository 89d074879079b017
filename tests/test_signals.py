"""SIGTERM and SIGINT on a real run (a real process, real signals): the run stops at the next
step, its bag is finalized (footer, metadata.yaml: it opens without recovery), the report of what
ran is written, the run directory says INTERRUPTED, and the exit code is 128 + the signal with one
line on stderr. A second signal during that shutdown exits at once and leaves a recoverable bag."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from reliability_helpers import SMALL_RUN, mcap_file, messages_in_file_order, read_running, start_run

from conftest import run_cli
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS

LONG = "duration_s=60"  # never reached: the signal comes first


def _wait_for_clock(run_dir: Path, proc, at_least_s: float = 0.6, timeout_s: float = 120) -> float:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the run ended before the signal"
        try:
            reached = float(read_running(run_dir)["simulated_s"])
        except (OSError, TypeError, KeyError, ValueError):
            reached = 0.0
        if reached >= at_least_s:
            return reached
        time.sleep(0.05)
    raise AssertionError("the run did not get going")


def _stderr(run_dir: Path) -> list[str]:
    text = (run_dir.parent / f"{run_dir.name}.stderr").read_text()
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_stops_the_run_and_finalizes_everything_it_recorded(
    tmp_path: Path, sig: signal.Signals, code: int
) -> None:
    run_dir = tmp_path / "run"
    proc = start_run(run_dir, *SMALL_RUN, LONG)
    reached = _wait_for_clock(run_dir, proc)
    sent = time.monotonic()
    os.kill(proc.pid, sig)
    bag = run_dir / "recording"
    while not (bag / "metadata.yaml").exists() and proc.poll() is None:
        time.sleep(0.01)
    finalized_s = time.monotonic() - sent
    assert proc.wait(timeout=60) == code
    assert finalized_s < 2.0, f"metadata.yaml {finalized_s:.2f} s after {sig.name}"

    lines = _stderr(run_dir)
    assert len(lines) == 1 and lines[0].startswith(f"error: interrupted by {sig.name} in {run_dir}"), lines
    logged = (run_dir / "run.log").read_text()  # Hydra's job log has the error line too
    assert f"[ERROR] - {lines[0].removeprefix('error: ')}" in logged
    # the bag is complete: the independent reader finds its summary (footer) and validates CRCs
    with mcap_file(bag).open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    messages = messages_in_file_order(bag)
    assert len(messages) == summary.statistics.message_count
    last_s = (max(m.log_time for m in messages) - DEFAULT_EPOCH_NS) / 1e9  # simulated time
    assert reached <= last_s + 0.25 and last_s < 60  # it recorded up to where the clock was, no further
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == len(messages)

    assert not (run_dir / "RUNNING").exists()
    marker = yaml.safe_load((run_dir / "INTERRUPTED").read_text())
    assert marker["signal"] == sig.name and marker["intended_duration_s"] == 60.0
    assert abs(marker["simulated_s"] - last_s) < 0.05
    metrics = yaml.safe_load((run_dir / "metrics.json").read_text())
    assert metrics["run.stopped_early"] == 1.0 and metrics["sim.duration_s"] == pytest.approx(
        marker["simulated_s"]
    )
    assert "**Stopped early**" in (run_dir / "report.md").read_text()
    # a reader that needs no recovery: replay --info opens it as a finished recording
    info = run_cli(str(bag), "--info", module="simlan_data.replay")
    assert info.returncode == 0, info.stderr


def test_a_second_signal_during_the_shutdown_exits_at_once_and_leaves_a_recoverable_bag(
    tmp_path: Path,
) -> None:
    run_dir = tmp_path / "run"
    proc = start_run(run_dir, *SMALL_RUN, LONG)
    _wait_for_clock(run_dir, proc)
    os.kill(proc.pid, signal.SIGTERM)
    time.sleep(0.02)  # inside the shutdown (it takes about a second: bag, metrics, report)
    second = time.monotonic()
    os.kill(proc.pid, signal.SIGTERM)
    assert proc.wait(timeout=30) == 143
    assert time.monotonic() - second < 1.0
    lines = _stderr(run_dir)
    assert len(lines) == 1 and "SIGTERM again during the shutdown: stopped at once" in lines[0], lines
    assert (run_dir / "RUNNING").exists() and not (run_dir / "INTERRUPTED").exists()
    rec = run_cli(str(run_dir), module="simlan_data.recover")
    assert rec.returncode == 0, rec.stderr
    assert (run_dir / "INCOMPLETE").exists() and messages_in_file_order(run_dir / "recording")


def test_sigterm_before_the_run_starts_writes_nothing_and_exits_143(tmp_path: Path) -> None:
    run_dir = tmp_path / "early" / "run"
    proc = start_run(run_dir, *SMALL_RUN, LONG)
    time.sleep(0.3)  # Python is importing the app: Hydra has not composed the config yet
    os.kill(proc.pid, signal.SIGTERM)
    assert proc.wait(timeout=30) == 143
    lines = _stderr(run_dir)
    assert lines == ["error: interrupted by SIGTERM"], lines
    assert not run_dir.exists()
