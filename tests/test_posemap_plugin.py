"""A user's pose mapper (role ``posemap``) behind the plug-in seam, end to end.

A nearest-neighbour mapper defined in a module of the test's tmp directory (``nn_mapper:Nearest``,
PYTHONPATH) looks up the closest of a few dataset samples; selected by import path it drives the
humanoid live (``experiment=posemap_drive``) and runs in the ``posemap`` replay (``--set
posemap=...``). Real processes, real PyBullet, bags read back with the independent reader; the
expected joint targets are computed here from the dataset and the landmarks as recorded.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import run_cli
from simlan_data.algorithms.posemap.dataset import read_dataset
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS
from simlan_data.sim.posemap_inputs import stream_from_recording

MAPPER = '''
from dataclasses import dataclass

import numpy as np

from simlan_data.algorithms.posemap.dataset import read_dataset


@dataclass(frozen=True)
class NearestConfig:
    dataset: str = ""
    samples: int = 8

    def __post_init__(self):
        if self.samples < 1:
            raise ValueError("samples must be >= 1")


class Nearest:
    """The joints of the nearest of the dataset's first samples (landmark x, y of every camera)."""

    role = "posemap"
    config_class = NearestConfig

    def __init__(self, config, context):
        self.cameras = sorted(c.camera_id for c in context.cameras)
        data = read_dataset(config.dataset).select_cameras(self.cameras)
        self.keys = data.landmarks[: config.samples, ..., :2].reshape(min(config.samples, len(data)), -1)
        self.joints = data.joints[: config.samples]

    def predict(self, landmarks, *, position=None):
        x = np.asarray(landmarks)[..., :2].reshape(len(landmarks), -1)
        d = ((x[:, None, :] - self.keys[None]) ** 2).sum(axis=2)
        return self.joints[d.argmin(axis=1)]


class Boom(Nearest):
    def predict(self, landmarks, *, position=None):
        raise RuntimeError("no pose today")
