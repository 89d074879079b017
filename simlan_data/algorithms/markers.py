"""ArUco marker detection and per-camera marker poses (ground constraint or PnP).

Pure OpenCV/numpy. Corners are detected in the distorted image; the corner points (not the image)
are undistorted through the camera model.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform

ARUCO_DICTIONARY = cv2.aruco.DICT_5X5_1000
MIN_SIDE_PX = 10.0  # a marker narrower than this in an image counts as not in view


@dataclass(frozen=True)
class MarkerMount:
    """Where an agent carries its marker: flat, facing up, axes aligned with base_link."""

    namespace: str
    marker_id: int
    size_m: float
    height_m: float  # marker face above the floor
    offset_xy_m: tuple[float, float]  # marker centre in base_link
    # how fast the robot reaches a commanded speed (its drive's braking on an emergency stop):
    # the localizer's motion model; None: the localizer's own accel_mps2
    accel_mps2: float | None = None


@dataclass(frozen=True)
class Detection:
    """Corners of one marker in one distorted image, OpenCV order (TL, TR, BR, BL)."""

    camera_id: str
    marker_id: int
    corners_px: NDArray[np.float64]  # (4, 2)


@dataclass(frozen=True)
class MarkerObservation:
    """A marker's pose seen by one camera, with an uncertainty model."""

    camera_id: str
    marker_id: int
    x_m: float
    y_m: float
    yaw_rad: float
    sigma_xy_m: float
    sigma_yaw_rad: float
    reprojection_px: float
    side_px: float


def _dictionary(marker_ids: tuple[int, ...] | None) -> cv2.aruco.Dictionary:
    """DICT_5X5_1000, or only its codes of ``marker_ids`` (in that order: index i is id ids[i])."""
    full = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY)
    if marker_ids is None:
        return full
    return cv2.aruco.Dictionary(
        np.ascontiguousarray(full.bytesList[list(marker_ids)]), full.markerSize, full.maxCorrectionBits
    )


def _detector(min_perimeter_rate: float, dictionary: cv2.aruco.Dictionary) -> cv2.aruco.ArucoDetector:
    params = cv2.aruco.DetectorParameters()
    params.minMarkerPerimeterRate = min_perimeter_rate
    params.perspectiveRemovePixelPerCell = 8  # small markers: sample each cell finely
    # measured on rendered 960x540 frames (single-camera marker poses against ground truth):
    # contour refinement 0.59 deg / 0.28 cm, no refinement 0.92 deg / 0.57 cm, sub-pixel corner
    # refinement 1.26 deg / 0.67 cm (it drifts towards the cells' inner edges on small markers)
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_CONTOUR
    return cv2.aruco.ArucoDetector(dictionary, params)


