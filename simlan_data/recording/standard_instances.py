"""The instance ground truth in standard ROS 2 types, beside simlan_msgs' (issue 25): the visible
2D boxes as ``vision_msgs/Detection2DArray`` per camera frame and the 3D boxes as a
``visualization_msgs/MarkerArray`` of cubes, so ROS tools and viewers (RViz, Foxglove's 3D and
image panels, vision_msgs consumers) read them without simlan_msgs."""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import quat_from_yaw
from simlan_data.recording import messages as M
from simlan_data.recording import schema

T = schema.typestore().types
Detection2DArray = T[schema.DETECTION_2D_ARRAY_TYPE]
Detection2D = T["vision_msgs/msg/Detection2D"]
BoundingBox2D = T["vision_msgs/msg/BoundingBox2D"]
Pose2D = T["vision_msgs/msg/Pose2D"]
Point2D = T["vision_msgs/msg/Point2D"]
ObjectHypothesis = T["vision_msgs/msg/ObjectHypothesis"]
ObjectHypothesisWithPose = T["vision_msgs/msg/ObjectHypothesisWithPose"]
MARKER_CUBE = 1  # visualization_msgs/Marker.CUBE
_NO_POSE = M.PoseWithCovariance(pose=M.pose_msg(0.0, 0.0, 0.0, (0.0, 0.0, 0.0, 1.0)), covariance=np.zeros(36))


def detections_2d(
    stamp_ns: int,
    camera: CameraModel,
    ids: NDArray[np.uint16],
    visible: NDArray[np.int32],
    class_of: dict[int, str],
) -> Any:
    """vision_msgs/Detection2DArray of one frame's visible boxes (``visible``: u0 v0 u1 v1 per
    instance, pixel edges, u1 v1 exclusive): bbox centre and size in pixels, ``id`` the track id,
    one hypothesis (the class name, score 1: ground truth)."""
    out = []
    for oid, (u0, v0, u1, v1) in zip(ids.tolist(), np.asarray(visible).reshape(-1, 4).tolist(), strict=True):
        box = BoundingBox2D(
            center=Pose2D(position=Point2D(x=(u0 + u1) / 2.0, y=(v0 + v1) / 2.0), theta=0.0),
            size_x=float(u1 - u0),
            size_y=float(v1 - v0),
        )
        hypothesis = ObjectHypothesisWithPose(
            hypothesis=ObjectHypothesis(class_id=class_of.get(oid, ""), score=1.0), pose=_NO_POSE
        )
        out.append(
            Detection2D(
                header=M.header(stamp_ns, camera.frame_id), results=[hypothesis], bbox=box, id=str(oid)
            )
        )
    return Detection2DArray(header=M.header(stamp_ns, camera.frame_id), detections=out)


def _colour(name: str) -> Any:
    """A fixed colour per class name (its CRC spread over the hue circle), half transparent."""
    h = (zlib.crc32(name.encode()) % 360) / 60.0
    x = 1 - abs(h % 2 - 1)
    r, g, b = [(1, x, 0), (x, 1, 0), (0, 1, x), (0, x, 1), (x, 0, 1), (1, 0, x)][int(h) % 6]
    return M.ColorRGBA(r=float(r), g=float(g), b=float(b), a=0.5)


def box_markers(
    stamp_ns: int,
    ids: Sequence[int],
    centers: NDArray[np.float64],
    sizes: NDArray[np.float64],
    yaw_rad: NDArray[np.float64],
    class_of: dict[int, str],
) -> Any:
    """visualization_msgs/MarkerArray: one cube per instance in map (ns = class name, id = track id)."""
    markers = []
    for oid, c, s, yaw in zip(ids, centers.reshape(-1, 3), sizes.reshape(-1, 3), yaw_rad, strict=True):
        name = class_of.get(int(oid), "instance")
        markers.append(
            M.marker(
                stamp_ns,
                name,
                int(oid),
                MARKER_CUBE,
                pose=M.pose_msg(float(c[0]), float(c[1]), float(c[2]), tuple(quat_from_yaw(float(yaw)))),
                scale=M.Vector3(x=float(s[0]), y=float(s[1]), z=float(s[2])),
                color=_colour(name),
            )
        )
    return M.MarkerArray(markers=markers)
