"""Instance ground truth and dataset export end to end (issue 25): one real 2 s run with three
cameras and stream instance, its new topics read back with the independent mcap + mcap_ros2
decoder, exported through the CLI to COCO (read back with pycocotools), YOLO, MOTChallenge (read
back and scored by TrackEval) and the AI City multi-camera tracking text."""

from __future__ import annotations

import hashlib
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
import pytest
import trackeval
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from pycocotools.coco import COCO

from conftest import export_cli, made_once, run_cli

CAMERAS = ("160", "161", "162")  # 160 and 161 overlap where the robot drives
RUN = (
    "duration_s=2",
    "progress=false",
    f"cameras.ids=[{','.join(CAMERAS)}]",
    "cameras.streams=[rgb,semantic,instance]",
    "seed=5",
)
FORMATS = ("coco", "yolo", "mot", "aicity")


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    def make(root: Path) -> None:
        proc = run_cli(*RUN, f"hydra.run.dir={root / 'run'}")
        assert proc.returncode == 0, proc.stderr
        for fmt in FORMATS:
            proc = export_cli(root / "run", fmt, root / fmt)
            assert proc.returncode == 0, proc.stderr

    return made_once(tmp_path_factory, "export_runs", make)


@pytest.fixture(scope="module")
def recorded(made: Path) -> dict:
    """The new topics, decoded independently: table, 3D boxes, and per (camera, stamp) the
    instance image and the 2D boxes message."""
    out: dict = {"masks": {}, "boxes": {}, "boxes3d": [], "detections": {}, "cubes": []}
    (bag,) = (made / "run" / "recording").glob("*.mcap")
    with bag.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, _message, msg in reader.iter_decoded_messages():
            topic = channel.topic
            if topic == "/ground_truth/instances":
                out["table"] = msg
            elif topic == "/ground_truth/boxes":
                out["boxes3d"].append(msg)
            elif topic.endswith("/instances/image_raw/compressed"):
                assert msg.format == "mono16; png compressed mono16"
                image = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_UNCHANGED)
                assert image is not None and image.dtype == np.uint16
                out["masks"][(msg.header.frame_id, _stamp(msg))] = image
            elif topic.endswith("/instances/boxes"):
                out["boxes"][(msg.header.frame_id, _stamp(msg))] = msg
            elif topic.endswith("/instances/detections"):
                out["detections"][(msg.header.frame_id, _stamp(msg))] = msg
            elif topic == "/ground_truth/boxes/markers":
                out["cubes"].append(msg)
    return out


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def test_recorded_boxes_are_the_masks_bounds(recorded: dict) -> None:
    table = recorded["table"]
    assert list(table.ids) == list(range(1, len(table.ids) + 1))
    assert table.namespaces[0] == "robot_agent_1"
    assert len(recorded["boxes3d"]) > 0 and len(recorded["boxes3d"][0].ids) == len(table.ids)
    seen = 0
    for key, msg in recorded["boxes"].items():
        mask = recorded["masks"][key]
        assert (msg.width, msg.height) == (mask.shape[1], mask.shape[0])
        assert sorted(set(np.unique(mask).tolist()) - {0}) == list(msg.ids)
        for k, iid in enumerate(msg.ids):
            vs, us = np.nonzero(mask == iid)
            assert list(msg.visible[4 * k : 4 * k + 4]) == [us.min(), vs.min(), us.max() + 1, vs.max() + 1]
            assert msg.pixels[k] == len(us)
            u0, v0, u1, v1 = msg.amodal[4 * k : 4 * k + 4]  # the 3D box's projection holds the mask
            assert (
                u0 - 2 <= us.min()
                and us.max() + 1 <= u1 + 2
                and v0 - 2 <= vs.min()
                and vs.max() + 1 <= v1 + 2
            )
            assert 0 < msg.visible_fraction[k] <= 1 and 0 <= msg.truncation[k] < 1
            seen += 1
    assert seen >= 10


