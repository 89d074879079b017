"""The ``posemap`` replay algorithm: a recorded landmark stream through a trained pose mapper.

A real posemap_motion run (PyBullet, EGL, 4 cameras at 480x270, the humanoid's spawn jittered),
the tiny fusion model of the ``trained`` fixture (conftest), replayed through the real CLI; its
recording and artifacts read back with the independent mcap reader and polars.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import polars as pl
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import REPO, run_cli
from simlan_data.algorithms.posemap.training import TrainedMapper
from simlan_data.apps import evals, replay
from simlan_data.errors import SimlanError
from simlan_data.evaluation import replay_algorithms  # noqa: F401 - registers the algorithms
from simlan_data.evaluation.suite import Job
from simlan_data.evaluation.suite_report import plot_posemap
from simlan_data.evaluation.suite_spec import load_suite
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS
from simlan_data.sim.posemap_inputs import stream_from_recording
from simlan_data.world.skeleton import JOINT_NAMES

GOLDEN = REPO / "recordings" / "golden" / "single_truck"


@pytest.fixture(scope="module")
def motion(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2 s of SIMLAN's motions with live landmarks at 5 Hz; the humanoid stands off its usual spot."""
    run = tmp_path_factory.mktemp("posemap_replay") / "motion"
    proc = run_cli(
        "experiment=posemap_motion",
        "duration_s=2.0",
        "world.fidelity=empty",
        "cameras.width=480",
        "cameras.height=270",
        "cameras.streams=[rgb]",
        "perturbation.spawn_xy_m=0.15",
        "perturbation.spawn_yaw_deg=3",
        "seed=1",
        "progress=false",
        f"hydra.run.dir={run}",
    )
    assert proc.returncode == 0, proc.stderr
    return run


def _truth(run: Path) -> tuple[dict[int, np.ndarray], tuple[float, float]]:
    """Joint states by stamp and the humanoid's base xy, read with the independent reader."""
    joints, base = {}, None
    with open(run / "recording" / "recording.mcap", "rb") as f:
        for _, channel, message, msg in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages(topics=["/robot_agent_1/joint_states", "/ground_truth/poses"]):
            if channel.topic == "/robot_agent_1/joint_states":
                joints[message.log_time - DEFAULT_EPOCH_NS] = np.array(msg.position)  # simulated time
            elif base is None:
                t = msg.transforms[0].transform.translation
                base = (t.x, t.y)
    assert base is not None
    return joints, base


