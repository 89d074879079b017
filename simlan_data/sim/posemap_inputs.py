"""Read a landmark stream (what a pose mapper sees) and its true joints from a dataset or a recording.

One reader for the live drive (``posemap.drive``, :mod:`simlan_data.sim.posemap_drive`) and the
``posemap`` replay (:mod:`~simlan_data.evaluation.posemap_replay`)::

    dataset.parquet                       --> frames (F, C, 33, 4) + joints (F, 47), frame k at k * period
    images or a video (posemap.source)    --> MediaPipe's landmarks as one camera's frames, no truth
    recording: /camera_<id>/pose_landmarks --> frames grouped by stamp (every camera present)
               /<ns>/joint_states          --> the posed humanoid's joints at those stamps (truth)
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.posemap.dataset import META_NAME, PARQUET_NAME, read_dataset, resolve_dataset
from simlan_data.algorithms.posemap.estimators import MediaPipeEstimator
from simlan_data.algorithms.posemap.features import Rig
from simlan_data.algorithms.posemap.source import SourceLandmarks
from simlan_data.errors import ConfigError, SimlanError
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import yaw_from_quat
from simlan_data.recording import schema
from simlan_data.recording.cameras import cameras_in_recording
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.skeleton import NUM_LANDMARKS


@dataclass
class LandmarkStream:
    """Landmark frames (F, C, 33, 4) of some cameras, their stamps and, if known, true joints."""

    stamps_ns: NDArray[np.int64]
    cameras: list[str]
    landmarks: NDArray[np.float32]
    truth: NDArray[np.float64] | None = None
    sizes: dict[str, tuple[int, int]] = field(default_factory=dict)
    estimators: tuple[str, ...] = ()  # who made the landmarks (``replay``: a drive's input)
    position: list[float] | None = None  # the person's support base (x, y, yaw) where known


def landmarks_topic(camera_id: str) -> str:
    return schema.camera_topics(camera_id, rgb="jpeg", depth=None, semantic=None)["pose_landmarks"].name


def landmark_cameras(reader: RecordingReader) -> list[str]:
    """The cameras that have a landmark topic in the recording (sorted)."""
    out = []
    for topic in reader.topics:
        parts = topic.split("/")
        if len(parts) == 3 and parts[1].startswith("camera_"):
            cid = parts[1].removeprefix("camera_")
            if landmarks_topic(cid) == topic:
                out.append(cid)
    return sorted(out)


def stream_from_dataset(path: str, cameras: list[str], period_ns: int) -> LandmarkStream:
    data = read_dataset(path).select_cameras(cameras)
    sizes = {str(m["id"]): (int(m["width"]), int(m["height"])) for m in data.meta.get("camera_models", [])}
    position = data.meta.get("position")
    return LandmarkStream(
        np.arange(len(data)) * period_ns,
        cameras,
        data.landmarks,
        data.joints,
        sizes,
        (data.estimator,),
        [float(v) for v in position] if position else None,
    )


def stream_from_source(source: SourceLandmarks, camera: str) -> LandmarkStream:
    """MediaPipe's landmarks of an image or video source as one camera's stream (no truth; the
    person stood where the model's training data stood)."""
    reader = source.reader
    return LandmarkStream(
        source.stamps_ns,
        [camera],
        source.landmarks[:, None],
        None,
        {camera: (reader.width, reader.height)},
        (MediaPipeEstimator.name,),
    )


def read_landmark_stream(
    bag: RecordingReader, cameras: list[str], namespace: str, *, where: str
) -> LandmarkStream:
    """Landmark frames of ``cameras`` grouped by stamp; the recorded joint states of ``namespace`` as truth.

    Raises:
        ConfigError: the recording has no landmarks of one of ``cameras``, or no stamp has all.
    """
    topics = {landmarks_topic(c): c for c in cameras}
    joint_topic = schema.agent_topics(namespace)["joint_states"].name
    frames: dict[int, dict[str, np.ndarray]] = {}
    sizes: dict[str, tuple[int, int]] = {}
    joints: dict[int, np.ndarray] = {}
    estimators: set[str] = set()
    missing = [t for t in topics if t not in bag.topics]
    if missing:
        raise ConfigError(
            "recording has no landmarks for the model's cameras",
            where,
            f"missing {', '.join(missing)}",
            "record with posemap.landmarks_rate_hz > 0 (experiment=posemap_motion) or drive from a dataset",
        )
    for m in bag.messages([*topics, joint_topic]):
        if m.topic == joint_topic:
            joints[m.stamp_ns] = np.asarray(m.msg.position, dtype=np.float64)
            continue
        lm = np.zeros((NUM_LANDMARKS, 4), dtype=np.float32)
        if m.msg.detected:
            lm[:] = np.stack([m.msg.x, m.msg.y, m.msg.z, m.msg.visibility], axis=1)
        frames.setdefault(m.stamp_ns, {})[topics[m.topic]] = lm
        sizes[topics[m.topic]] = (int(m.msg.width), int(m.msg.height))
        estimators.add(str(m.msg.estimator))
    stamps = sorted(s for s, f in frames.items() if len(f) == len(cameras))
    if not stamps:
        raise ConfigError(
            "no complete landmark frames",
            where,
            "no stamp has landmarks of every camera",
            "check the recording",
        )
    lm_all = np.stack([np.stack([frames[s][c] for c in cameras]) for s in stamps])
    truth = np.stack([joints[s] for s in stamps]) if all(s in joints for s in stamps) else None
    position = base_pose(bag, namespace)
    return LandmarkStream(
        np.asarray(stamps, dtype=np.int64),
        cameras,
        lm_all,
        truth,
        sizes,
        tuple(sorted(estimators)),
        list(position) if position else None,
    )


def stream_from_recording(path: str, cameras: list[str], namespace: str) -> LandmarkStream:
    with RecordingReader(path) as bag:
        return read_landmark_stream(bag, cameras, namespace, where=f"posemap.drive={path}")


def source_cameras(path: str) -> list[CameraModel]:
    """The cameras of a landmark source (what a pose mapper is built with), sorted by id: a dataset's
    calibrations (dataset.json), a recording's cameras that have landmark topics."""
    if _is_dataset(path):
        parquet = resolve_dataset(path)
        meta_path = parquet.with_name(META_NAME)
        models = json.loads(meta_path.read_text()).get("camera_models", []) if meta_path.is_file() else []
        ids = sorted(str(m["id"]) for m in models)
        return list(Rig.from_meta(models, ids, [0.0, 0.0, 0.0]).cameras)
    try:
        with RecordingReader(path) as bag:
            have = landmark_cameras(bag)
            models = cameras_in_recording(bag)
    except SimlanError:  # reading the stream says what is wrong with it (after the mapper's checks)
        return []
    return [models[c] for c in have if c in models]


def _is_dataset(path: str) -> bool:
    p = Path(path)
    return p.suffix == ".parquet" or (p / PARQUET_NAME).is_file()


def load_stream(path: str, cameras: list[str], *, period_ns: int, namespace: str) -> LandmarkStream:
    """A dataset (directory or parquet) or a recording, whichever ``path`` is."""
    if _is_dataset(path):
        return stream_from_dataset(path, cameras, period_ns)
    if Path(path).exists():
        return stream_from_recording(path, cameras, namespace)
    raise ConfigError(
        "landmark source not found",
        f"posemap.drive={path}",
        "no such dataset or recording",
        "give a dataset run directory or a recording",
    )


def base_pose(reader: RecordingReader, namespace: str) -> tuple[float, float, float] | None:
    """Where the posed humanoid's support base stands (x, y, yaw), from the first ground truth
    (None if the recording has none of ``namespace``)."""
    first = reader.first(schema.GROUND_TRUTH_POSES)
    for tf in first.msg.transforms if first is not None else []:
        if schema.ground_truth_namespace(tf.child_frame_id) == namespace:  # (old recordings' names too)
            t = tf.transform.translation
            return (
                float(t.x),
                float(t.y),
                yaw_from_quat(
                    [
                        tf.transform.rotation.x,
                        tf.transform.rotation.y,
                        tf.transform.rotation.z,
                        tf.transform.rotation.w,
                    ]
                ),
            )
    return None
