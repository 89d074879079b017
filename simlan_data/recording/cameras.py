"""Camera models rebuilt from a recording's own messages (camera_info + the static transforms).

The live run builds the models its algorithms use this way too, so that a replay reproduces live
outputs bit for bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from simlan_data.errors import RecordingInputError
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader


def camera_from_messages(info: Any, map_from_camera: Any, camera_id: str) -> CameraModel:
    """A camera model from a sensor_msgs/CameraInfo and its geometry_msgs/Transform in ``map``."""
    t, q = map_from_camera.translation, map_from_camera.rotation
    world_from_camera = Transform.from_quat([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
    K = np.asarray(info.k, dtype=np.float64).reshape(3, 3)
    D = np.asarray(info.d, dtype=np.float64).reshape(-1)[:5]
    return CameraModel(camera_id, int(info.width), int(info.height), K, D, world_from_camera.inverse())


def cameras_in_recording(reader: RecordingReader) -> dict[str, CameraModel]:
    """Every camera of a recording, from its first camera_info and the static transforms."""
    infos = [t for t in sorted(reader.topics) if t.startswith("/camera_") and t.endswith("/camera_info")]
    first = reader.firsts([schema.TF_STATIC, *infos])  # (one pass)
    tf_static = first.get(schema.TF_STATIC)
    if tf_static is None:
        raise RecordingInputError(
            "recording lacks /tf_static",
            str(reader.path),
            "camera poses are unknown",
            "record with simlan_data >= 0.1",
        )
    frames = {t.child_frame_id: t.transform for t in tf_static.msg.transforms}
    out: dict[str, CameraModel] = {}
    for topic in infos:
        cid = topic.split("/")[1].removeprefix("camera_")
        info = first.get(topic)
        frame = schema.camera_frame(cid)
        if info is None or frame not in frames:
            continue
        out[cid] = camera_from_messages(info.msg, frames[frame], cid)
    return out
