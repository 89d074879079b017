"""Humanoid keypoints end to end (issue 25): one real 0.6 s run of two people under the four
humanoid-capture cameras with stream instance, its keypoint topics read back with the independent
mcap + mcap_ros2 decoder, checked against PyBullet's link poses and known occlusions, and exported
to COCO keypoints that pycocotools loads and COCOeval scores.

The scene: the articulated humanoid in its zero pose (a T-pose facing +x, pelvis at (5.5, -10))
in the ring of cameras 500 (behind it, looking +x), 501 (its right), 502 (in front of it,
looking -x) and 503 (its left, looking -y); the walker stands between it and camera 503, facing
that camera.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from conftest import export_cli, made_once, run_cli
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform
from simlan_data.sim.agents import AGENT_TYPES, spawn_agent
from simlan_data.sim.pybullet_client import connect
from simlan_data.world._pybullet import pb
from simlan_data.world.skeleton import LANDMARK_NAMES, LANDMARKS

PEOPLE = """\
# @package _global_
agents:
  robot_agent_1: {type: posed_humanoid, pose: [5.3, -10.0, 0.0], goals: []}
  robot_agent_2: {type: humanoid, pose: [5.5, -8.5, 1.5708], goals: []}
"""
HUMANOID, WALKER = 1, 2  # instance ids: the agents in config order
NOSE, LEFT_SHOULDER, LEFT_KNEE = (LANDMARK_NAMES.index(n) for n in ("nose", "left_shoulder", "left_knee"))


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    def make(root: Path) -> None:
        (root / "conf" / "agents").mkdir(parents=True)
        (root / "conf" / "agents" / "people.yaml").write_text(PEOPLE)
        proc = run_cli(
            f"hydra.searchpath=[file://{root / 'conf'}]",
            "agents=people",
            "cameras=humanoid_capture",
            "cameras.rate_hz=5",
            "duration_s=0.6",
            "progress=false",
            "cameras.streams=[rgb,semantic,instance]",
            f"hydra.run.dir={root / 'run'}",
        )
        assert proc.returncode == 0, proc.stderr
        proc = export_cli(root / "run", "coco", root / "coco")
        assert proc.returncode == 0, proc.stderr

    return made_once(tmp_path_factory, "keypoint_runs", make)


@pytest.fixture(scope="module")
def recorded(made: Path) -> dict:
    """Decoded independently: per (camera, log time) the keypoints (ids, (N, 33, 2), (N, 33)) and
    the instance image; the cameras; the humanoid's joints and base pose."""
    out: dict = {"keypoints": {}, "masks": {}, "info": {}, "joints": {}}
    (bag,) = (made / "run" / "recording").glob("*.mcap")
    with bag.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, msg in reader.iter_decoded_messages():
            topic, cam = channel.topic, channel.topic.split("/")[1].removeprefix("camera_")
            if topic.endswith("/instances/keypoints"):
                n = len(msg.ids)
                uv = np.stack([np.asarray(msg.u), np.asarray(msg.v)], axis=-1).reshape(n, 33, 2)
                vis = np.frombuffer(bytes(msg.visibility), np.uint8).reshape(n, 33)  # (uint8[]: bytes)
                out["keypoints"][(cam, message.log_time)] = (list(msg.ids), uv, vis)
            elif topic.endswith("/instances/image_raw/compressed"):
                mask = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_UNCHANGED)
                out["masks"][(cam, message.log_time)] = mask
            elif topic.endswith("/camera_info") and cam not in out["info"]:
                out["info"][cam] = msg
            elif topic == "/tf_static":
                out["tf_static"] = {t.child_frame_id: t.transform for t in msg.transforms}
            elif topic == "/robot_agent_1/joint_states":
                out["joints"][message.log_time] = (list(msg.name), np.asarray(msg.position))
            elif topic == "/ground_truth/poses" and "pose" not in out:
                (t,) = [t for t in msg.transforms if t.child_frame_id.endswith("robot_agent_1/base_link")]
                out["pose"] = t.transform
    return out


def _transform(msg) -> Transform:
    t, q = msg.translation, msg.rotation
    return Transform.from_quat([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])


def _camera(recorded: dict, cam: str) -> CameraModel:
    info = recorded["info"][cam]
    world_from_camera = _transform(recorded["tf_static"][f"camera_{cam}_optical_frame"])
    K = np.asarray(info.k, dtype=float).reshape(3, 3)
    D = np.asarray(info.d, dtype=float)[:5]
    return CameraModel(cam, int(info.width), int(info.height), K, D, world_from_camera.inverse())


def test_every_camera_frame_has_both_people(recorded: dict) -> None:
    assert len(recorded["keypoints"]) == 4 * 4  # 4 cameras x frames at 0, 0.2, 0.4, 0.6 s
    assert recorded["keypoints"].keys() == recorded["masks"].keys()
    for ids, uv, vis in recorded["keypoints"].values():
        assert ids == [HUMANOID, WALKER]
        assert uv.shape == (2, 33, 2) and set(np.unique(vis)) <= {0, 1, 2}
        assert (vis == 2).sum() > 20  # (both people face some camera: many landmarks are seen)