'''
COMMON = ("world.fidelity=empty", "cameras.width=480", "cameras.height=270", "progress=false")


def nearest(ds: Path, cameras: list[str], landmarks: np.ndarray, samples: int) -> np.ndarray:
    """What the plug-in should return, computed independently of it."""
    data = read_dataset(str(ds)).select_cameras(cameras)
    keys = data.landmarks[:samples, ..., :2].reshape(samples, -1)
    x = landmarks[..., :2].reshape(len(landmarks), -1)
    return data.joints[:samples][np.argmin(((x[:, None] - keys[None]) ** 2).sum(axis=2), axis=1)]


@pytest.fixture(scope="module")
def plugin(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The directory of the plug-in's module, as the environment that imports it."""
    root = tmp_path_factory.mktemp("posemap_plugin")
    (root / "nn_mapper.py").write_text(textwrap.dedent(MAPPER))
    return {"PYTHONPATH": str(root)}


@pytest.fixture(scope="module")
def motion(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """1 s of SIMLAN's motions with live landmarks at 5 Hz on the four capture cameras."""
    run = tmp_path_factory.mktemp("posemap_plugin") / "motion"
    proc = run_cli("experiment=posemap_motion", "duration_s=1.0", *COMMON, f"hydra.run.dir={run}")
    assert proc.returncode == 0, proc.stderr
    return run


def test_a_users_mapper_runs_in_the_replay(
    trained: tuple[Path, Path], motion: Path, plugin: dict[str, str], tmp_path: Path
) -> None:
    ds, _ = trained
    out = tmp_path / "replay"
    proc = run_cli(
        str(motion), "--out", str(out), "--algorithms", "posemap",
        "--set", "posemap=nn_mapper:Nearest", "--set", f"dataset={ds}", "--set", "samples=40",
        module="simlan_data.replay", env=plugin, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["replay.posemap.frames"] == 6  # 1 s of 5 Hz landmark frames
    frames = pl.read_parquet(out / "posemap_frames.parquet")
    cameras = ["500", "501", "502", "503"]  # every camera with landmarks (the context's)
    stream = stream_from_recording(str(motion), cameras, "robot_agent_1")
    expected = nearest(ds, cameras, stream.landmarks, 40)
    assert np.array_equal(np.stack(frames["predicted_rad"].to_list()), expected)
    # no model of its own: the baseline is the recording's mean pose
    assert metrics["replay.posemap.baseline.mean_pose.mae_rad"] == pytest.approx(
        float(np.abs(stream.truth.mean(0) - stream.truth).mean())
    )


def test_a_users_mapper_drives_the_humanoid_live(
    trained: tuple[Path, Path], plugin: dict[str, str], tmp_path: Path
) -> None:
    ds, _ = trained
    proc = run_cli(
        "experiment=posemap_drive",
        f"posemap.drive={ds}",
        "algorithms/posemap=nn_mapper:Nearest",
        f"algorithms.posemap.dataset={ds}",
        "algorithms.posemap.samples=5",
        "duration_s=1.0",
        "cameras.ids=[500]",
        *COMMON,
        f"hydra.run.dir={tmp_path / 'drive'}",
        env=plugin,
    )
    assert proc.returncode == 0, proc.stderr
    states = []
    with open(tmp_path / "drive" / "recording" / "recording.mcap", "rb") as f:
        for _, _, message, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            topics=["/robot_agent_1/joint_states"]
        ):
            states.append((message.log_time - DEFAULT_EPOCH_NS, np.array(msg.position)))
    assert len(states) == 21  # 1 s at the 20 Hz control rate
    data = read_dataset(str(ds))  # the dataset's cameras: the context of the drive
    expected = nearest(ds, list(data.cameras), data.landmarks[:6], 5)
    for stamp, pos in states:  # frame k drives the body from k / cameras.rate_hz on
        assert np.allclose(pos, expected[int(stamp // 200_000_000)], atol=1e-6)
    metrics = json.loads((tmp_path / "drive" / "metrics.json").read_text())
    assert metrics["posemap.drive.frames"] == 600


@pytest.mark.parametrize(
    ("args", "code", "expected"),
    [
        # the built-in's own config refuses a value: exit 2, the key named
        (["--set", "model=x", "--set", "refine=icp"], 2, "invalid algorithms.posemap.refine='icp'"),
        (["--set", "posemap=nn_mapper:Nearest", "--set", "samples=0"], 2, "samples must be >= 1"),
        (
            ["--set", "posemap=nn_mapper:Nearest", "--set", "model=x"],
            2,
            "unknown posemap replay option 'model'",
        ),
        (["--set", "posemap=nn_mapper:Nope"], 2, "cannot import posemap 'nn_mapper:Nope'"),
        (["--set", "posemap=no_such"], 2, "no posemap named 'no_such'"),
        # an exception inside the plug-in names it (exit 1)
        (
            ["--set", "posemap=nn_mapper:Boom", "--set", "dataset={ds}"],
            1,
            "posemap 'nn_mapper:Boom' failed in predict()",
        ),
    ],
)
def test_refusals_are_one_line(
    trained: tuple[Path, Path], motion: Path, plugin: dict[str, str], tmp_path: Path,
    args: list[str], code: int, expected: str,
) -> None:  # fmt: skip
    ds, _ = trained
    proc = run_cli(
        str(motion), "--out", str(tmp_path / "out"), "--algorithms", "posemap",
        *[a.format(ds=ds) for a in args], module="simlan_data.replay", env=plugin, timeout=300,
    )  # fmt: skip
    assert proc.returncode == code, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], proc.stderr


def test_the_builtin_refuses_a_bad_value_live_with_exit_2(tmp_path: Path) -> None:
    proc = run_cli(
        "experiment=posemap_drive",
        "algorithms.posemap.refine_starts=0",
        *COMMON,
        f"hydra.run.dir={tmp_path / 'r'}",
    )
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "invalid algorithms.posemap.refine_starts=0" in lines[0], proc.stderr


def test_recordings_before_the_algorithms_section_replay_with_the_builtin() -> None:
    from simlan_data.evaluation.posemap_replay import selected_mapper

    legacy = {"posemap": {"drive_model": "runs/m", "refine": "none", "refine_starts": 2}}
    spec, config = selected_mapper(legacy)
    # the old section's refine keys were training's: the drive applied the model's saved fit
    assert (spec.name, config.model, config.refine, config.refine_starts) == ("trained", "runs/m", "fit", 8)
    spec, config = selected_mapper(legacy, {"model": "other", "refine": "none"})
    assert (config.model, config.refine) == ("other", "none")
    spec, config = selected_mapper(
        {"algorithms": {"posemap": {"name": "trained", "model": "a", "refine": "none"}}}
    )
    assert (config.model, config.refine) == ("a", "none")
