"""Algorithm plug-ins end to end: the example package examples/simlan_centroid_localizer installed
into this environment, selected by name or import path, run live, replayed, and refused with one
line when it is misconfigured or broken. Real processes, real PyBullet, bags read back with the
independent reader (mcap + mcap_ros2), no mocks.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import polars as pl
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "simlan_centroid_localizer"
# two cameras over the truck's start (160, 161), half resolution: the marker is still found
SMALL = ["cameras=gpss", "cameras.count=2", "cameras.width=480", "cameras.height=270", "progress=false"]

BROKEN = """
from dataclasses import dataclass

from simlan_centroid_localizer import CentroidLocalizer


@dataclass(frozen=True)
class Cfg:
    k: int = 1


class NoEstimate:
    role = "localizer"
    config_class = Cfg

    def __init__(self, config, context):
        pass

    def observe(self, t_ns, frames):
        pass

    def command(self, t_ns, namespace, linear_mps, angular_rps):
        pass


class NoRole:
    config_class = Cfg

    def __init__(self, config, context):
        pass


class Boom(CentroidLocalizer):
    def observe(self, t_ns, frames):
        if t_ns >= 1_000_000_000:
            raise RuntimeError("boom in observe")
        super().observe(t_ns, frames)
"""


pytestmark = pytest.mark.usefixtures("plugin_installed")  # (session scope: before any run)


def _run(args: list[str], *, cwd: Path, env_path: Path | None = None, module: str = "simlan_data.run"):
    env = dict(os.environ)
    if env_path is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(env_path), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.run(
        [sys.executable, "-m", module, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


def _error_line(stderr: str) -> str:
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one error line, got:\n{stderr}"
    assert lines[0].startswith("error: "), lines[0]
    return lines[0]


def _messages(bag: Path, topic: str) -> list:
    with open(bag / "recording.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [msg for _, _, _, msg in reader.iter_decoded_messages(topics=[topic])]


def _recorded_config(bag: Path) -> dict:
    (msg,) = _messages(bag, "/simlan/config")
    return yaml.safe_load(msg.data)


def _replay(recording: Path, out: Path, *sets: str) -> dict[str, float]:
    args = [str(recording), "--algorithms", "localization", "--out", str(out)]
    for s in sets:
        args += ["--set", s]
    done = _run(args, cwd=out.parent, module="simlan_data.replay")
    assert done.returncode == 0, done.stderr
    return json.loads((out / "metrics.json").read_text())


@pytest.fixture(scope="module")
def centroid_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run_dir = tmp_path_factory.mktemp("centroid") / "run"
    done = _run(
        ["duration_s=3", *SMALL, "algorithms/localizer=centroid", f"hydra.run.dir={run_dir}"],
        cwd=run_dir.parent,
    )
    assert done.returncode == 0, done.stderr
    return run_dir


def test_live_run_records_centroid_estimates(centroid_run: Path) -> None:
    """(a) selected by its registered name, it localizes the truck live; the bag says which."""
    bag = centroid_run / "recording"
    estimates = _messages(bag, "/robot_agent_1/pose_estimate")
    assert len(estimates) >= 40  # 3 s at 20 Hz: every control tick after the first fix
    config = _recorded_config(bag)
    assert config["algorithms"]["localizer"]["name"] == "centroid"
    assert config["algorithms"]["localizer"]["alpha"] == 0.9
    metrics = json.loads((centroid_run / "metrics.json").read_text())
    assert metrics["localization.availability"] == 1.0
    assert metrics["localization.ate_xy_rmse_m"] < 0.05  # cm level (1-2 cm measured at 480x270)


def test_replay_reproduces_live_and_a_config_key_changes_it(centroid_run: Path, tmp_path: Path) -> None:
    """(b) the replay hands it the recorded JPEGs: bit for bit the live estimates; --set alpha
    (a key of its own config) changes them."""
    same = _replay(centroid_run / "recording", tmp_path / "same", "localizer=centroid")
    assert same["replay.localization.max_diff_to_live_m"] == 0.0
    assert "replay.localization.frames_processed" not in same  # it keeps no frame timings: no figure, not 0
    slow = _replay(
        centroid_run / "recording", tmp_path / "slow", "localizer=centroid", "alpha=0.2", "beta=0.05"
    )
    assert slow["replay.localization.max_diff_to_live_m"] > 0.005
    assert slow["localization.ate_xy_rmse_m"] != same["localization.ate_xy_rmse_m"]


def test_config_key_from_the_command_line_lands_in_the_recorded_config(tmp_path: Path) -> None:
    """(c) algorithms.localizer.alpha=0.5 reaches the plug-in and the recorded config."""
    run_dir = tmp_path / "run"
    done = _run(
        [
            "duration_s=0.5",
            *SMALL,
            "algorithms/localizer=centroid",
            "algorithms.localizer.alpha=0.5",
            f"hydra.run.dir={run_dir}",
        ],
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    section = _recorded_config(run_dir / "recording")["algorithms"]["localizer"]
    assert section["name"] == "centroid" and section["alpha"] == 0.5, section


def test_a_value_the_config_rejects_exits_2_with_its_check(tmp_path: Path) -> None:
    """(c) alpha=7: its dataclass refuses it; one line naming key and value, nothing written."""
    run_dir = tmp_path / "run"
    done = _run(
        [
            "duration_s=0.5",
            *SMALL,
            "algorithms/localizer=centroid",
            "algorithms.localizer.alpha=7",
            f"hydra.run.dir={run_dir}",
        ],
        cwd=tmp_path,
    )
    assert done.returncode == 2, done.stderr
    line = _error_line(done.stderr)
    assert line == (
        "error: invalid config for localizer 'centroid' in config algorithms.localizer: "
        "alpha=7.0 is out of range: alpha must be in (0, 1]; fix the value"
    ), line
    assert not run_dir.exists()  # nothing written: the directory Hydra made for it is gone too


def test_an_unknown_name_lists_the_registered_ones(tmp_path: Path) -> None:
    """(d) algorithms/localizer=nope: exit 2, one line listing aruco and centroid."""
    done = _run(
        ["duration_s=0.5", *SMALL, "algorithms/localizer=nope", f"hydra.run.dir={tmp_path / 'run'}"],
        cwd=tmp_path,
    )
    assert done.returncode == 2, done.stderr
    line = _error_line(done.stderr)
    assert (
        "no localizer named 'nope'" in line and "registered localizers: aruco, centroid, foreground" in line
    ), line
    assert not (tmp_path / "run").exists()


@pytest.fixture
def broken_module(tmp_path: Path) -> Path:
    (tmp_path / "badloc.py").write_text(textwrap.dedent(BROKEN))
    return tmp_path


@pytest.mark.parametrize(
    ("target", "words"),
    [
        (
            "badloc:NoEstimate",
            ["badloc.NoEstimate does not implement the localizer protocol", "missing method: estimate"],
        ),
        (
            "badloc:NoRole",
            ["badloc.NoRole is not a localizer", "it declares no role", 'set role = "localizer"'],
        ),
    ],
)
def test_a_class_that_is_no_localizer_is_refused(broken_module: Path, target: str, words: list[str]) -> None:
    """(e) by import path: exit 2 before anything runs, one line saying what is missing."""
    run_dir = broken_module / "run"
    done = _run(
        ["duration_s=0.5", *SMALL, f"algorithms/localizer={target}", f"hydra.run.dir={run_dir}"],
        cwd=broken_module,
        env_path=broken_module,
    )
    assert done.returncode == 2, done.stderr
    line = _error_line(done.stderr)
    for w in words:
        assert w in line, line
    assert not run_dir.exists()


@pytest.fixture(scope="module")
def failing_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess, Path]:
    broken_module = tmp_path_factory.mktemp("failing")
    (broken_module / "badloc.py").write_text(textwrap.dedent(BROKEN))
    run_dir = broken_module / "run"
    done = _run(
        ["duration_s=2", *SMALL, "algorithms/localizer=badloc:Boom", f"hydra.run.dir={run_dir}"],
        cwd=broken_module,
        env_path=broken_module,
    )
    return done, run_dir


def test_an_exception_in_the_plugin_names_it_and_the_time(
    failing_run: tuple[subprocess.CompletedProcess, Path],
) -> None:
    """(f) raises in observe() at t >= 1 s: exit 1, one line naming role, name, method and time."""
    done, run_dir = failing_run
    assert done.returncode == 1, done.stderr
    line = _error_line(done.stderr)
    assert "localizer 'badloc:Boom' failed in observe()" in line, line
    assert "at t=1.000 s" in line and "RuntimeError: boom in observe" in line, line
    assert (run_dir / "recording" / "recording.mcap").exists()


def test_an_exception_in_the_plugin_leaves_a_finalized_recording(
    failing_run: tuple[subprocess.CompletedProcess, Path],
) -> None:
    """(f) the recording up to the failure is closed properly: summary and metadata.yaml."""
    done, run_dir = failing_run
    assert done.returncode == 1, done.stderr
    bag = run_dir / "recording"
    assert (bag / "metadata.yaml").exists()
    with open(bag / "recording.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count > 0
    assert not (run_dir / "RUNNING").exists(), "a finished recording needs no recovery marker"


@pytest.mark.slow  # (20 s of suite runs: the default suite stays under 10 minutes; CI runs slow too)
def test_the_example_plugin_is_scored_against_the_built_in_in_a_suite(tmp_path: Path) -> None:
    """(5) the installed plug-in through a V&V suite: `evals --candidate algorithms/localizer=centroid`
    simulates both sides over the same seeds (the candidate's robots steer on centroid's
    estimates), replays each with its own localizer and writes the comparison."""
    from test_evals_compare import tiny_suite

    suite, out = tiny_suite(tmp_path), tmp_path / "out"
    done = _run(
        [
            "mini",
            "--file",
            str(suite),
            "--jobs",
            "2",
            "--out",
            str(out),
            "--candidate",
            "algorithms/localizer=centroid",
        ],
        cwd=tmp_path,
        module="simlan_data.evals",
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    cmp = pl.read_parquet(out / "compare.parquet")
    ate = cmp.filter(pl.col("metric") == "localization.ate_xy_rmse_m", pl.col("source") == "localization")
    assert ate["baseline_n"][0] == 2 and ate["candidate_n"][0] == 2
    assert ate["diff"][0] != 0  # two different localizers: not the same estimates
    # the candidate's runs recorded centroid as their localizer, the baseline's the built-in
    for side, name in (("baseline", "aruco"), ("candidate", "centroid")):
        config = _recorded_config(out / side / "runs" / "truck__s0" / "recording")
        assert config["algorithms"]["localizer"]["name"] == name
    assert "algorithms/localizer=centroid" in (out / "compare.md").read_text()