class MarkerDetector:
    """DICT_5X5_1000 detection, full frame or in regions of interest.

    The minimum marker size is relative to the searched image: in a full 960x540 frame markers
    from 10 px across are kept (perimeter rate 0.04; smaller rates only cost time, measured);
    in a region around a predicted marker the marker is at least a sixth of the region, and the
    rate of 0.15 keeps the detector from chasing tiny contours.

    ``marker_ids`` (the markers the fleet carries) restricts identification to those codes of the
    dictionary. OpenCV compares every candidate square (most are not markers: shelf edges,
    texture) with every code of the dictionary in four rotations; against all 1000 codes that
    was 80-90 % of the detection time (measured on recorded 960x540 frames: a region 1.2 ->
    0.19 ms, a full frame 37 -> 4.4 ms with four ids). The markers found are the same, with the
    same corners: DICT_5X5_1000's codes are at least 5 bits apart and OpenCV corrects at most
    one bit (maxCorrectionBits 2 x errorCorrectionRate 0.6), so a candidate matches at most one
    code whichever subset is searched. Markers of other ids are then not reported at all.
    """

    def __init__(
        self,
        *,
        full_rate: float = 0.04,
        roi_rate: float = 0.15,
        marker_ids: tuple[int, ...] | list[int] | None = None,
    ) -> None:
        ids = None if marker_ids is None else tuple(sorted({int(i) for i in marker_ids}))
        size = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY).bytesList.shape[0]
        if ids is not None and any(not 0 <= i < size for i in ids):
            raise ValueError(f"marker ids must be in 0..{size - 1} (DICT_5X5_1000), got {list(ids)}")
        self.marker_ids = ids
        self._ids = None if ids is None else np.asarray(ids, dtype=np.int64)
        self._full: cv2.aruco.ArucoDetector | None = None
        self._roi: cv2.aruco.ArucoDetector | None = None
        if ids is None or ids:  # (no id at all: nothing to look for)
            dictionary = _dictionary(ids)
            self._full = _detector(full_rate, dictionary)
            self._roi = _detector(roi_rate, dictionary)

    def detect(
        self, camera_id: str, gray: NDArray[np.uint8], roi: tuple[int, int, int, int] | None = None
    ) -> list[Detection]:
        """Markers in ``gray`` (or in ``roi`` = u0, v0, u1, v1 of it), sorted by id."""
        if roi is not None:
            u0, v0, u1, v1 = roi
            return self.detect_region(camera_id, gray[v0:v1, u0:u1], (u0, v0))
        return self._detect(camera_id, gray, self._full, 0, 0)

    def detect_region(
        self, camera_id: str, pixels: NDArray[np.uint8], origin: tuple[int, int]
    ) -> list[Detection]:
        """Markers in a region of interest given by its pixels, whose top-left pixel is
        ``origin`` (u0, v0) of the image; corners in the image's pixels, sorted by id."""
        return self._detect(camera_id, pixels, self._roi, origin[0], origin[1])

    def _detect(
        self,
        camera_id: str,
        image: NDArray[np.uint8],
        detector: cv2.aruco.ArucoDetector | None,
        u0: int,
        v0: int,
    ) -> list[Detection]:
        if detector is None or image.size == 0:
            return []
        corners, ids, _ = detector.detectMarkers(image)
        if ids is None:
            return []
        found = ids.ravel() if self._ids is None else self._ids[ids.ravel()]
        out = [
            Detection(
                camera_id,
                int(i),
                np.asarray(c, dtype=np.float64).reshape(4, 2) + np.array([u0, v0], dtype=np.float64),
            )
            for c, i in zip(corners, found)
        ]
        return sorted(out, key=lambda d: (d.marker_id, float(d.corners_px[0, 0]), float(d.corners_px[0, 1])))


def side_length_px(det: Detection) -> float:
    """Mean side length of a detected marker in pixels (plain floats: four corners)."""
    c = det.corners_px.tolist()
    return sum(math.dist(c[i], c[i - 1]) for i in range(4)) / 4.0


