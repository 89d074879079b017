"""Injected faults and seeded perturbations: what they change, and that they change nothing else."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import compose_config, run_cli
from simlan_data.algorithms.markers import MarkerObservation
from simlan_data.config.faults import CameraFaults, with_yaw_error
from simlan_data.config.validation import to_config
from simlan_data.errors import ConfigError
from simlan_data.evaluation.camera_health import MIN_SHARED_FRAMES, CameraConsistency
from simlan_data.geometry.calibration import load_calibration
from simlan_data.recording.reader import RecordingReader

CAMERA = load_calibration(163).camera.scaled(960, 540)


def floor_points(camera, uv: np.ndarray) -> np.ndarray:
    xyz, ok = camera.intersect_plane_z(uv, 0.0)
    assert ok.all()
    return xyz[:, :2]


def test_yaw_error_turns_every_ray_about_the_camera_vertical() -> None:
    wrong = with_yaw_error(CAMERA, 1.0)
    np.testing.assert_allclose(wrong.position, CAMERA.position, atol=1e-12)
    uv = np.array([[250.0, 150.0], [480.0, 270.0], [720.0, 420.0]])
    true_xy, believed_xy = floor_points(CAMERA, uv), floor_points(wrong, uv)
    c = CAMERA.position[:2]
    a = math.radians(1.0)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    np.testing.assert_allclose(believed_xy - c, (true_xy - c) @ rot.T, atol=1e-9)
    # a point d metres away (horizontally) lands d * 1 degree off: 5 m -> 8.7 cm
    d = np.linalg.norm(true_xy - c, axis=1)
    np.testing.assert_allclose(
        np.linalg.norm(believed_xy - true_xy, axis=1), d * 2 * math.sin(a / 2), rtol=1e-9
    )
    assert with_yaw_error(CAMERA, 0.0) is CAMERA


def test_camera_faults_from_the_run_config_and_replay_options() -> None:
    cameras = {"162": load_calibration(162).camera, "163": CAMERA}
    recorded = {"faults": {"drop_cameras": [163], "yaw_error_deg": 0.0, "yaw_error_cameras": []}}
    faults = CameraFaults.from_settings(recorded)
    assert faults.active and list(faults.apply(cameras)) == ["162"]
    # a replay option overrides the recorded section (here: the camera comes back, another is wrong)
    faults = CameraFaults.from_settings(
        recorded, {"drop_cameras": [], "yaw_error_deg": 1, "yaw_error_cameras": [162]}
    )
    believed = faults.apply(cameras)
    assert list(believed) == ["162", "163"] and believed["163"] is CAMERA
    assert not np.allclose(
        believed["162"].camera_from_world.rotation, cameras["162"].camera_from_world.rotation
    )
    assert faults.describe() == "1 deg yaw error on camera 162"
    assert not CameraFaults.from_settings({}).active
    with pytest.raises(
        ConfigError, match="unknown camera 170 in the injected faults in here: the cameras are 162, 163"
    ):
        CameraFaults.from_settings({}, {"drop_cameras": [170]}).apply(cameras, where="here")
    with pytest.raises(ConfigError, match=r"invalid drop_cameras=\{'163': 1\} in faults: expected a list"):
        CameraFaults.from_settings({}, {"drop_cameras": {"163": 1}})


def test_faults_config_must_name_configured_cameras() -> None:
    with pytest.raises(
        ConfigError, match=r"invalid faults=999 in config: not one of cameras.ids; use one of 160"
    ):
        to_config(compose_config("faults.drop_cameras=[999]"))
    with pytest.raises(ConfigError, match=r"invalid faults.yaw_error_deg=45.0"):
        to_config(compose_config("faults.yaw_error_deg=45", "faults.yaw_error_cameras=[163]"))


def spawn(*overrides: str) -> list[float]:
    return list(to_config(compose_config("scenario=multi_robot", *overrides)).agents["robot_agent_3"].pose)


def test_the_seed_jitters_spawn_poses_deterministically() -> None:
    plain = spawn()
    assert spawn("seed=1") == plain  # without a perturbation the seed changes nothing
    jitter = ("perturbation.spawn_xy_m=0.15", "perturbation.spawn_yaw_deg=3")
    a, b, c = spawn("seed=1", *jitter), spawn("seed=1", *jitter), spawn("seed=2", *jitter)
    assert a == b and a != c
    for pose in (a, c):
        assert abs(pose[0] - plain[0]) <= 0.15 and abs(pose[1] - plain[1]) <= 0.15
        assert abs(pose[2] - plain[2]) <= math.radians(3) + 1e-12
        assert pose != plain
    # each agent draws from (seed, its number): another agent's jitter does not depend on the list
    four = to_config(compose_config("scenario=multi_robot", "seed=1", *jitter)).agents
    assert list(four["robot_agent_3"].pose) == a
    with pytest.raises(
        ConfigError, match=r"invalid perturbation.spawn_xy_m=5.0 in config: must be within 0..2 m"
    ):
        spawn("perturbation.spawn_xy_m=5")


def test_a_dropped_camera_still_records_but_never_reaches_the_localizer(tmp_path: Path) -> None:
    """A real 2 s run with the truck under camera 163 and 163 dropped: the bag holds its images,
    the localizer saw none; a replay that gives 163 back localizes the truck."""
    run = tmp_path / "dropped"
    proc = run_cli(
        "duration_s=2",
        "cameras=single",
        "cameras.width=480",
        "cameras.height=270",
        "cameras.streams=[rgb]",
        "agents.robot_agent_1.pose=[5.0,0.4,0.0]",
        "faults.drop_cameras=[163]",
        f"hydra.run.dir={run}",
        "progress=false",
    )
    assert proc.returncode == 0, proc.stderr
    with RecordingReader(run) as bag:
        assert bag.topics["/camera_163/image_raw/compressed"].count == 11
        assert "/robot_agent_1/pose_estimate" not in bag.topics
        assert "/camera_163/marker_detections" not in bag.topics
    replay = run_cli(
        str(run), "--out", str(tmp_path / "back"), "--set", "drop_cameras=[]", module="simlan_data.replay"
    )
    assert replay.returncode == 0, replay.stderr
    assert "localization.robot_agent_1.ticks_valid" in replay.stdout
    valid = float(replay.stdout.split("localization.robot_agent_1.ticks_valid")[1].split()[0])
    assert valid >= 30  # 2 s at 20 Hz: localized from the first frame on


def obs(camera: str, x: float, y: float, marker: int = 1) -> MarkerObservation:
    return MarkerObservation(camera, marker, x, y, 0.0, 0.01, 0.01, 0.2, 40.0)


def test_camera_health_points_at_the_camera_that_disagrees() -> None:
    health = CameraConsistency()
    for k in range(20):
        x = 0.1 * k
        # 162 and 164 agree within 2 mm; 163 sees the marker 6 cm off (a wrong calibration)
        health.add([obs("162", x, 0.0), obs("163", x + 0.06, 0.0), obs("164", x + 0.002, 0.0)])
        health.add([obs("170", 5.0, 5.0, marker=2)])  # seen alone: no comparison possible
    m = health.metrics("p.")
    assert m["p.cameras_detecting"] == 4
    assert m["p.camera_163.disagreement_m"] == pytest.approx(0.059)
    assert m["p.camera_162.disagreement_m"] < 0.032 and m["p.camera_164.disagreement_m"] < 0.032
    assert m["p.camera_disagreement_max_m"] == m["p.camera_163.disagreement_m"]
    assert "p.camera_170.disagreement_m" not in m


def test_camera_health_gives_no_figure_to_a_camera_that_shared_a_marker_too_rarely() -> None:
    health = CameraConsistency()
    for k in range(10):
        x = 0.1 * k
        health.add([obs("162", x, 0.0), obs("163", x + 0.004, 0.0)])
    for _ in range(MIN_SHARED_FRAMES - 1):  # too rarely, 2 cm off, at the edge of its image
        health.add([obs("160", 0.92, 0.0), obs("162", 0.9, 0.0)])
    m = health.metrics("p.")
    assert m["p.cameras_detecting"] == 3  # it delivered: it counts as detecting
    assert "p.camera_160.disagreement_m" not in m
    assert m["p.camera_disagreement_max_m"] == pytest.approx(
        max(m["p.camera_162.disagreement_m"], m["p.camera_163.disagreement_m"])
    )
    assert m["p.camera_disagreement_max_m"] < 0.01
