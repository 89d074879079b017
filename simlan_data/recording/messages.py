"""Build ROS 2 message objects (rosbags typestore classes) from numpy values."""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from simlan_data.constants import NS_PER_S
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import schema

T = schema.typestore().types
Time = T["builtin_interfaces/msg/Time"]
Header = T["std_msgs/msg/Header"]
Vector3 = T["geometry_msgs/msg/Vector3"]
Quaternion = T["geometry_msgs/msg/Quaternion"]
Point = T["geometry_msgs/msg/Point"]
Pose = T["geometry_msgs/msg/Pose"]
PoseStamped = T["geometry_msgs/msg/PoseStamped"]
TransformMsg = T["geometry_msgs/msg/Transform"]
TransformStamped = T["geometry_msgs/msg/TransformStamped"]
Twist = T["geometry_msgs/msg/Twist"]
TwistStamped = T[schema.TWIST_STAMPED_TYPE]
TFMessage = T[schema.TF_TYPE]
Clock = T[schema.CLOCK_TYPE]
String = T[schema.STRING_TYPE]
Image = T[schema.IMAGE_TYPE]
CompressedImage = T[schema.COMPRESSED_IMAGE_TYPE]
CameraInfo = T[schema.CAMERA_INFO_TYPE]
RegionOfInterest = T["sensor_msgs/msg/RegionOfInterest"]
Path = T[schema.PATH_TYPE]
RunInfo = T[schema.RUN_INFO_TYPE]
SemanticLabels = T[schema.SEMANTIC_LABELS_TYPE]
CollisionState = T[schema.COLLISION_STATE_TYPE]
MarkerDetections = T[schema.MARKER_DETECTIONS_TYPE]
JointState = T[schema.JOINT_STATE_TYPE]
PoseLandmarksMsg = T[schema.POSE_LANDMARKS_TYPE]
NavigationStatusMsg = T[schema.NAVIGATION_STATUS_TYPE]
LocalizationStatusMsg = T[schema.LOCALIZATION_STATUS_TYPE]
PoseWithCovariance = T["geometry_msgs/msg/PoseWithCovariance"]
PoseWithCovarianceStamped = T[schema.POSE_COV_TYPE]
PoseArray = T[schema.POSE_ARRAY_TYPE]
MarkerArray = T[schema.MARKER_ARRAY_TYPE]
Marker = T["visualization_msgs/msg/Marker"]
ColorRGBA = T["std_msgs/msg/ColorRGBA"]
Duration = T["builtin_interfaces/msg/Duration"]
MeshFile = T["visualization_msgs/msg/MeshFile"]
SafetyEventMsg = T[schema.SAFETY_EVENT_TYPE]
SafetyStateMsg = T[schema.SAFETY_STATE_TYPE]
CameraEffectsMsg = T[schema.CAMERA_EFFECTS_TYPE]
InstanceTableMsg = T[schema.INSTANCE_TABLE_TYPE]
InstanceBoxes2DMsg = T[schema.INSTANCE_BOXES_2D_TYPE]
InstanceBoxes3DMsg = T[schema.INSTANCE_BOXES_3D_TYPE]
InstanceKeypointsMsg = T[schema.INSTANCE_KEYPOINTS_TYPE]
MARKER_ADD, MARKER_LINE_STRIP, MARKER_TEXT = 0, 4, 9  # visualization_msgs/Marker constants


def time_msg(stamp_ns: int) -> Any:
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def stamp_ns_of(time: Any) -> int:
    return int(time.sec) * NS_PER_S + int(time.nanosec)


_CDR_LE = b"\x00\x01\x00\x00"
_STAMP = struct.Struct("<iI")


def restamp(cdr: bytes, stamp_ns: int) -> bytes:
    """The same serialized message with another header stamp.

    For types whose first field is a std_msgs/Header (images, camera info): in little-endian CDR
    the stamp's sec and nanosec sit right after the 4-byte encapsulation header.
    """
    if cdr[:4] != _CDR_LE:
        raise ValueError("not little-endian CDR")
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return b"".join((cdr[:4], _STAMP.pack(sec, nanosec), cdr[12:]))


_U32 = struct.Struct("<I")


def header_stamp_ns(cdr: bytes | memoryview) -> int | None:
    """The header stamp (bag time) of a serialized message whose first field is a std_msgs/Header,
    without deserializing it; None if ``cdr`` is not little-endian CDR."""
    view = memoryview(cdr).cast("B")
    if len(view) < 12 or view[:4] != _CDR_LE:
        return None
    sec, nanosec = _STAMP.unpack_from(view, 4)
    return sec * NS_PER_S + nanosec