def marker_corners_in_marker_frame(size_m: float) -> NDArray[np.float64]:
    """(4, 3) corners in the marker frame, OpenCV order: (-s/2, s/2), (s/2, s/2), (s/2, -s/2), (-s/2, -s/2)."""
    h = size_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def markers_in_view(
    cameras: Iterable[CameraModel],
    marker_xyz: Sequence[float],
    poses_xyyaw: NDArray[np.float64],
    *,
    size_m: float,
) -> NDArray[np.bool_]:
    """For base_link poses (N, 3) of a robot whose marker sits at ``marker_xyz`` (base_link, facing
    up): is the whole marker inside some camera's image, with a valid ray at every corner and at
    least ``MIN_SIDE_PX`` across? (One projection per camera for all poses.)"""
    mx, my, mz = marker_xyz
    poses = np.asarray(poses_xyyaw, dtype=float).reshape(-1, 3)
    n = len(poses)
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    local = marker_corners_in_marker_frame(size_m) + [mx, my, mz]  # in base_link
    corners = np.stack(
        [
            poses[:, :1] + c * local[:, 0] - s * local[:, 1],
            poses[:, 1:2] + s * local[:, 0] + c * local[:, 1],
            np.broadcast_to(local[:, 2], (n, 4)),
        ],
        axis=-1,
    )  # (N, 4, 3)
    visible = np.zeros(n, dtype=bool)
    for cam in cameras:
        if cam.position[2] <= mz or visible.all():
            continue
        # only corners whose rays fall near the image are projected (OpenCV's distortion is the
        # cost: the floor of a hall is mostly outside any one camera's view)
        pts = cam.world_to_camera(corners.reshape(-1, 3)).reshape(n, 4, 3)
        z = pts[..., 2]
        xy = pts[..., :2] / np.where(z > 1e-9, z, 1.0)[..., None]
        x0, x1, y0, y1 = cam.normalized_bounds
        near = (
            (z > 1e-9).all(axis=1)
            & (xy[..., 0] >= x0).all(axis=1)
            & (xy[..., 0] <= x1).all(axis=1)
            & (xy[..., 1] >= y0).all(axis=1)
            & (xy[..., 1] <= y1).all(axis=1)
            & ~visible
        )
        if not near.any():
            continue
        cand = np.flatnonzero(near)
        uv, ok = cam.project_camera_points(pts[cand].reshape(-1, 3))
        uv = uv.reshape(-1, 4, 2)
        inside = (
            ok.reshape(-1, 4).all(axis=1)
            & (uv >= 0).all(axis=(1, 2))
            & (uv[..., 0] <= cam.width - 1).all(axis=1)
            & (uv[..., 1] <= cam.height - 1).all(axis=1)
        )
        if not inside.any():
            continue
        rows = cand[inside]
        uv = uv[inside]
        _, ok_px = cam.undistort_pixels(uv.reshape(-1, 2))
        side = np.linalg.norm(uv - np.roll(uv, 1, axis=1), axis=2).mean(axis=1)
        visible[rows] = ok_px.reshape(-1, 4).all(axis=1) & (side >= MIN_SIDE_PX)
    return visible


def _square_from_points(points_xy: list[tuple[float, float]]) -> tuple[float, float, float]:
    """Centre and yaw of a square from its four corners in OpenCV order (marker x along TL->TR)."""
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = points_xy  # TL, TR, BR, BL
    ax, ay = (x1 - x0) + (x2 - x3), (y1 - y0) + (y2 - y3)  # x axis: TR - TL + BR - BL
    bx, by = (x0 - x3) + (x1 - x2), (y0 - y3) + (y1 - y2)  # y axis: TL - BL + TR - BR
    # average the two axis estimates: y rotated by -90 degrees points along x
    na, nb = math.hypot(ax, ay), math.hypot(bx, by)
    vx, vy = ax / na + by / nb, ay / na - bx / nb
    return (x0 + x1 + x2 + x3) / 4.0, (y0 + y1 + y2 + y3) / 4.0, math.atan2(vy, vx)


def _uncertainty(side_px: float, reproj_px: float, size_m: float) -> tuple[float, float]:
    """Position and yaw standard deviations of one camera's marker pose.

    Calibrated on rendered 960x540 frames with contour corner refinement: fixes scatter by about
    0.13 px at the marker in position and about 14 degree-pixels over the marker's side in yaw,
    from 15 px to 60 px wide markers (docs/benchmarks/gpss.md). A poor fit of the square (reprojection
    error) inflates both.
    """
    metres_per_px = size_m / max(side_px, 1.0)
    quality = 1.0 + reproj_px
    return 0.15 * metres_per_px * quality, 0.25 / max(side_px, 1.0) * quality


