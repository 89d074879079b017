"""A real short run of the default scenario, read back with the independent mcap + mcap_ros2 reader."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import run_cli
from simlan_data.constants import FORMAT_VERSION
from simlan_data.recording.codecs import decode_compressed
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS

CAMERAS = [str(c) for c in range(160, 171)]


@pytest.fixture(scope="module")
def bag(short_run: Path) -> dict[str, list]:
    """Every message of the run's MCAP file, decoded by mcap_ros2: {topic: [(log_time, msg)]}."""
    files = list((short_run / "recording").glob("*.mcap"))
    assert len(files) == 1
    out: dict[str, list] = defaultdict(list)
    with files[0].open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            out[channel.topic].append((message.log_time, decoded))
    return out


def test_run_directory_layout(short_run: Path) -> None:
    assert (short_run / "recording" / "metadata.yaml").is_file()
    assert (short_run / "report.md").is_file()
    assert (short_run / ".hydra" / "config.yaml").is_file()
    assert not (short_run / "RUNNING").exists()
    metrics = json.loads((short_run / "metrics.json").read_text())
    for key in ("sim.rtf", "sim.duration_s", "sim.wall_s", "sim.camera_frames", "agents.collisions"):
        assert isinstance(metrics[key], float), key
    assert metrics["sim.duration_s"] == pytest.approx(3.0)
    assert metrics["sim.camera_frames"] == 11 * 16  # 5 Hz over [0, 3] s, both ends included
    assert metrics["agents.collisions"] == 0
    assert metrics["sim.rtf"] > 0


def test_every_topic_is_present(bag: dict[str, list]) -> None:
    expected = {
        "/clock",
        "/tf_static",
        "/ground_truth/poses",
        "/simlan/config",
        "/simlan/run_info",
        "/simlan/semantic_labels",
        "/robot_agent_1/cmd_vel",
        "/robot_agent_1/collision",
        "/robot_agent_1/plan",
    }
    for cid in CAMERAS:
        expected |= {
            f"/camera_{cid}/image_raw/compressed",
            f"/camera_{cid}/camera_info",
            f"/camera_{cid}/depth/image_raw",
            f"/camera_{cid}/semantic/image_raw/compressed",
        }
    assert expected <= set(bag), expected - set(bag)


def test_clock_and_ground_truth_rates(bag: dict[str, list]) -> None:
    clock = [stamp for stamp, _ in bag["/clock"]]
    assert clock == sorted(clock) and clock[0] == DEFAULT_EPOCH_NS  # simulated time 0 (timebase.py)
    gt = bag["/ground_truth/poses"]
    times = np.array([t for t, _ in gt]) / 1e9
    assert 1.0 / np.diff(times).max() >= 50.0  # >= 50 Hz
    tf = gt[-1][1].transforms[0]
    assert tf.header.frame_id == "map" and tf.child_frame_id == "ground_truth/robot_agent_1/base_link"
    # the truck starts at (-16, 0.4) and drives east along the aisle
    first, last = gt[0][1].transforms[0].transform.translation, tf.transform.translation
    assert first.x == pytest.approx(-16.0, abs=0.05) and first.y == pytest.approx(0.4, abs=0.05)
    assert 1.0 < last.x - first.x < 3.5


def test_camera_streams_decode_to_sane_images(bag: dict[str, list]) -> None:
    _stamp, info = bag["/camera_163/camera_info"][0]
    assert (info.width, info.height, info.distortion_model) == (960, 540, "plumb_bob")
    assert info.k[0] == pytest.approx(2149.369022 / 4)
    assert info.header.frame_id == "camera_163_optical_frame"
    _, rgb_msg = bag["/camera_163/image_raw/compressed"][0]
    rgb = cv2.imdecode(np.frombuffer(bytes(rgb_msg.data), np.uint8), cv2.IMREAD_COLOR)
    assert rgb.shape == (540, 960, 3) and rgb.std() > 10
    _, depth_msg = bag["/camera_163/depth/image_raw"][0]
    assert (depth_msg.encoding, depth_msg.is_bigendian, depth_msg.step) == ("16UC1", 0, 2 * 960)
    depth_mm = np.frombuffer(bytes(depth_msg.data), "<u2").reshape(depth_msg.height, depth_msg.width)
    assert depth_mm.shape == (540, 960)
    valid = depth_mm > 0
    assert 0.7 < valid.mean() < 0.97  # the distortion vignette has no depth
    assert 4000 < np.median(depth_mm[valid]) < 20000  # camera 7.3 m up, looking down the aisle
    _, sem_msg = bag["/camera_163/semantic/image_raw/compressed"][0]
    labels = decode_compressed(sem_msg.format, sem_msg.data)  # (the palette PNG's indices)
    names = dict(zip(bag["/simlan/semantic_labels"][0][1].ids, bag["/simlan/semantic_labels"][0][1].names))
    present = {names[i] for i in np.unique(labels)}
    assert {"floor", "shelf", "box"} <= present


def test_truck_is_labelled_51_where_it_is_seen(bag: dict[str, list]) -> None:
    truck_pixels = 0
    for cid in ("160", "161"):
        for _, msg in bag[f"/camera_{cid}/semantic/image_raw/compressed"]:
            labels = decode_compressed(msg.format, msg.data)
            truck_pixels += int((labels == 51).sum())
    assert truck_pixels > 1000


def test_marker_detected_by_opencv_in_a_recorded_image(bag: dict[str, list]) -> None:
    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_1000), cv2.aruco.DetectorParameters()
    )
    found = []
    for cid in CAMERAS:
        for stamp, msg in bag[f"/camera_{cid}/image_raw/compressed"]:
            img = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_COLOR)
            _, ids, _ = detector.detectMarkers(img)
            if ids is not None and 1 in ids.ravel():
                found.append((cid, stamp))
    assert found, "marker id 1 (robot_agent_1) was never detected"


def test_static_transforms_and_provenance(bag: dict[str, list]) -> None:
    tfs = {t.child_frame_id: t for t in bag["/tf_static"][0][1].transforms}
    assert {f"camera_{c}_optical_frame" for c in CAMERAS} <= set(tfs)
    t = tfs["camera_163_optical_frame"].transform.translation
    assert (t.x, t.y, t.z) == pytest.approx((6.408863, 1.058466, 7.292501), abs=1e-4)
    info = bag["/simlan/run_info"][0][1]
    assert info.format_version == FORMAT_VERSION and info.seed == 0 and info.renderer in ("egl", "tiny")
    assert "rosbags" in info.dependency_names
    config = yaml.safe_load(bag["/simlan/config"][0][1].data)
    assert config["duration_s"] == 3.0 and config["cameras"]["ids"][0] == 160


def test_commands_and_collision_sensor(bag: dict[str, list]) -> None:
    cmds = bag["/robot_agent_1/cmd_vel"]
    assert len(cmds) == 61  # 20 Hz over [0, 3] s
    assert max(m.twist.linear.x for _, m in cmds) > 0.5
    assert cmds[0][1].header.frame_id == "robot_agent_1/base_link"
    assert not any(m.in_collision for _, m in bag["/robot_agent_1/collision"])


def test_replay_info_prints_a_summary(short_run: Path) -> None:
    proc = run_cli(str(short_run / "recording"), "--info", module="simlan_data.replay")
    assert proc.returncode == 0, proc.stderr
    assert "Topic: /camera_163/image_raw/compressed" in proc.stdout
    assert "Format version:    1.1" in proc.stdout
