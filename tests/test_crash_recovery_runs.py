"""Real runs (``python -m simlan_data.run``) that crash: SIGKILL at several points, a full disk.

The killed runs are compared with a complete run of the same config: a run is a pure function of
(config, seed), so everything recovered must be exactly the beginning of the complete recording,
and it must reach to within one flush period of where the simulated clock was at the kill.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from reliability_helpers import (
    REPO,
    SMALL_RUN,
    finish_kill,
    kill_when,
    mcap_file,
    messages_in_file_order,
    read_running,
    start_run,
)

from conftest import run_cli
from simlan_data.constants import FORMAT_VERSION, NS_PER_S
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS

FLUSH_PERIOD_S = 1.0  # the default recording.flush_period_s
TRUTH_STEP_S = 1 / 60  # messages come at least this often (ground truth)


@pytest.mark.slow
def test_sigkill_at_several_points_recovers_all_but_the_last_flush_period(tmp_path: Path) -> None:
    overrides = (*SMALL_RUN, "duration_s=6")
    ref_dir = tmp_path / "reference"
    proc = run_cli(*overrides, f"hydra.run.dir={ref_dir}")
    assert proc.returncode == 0, proc.stderr
    reference = messages_in_file_order(ref_dir / "recording")
    for kill_s in (0.6, 2.5, 4.4):
        run_dir = tmp_path / f"killed_at_{kill_s}"
        proc = start_run(run_dir, *overrides)

        def reached(run_dir: Path = run_dir, kill_s: float = kill_s) -> bool:
            try:
                return float(read_running(run_dir)["simulated_s"]) >= kill_s
            except (OSError, TypeError, KeyError):
                return False

        assert kill_when(proc, reached), "the run finished before the kill point"
        reached_s = float(read_running(run_dir)["simulated_s"])
        finish_kill(proc)
        assert (run_dir / "RUNNING").is_file() and not (run_dir / "metrics.json").exists()
        info = run_cli(str(run_dir), "--info", module="simlan_data.replay")
        assert info.returncode == 2 and "python -m simlan_data.recover" in info.stderr, info.stderr
        rec = run_cli(str(run_dir), module="simlan_data.recover")
        assert rec.returncode == 0, rec.stderr
        assert f"before {reached_s:.3f} s, the last camera tick the run reported" in rec.stdout
        got = messages_in_file_order(run_dir / "recording")
        assert got == reference[: len(got)], "recovered messages are not the start of the complete run"
        last_s = (max(m.log_time for m in got) - DEFAULT_EPOCH_NS) / NS_PER_S
        assert last_s >= reached_s - FLUSH_PERIOD_S - TRUTH_STEP_S, (kill_s, reached_s, last_s)
        # every message stamped more than one flush period before the kill is there
        must = sum(
            1 for m in reference if m.log_time - DEFAULT_EPOCH_NS < (reached_s - FLUSH_PERIOD_S) * NS_PER_S
        )
        assert len(got) >= must
        # ROS 2 tools see a normal bag: every message decodes with mcap_ros2, metadata is v9
        with mcap_file(run_dir / "recording").open("rb") as f:
            decoded = sum(
                1 for _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
            )
        assert decoded == len(got)
        meta = yaml.safe_load((run_dir / "recording" / "metadata.yaml").read_text())[
            "rosbag2_bagfile_information"
        ]
        assert meta["version"] == 9 and meta["message_count"] == len(got)
        assert meta["custom_data"]["simlan.format_version"] == FORMAT_VERSION
        assert meta["custom_data"]["simlan.recovered"] == "true"
        marker = yaml.safe_load((run_dir / "INCOMPLETE").read_text())
        assert marker["messages_recovered"] == len(got) and marker["reached_s"] == pytest.approx(reached_s)
        with RecordingReader(run_dir) as r:
            assert r.recovered and "Recovered:         yes" in r.summary()


def _limit_file_size() -> None:
    """In the child: no file may grow past 4 MiB (the world's meshes fit), and hitting that is an
    error (EFBIG), not a signal: the disk is "full" for the recording after a second or so."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (4 << 20, 4 << 20))


def test_a_full_disk_fails_the_run_with_exit_1_and_the_recording_recovers(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "simlan_data.run",
            *SMALL_RUN,
            "recording.depth_encoding=raw",  # raw 32FC1 depth with every frame: about 7 MiB/s
            "recording.depth_rate_hz=5",
            "duration_s=6",
            f"hydra.run.dir={run_dir}",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        preexec_fn=_limit_file_size,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 1, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: recording failed in "), proc.stderr
    assert "File too large" in lines[0] and f"python -m simlan_data.recover {run_dir}" in lines[0]
    assert (run_dir / "RUNNING").is_file()
    rec = run_cli(str(run_dir), module="simlan_data.recover")
    assert rec.returncode == 0, rec.stderr
    with RecordingReader(run_dir) as r:
        assert r.recovered and r.message_count > 100
        assert r.topics["/clock"].count >= 30  # at least half a second of data before the disk filled
        assert r.format_version == FORMAT_VERSION