def compressed_image_data(cdr: bytes | memoryview) -> memoryview | None:
    """The ``data`` field of a serialized sensor_msgs/CompressedImage, without deserializing it
    (no copy of the image bytes; a replay skips most images it reads); None if ``cdr`` is not
    little-endian CDR of that layout (then deserialize it the ordinary way).

    Little-endian CDR after the 4-byte encapsulation header: header.stamp (8 bytes), then the
    strings frame_id and format and the uint8 sequence data, each a uint32 length (aligned to 4
    from the body's start) and its bytes.
    """
    view = memoryview(cdr).cast("B")
    if len(view) < 12 or view[:4] != _CDR_LE:
        return None
    pos = 12  # encapsulation (4) + stamp (8)
    for _ in range(3):  # frame_id, format, data
        pos += -(pos - 4) % 4
        if pos + 4 > len(view):
            return None
        (n,) = _U32.unpack_from(view, pos)
        pos += 4
        if pos + n > len(view):
            return None
        pos += n
    if pos + -(pos - 4) % 4 < len(view) - 3:  # something follows: not this layout
        return None
    return view[pos - n : pos]


def header(stamp_ns: int, frame_id: str) -> Any:
    return Header(stamp=time_msg(stamp_ns), frame_id=frame_id)


def transform_stamped(stamp_ns: int, parent: str, child: str, tf: Transform) -> Any:
    x, y, z, w = (float(v) for v in tf.quat())
    tx, ty, tz = (float(v) for v in tf.translation)
    return TransformStamped(
        header=header(stamp_ns, parent),
        child_frame_id=child,
        transform=TransformMsg(
            translation=Vector3(x=tx, y=ty, z=tz), rotation=Quaternion(x=x, y=y, z=z, w=w)
        ),
    )


def tf_message(transforms: Iterable[Any]) -> Any:
    return TFMessage(transforms=list(transforms))


def clock(stamp_ns: int) -> Any:
    return Clock(clock=time_msg(stamp_ns))


def string(text: str) -> Any:
    return String(data=text)


def compressed_image(stamp_ns: int, frame_id: str, fmt: str, data: bytes) -> Any:
    return CompressedImage(
        header=header(stamp_ns, frame_id), format=fmt, data=np.frombuffer(data, dtype=np.uint8)
    )


def raw_image(stamp_ns: int, frame_id: str, array: np.ndarray) -> Any:
    """sensor_msgs/Image from rgb8 (H, W, 3) uint8, mono8 (H, W) uint8, 16UC1 (H, W) uint16 or
    32FC1 (H, W) float32 (little-endian)."""
    arr = np.ascontiguousarray(array)
    if arr.dtype == np.uint8 and arr.ndim == 3:
        encoding = "rgb8"
    elif arr.dtype == np.uint8:
        encoding = "mono8"
    elif arr.dtype == np.uint16 and arr.ndim == 2:
        encoding = "16UC1"
        arr = np.ascontiguousarray(arr.astype("<u2", copy=False))
    elif arr.dtype == np.float32:
        encoding = "32FC1"
    else:
        raise ValueError(f"no raw image encoding for {arr.dtype} {arr.shape}")
    height, width = arr.shape[:2]
    return Image(
        header=header(stamp_ns, frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=arr.strides[0],
        data=arr.view(np.uint8).reshape(-1),
    )


def camera_info(stamp_ns: int, camera: CameraModel) -> Any:
    K = camera.K
    P = np.zeros((3, 4))
    P[:, :3] = K
    return CameraInfo(
        header=header(stamp_ns, camera.frame_id),
        height=camera.height,
        width=camera.width,
        distortion_model="plumb_bob",
        d=np.asarray(camera.D, dtype=np.float64).reshape(-1),
        k=K.astype(np.float64).reshape(-1),
        r=np.eye(3).reshape(-1),
        p=P.reshape(-1),
        binning_x=0,
        binning_y=0,
        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def twist_stamped(stamp_ns: int, frame_id: str, linear_mps: float, angular_rps: float) -> Any:
    return TwistStamped(
        header=header(stamp_ns, frame_id),
        twist=Twist(
            linear=Vector3(x=float(linear_mps), y=0.0, z=0.0),
            angular=Vector3(x=0.0, y=0.0, z=float(angular_rps)),
        ),
    )


def camera_effects(
    stamp_ns: int,
    frame_id: str,
    written_ns: int,
    *,
    dropped: bool,
    noise_phase: int,
    exposure_scale: float,
    gain: float,
    illumination: float,
    true_pose: Transform,
    exposure_time_s: float = 0.0,
    line_time_s: float = 0.0,
    subframes: int = 1,
    delay_s: float = 0.0,
) -> Any:
    """simlan_msgs/CameraEffects: what the camera stage did to one frame (``sim/sensors.py``)."""
    x, y, z = (float(v) for v in true_pose.translation)
    return CameraEffectsMsg(
        header=header(stamp_ns, frame_id),
        stamp_written=time_msg(written_ns),
        dropped=bool(dropped),
        noise_phase=int(noise_phase),
        exposure_scale=float(exposure_scale),
        gain=float(gain),
        illumination=float(illumination),
        exposure_time_s=float(exposure_time_s),
        line_time_s=float(line_time_s),
        subframes=int(subframes),
        true_pose=pose_msg(x, y, z, [float(q) for q in true_pose.quat()]),
        delay_s=float(delay_s),
    )


def pose_msg(x: float, y: float, z: float, quat_xyzw: Sequence[float]) -> Any:
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    return Pose(
        position=Point(x=float(x), y=float(y), z=float(z)), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)
    )


def path(stamp_ns: int, frame_id: str, points_xy: Sequence[Sequence[float]]) -> Any:
    poses = []
    for i, (x, y) in enumerate(points_xy):
        if i + 1 < len(points_xy):
            nx, ny = points_xy[i + 1]
            yaw = float(np.arctan2(ny - y, nx - x))
        elif i > 0:
            px, py = points_xy[i - 1]
            yaw = float(np.arctan2(y - py, x - px))
        else:
            yaw = 0.0
        q = (0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2)))
        poses.append(PoseStamped(header=header(stamp_ns, frame_id), pose=pose_msg(x, y, 0.0, q)))
    return Path(header=header(stamp_ns, frame_id), poses=poses)