def test_standard_types_carry_the_same_boxes(recorded: dict) -> None:
    """vision_msgs detections are the visible boxes (centre, size, track id, class name), and the
    MarkerArray cubes are the 3D boxes: decoded by mcap_ros2 from the schemas the bag embeds."""
    names = dict(zip(list(recorded["table"].ids), recorded["table"].names, strict=True))
    assert recorded["detections"].keys() == recorded["boxes"].keys()
    seen = 0
    for key, boxes in recorded["boxes"].items():
        dets = recorded["detections"][key].detections
        assert [int(d.id) for d in dets] == list(boxes.ids)
        for d, (u0, v0, u1, v1) in zip(dets, np.reshape(boxes.visible, (-1, 4)).tolist(), strict=True):
            assert (d.bbox.center.position.x, d.bbox.center.position.y) == ((u0 + u1) / 2, (v0 + v1) / 2)
            assert (d.bbox.size_x, d.bbox.size_y) == (u1 - u0, v1 - v0)
            assert d.results[0].hypothesis.score == 1.0
            seen += int(
                d.results[0].hypothesis.class_id == "pallet_truck" and names[int(d.id)] == "pallet_truck"
            )
    assert seen > 0
    assert len(recorded["cubes"]) == len(recorded["boxes3d"])
    for cubes, boxes in zip(recorded["cubes"], recorded["boxes3d"], strict=True):
        assert [m.id for m in cubes.markers] == list(boxes.ids)
        centres = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for m in cubes.markers])
        sizes = np.array([[m.scale.x, m.scale.y, m.scale.z] for m in cubes.markers])
        assert np.allclose(centres, np.reshape(boxes.centers, (-1, 3)))
        assert np.allclose(sizes, np.reshape(boxes.sizes, (-1, 3)))
        assert all(m.type == 1 and m.header.frame_id == "map" for m in cubes.markers)  # CUBE in map


def test_coco_reads_back_with_pycocotools(made: Path, recorded: dict) -> None:
    coco = COCO(str(made / "coco" / "annotations" / "instances.json"))
    frames = {
        (f"camera_{im['camera_id']}_optical_frame", im["stamp_ns"]): im for im in coco.dataset["images"]
    }
    assert len(frames) == len(recorded["boxes"]) > 0
    checked = 0
    for key, im in frames.items():
        assert (made / "coco" / im["file_name"]).is_file()
        mask = recorded["masks"][key]
        for ann in coco.loadAnns(coco.getAnnIds(imgIds=[im["id"]])):
            drawn = coco.annToMask(ann)
            assert np.array_equal(drawn, mask == ann["track_id"])
            vs, us = np.nonzero(drawn)
            assert ann["bbox"] == [us.min(), vs.min(), us.max() + 1 - us.min(), vs.max() + 1 - vs.min()]
            assert ann["area"] == len(us) and ann["iscrowd"] == 0
            checked += 1
    assert checked >= 10
    names = {c["id"]: c["name"] for c in coco.loadCats(coco.getCatIds())}
    assert "pallet_truck" in names.values()


def test_track_ids_name_one_object_in_every_camera(made: Path, recorded: dict) -> None:
    coco = COCO(str(made / "coco" / "annotations" / "instances.json"))
    cameras_of: dict[int, set[str]] = defaultdict(set)
    for ann in coco.dataset["annotations"]:
        image = coco.imgs[ann["image_id"]]
        cameras_of[ann["track_id"]].add(image["camera_id"])
        row = list(recorded["table"].ids).index(ann["track_id"])
        assert ann["attributes"]["namespace"] == recorded["table"].namespaces[row]
    # the robot (track 1, robot_agent_1 in the ground truth) is seen by two cameras under one id
    assert len(cameras_of[1]) >= 2


def test_yolo_labels_match_coco(made: Path) -> None:
    coco = COCO(str(made / "coco" / "annotations" / "instances.json"))
    names = (made / "yolo" / "data.yaml").read_text()
    for im in coco.dataset["images"]:
        stem = Path(im["file_name"]).stem
        assert (made / "yolo" / "images" / f"{stem}.jpg").read_bytes() == (
            made / "coco" / im["file_name"]
        ).read_bytes()
        rows = [line.split() for line in (made / "yolo" / "labels" / f"{stem}.txt").read_text().splitlines()]
        anns = coco.loadAnns(coco.getAnnIds(imgIds=[im["id"]]))
        assert len(rows) == len(anns)
        for row, ann in zip(rows, anns, strict=True):
            x, y, w, h = ann["bbox"]
            expected = [
                (x + w / 2) / im["width"],
                (y + h / 2) / im["height"],
                w / im["width"],
                h / im["height"],
            ]
            assert np.allclose([float(v) for v in row[1:]], expected, atol=1e-6)
            assert f"{coco.cats[ann['category_id']]['name']}" in names


