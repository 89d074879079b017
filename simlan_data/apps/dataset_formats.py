"""Dataset writers for ``python -m simlan_data.export``: COCO instances and YOLO (issue 25).

COCO person keypoints: an annotation of a person (an instance with recorded keypoints) carries
COCO's 17 keypoints (``keypoints`` [x, y, v] * 17, ``num_keypoints``), taken by name from the 33
MediaPipe landmarks the recording holds, and all 33 in ``attributes.landmarks``; its category
lists both name lists and COCO's skeleton. The 17 are the standard so that COCO tools work as
they are: COCOeval's keypoint similarity has per-keypoint constants (sigmas) for exactly these.

Each writer takes annotated frames one at a time (``add``) and finishes its index files at the
end (``finish``), so an export holds one frame in memory however long the recording. Output is
deterministic: files are named by camera and frame index, JSON keys are sorted, and the JPEG
bytes are the recording's own (no re-encoding) when the colour stream is JPEG.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray
from pycocotools import mask as coco_mask

# the frames every writer takes: read by the reader the tracking metrics share
from simlan_data.evaluation.instance_truth import AnnotatedFrame, InstanceInfo
from simlan_data.world.skeleton import LANDMARK_NAMES

COCO_JSON = Path("annotations") / "instances.json"
COCO_KEYPOINTS = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip", "left_knee",
    "right_knee", "left_ankle", "right_ankle",
)  # fmt: skip
COCO_FROM_LANDMARKS = [LANDMARK_NAMES.index(name) for name in COCO_KEYPOINTS]  # same names in both
# COCO's person skeleton: limbs as 1-based keypoint index pairs (as in person_keypoints_*.json)
COCO_SKELETON = [
    [16, 14], [14, 12], [17, 15], [15, 13], [12, 13], [6, 12], [7, 13], [6, 7], [6, 8], [7, 9],
    [8, 10], [9, 11], [2, 3], [1, 2], [1, 3], [2, 4], [3, 5], [4, 6], [5, 7],
]  # fmt: skip
YOLO_YAML = "data.yaml"


def _dumps(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


class CocoWriter:
    """COCO instances: ``images/<stem>.jpg`` and ``annotations/instances.json`` with RLE masks.

    The JSON's image and annotation lists are streamed to two part files and joined at the end.
    """

    def __init__(self, out: Path, objects: dict[int, InstanceInfo], class_names: dict[int, str]) -> None:
        self.out, self.objects = out, objects
        (out / "images").mkdir(parents=True)
        (out / COCO_JSON.parent).mkdir(parents=True)
        classes = sorted({o.class_id for o in objects.values()})
        self.categories = [
            {"id": c, "name": class_names.get(c, str(c)), "supercategory": ""} for c in classes
        ]
        self._images: IO[str] = (out / "images.part").open("w")
        self._anns: IO[str] = (out / "annotations.part").open("w")
        self._person_classes: set[int] = set()  # classes of the instances with keypoints
        self.files: list[Path] = [out / COCO_JSON]
        self.image_count = self.annotation_count = 0

    def add(self, frame: AnnotatedFrame) -> None:
        name = f"images/{frame.stem}.jpg"
        (self.out / name).write_bytes(frame.jpeg)
        self.files.append(self.out / name)
        self.image_count += 1
        image_id = self.image_count
        image = {
            "id": image_id,
            "file_name": name,
            "width": frame.width,
            "height": frame.height,
            "camera_id": frame.camera_id,
            "frame_index": frame.index,
            "stamp_ns": frame.stamp_ns,
        }
        self._images.write(("," if image_id > 1 else "") + _dumps(image))
        people = {int(i): n for n, i in enumerate(frame.keypoint_ids.tolist())}
        for k, iid in enumerate(frame.ids.tolist()):
            obj = self.objects.get(iid)
            if obj is None:
                continue
            u0, v0, u1, v1 = (int(x) for x in frame.visible[k])
            mask = np.asfortranarray(frame.instances[v0:v1, u0:u1] == iid)
            full = np.zeros((frame.height, frame.width), dtype=np.uint8, order="F")
            full[v0:v1, u0:u1] = mask
            rle = coco_mask.encode(full)
            self.annotation_count += 1
            attributes: dict[str, Any] = {
                "namespace": obj.namespace,
                "name": obj.name,
                "amodal_bbox": _xywh(frame.amodal[k]),
                "visible_fraction": round(float(frame.visible_fraction[k]), 6),
                "truncation": round(float(frame.truncation[k]), 6),
            }
            ann: dict[str, Any] = {
                "id": self.annotation_count,
                "image_id": image_id,
                "category_id": obj.class_id,
                "bbox": [u0, v0, u1 - u0, v1 - v0],
                "area": int(frame.pixels[k]),
                "segmentation": {
                    "size": [frame.height, frame.width],
                    "counts": rle["counts"].decode("ascii"),
                },
                "iscrowd": 0,
                "track_id": iid,
                "attributes": attributes,
            }
            if iid in people:
                self._person_classes.add(obj.class_id)
                fields, landmarks = _keypoint_fields(frame.keypoints[people[iid]])
                ann.update(fields)
                attributes["landmarks"] = landmarks
            self._anns.write(("," if self.annotation_count > 1 else "") + _dumps(ann))

    def finish(self, info: dict[str, Any]) -> None:
        self._images.close()
        self._anns.close()
        for category in self.categories:
            if category["id"] in self._person_classes:
                category.update(
                    keypoints=list(COCO_KEYPOINTS), skeleton=COCO_SKELETON, landmarks=list(LANDMARK_NAMES)
                )
        images, anns = self.out / "images.part", self.out / "annotations.part"
        with (self.out / COCO_JSON).open("w") as f:
            f.write('{"info":' + _dumps(info) + ',"licenses":[],"categories":' + _dumps(self.categories))
            f.write(',"images":[')
            with images.open() as src:
                shutil.copyfileobj(src, f)
            f.write('],"annotations":[')
            with anns.open() as src:
                shutil.copyfileobj(src, f)
            f.write("]}\n")
        images.unlink()
        anns.unlink()


class YoloWriter:
    """YOLO detection: ``images/<stem>.jpg``, ``labels/<stem>.txt`` (class cx cy w h, normalized,
    visible boxes) and ``data.yaml``; class indices 0..K-1 in the order of the semantic class ids."""

    def __init__(self, out: Path, objects: dict[int, InstanceInfo], class_names: dict[int, str]) -> None:
        self.out, self.objects = out, objects
        (out / "images").mkdir(parents=True)
        (out / "labels").mkdir(parents=True)
        classes = sorted({o.class_id for o in objects.values()})
        self.index = {c: i for i, c in enumerate(classes)}
        self.names = [class_names.get(c, str(c)) for c in classes]
        self.files: list[Path] = [out / YOLO_YAML]
        self.image_count = self.annotation_count = 0

    def add(self, frame: AnnotatedFrame) -> None:
        image, label = self.out / "images" / f"{frame.stem}.jpg", self.out / "labels" / f"{frame.stem}.txt"
        image.write_bytes(frame.jpeg)
        lines = []
        for k, iid in enumerate(frame.ids.tolist()):
            obj = self.objects.get(iid)
            if obj is None:
                continue
            u0, v0, u1, v1 = (float(x) for x in frame.visible[k])
            w, h = frame.width, frame.height
            cx, cy, bw, bh = (u0 + u1) / 2 / w, (v0 + v1) / 2 / h, (u1 - u0) / w, (v1 - v0) / h
            lines.append(f"{self.index[obj.class_id]} {cx:.6f} {cy:.6f} {bw:.6f} {bh:.6f}\n")
        label.write_text("".join(lines))
        self.files += [image, label]
        self.image_count += 1
        self.annotation_count += len(lines)

    def finish(self, info: dict[str, Any]) -> None:
        names = "".join(f"  {i}: {n}\n" for i, n in enumerate(self.names))
        recording = info["recording"]
        (self.out / YOLO_YAML).write_text(
            f"# exported by python -m simlan_data.export from {recording}\n"
            f"path: .\ntrain: images\nval: images\nnc: {len(self.names)}\nnames:\n{names}"
        )


def _keypoint_fields(landmarks: NDArray[np.float32]) -> tuple[dict[str, Any], list[float]]:
    """COCO's keypoint fields of one person from its 33 landmarks (33, 3) = u, v, visibility:
    ``keypoints`` and ``num_keypoints`` of COCO's 17, and all 33 flat (``attributes.landmarks``).
    A keypoint that is not in the image is written 0, 0, 0, as COCO writes unlabelled ones."""
    vis = landmarks[:, 2].astype(int)
    flat = [
        [round(float(u), 3), round(float(v), 3), int(f)] if f > 0 else [0, 0, 0]
        for (u, v, _), f in zip(landmarks, vis)
    ]
    coco = [flat[i] for i in COCO_FROM_LANDMARKS]
    fields = {"keypoints": [x for kp in coco for x in kp], "num_keypoints": sum(kp[2] > 0 for kp in coco)}
    return fields, [x for kp in flat for x in kp]


def _xywh(box: NDArray[np.float32]) -> list[float]:
    u0, v0, u1, v1 = (round(float(x), 3) for x in box)
    return [u0, v0, round(u1 - u0, 3), round(v1 - v0, 3)]


WRITERS: dict[str, type[CocoWriter] | type[YoloWriter]] = {"coco": CocoWriter, "yolo": YoloWriter}