def test_replay_scores_the_model_against_the_recorded_targets(
    trained: tuple[Path, Path], motion: Path, tmp_path: Path
) -> None:
    _, model_run = trained
    out = tmp_path / "replay"
    proc = run_cli(
        str(motion), "--out", str(out), "--algorithms", "posemap", "--set", f"model={model_run}",
        module="simlan_data.replay", timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    p = "replay.posemap."
    assert m[p + "frames"] == 11  # 2 s of 5 Hz landmark frames, both ends included
    for key in ("mae_rad", "mae_deg", "mse_rad2", "mpjpe_m", "predict_ms_per_frame"):
        assert np.isfinite(m[p + key]) and m[p + key] > 0, key
    assert m[p + "mae_deg"] == pytest.approx(np.degrees(m[p + "mae_rad"]))
    # the tiny model knows something: better than its training set's mean pose, on motions it never saw
    assert m[p + "mae_rad"] < m[p + "baseline.mean_pose.mae_rad"], m
    assert m[p + "mpjpe_m"] < m[p + "baseline.mean_pose.mpjpe_m"], m
    # the recorded base pose was used: the jittered spawn, not where the dataset's humanoid stood
    joints, base = _truth(motion)
    assert m[p + "base_offset_m"] == pytest.approx(np.hypot(base[0] - 5.3, base[1] + 10.0), abs=1e-6)
    assert m[p + "base_offset_m"] > 0.01
    # artifacts: per frame (errors, predicted and true joints) and per joint
    frames = pl.read_parquet(out / "posemap_frames.parquet")
    assert frames.height == 11 and frames["stamp_ns"].to_list() == [k * 200_000_000 for k in range(11)]
    truth = frames["truth_rad"].to_numpy()
    assert np.array_equal(truth, np.stack([joints[s] for s in frames["stamp_ns"]]))  # the posed targets
    pred = frames["predicted_rad"].to_numpy()
    assert np.abs(pred - truth).mean() == pytest.approx(m[p + "mae_rad"])
    assert frames["mae_rad"].mean() == pytest.approx(m[p + "mae_rad"])
    assert frames["mpjpe_m"].mean() == pytest.approx(m[p + "mpjpe_m"])
    per_joint = pl.read_parquet(out / "posemap_joints.parquet")
    assert per_joint["joint"].to_list() == list(JOINT_NAMES)
    assert per_joint["mae_rad"].mean() == pytest.approx(m[p + "mae_rad"])
    # the model as the drive uses it gives the same predictions (one reader, one predictor)
    stream = stream_from_recording(str(motion), TrainedMapper(str(model_run)).cameras, "robot_agent_1")
    again = TrainedMapper(str(model_run)).predict(stream.landmarks, position=stream.position)
    assert np.allclose(again, pred, atol=1e-9)
    # and the suite report draws it (error over time per seed, worst joints)
    (case,) = [c for c in load_suite(evals.DEFAULT_FILE, "base").cases if c.name == "posemap_replay"]
    suite_out = tmp_path / "suite"
    shutil.copytree(out, suite_out / "replays" / "posemap_replay__s0" / "posemap")
    png = plot_posemap(tmp_path / "pm.png", case, [Job(case, 0, "posemap_replay__s0", motion)], suite_out)
    assert png is not None and cv2.imread(str(png)).shape[1] > 500


def _model_copy(model_run: Path, tmp_path: Path, edit) -> Path:
    """A copy of the trained model with ``edit(model_json_dict, directory)`` applied."""
    copy = tmp_path / "model_copy"
    shutil.copytree(model_run / "model", copy)
    info = json.loads((copy / "model.json").read_text())
    edit(info, copy)
    (copy / "model.json").write_text(json.dumps(info))
    return copy


def _moved_camera(info: dict, _: Path) -> None:
    info["feature_spec"]["camera_models"][1]["world_from_camera"][0][3] += 0.5


def _other_cameras(info: dict, _: Path) -> None:
    info["feature_spec"]["cameras"][3] = "163"


def _broken_weights(_: dict, directory: Path) -> None:
    (directory / "model.pt").write_bytes(b"not a torch file")


@pytest.mark.parametrize(
    ("recording", "options", "expected"),
    [
        ("golden", ["model={model}"], "recording has no landmark topics in .*: no /camera_<id>/pose_landmarks"),
        ("motion", [], "invalid posemap replay option model='' in config: no trained pose mapper given"),
        ("motion", ["model=/no/such/model"], "model not found in posemap replay option model=/no/such/model"),
        ("motion", ["model={broken}"], "model unreadable in posemap replay option model=.*model_copy: "),
        ("motion", ["model={moved}"], "model's cameras do not match the recording's in .*: camera 501 stands 0.500 m"),
        ("motion", ["model={other}"], "model's cameras do not match .*the model reads cameras 500, 501, 502, 163"),
        ("motion", ["model={model}", "modle=x"], "unknown posemap replay option 'modle'"),
        ("motion", ["model={model}", "position=[1,2]"], "invalid posemap replay option position=\\[1, 2\\]"),
    ],
)  # fmt: skip
def test_bad_input_is_one_error_with_exit_code_2(
    trained: tuple[Path, Path],
    motion: Path,
    tmp_path: Path,
    recording: str,
    options: list[str],
    expected: str,
) -> None:
    _, model_run = trained
    edits = {"broken": _broken_weights, "moved": _moved_camera, "other": _other_cameras}
    names = {"model": str(model_run)}
    for name, edit in edits.items():
        if "{" + name + "}" in " ".join(options):
            names[name] = str(_model_copy(model_run, tmp_path, edit))
    rec = GOLDEN if recording == "golden" else motion
    args = [str(rec), "--out", str(tmp_path / "out"), "--algorithms", "posemap"]
    for o in options:
        args += ["--set", o.format(**names)]
    with pytest.raises(SimlanError, match=expected) as err:
        replay.main(args)
    assert err.value.exit_code == 2
    assert not (tmp_path / "out" / "metrics.json").exists()


def test_a_bad_model_is_one_line_on_stderr(motion: Path, tmp_path: Path) -> None:
    proc = run_cli(
        str(motion), "--out", str(tmp_path / "out"), "--algorithms", "posemap", "--set", "model=/no/such/model",
        module="simlan_data.replay", timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: model not found in posemap replay option model=/no/such/model: no model.json there; give a "
        "training run directory or its model/ (python -m simlan_data.run experiment=posemap_train ...)"
    ]


def test_a_suite_resolves_the_model_relative_to_the_suite_file(tmp_path: Path) -> None:
    case = {
        "overrides": ["experiment=posemap_motion"],
        "replay": {"posemap": {"model": "models/small"}},
        "metrics": {"posemap": {"replay.posemap.mae_rad": {"max": 1.0}}},
    }
    (tmp_path / "evals").mkdir()
    path = tmp_path / "evals" / "s.yaml"
    path.write_text(yaml.safe_dump({"suites": {"s": {"baseline": "b.parquet", "cases": {"c": case}}}}))
    (c,) = load_suite(path, "s").cases
    assert c.replay["posemap"]["model"] == str(tmp_path / "evals" / "models" / "small")
    assert not c.pending