def _digest(root: Path) -> str:
    h = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


def test_export_is_deterministic_and_never_overwrites(made: Path, tmp_path: Path) -> None:
    for fmt in FORMATS:
        proc = export_cli(made / "run", fmt, tmp_path / fmt)
        assert proc.returncode == 0, proc.stderr
        assert _digest(tmp_path / fmt) == _digest(made / fmt)
    before = _digest(tmp_path / "coco")
    proc = export_cli(made / "run", "coco", tmp_path / "coco")
    assert proc.returncode == 2
    assert (
        proc.stderr.strip().count("\n") == 0
        and "--out" in proc.stderr
        and "choose a new --out" in proc.stderr
    )
    assert _digest(tmp_path / "coco") == before
    for fmt in ("mot", "aicity"):
        before = _digest(tmp_path / fmt)
        proc = export_cli(made / "run", fmt, tmp_path / fmt)
        assert proc.returncode == 2 and "choose a new --out" in proc.stderr
        assert _digest(tmp_path / fmt) == before
    proc = export_cli(made / "run", "voc", tmp_path / "voc")
    assert proc.returncode == 2 and "--format" in proc.stderr and proc.stderr.strip().count("\n") == 0
    assert not (tmp_path / "voc").exists()


def _coco_by_frame(made: Path) -> tuple[COCO, dict[tuple[str, int], dict]]:
    """The COCO export and its images by (camera id, frame index)."""
    coco = COCO(str(made / "coco" / "annotations" / "instances.json"))
    return coco, {(im["camera_id"], im["frame_index"]): im for im in coco.dataset["images"]}


def _trackeval(gt: Path, trackers: Path) -> dict:
    """TrackEval's MotChallenge2DBox results of every tracker under ``trackers`` on the export ``gt``."""
    evaluator = trackeval.Evaluator(
        {
            "USE_PARALLEL": False,
            "PRINT_RESULTS": False,
            "PRINT_CONFIG": False,
            "TIME_PROGRESS": False,
            "OUTPUT_SUMMARY": False,
            "OUTPUT_DETAILED": False,
            "PLOT_CURVES": False,
        }
    )
    dataset = trackeval.datasets.MotChallenge2DBox(
        {
            "GT_FOLDER": str(gt),
            "TRACKERS_FOLDER": str(trackers),
            "BENCHMARK": "SIMLAN",
            "SPLIT_TO_EVAL": "train",
            "PRINT_CONFIG": False,
        }
    )
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR(), trackeval.metrics.Identity()]
    results, messages = evaluator.evaluate([dataset], metrics)
    assert set(messages["MotChallenge2DBox"].values()) == {"Success"}
    out = {}
    for tracker, sequences in results["MotChallenge2DBox"].items():
        p = sequences["COMBINED_SEQ"]["pedestrian"]
        out[tracker] = {
            "HOTA": float(np.mean(p["HOTA"]["HOTA"])),
            "MOTA": float(p["CLEAR"]["MOTA"]),
            "IDF1": float(p["Identity"]["IDF1"]),
            "IDSW": int(p["CLEAR"]["IDSW"]),
        }
    return out