def run_info(
    *,
    format_version: str,
    version: str,
    scenario: str,
    seed: int,
    renderer: str,
    renderer_info: str,
    dependencies: dict[str, str],
) -> Any:
    names = sorted(dependencies)
    return RunInfo(
        format_version=format_version,
        simlan_data_version=version,
        scenario=scenario,
        seed=int(seed),
        renderer=renderer,
        renderer_info=renderer_info,
        dependency_names=names,
        dependency_versions=[dependencies[n] for n in names],
    )


def semantic_labels(table: dict[str, int]) -> Any:
    items = sorted(table.items(), key=lambda kv: kv[1])
    return SemanticLabels(ids=np.array([v for _, v in items], dtype=np.uint8), names=[k for k, _ in items])


def collision_state(
    stamp_ns: int,
    frame_id: str,
    *,
    in_collision: bool,
    max_force_n: float,
    total_force_n: float,
    others: Sequence[str],
) -> Any:
    return CollisionState(
        header=header(stamp_ns, frame_id),
        in_collision=bool(in_collision),
        max_normal_force_n=float(max_force_n),
        total_normal_force_n=float(total_force_n),
        other_bodies=list(others),
    )


def pose_stamped(stamp_ns: int, frame_id: str, x: float, y: float, yaw: float) -> Any:
    q = (0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2)))
    return PoseStamped(header=header(stamp_ns, frame_id), pose=pose_msg(x, y, 0.0, q))


def pose_with_covariance(
    stamp_ns: int, frame_id: str, x: float, y: float, yaw: float, cov_xyyaw: np.ndarray
) -> Any:
    """PoseWithCovarianceStamped of a planar pose; covariance over (x, y, yaw), z/roll/pitch fixed."""
    cov = np.zeros((6, 6))
    idx = [0, 1, 5]
    cov[np.ix_(idx, idx)] = cov_xyyaw
    q = (0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2)))
    return PoseWithCovarianceStamped(
        header=header(stamp_ns, frame_id),
        pose=PoseWithCovariance(pose=pose_msg(x, y, 0.0, q), covariance=cov.reshape(-1)),
    )


def marker_detections(
    stamp_ns: int, frame_id: str, ids: Sequence[int], corners_px: ArrayLike, mode: str
) -> Any:
    corners = np.asarray(corners_px, dtype=np.float32).reshape(-1)
    return MarkerDetections(
        header=header(stamp_ns, frame_id), ids=np.asarray(ids, dtype=np.int32), corners_px=corners, mode=mode
    )


