"""A recording's instance ground truth as annotated camera frames (issue 25): what the dataset
exports (:mod:`simlan_data.apps.export`) write and the tracking metrics
(:mod:`simlan_data.evaluation.tracking_replay`) score against, read by one reader.

The run must have been recorded with ``cameras.streams=[...,instance]`` and JPEG or PNG colour
images. Data flow::

    bag --reader, time order--> per camera and log time: colour image + instance image + boxes
                                (+ the people's keypoints where recorded)
                                (+ the latest /ground_truth/boxes: world positions)
        --complete frame--> AnnotatedFrame (index: the camera's complete frames counted from 0)

A frame's number is the same for every consumer: an export's MOT frame ``n`` is the frame with
``index == n - 1`` here, which is how a tracker's file is matched to the ground truth.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.errors import RecordingInputError, RunError
from simlan_data.recording import schema
from simlan_data.recording.messages import stamp_ns_of
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.skeleton import NUM_LANDMARKS

_STREAMS = ("rgb", "instance", "boxes_2d")
_OPTIONAL = ("keypoints",)  # recorded only in scenes with people: a frame waits for it where present


@dataclass(frozen=True)
class InstanceInfo:
    """One row of the recording's instance table."""

    id: int
    namespace: str
    name: str
    class_id: int


@dataclass(frozen=True)
class AnnotatedFrame:
    """One camera frame with its ground truth: the JPEG bytes, the instance image and the boxes
    message's arrays (visible boxes (N, 4) as u0 v0 u1 v1, u1 and v1 exclusive)."""

    camera_id: str
    index: int  # the frame's number in its camera, from 0
    stamp_ns: int  # header stamp (bag time)
    jpeg: bytes
    width: int
    height: int
    instances: NDArray[np.uint16]
    ids: NDArray[np.uint16]
    pixels: NDArray[np.uint32]
    visible: NDArray[np.int32]
    amodal: NDArray[np.float32]
    visible_fraction: NDArray[np.float32]
    truncation: NDArray[np.float32]
    # the 3D box centres in map (M, 3) at the frame's camera tick, for the ids world_ids
    world_ids: NDArray[np.uint16] = field(default_factory=lambda: np.zeros(0, dtype=np.uint16))
    world_centers: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    # every person's 33 landmarks (P, 33, 3) as u, v (OpenCV pixels) and COCO visibility 0/1/2,
    # for the person instance ids keypoint_ids (P,); empty where the recording has no keypoints
    keypoint_ids: NDArray[np.uint16] = field(default_factory=lambda: np.zeros(0, dtype=np.uint16))
    keypoints: NDArray[np.float32] = field(
        default_factory=lambda: np.zeros((0, NUM_LANDMARKS, 3), dtype=np.float32)
    )
    log_ns: int = -1  # the frame's log time (the recording's clock, which other topics share)

    @property
    def stem(self) -> str:
        return f"camera_{self.camera_id}_{self.index:06d}"


def camera_topics(reader: RecordingReader) -> dict[str, tuple[str, str]]:
    """topic -> (camera id, stream) for every camera with instance ground truth.

    Raises:
        RecordingInputError: the run was recorded without stream instance.
    """
    out: dict[str, tuple[str, str]] = {}
    for name in reader.topics:
        if name.startswith("/camera_") and name.endswith("/instances/boxes"):
            cid = name[len("/camera_") :].split("/")[0]
            for rgb in ("jpeg", "raw"):
                topics = {
                    **schema.camera_topics(cid, rgb=rgb, depth=None, semantic=None),
                    **schema.instance_topics(cid),
                }
                for stream in (*_STREAMS, *_OPTIONAL):
                    if topics[stream].name in reader.topics:
                        out[topics[stream].name] = (cid, stream)
    if not out:
        raise RecordingInputError(
            "no instance ground truth",
            str(reader.path),
            "the run was recorded without stream instance",
            "record it with cameras.streams=[rgb,semantic,instance]",
        )
    return out


def instance_table(reader: RecordingReader) -> tuple[dict[int, InstanceInfo], dict[int, str]]:
    """The recording's instance table (id -> object) and class names (class id -> name).

    Raises:
        RecordingInputError: the table or the class labels are missing.
    """
    table = reader.first(schema.INSTANCES)
    labels = reader.first(schema.SEMANTIC_LABELS)
    if table is None or labels is None:
        raise RecordingInputError(
            "no instance table",
            str(reader.path),
            f"{schema.INSTANCES} is missing",
            "record with stream instance",
        )
    objects = {
        int(i): InstanceInfo(int(i), ns, name, int(c))
        for i, ns, name, c in zip(
            table.msg.ids, table.msg.namespaces, table.msg.names, table.msg.class_ids, strict=True
        )
    }
    class_names = {int(i): str(n) for i, n in zip(labels.msg.ids, labels.msg.names, strict=True)}
    return objects, class_names