def test_mot_matches_coco_and_trackeval_scores_it(made: Path, tmp_path: Path) -> None:
    mot = made / "mot"
    coco, images = _coco_by_frame(made)
    assert (mot / "seqmaps" / "SIMLAN-train.txt").read_text() == "name\n" + "".join(
        f"camera_{c}\n" for c in CAMERAS
    )
    rows: dict[str, list[list[str]]] = {}
    for cid in CAMERAS:
        seq = mot / "SIMLAN-train" / f"camera_{cid}"
        info = (seq / "seqinfo.ini").read_text()
        frames = sorted(i for c, i in images if c == cid)
        assert f"seqLength={len(frames)}\n" in info and "frameRate=5\n" in info and "imExt=.jpg" in info
        for index in frames:
            assert (seq / "img1" / f"{index + 1:06d}.jpg").read_bytes() == (
                made / "coco" / images[(cid, index)]["file_name"]
            ).read_bytes()
        rows[cid] = [line.split(",") for line in (seq / "gt" / "gt.txt").read_text().splitlines()]
        expected = []
        for index in frames:
            for ann in coco.loadAnns(coco.getAnnIds(imgIds=[images[(cid, index)]["id"]])):
                vis = ann["attributes"]["visible_fraction"]
                expected.append([index + 1, ann["track_id"], *ann["bbox"], 1, 1, vis])
        got = [
            [int(r[0]), int(r[1]), *(int(v) for v in r[2:6]), int(r[6]), int(r[7]), float(r[8])]
            for r in rows[cid]
        ]
        assert len(got) == len(expected)
        np.testing.assert_allclose(
            np.array(got, dtype=float).reshape(-1, 9),
            np.array(expected, dtype=float).reshape(-1, 9),
            atol=1e-6,
        )
    # the ground truth as a tracker's output scores 1 on every metric; one id changed mid-track
    # (a tracker that loses the robot and picks it up as a new object) scores below 1
    busiest = max(CAMERAS, key=lambda c: len(rows[c]))
    assert len(rows[busiest]) >= 6
    for name in ("self", "swapped"):
        data = tmp_path / "trackers" / "SIMLAN-train" / name / "data"
        data.mkdir(parents=True)
        for cid in CAMERAS:
            lines = [list(r) for r in rows[cid]]
            if name == "swapped" and cid == busiest:
                track = lines[0][1]
                mine = [r for r in lines if r[1] == track]
                for r in mine[len(mine) // 2 :]:
                    r[1] = "999"
            (data / f"camera_{cid}.txt").write_text("".join(",".join(r) + "\n" for r in lines))
    scores = _trackeval(mot, tmp_path / "trackers")
    assert scores["self"] == {"HOTA": 1.0, "MOTA": 1.0, "IDF1": 1.0, "IDSW": 0}
    assert scores["swapped"]["IDF1"] < 0.9 and scores["swapped"]["IDSW"] == 1
    assert scores["swapped"]["HOTA"] < 1.0 and scores["swapped"]["MOTA"] < 1.0


def test_aicity_world_positions_are_the_3d_box_centres(made: Path, recorded: dict) -> None:
    coco, images = _coco_by_frame(made)
    centres = {
        _stamp(msg): {int(i): msg.centers[3 * k : 3 * k + 3] for k, i in enumerate(msg.ids)}
        for msg in recorded["boxes3d"]
    }
    lines = (made / "aicity" / "ground_truth.txt").read_text().splitlines()
    assert len(lines) == len(coco.dataset["annotations"]) >= 10
    cameras = set()
    for line in lines:
        camera, obj, frame, x, y, w, h, xw, yw = line.split(" ")
        im = images[(camera, int(frame))]
        (ann,) = [a for a in coco.loadAnns(coco.getAnnIds(imgIds=[im["id"]])) if a["track_id"] == int(obj)]
        assert [int(x), int(y), int(w), int(h)] == ann["bbox"]
        centre = centres[im["stamp_ns"]][int(obj)]
        assert (float(xw), float(yw)) == pytest.approx((centre[0], centre[1]), abs=1e-6)
        cameras.add(camera)
    assert len(cameras) >= 2  # one file for several cameras, one id per object across them
    table = (made / "aicity" / "instances.csv").read_text().splitlines()
    assert table[0] == "id,namespace,name,class_id,class_name"
    assert table[1].startswith("1,robot_agent_1,pallet_truck,")


def test_mot_amodal_boxes_by_flag(made: Path, tmp_path: Path) -> None:
    proc = export_cli(made / "run", "mot", tmp_path / "mot", "--box", "amodal")
    assert proc.returncode == 0, proc.stderr
    coco, images = _coco_by_frame(made)
    checked = 0
    for cid in CAMERAS:
        gt = tmp_path / "mot" / "SIMLAN-train" / f"camera_{cid}" / "gt" / "gt.txt"
        for row in gt.read_text().splitlines():
            frame, track, *box = row.split(",")[:6]
            im = images[(cid, int(frame) - 1)]
            (ann,) = [
                a for a in coco.loadAnns(coco.getAnnIds(imgIds=[im["id"]])) if a["track_id"] == int(track)
            ]
            assert [float(v) for v in box] == pytest.approx(ann["attributes"]["amodal_bbox"], abs=0.02)
            checked += 1
    assert checked >= 10
    proc = export_cli(made / "run", "coco", tmp_path / "c", "--box", "amodal")
    assert proc.returncode == 2 and "--box" in proc.stderr and proc.stderr.strip().count("\n") == 0
    assert not (tmp_path / "c").exists()