def joint_state(stamp_ns: int, frame_id: str, names: Sequence[str], positions: np.ndarray) -> Any:
    empty = np.zeros(0, dtype=np.float64)
    return JointState(
        header=header(stamp_ns, frame_id),
        name=list(names),
        position=np.asarray(positions, dtype=np.float64),
        velocity=empty,
        effort=empty,
    )


def pose_landmarks(
    stamp_ns: int, frame_id: str, landmarks: np.ndarray, *, estimator: str, width: int, height: int
) -> Any:
    """Landmarks (33, 4) = x, y, z, visibility; all-zero rows mean no person found."""
    lm = np.asarray(landmarks, dtype=np.float32)
    detected = bool((lm[:, 3] > 0).any())
    cols = [lm[:, k].copy() if detected else np.zeros(0, dtype=np.float32) for k in range(4)]
    return PoseLandmarksMsg(
        header=header(stamp_ns, frame_id),
        estimator=estimator,
        detected=detected,
        width=int(width),
        height=int(height),
        x=cols[0],
        y=cols[1],
        z=cols[2],
        visibility=cols[3],
    )


def navigation_status(
    stamp_ns: int,
    *,
    state: str,
    goal_index: int,
    goals_total: int,
    goals_reached: int,
    goals_failed: int,
    planned_length_m: float,
    blocked_by: Sequence[str],
) -> Any:
    return NavigationStatusMsg(
        header=header(stamp_ns, schema.MAP_FRAME),
        state=state,
        goal_index=int(goal_index),
        goals_total=int(goals_total),
        goals_reached=int(goals_reached),
        goals_failed=int(goals_failed),
        planned_length_m=float(planned_length_m),
        blocked_by=list(blocked_by),
    )


def localization_status(
    stamp_ns: int, *, observed: bool, valid: bool, fix_age_s: float, cameras: Sequence[str]
) -> Any:
    return LocalizationStatusMsg(
        header=header(stamp_ns, schema.MAP_FRAME),
        observed=bool(observed),
        valid=bool(valid),
        fix_age_s=float(fix_age_s),
        cameras=list(cameras),
    )


def _planar_pose(x: float, y: float, yaw: float) -> Any:
    return pose_msg(x, y, 0.0, (0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2))))


def safety_event(
    stamp_ns: int,
    *,
    namespace: str,
    cause: str,
    action: str,
    pose: Sequence[float] | None,
    pose_valid: bool,
    speed_mps: float,
    other: str,
    detail: str,
) -> Any:
    x, y, yaw = (float(v) for v in pose) if pose is not None else (0.0, 0.0, 0.0)
    return SafetyEventMsg(
        header=header(stamp_ns, schema.MAP_FRAME),
        robot=namespace,  # the field is "robot": "namespace" is a C++ keyword (rosidl)
        cause=cause,
        action=action,
        pose=_planar_pose(x, y, yaw),
        pose_valid=bool(pose_valid),
        speed_mps=float(speed_mps),
        other=other,
        detail=detail,
    )


def safety_state(
    stamp_ns: int,
    *,
    state: str,
    cause: str,
    speed_limit_mps: float | None,
    min_ttc_s: float,
    cpa_m: float,
    nearest_m: float,
    nearest: str,
    zone_clearance_m: float,
) -> Any:
    return SafetyStateMsg(
        header=header(stamp_ns, schema.MAP_FRAME),
        state=state,
        cause=cause,
        speed_limit_mps=-1.0 if speed_limit_mps is None else float(speed_limit_mps),
        min_ttc_s=float(min_ttc_s),
        cpa_m=float(cpa_m),
        nearest_m=float(nearest_m),
        nearest=nearest,
        zone_clearance_m=float(zone_clearance_m),
    )


def pose_array(stamp_ns: int, frame_id: str, points_xy: Sequence[Sequence[float]]) -> Any:
    """geometry_msgs/PoseArray of floor positions (z = 0, no rotation)."""
    return PoseArray(
        header=header(stamp_ns, frame_id),
        poses=[pose_msg(float(x), float(y), 0.0, (0.0, 0.0, 0.0, 1.0)) for x, y in points_xy],
    )


