"""Pose mapping (issue 6): the humanoid, landmark projection, datasets, training, the drive.

Real PyBullet worlds, real EGL/Tiny renders, real parquet files read back with polars, real bags
read back with the independent mcap + mcap_ros2 reader. Small sizes keep the suite short.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import DATASET_ARGS, REPO, run_cli
from simlan_data.algorithms.posemap.dataset import read_dataset, split_of
from simlan_data.algorithms.posemap.estimators import CameraView, ProjectionEstimator
from simlan_data.algorithms.posemap.motion import load_motion
from simlan_data.constants import URDF_DIR
from simlan_data.errors import RecordingInputError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS
from simlan_data.sim.agents import spawn_agent
from simlan_data.sim.pybullet_client import connect
from simlan_data.sim.rendering import CameraRenderer, LabelTable
from simlan_data.world import skeleton as S
from simlan_data.world._pybullet import pb
from simlan_data.world.agent_types import AGENT_TYPES
from simlan_data.world.builder import build_world
from simlan_data.world.humanoid_urdf import urdf_text
from simlan_data.world.labels import label_id
from simlan_data.world.layout import load_layout

SIMLAN_REF = REPO.parent.parent / "shared" / "reference" / "simlan"
# SIMLAN's pose_to_motion config (its lists as published: upper and lower swapped for the 44 human joints)
SIMLAN_UPPER = [-0.610865, -0.523599, -0.349066, -0.261799, -0.610865, -0.785398, -0.0872665, -0.610865, -0.959931, -1.22173, -0.610865, -0.436332, -2.35619, -1.5708, -0.785398, -1.5708, 0.0, -0.872665, -0.523599, -1.5708, -1.5708, -3.14159, -1.5708, -2.53073, -1.0472, -0.349066, -0.785398, -2.0944, -0.785398, 0.0, -0.698132, -0.610865, -0.523599, -0.436332, -0.174533, -0.523599, -2.0944, -0.785398, 0.0, -0.523599, -0.785398, -0.523599, -0.872665, -0.174533, 1.5707, 1.5707, 1.5707]  # fmt: skip
SIMLAN_LOWER = [0.610865, 1.309, 0.349066, 0.698132, 0.610865, 0.0872665, 0.785398, 0.610865, 1.5708, 1.22173, 0.610865, 0.174533, 1.5708, 1.5708, 3.14159, 1.48353, 2.53073, 1.0472, 0.349066, 2.35619, 1.5708, 0.785398, 1.48353, 0.0, 0.872665, 0.523599, 0.523599, 0.261799, 0.785398, 2.35619, 0.523599, 0.785398, 0.872665, 0.872665, 1.5708, 0.785398, 0.261799, 0.785398, 2.35619, 0.698132, 0.610865, 0.872665, 0.436332, 1.5708, -1.5707, -1.5707, -1.5707]  # fmt: skip


def _one_error_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: "), stderr
    return lines[0]


@pytest.fixture
def tiny_client():
    client = connect("tiny")
    yield client
    client.disconnect()


# ------------------------------------------------------------------------------------ the body
def test_urdf_joints_and_limits_match_simlan(tiny_client) -> None:
    assert (URDF_DIR / "humanoid.urdf").read_text() == urdf_text(), (
        "regenerate: python -m simlan_data.world.humanoid_urdf"
    )
    body = pb.loadURDF(str(URDF_DIR / "humanoid.urdf"), useFixedBase=True, physicsClientId=tiny_client.id)
    revolute = {}
    for j in range(pb.getNumJoints(body, physicsClientId=tiny_client.id)):
        info = pb.getJointInfo(body, j, physicsClientId=tiny_client.id)
        if info[2] == pb.JOINT_REVOLUTE:
            revolute[info[1].decode()] = (info[8], info[9])
    assert len(revolute) == 47
    for motion in sorted((REPO / "assets" / "motions").glob("*.json")) + sorted(
        (SIMLAN_REF / "motions").glob("*.json")
    ):
        names = json.loads(motion.read_text())
        assert set(names) == set(revolute), motion  # exactly the motion files' joints
        assert list(names) == list(S.JOINT_NAMES), motion  # and in SIMLAN's order
        q = load_motion(str(motion))
        assert np.all(q >= S.LOWER) and np.all(q <= S.UPPER)
    # SIMLAN's swapped lists, read the right way round, are the URDF's limits
    simlan = S.limits_from_simlan_lists(list(S.JOINT_NAMES), SIMLAN_UPPER, SIMLAN_LOWER)
    for name, (lo, hi) in revolute.items():
        assert lo < hi
        assert (lo, hi) == pytest.approx(simlan[name], abs=2e-4), name
    # swapped as published: the "upper" list is below the "lower" list for every human joint
    assert all(u < lo for u, lo in zip(SIMLAN_UPPER[:44], SIMLAN_LOWER[:44]) if (u, lo) != (0.0, 0.0))


def test_numpy_kinematics_match_pybullet(tiny_client) -> None:
    agent = spawn_agent(
        tiny_client.id, "robot_agent_1", AGENT_TYPES["posed_humanoid"], pose=[5.3, -10.0, 0.7], marker_id=None
    )
    order = S.link_names()
    rng = np.random.default_rng(3)
    for q in S.sample_joints(rng, 4):
        agent.set_joints(q)
        assert np.allclose(agent.joint_positions(), q, atol=1e-9)
        T = S.forward_kinematics(q[None], agent.pose().matrix())[0]
        for i, name in enumerate(order[1:], 1):
            state = pb.getLinkState(
                agent.body, agent.links[name], computeForwardKinematics=True, physicsClientId=tiny_client.id
            )
            assert np.allclose(state[4], T[i, :3, 3], atol=1e-5), name
    # dressed: skin, shirt, trousers and shoes are different colours on the links
    colours = {
        tuple(round(c, 2) for c in v[7][:3])
        for v in pb.getVisualShapeData(agent.body, physicsClientId=tiny_client.id)
    }
    assert len(colours) >= 6
    assert agent.label == label_id("humanoid")


def test_sample_joints_stay_within_the_scaled_limits() -> None:
    q = S.sample_joints(np.random.default_rng(0), 5000, limit_scale=0.8)
    assert np.all(q >= 0.8 * S.LOWER - 1e-12) and np.all(q <= 0.8 * S.UPPER + 1e-12)
    # and cover them: the extremes come within 2 % of the scaled range
    span = 0.8 * (S.UPPER - S.LOWER)
    assert np.all(q.min(axis=0) - 0.8 * S.LOWER < 0.02 * span)
    assert np.all(0.8 * S.UPPER - q.max(axis=0) < 0.02 * span)


# -------------------------------------------------------------------------- landmark projection
def test_projected_landmarks_land_on_the_humanoid_in_rendered_images() -> None:
    """Visible landmarks fall on humanoid pixels of the rendered segmentation; depth- and
    ray-based occlusion agree."""
    client = connect("auto")
    try:
        labels = LabelTable()
        with tempfile.TemporaryDirectory() as tmp:
            world = build_world(
                client.id, load_layout("warehouse_layout.csv", "empty"), {}, mesh_dir=Path(tmp)
            )
        for body, label in world.labels.items():
            labels.set(body, label)
        cams = [load_calibration(c).camera.scaled(640, 360) for c in (500, 501, 502, 503)]
        renderers = [CameraRenderer(client, c, labels, near_m=0.3, far_m=60.0) for c in cams]
        for r in renderers:
            r.render_static()
        agent = spawn_agent(
            client.id, "robot_agent_1", AGENT_TYPES["posed_humanoid"], pose=[5.3, -10.0, 0.0], marker_id=None
        )
        labels.set(agent.body, agent.label)
        est = ProjectionEstimator(noise_px=0.0, hidden_noise_px=0.0, seed=0)
        on_body = visible = agree = total = 0
        for q in [
            load_motion("random_motion_1"),
            load_motion("random_motion_2"),
            *S.sample_joints(np.random.default_rng(5), 3),
        ]:
            agent.set_joints(q)
            world = agent.landmarks_world()
            box = agent.aabb()
            for r in renderers:
                images = r.render([box])
                lm = est.estimate([CameraView(r.camera, images.rgb, images.depth_m, world)])[0]
                u, v = lm[:, 0] * r.camera.width, lm[:, 1] * r.camera.height
                for k in np.flatnonzero(lm[:, 3] > 0.5):
                    i, j = round(float(v[k])), round(float(u[k]))
                    patch = images.labels[max(0, i - 1) : i + 2, max(0, j - 1) : j + 2]
                    visible += 1
                    on_body += int((patch == agent.label).any())
                # occlusion by ray casts gives the same answer for (almost) every landmark
                hits = pb.rayTestBatch(
                    [r.camera.position.tolist()] * 33, world.tolist(), physicsClientId=client.id
                )
                dist = np.linalg.norm(world - r.camera.position, axis=1)
                hidden = np.array([h[0] >= 0 for h in hits]) & (
                    np.array([h[2] for h in hits]) * dist < dist - S.LANDMARK_INSIDE_M - 0.03
                )
                rays = est.estimate([CameraView(r.camera, None, None, world, hidden=hidden)])[0]
                agree += int(((rays[:, 3] > 0.5) == (lm[:, 3] > 0.5)).sum())
                total += 33
        assert visible > 200
        assert on_body / visible > 0.97, (on_body, visible)
        assert agree / total > 0.93, (agree, total)
    finally:
        client.disconnect()


def test_projection_estimator_output_is_mediapipe_shaped() -> None:
    cam = load_calibration(502).camera.scaled(960, 540)  # at (8.5, -10) looking along -x: the person's front
    world = S.landmark_positions(
        np.zeros((1, 47)), np.array([[1, 0, 0, 5.3], [0, 1, 0, -10.0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    )[0]
    lm = ProjectionEstimator(noise_px=0.0, z_noise=0.0, seed=0).estimate(
        [CameraView(cam, landmarks_world=world)]
    )[0]
    assert lm.shape == (33, 4) and lm.dtype == np.float32
    assert np.all((lm[:, :2] > 0) & (lm[:, :2] < 1))  # the T-pose is in view
    hips = lm[[S.LANDMARK_NAMES.index("left_hip"), S.LANDMARK_NAMES.index("right_hip")], 2]
    assert abs(hips.mean()) < 1e-6  # z relative to the hips' midpoint
    # the nose is closer to the camera than the hips
    assert lm[S.LANDMARK_NAMES.index("nose"), 2] < 0
    uv, _ = cam.project(world)
    assert np.allclose(lm[:, 0] * 960, uv[:, 0], atol=1e-3)


# ------------------------------------------------------------------------------------- datasets
@pytest.mark.slow
def test_dataset_is_deterministic_per_seed(tmp_path: Path) -> None:
    digests = []
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        proc = run_cli(*DATASET_ARGS, "posemap.samples=6", f"seed={seed}", f"hydra.run.dir={tmp_path / name}")
        assert proc.returncode == 0, proc.stderr
        digests.append(read_dataset(str(tmp_path / name)).sha256)
    assert digests[0] == digests[1]
    assert (tmp_path / "a" / "dataset.parquet").read_bytes() == (
        tmp_path / "b" / "dataset.parquet"
    ).read_bytes()
    assert digests[2] != digests[0]
    # the summary goes through logging: on the console and in Hydra's run.log alike
    assert "posemap dataset (projection) finished" in proc.stdout
    assert "posemap dataset (projection) finished" in (tmp_path / "c" / "run.log").read_text()
    df = pl.read_parquet(tmp_path / "a" / "dataset.parquet")  # the columns the README promises
    assert df.columns == ["sample_id", "camera", "estimator", "detected", "landmarks", "joints"]
    assert df.height == 6 * 4 and set(df["camera"]) == {"500", "501", "502", "503"}
    assert df["estimator"].unique().to_list() == ["projection"]
    assert df["landmarks"].dtype == pl.Array(pl.Float32, (33, 4)) and df["joints"].dtype == pl.Array(
        pl.Float64, 47
    )
    q = df["joints"].to_numpy()
    assert np.all(q >= 0.8 * S.LOWER - 1e-9) and np.all(q <= 0.8 * S.UPPER + 1e-9)
    metrics = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert metrics["posemap.dataset.samples"] == 6 and metrics["posemap.dataset.visible_fraction"] > 0.3
    meta = json.loads((tmp_path / "a" / "dataset.json").read_text())
    assert meta["sha256"] == digests[0] and len(meta["camera_models"]) == 4
    assert (tmp_path / "a" / ".hydra" / "config.yaml").is_file()
    # the same run directory is never overwritten
    again = run_cli(*DATASET_ARGS, "posemap.samples=6", f"hydra.run.dir={tmp_path / 'a'}")
    assert again.returncode == 2 and "run directory not empty" in _one_error_line(again.stderr)


def test_split_is_by_sample_and_stable() -> None:
    ids = np.arange(20000)
    split = split_of(ids, val_fraction=0.1, test_fraction=0.15)
    assert abs((split == "test").mean() - 0.15) < 0.01 and abs((split == "val").mean() - 0.1) < 0.01
    # a sample keeps its split when the dataset grows
    assert np.array_equal(split_of(ids[:500], val_fraction=0.1, test_fraction=0.15), split[:500])


def test_tiny_training_beats_the_mean_pose(trained: tuple[Path, Path]) -> None:
    _, run = trained
    metrics = json.loads((run / "metrics.json").read_text())
    # 450 training samples, 40 epochs of a small MLP: better than the mean pose (measured 0.359 vs
    # 0.397 rad), and a fraction of its MPJPE (the support arm's global rotation is learnt first)
    mae, baseline = metrics["posemap.mae_rad"], metrics["posemap.baseline.mean_pose.mae_rad"]
    assert mae < 0.95 * baseline, (mae, baseline)
    assert metrics["posemap.mpjpe_m"] < 0.6 * metrics["posemap.baseline.mean_pose.mpjpe_m"]
    for key in ("posemap.mse_rad2", "posemap.mae_deg", "posemap.mse_deg2", "posemap.inference_us_per_sample"):
        assert metrics[key] > 0
    assert metrics["posemap.mae_deg"] == pytest.approx(np.degrees(metrics["posemap.mae_rad"]))
    assert all(f"posemap.joint.{n}.mae_rad" in metrics for n in S.JOINT_NAMES)
    info = json.loads((run / "model" / "model.json").read_text())
    assert info["dataset_sha256"] == read_dataset(info["dataset"]).sha256
    assert (
        info["config"]["model"] == "fusion"
        and info["metrics"]["posemap.mae_rad"] == metrics["posemap.mae_rad"]
    )
    assert (run / "posemap_report.md").read_text().count("| j") >= 44


@pytest.mark.slow  # (the default suite stays under 10 minutes; CI runs the slow suite too)
def test_drive_replays_landmarks_through_the_model(trained: tuple[Path, Path], tmp_path: Path) -> None:
    ds, run = trained
    proc = run_cli(
        "experiment=posemap_drive",
        f"posemap.drive={ds}",
        f"algorithms.posemap.model={run}",
        "duration_s=1.0",
        "world.fidelity=empty",
        "cameras.ids=[500]",
        "cameras.width=480",
        "cameras.height=270",
        "progress=false",
        f"hydra.run.dir={tmp_path / 'drive'}",
    )
    assert proc.returncode == 0, proc.stderr
    states, landmarks = [], 0
    with open(tmp_path / "drive" / "recording" / "recording.mcap", "rb") as f:
        for _, channel, message, msg in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            if channel.topic == "/robot_agent_1/joint_states":
                states.append((message.log_time - DEFAULT_EPOCH_NS, list(msg.name), np.array(msg.position)))
            elif channel.topic.endswith("/pose_landmarks"):
                landmarks += 1
                assert msg.estimator == "replay" and len(msg.x) == 33
    assert len(states) == 21  # 1 s at the 20 Hz control rate
    assert states[0][1] == list(S.JOINT_NAMES)
    # frame k of the dataset drives the body from k / cameras.rate_hz on
    from simlan_data.algorithms.posemap.training import TrainedMapper

    mapper = TrainedMapper(str(run))
    data = read_dataset(str(ds)).select_cameras(mapper.cameras)
    expected = mapper.predict(data.landmarks[:6])
    for stamp, _, pos in states:
        assert np.allclose(pos, expected[int(stamp // 200_000_000)], atol=1e-6)
    assert landmarks == 6 * 4  # the drive's input, per camera and frame
    metrics = json.loads((tmp_path / "drive" / "metrics.json").read_text())
    assert metrics["posemap.drive.frames"] == 600 and metrics["posemap.drive.mae_rad"] > 0


def test_motion_run_records_a_landmark_stream_the_drive_can_replay(
    trained: tuple[Path, Path], tmp_path: Path
) -> None:
    _, run = trained
    common = ("world.fidelity=empty", "cameras.width=480", "cameras.height=270", "progress=false")
    proc = run_cli(
        "experiment=posemap_motion", "duration_s=1.0", *common, f"hydra.run.dir={tmp_path / 'motion'}"
    )
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(
        "experiment=posemap_drive",
        f"posemap.drive={tmp_path / 'motion'}",
        f"algorithms.posemap.model={run}",
        "duration_s=1.0",
        *common,
        f"hydra.run.dir={tmp_path / 'drive'}",
    )
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((tmp_path / "drive" / "metrics.json").read_text())
    assert metrics["posemap.drive.frames"] == 6  # 1 s of 5 Hz landmark frames
    assert 0 < metrics["posemap.drive.mae_rad"] < 1.0  # against the motion run's joint states
    # the replay of the motion recording scores the same predictions: one reader, one predictor
    from simlan_data.apps import replay

    out = tmp_path / "replay"
    replay.main(
        [str(tmp_path / "motion"), "--out", str(out), "--algorithms", "posemap", "--set", f"model={run}"]
    )
    replayed = json.loads((out / "metrics.json").read_text())
    assert replayed["replay.posemap.mae_rad"] == pytest.approx(metrics["posemap.drive.mae_rad"], abs=1e-12)
    assert replayed["replay.posemap.mpjpe_m"] == pytest.approx(metrics["posemap.drive.mpjpe_m"], abs=1e-12)
    # the drive's own recording is refused: its joint states are the model's output, not truth
    with pytest.raises(RecordingInputError, match=r"recording is a drive's output in .*drive"):
        replay.main([str(tmp_path / "drive"), "--out", str(tmp_path / "r2"), "--algorithms", "posemap",
                     "--set", f"model={run}"])  # fmt: skip


# ------------------------------------------------------------------------------------ bad input
def test_motion_file_with_unknown_joints_is_one_error_line(tmp_path: Path) -> None:
    good = json.loads((REPO / "assets" / "motions" / "random_motion_1.json").read_text())
    bad = tmp_path / "bad_motion.json"
    bad.write_text(json.dumps({**good, "jLeftPinky_rotx": 0.1}))
    proc = run_cli(
        "experiment=posemap_motion",
        f"posemap.motion=[{bad}]",
        "progress=false",
        f"hydra.run.dir={tmp_path / 'run'}",
    )
    assert proc.returncode == 2
    line = _one_error_line(proc.stderr)
    assert "unknown joint jLeftPinky_rotx" in line and str(bad) in line
    assert not (tmp_path / "run" / "recording").exists()


def test_empty_dataset_is_one_error_line(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    schema = {"sample_id": pl.UInt32, "camera": pl.String, "estimator": pl.String, "detected": pl.Boolean,
              "landmarks": pl.Array(pl.Float32, (33, 4)), "joints": pl.Array(pl.Float64, 47)}  # fmt: skip
    pl.DataFrame(schema=schema).write_parquet(empty / "dataset.parquet")
    proc = run_cli(
        "experiment=posemap_train", f"posemap.dataset={empty}", f"hydra.run.dir={tmp_path / 'run'}"
    )
    assert proc.returncode == 2
    assert "empty dataset" in _one_error_line(proc.stderr)


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        (["experiment=posemap_train"], "invalid posemap.dataset=''"),
        (["experiment=posemap_train", "posemap.dataset=/no/such/dir"], "dataset not found"),
        (["experiment=posemap_dataset", "posemap.samples=0"], "invalid posemap.samples=0"),
        (
            ["experiment=posemap_dataset", "posemap.estimator=openpose"],
            "invalid posemap.estimator='openpose'",
        ),
        (["experiment=posemap_drive", "posemap.drive=/no/such/dir"], "invalid algorithms.posemap.model=''"),
        (
            ["experiment=posemap_drive", "posemap.drive=/tmp", "algorithms.posemap.model=/no/model"],
            "model not found",
        ),
        (["experiment=posemap_motion", "posemap.motion=[no_such_motion]"], "motion file not found"),
        (["posemap.motion=[random_motion_1]"], "no posed humanoid robot_agent_1"),
    ],
)
def test_bad_posemap_config_gives_one_line_and_exit_2(
    tmp_path: Path, overrides: list[str], expected: str
) -> None:
    proc = run_cli(*overrides, "progress=false", f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode == 2, proc.stderr
    assert expected in _one_error_line(proc.stderr)


def test_ambiguous_joints_give_identical_landmarks() -> None:
    """The shoulder (xyz) + elbow roty of an arm have one angle too many: another configuration on
    the same curve moves no landmark. (This is why the MAE has a floor; see ambiguity.py.)"""
    from scipy.spatial.transform import Rotation

    q = S.sample_joints(np.random.default_rng(1), 1)[0]
    idx = [
        S.JOINT_NAMES.index(n)
        for n in ("jRightShoulder_rotx", "jRightShoulder_roty", "jRightShoulder_rotz", "jRightElbow_roty")
    ]
    a = q[idx]
    R = Rotation.from_euler("XYZ", a[:3]).as_matrix() @ Rotation.from_euler("Y", a[3]).as_matrix()
    d = a[3] + 0.3
    other = q.copy()
    other[idx[:3]] = Rotation.from_matrix(R @ Rotation.from_euler("Y", -d).as_matrix()).as_euler("XYZ")
    other[idx[3]] = d
    assert np.abs(other - q).max() > 0.1
    assert np.allclose(S.landmark_positions(other[None]), S.landmark_positions(q[None]), atol=1e-9)


@pytest.mark.slow
def test_fusion_beats_simlans_single_camera_mlp_on_the_same_data(tmp_path: Path) -> None:
    """Guards the BENCHMARKS.md comparison at a CI-sized scale: 6000 samples, 12 epochs; the
    learned models alone, then the fusion model with the kinematic fit."""
    ds = tmp_path / "dataset"
    proc = run_cli(*DATASET_ARGS, "posemap.samples=6000", "posemap.occlusion=rays", f"hydra.run.dir={ds}")
    assert proc.returncode == 0, proc.stderr
    maes = {}
    for name, overrides in (
        ("simlan_mlp", ["posemap.model=mlp", "posemap.cameras=[500]", "algorithms.posemap.refine=none"]),
        (
            "fusion",
            [
                "posemap.model=fusion",
                "posemap.width=512",
                "posemap.dropout=0.0",
                "algorithms.posemap.refine=none",
            ],
        ),
        (
            "fusion_fit",
            [
                "posemap.model=fusion",
                "posemap.width=512",
                "posemap.dropout=0.0",
                "algorithms.posemap.refine=fit",
            ],
        ),
    ):
        run = tmp_path / name
        proc = run_cli(
            "experiment=posemap_train",
            f"posemap.dataset={ds}",
            "posemap.epochs=12",
            "posemap.batch_size=512",
            *overrides,
            f"hydra.run.dir={run}",
        )
        assert proc.returncode == 0, proc.stderr
        maes[name] = json.loads((run / "metrics.json").read_text())["posemap.mae_rad"]
    # at this scale fusion is 8-11 % better (0.305 vs 0.333 rad in one CI-sized run); >= 5 % is
    # asked so that run-to-run noise of a few thousandths does not decide
    assert maes["fusion"] < 0.95 * maes["simlan_mlp"], maes
    assert maes["fusion"] < 0.359  # SIMLAN's reported single-camera MLP
    # the kinematic fit on top: 0.118 rad on 100k samples (BENCHMARKS.md); at this scale it must
    # still beat SIMLAN's reported AutoGluon figure (0.2465) by far and halve SIMLAN's MLP here
    assert maes["fusion_fit"] < 0.55 * maes["simlan_mlp"], maes
    assert maes["fusion_fit"] < 0.16, maes