def _jpeg(msg: Any) -> bytes:
    """The JPEG bytes of a colour image message (re-encoded only if the recording holds PNG)."""
    fmt = str(getattr(msg, "format", ""))
    data = np.asarray(msg.data, dtype=np.uint8)
    if "jpeg" in fmt:
        return data.tobytes()
    if not fmt:
        raise RecordingInputError(
            "raw colour images",
            "the recording",
            "export reads compressed colour images",
            "record with recording.rgb_encoding=jpeg or png",
        )
    image = cv2.imdecode(data, cv2.IMREAD_COLOR)
    ok, out = (False, None) if image is None else cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
    if not ok or out is None:
        raise RunError("JPEG encoding failed", "export")
    return out.tobytes()


def frames(
    reader: RecordingReader, topics: dict[str, tuple[str, str]], *, images: bool = True
) -> Iterator[AnnotatedFrame]:
    """Complete annotated frames in log-time order; a frame's three messages share its log time,
    and its world positions are the 3D boxes of the latest camera tick at or before it.

    ``images=False`` leaves the JPEG bytes and the instance image empty (the metrics need only
    the boxes); which frames are complete, and so their numbers, do not change.
    """
    pending: dict[tuple[str, int], dict[str, Any]] = {}
    counts: dict[str, int] = {}
    needed: dict[str, int] = {}  # per camera: how many messages make a frame
    for cid, _ in topics.values():
        needed[cid] = needed.get(cid, 0) + 1
    world: tuple[np.ndarray, np.ndarray] = (np.zeros(0, dtype=np.uint16), np.zeros((0, 3)))
    for m in reader.messages([*topics, schema.INSTANCE_BOXES_3D]):
        if m.topic == schema.INSTANCE_BOXES_3D:
            world = (np.asarray(m.msg.ids), np.asarray(m.msg.centers, dtype=np.float64).reshape(-1, 3))
            continue
        cid, stream = topics[m.topic]
        parts = pending.setdefault((cid, m.stamp_ns), {})
        parts[stream] = m.msg
        if len(parts) < needed[cid]:
            continue
        del pending[(cid, m.stamp_ns)]
        for key in [k for k in pending if k[0] == cid and k[1] < m.stamp_ns]:  # (incomplete: left out)
            del pending[key]
        boxes = parts["boxes_2d"]
        instances = (
            cv2.imdecode(np.asarray(parts["instance"].data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
            if images
            else np.zeros((0, 0))
        )
        index = counts.get(cid, 0)
        counts[cid] = index + 1
        yield AnnotatedFrame(
            camera_id=cid,
            index=index,
            stamp_ns=stamp_ns_of(boxes.header.stamp),
            jpeg=_jpeg(parts["rgb"]) if images else b"",
            width=int(boxes.width),
            height=int(boxes.height),
            instances=np.asarray(instances, dtype=np.uint16),
            ids=np.asarray(boxes.ids),
            pixels=np.asarray(boxes.pixels),
            visible=np.asarray(boxes.visible, dtype=np.int32).reshape(-1, 4),
            amodal=np.asarray(boxes.amodal, dtype=np.float32).reshape(-1, 4),
            visible_fraction=np.asarray(boxes.visible_fraction),
            truncation=np.asarray(boxes.truncation),
            world_ids=world[0],
            world_centers=world[1],
            **_keypoints(parts.get("keypoints")),
            log_ns=m.stamp_ns,
        )


def _keypoints(msg: Any) -> dict[str, Any]:
    """AnnotatedFrame's keypoint fields from an InstanceKeypoints message (none: empty)."""
    if msg is None:
        return {}
    ids = np.asarray(msg.ids, dtype=np.uint16)
    u, v, vis = (
        np.asarray(a, dtype=np.float32).reshape(len(ids), NUM_LANDMARKS)
        for a in (msg.u, msg.v, msg.visibility)
    )
    return {"keypoint_ids": ids, "keypoints": np.stack([u, v, vis], axis=-1)}