def marker(stamp_ns: int, ns: str, marker_id: int, kind: int, **fields: Any) -> Any:
    """visualization_msgs/Marker in map with every field set (``fields`` override the defaults)."""
    base: dict[str, Any] = {
        "header": header(stamp_ns, schema.MAP_FRAME),
        "ns": ns,
        "id": marker_id,
        "type": kind,
        "action": MARKER_ADD,
        "pose": pose_msg(0.0, 0.0, 0.0, (0.0, 0.0, 0.0, 1.0)),
        "scale": Vector3(x=0.08, y=0.08, z=0.08),
        "color": ColorRGBA(r=1.0, g=0.2, b=0.1, a=1.0),
        "lifetime": Duration(sec=0, nanosec=0),
        "frame_locked": False,
        "points": [],
        "colors": [],
        "texture_resource": "",
        "texture": CompressedImage(header=header(0, ""), format="", data=np.zeros(0, dtype=np.uint8)),
        "uv_coordinates": [],
        "text": "",
        "mesh_resource": "",
        "mesh_file": MeshFile(filename="", data=np.zeros(0, dtype=np.uint8)),
        "mesh_use_embedded_materials": False,
    }
    base.update(fields)
    return Marker(**base)


def zone_markers(stamp_ns: int, zones: Sequence[tuple[str, Sequence[Sequence[float]]]]) -> Any:
    """visualization_msgs/MarkerArray: each zone as a closed line strip plus its name."""
    markers = []
    for i, (name, corners) in enumerate(zones):
        ring = [Point(x=float(x), y=float(y), z=0.02) for x, y in [*corners, corners[0]]]
        markers.append(marker(stamp_ns, "safety_zones", 2 * i, MARKER_LINE_STRIP, points=ring))
        cx = float(np.mean([c[0] for c in corners]))
        cy = float(np.mean([c[1] for c in corners]))
        markers.append(
            marker(
                stamp_ns,
                "safety_zone_names",
                2 * i + 1,
                MARKER_TEXT,
                pose=pose_msg(cx, cy, 0.5, (0.0, 0.0, 0.0, 1.0)),
                scale=Vector3(x=0.0, y=0.0, z=0.5),
                text=name,
            )
        )
    return MarkerArray(markers=markers)


def instance_table(rows: Sequence[Any]) -> Any:
    """The instance table from rows with ``id``, ``namespace``, ``name``, ``class_id``."""
    return InstanceTableMsg(
        ids=np.array([r.id for r in rows], dtype=np.uint16),
        namespaces=[r.namespace for r in rows],
        names=[r.name for r in rows],
        class_ids=np.array([r.class_id for r in rows], dtype=np.uint8),
    )


def instance_boxes_2d(stamp_ns: int, camera: CameraModel, boxes: Any) -> Any:
    """One camera frame's 2D boxes from arrays ``ids``, ``pixels``, ``visible`` (N, 4),
    ``amodal`` (N, 4), ``visible_fraction``, ``truncation``."""
    return InstanceBoxes2DMsg(
        header=header(stamp_ns, camera.frame_id),
        width=camera.width,
        height=camera.height,
        ids=np.asarray(boxes.ids, dtype=np.uint16),
        pixels=np.asarray(boxes.pixels, dtype=np.uint32),
        visible=np.asarray(boxes.visible, dtype=np.int32).reshape(-1),
        amodal=np.asarray(boxes.amodal, dtype=np.float32).reshape(-1),
        visible_fraction=np.asarray(boxes.visible_fraction, dtype=np.float32),
        truncation=np.asarray(boxes.truncation, dtype=np.float32),
    )


def instance_boxes_3d(
    stamp_ns: int, ids: Sequence[int], centers: np.ndarray, sizes: np.ndarray, yaw_rad: np.ndarray
) -> Any:
    """3D boxes in map: centres (N, 3), sizes (N, 3), yaws (N,)."""
    return InstanceBoxes3DMsg(
        header=header(stamp_ns, schema.MAP_FRAME),
        ids=np.asarray(ids, dtype=np.uint16),
        centers=np.asarray(centers, dtype=np.float64).reshape(-1),
        sizes=np.asarray(sizes, dtype=np.float64).reshape(-1),
        yaw_rad=np.asarray(yaw_rad, dtype=np.float64),
    )


def instance_keypoints(stamp_ns: int, camera: CameraModel, keypoints: Any) -> Any:
    """One camera frame's keypoints from arrays ``ids`` (N,), ``uv`` (N, 33, 2), ``visibility`` (N, 33)."""
    uv = np.asarray(keypoints.uv, dtype=np.float32).reshape(-1, 2)
    return InstanceKeypointsMsg(
        header=header(stamp_ns, camera.frame_id),
        width=camera.width,
        height=camera.height,
        ids=np.asarray(keypoints.ids, dtype=np.uint16),
        u=np.ascontiguousarray(uv[:, 0]),
        v=np.ascontiguousarray(uv[:, 1]),
        visibility=np.asarray(keypoints.visibility, dtype=np.uint8).reshape(-1),
    )