def ground_constraint_pose(
    camera: CameraModel, det: Detection, mount: MarkerMount
) -> MarkerObservation | None:
    """Intersect the corner rays with the marker's known plane z = height; None if a ray is invalid.

    In plain floats (four corners: numpy's per-call overhead was most of its cost, with the GIL
    held, for every marker every camera sees)."""
    corners = det.corners_px.tolist()
    points = camera.intersect_plane_z_few(corners, mount.height_m)
    if points is None:
        return None
    x, y, yaw = _square_from_points(points)
    # the ideal square at that pose, back into the image
    c, s = math.cos(yaw), math.sin(yaw)
    ideal = [
        (x + c * mx - s * my, y + s * mx + c * my, mount.height_m)
        for mx, my, _ in marker_corners_in_marker_frame(mount.size_m).tolist()
    ]
    uv = camera.project_few(ideal)
    if uv is None:
        return None
    reproj = math.sqrt(sum((u - cu) ** 2 + (v - cv) ** 2 for (u, v), (cu, cv) in zip(uv, corners)) / 4.0)
    side = side_length_px(det)
    sigma_xy, sigma_yaw = _uncertainty(side, reproj, mount.size_m)
    return MarkerObservation(det.camera_id, det.marker_id, x, y, yaw, sigma_xy, sigma_yaw, reproj, side)


def pnp_pose(camera: CameraModel, det: Detection, mount: MarkerMount) -> MarkerObservation | None:
    """solvePnP (IPPE_SQUARE) on the distorted corners; the marker's height is not used."""
    obj = marker_corners_in_marker_frame(mount.size_m)
    ok, rvec, tvec = cv2.solvePnP(
        obj, det.corners_px.reshape(-1, 1, 2), camera.K, camera.D, flags=cv2.SOLVEPNP_IPPE_SQUARE
    )
    if not ok:
        return None
    R_cm, _ = cv2.Rodrigues(rvec)
    world_from_marker = camera.world_from_camera @ Transform(
        np.asarray(R_cm, dtype=np.float64), np.asarray(tvec, dtype=np.float64).reshape(3)
    )
    proj, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.D)
    reproj = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - det.corners_px) ** 2, axis=1))))
    x, y = (float(v) for v in world_from_marker.translation[:2])
    yaw = world_from_marker.yaw()
    side = side_length_px(det)
    sigma_xy, sigma_yaw = _uncertainty(side, reproj, mount.size_m)
    # PnP's depth comes from the marker's apparent size alone: a fraction of a pixel on a 20 px
    # marker moves it by centimetres to decimetres along the viewing ray. Measured on rendered
    # 960x540 frames: position error = 0.25 x range / side_px (median), 0.73 (90th percentile)
    sigma_xy = max(sigma_xy, 0.35 * float(np.linalg.norm(tvec)) / max(side, 1.0))
    return MarkerObservation(det.camera_id, det.marker_id, x, y, yaw, sigma_xy, sigma_yaw, reproj, side)


POSE_METHODS = {"ground": ground_constraint_pose, "pnp": pnp_pose}


def fuse(observations: list[MarkerObservation]) -> tuple[float, float, float, float, float]:
    """Inverse-variance weighted position and circular-mean yaw of one marker's observations.

    Returns (x, y, yaw, sigma_xy, sigma_yaw). The yaw mean is on the circle (sum of weighted unit
    vectors): SIMLAN averaged raw quaternions, which breaks when their signs differ.
    """
    w_xy = np.array([1.0 / o.sigma_xy_m**2 for o in observations])
    w_yaw = np.array([1.0 / o.sigma_yaw_rad**2 for o in observations])
    xs = np.array([o.x_m for o in observations])
    ys = np.array([o.y_m for o in observations])
    yaws = np.array([o.yaw_rad for o in observations])
    x = float(np.sum(w_xy * xs) / w_xy.sum())
    y = float(np.sum(w_xy * ys) / w_xy.sum())
    yaw = float(np.arctan2(np.sum(w_yaw * np.sin(yaws)), np.sum(w_yaw * np.cos(yaws))))
    return x, y, yaw, float(1.0 / np.sqrt(w_xy.sum())), float(1.0 / np.sqrt(w_yaw.sum()))