def test_a_landmark_is_pybullets_link_projected(recorded: dict) -> None:
    """The left shoulder is the origin of the LeftUpperArm link: pose a fresh PyBullet humanoid
    with the recorded joints at the recorded base pose and project that link through the
    recorded camera model."""
    assert LANDMARKS[LEFT_SHOULDER].link == "LeftUpperArm" and LANDMARKS[LEFT_SHOULDER].xyz == (0, 0, 0)
    client = connect("tiny")
    try:
        pose = _transform(recorded["pose"])
        agent = spawn_agent(
            client.id, "check", AGENT_TYPES["posed_humanoid"], pose=[0.0, 0.0, 0.0], marker_id=None
        )
        yaw = float(np.arctan2(pose.rotation[1, 0], pose.rotation[0, 0]))
        agent.place(pose.translation, yaw)
        checked = 0
        for (cam, log_ns), (ids, uv, vis) in sorted(recorded["keypoints"].items()):
            names, q = recorded["joints"][log_ns]
            for name, value in zip(names, q):
                pb.resetJointState(agent.body, agent.joints[name], float(value), physicsClientId=client.id)
            link = pb.getLinkState(
                agent.body,
                agent.links["LeftUpperArm"],
                computeForwardKinematics=True,
                physicsClientId=client.id,
            )
            expected, ok = _camera(recorded, cam).project(np.asarray(link[4])[None])
            assert ok[0] == (vis[ids.index(HUMANOID), LEFT_SHOULDER] > 0)
            np.testing.assert_allclose(uv[ids.index(HUMANOID), LEFT_SHOULDER], expected[0], atol=1e-3)
            checked += 1
        assert checked == 16
    finally:
        client.disconnect()


def test_known_occlusions(recorded: dict) -> None:
    """The humanoid's nose is seen from the front (502), hidden by its own head from behind (500);
    its left knee is hidden from 503 by the walker standing in between: the instance image shows
    the walker at that pixel. The walker faces 503: its nose is seen there, hidden from 501."""
    for (cam, log_ns), (ids, uv, vis) in recorded["keypoints"].items():
        human, walker = vis[ids.index(HUMANOID)], vis[ids.index(WALKER)]
        if cam == "502":
            assert human[NOSE] == 2
        if cam == "500":
            assert human[NOSE] == 1
        if cam == "503":
            assert human[LEFT_KNEE] == 1 and walker[NOSE] == 2
            u, v = np.rint(uv[ids.index(HUMANOID), LEFT_KNEE]).astype(int)
            assert recorded["masks"][(cam, log_ns)][v, u] == WALKER
        if cam == "501":
            assert walker[NOSE] == 1


def test_visible_keypoints_lie_on_their_person_in_the_instance_image(recorded: dict) -> None:
    """The occlusion test reads the render's depth, the instance image its segmentation: a visible
    landmark lies on its own person's pixels, or within 3 px of them (on a silhouette: the
    humanoid's nose and mouth, seen in profile, sit about 1 cm before its drawn head)."""
    checked = 0
    near = np.ones((7, 7), np.uint8)
    for key, (ids, uv, vis) in recorded["keypoints"].items():
        mask = recorded["masks"][key]
        for n, iid in enumerate(ids):
            own = cv2.dilate((mask == iid).astype(np.uint8), near)
            for u, v in np.rint(uv[n][vis[n] == 2]).astype(int):
                assert own[v, u], (key, iid)
                checked += 1
    assert checked > 300


def test_coco_keypoints_load_and_score_one_against_themselves(made: Path) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO(str(made / "coco" / "annotations" / "instances.json"))
    (person,) = gt.getCatIds(catNms=["humanoid"])
    category = gt.loadCats(person)[0]
    assert len(category["keypoints"]) == 17 and len(category["landmarks"]) == 33
    assert category["skeleton"][0] == [16, 14]
    anns = gt.loadAnns(gt.getAnnIds(catIds=[person]))
    assert anns and all(len(a["keypoints"]) == 51 and len(a["attributes"]["landmarks"]) == 99 for a in anns)
    for a in anns:
        kp = np.reshape(a["keypoints"], (17, 3))
        assert a["num_keypoints"] == int((kp[:, 2] > 0).sum())
        assert (kp[kp[:, 2] == 0] == 0).all()  # not in the image: 0, 0, 0 as COCO writes it
        landmarks = np.reshape(a["attributes"]["landmarks"], (33, 3))
        assert (kp[0] == landmarks[NOSE]).all()  # COCO's nose is MediaPipe's
    scored = [a for a in anns if a["num_keypoints"] > 0]

    def ap(shift_px: float) -> float:
        dets = [
            {
                "image_id": a["image_id"],
                "category_id": person,
                "keypoints": [x + shift_px if i % 3 < 2 else x for i, x in enumerate(a["keypoints"])],
                "score": 1.0,
            }
            for a in scored
        ]
        with contextlib.redirect_stdout(io.StringIO()):
            run = COCOeval(gt, gt.loadRes(dets), "keypoints")
            run.params.catIds = [person]
            run.evaluate()
            run.accumulate()
            run.summarize()
        return float(run.stats[0])

    assert ap(0.0) == pytest.approx(1.0)
    assert ap(15.0) < 0.5  # (the evaluation reads the keypoints: moved ones score less)
