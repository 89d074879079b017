"""Boxes of the instance ground truth (issue 25): an instance image's visible boxes, and a 3D box
projected through a camera model with its distortion (amodal box, outline area, truncation).

Pixel-edge coordinates as COCO's: pixel (u, v) covers [u, u+1) x [v, v+1); OpenCV projects a
point onto pixel centres at integers, hence the half pixel added to projections.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from simlan_data.geometry.camera import CameraModel

# corner index = 4 * ix + 2 * iy + iz over (-, +) half sizes; edges join corners differing in one bit
_CORNER_SIGNS = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], dtype=float) * 2 - 1
_EDGES = np.array([(i, i ^ bit) for i in range(8) for bit in (1, 2, 4) if i < i ^ bit])
# samples per edge: a distorted straight edge bows; 9 samples bound it to well under a pixel at the
# SIMLAN lenses' distortion
EDGE_SAMPLES = 9
NEAR_M = 0.05  # box points closer to the camera plane than this are left out (not projectable)


class VisibleBoxes(NamedTuple):
    """The instances an image shows: ids (N,), mask pixel counts (N,), boxes (N, 4) u0 v0 u1 v1
    (u1, v1 exclusive)."""

    ids: NDArray[np.uint16]
    pixels: NDArray[np.uint32]
    boxes: NDArray[np.int32]


class Amodal(NamedTuple):
    """A 3D box seen by a camera: its projected bounds (u0, v0, u1, v1; unclipped) and the area of
    its projected outline (pixels^2)."""

    bounds: tuple[float, float, float, float]
    outline_area: float


def visible_boxes(instances: NDArray[np.uint16]) -> VisibleBoxes:
    """The bounding box and pixel count of every instance id > 0 in an instance image.

    ``find_objects`` runs on the crop around all instance pixels only (objects cover a few percent
    of a ceiling camera's image: 2.4 ms for a whole 960x540 image, a tenth of it for the crop);
    pixels are counted inside each box.
    """
    rows, cols = np.flatnonzero(instances.any(axis=1)), np.flatnonzero(instances.any(axis=0))
    ids, pixels, boxes = [], [], []
    if len(rows):
        v0, u0 = int(rows[0]), int(cols[0])
        crop = instances[v0 : int(rows[-1]) + 1, u0 : int(cols[-1]) + 1]
        for i, sl in enumerate(ndimage.find_objects(crop), start=1):
            if sl is not None:
                ids.append(i)
                pixels.append(np.count_nonzero(crop[sl] == i))
                boxes.append((u0 + sl[1].start, v0 + sl[0].start, u0 + sl[1].stop, v0 + sl[0].stop))
    return VisibleBoxes(
        np.array(ids, dtype=np.uint16),
        np.array(pixels, dtype=np.uint32),
        np.array(boxes, dtype=np.int32).reshape(-1, 4),
    )


def box_corners(
    center: NDArray[np.float64], size: NDArray[np.float64], yaw_rad: float
) -> NDArray[np.float64]:
    """The 8 corners (8, 3) of a box rotated by ``yaw_rad`` about z."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(center) + (_CORNER_SIGNS * (np.asarray(size) / 2)) @ rot.T


def project_box(
    camera: CameraModel, center: NDArray[np.float64], size: NDArray[np.float64], yaw_rad: float
) -> Amodal | None:
    """Project a 3D box (map frame) into the camera's distorted image; None if no part of it lies
    in front of the camera within the lens model's valid radius.

    The box's edges are sampled (they bow under distortion); points behind the near distance or
    outside the valid radius are left out, so a box that reaches behind the camera is bounded by
    the part in front (ceiling cameras see the floor: rare).
    """
    corners = box_corners(center, size, yaw_rad)
    t = np.linspace(0.0, 1.0, EDGE_SAMPLES)[:, None, None]
    a, b = corners[_EDGES[:, 0]], corners[_EDGES[:, 1]]
    points = (a + t * (b - a)).reshape(-1, 3)
    pc = np.atleast_2d(camera.world_to_camera(points))
    pc = pc[pc[:, 2] > NEAR_M]
    if len(pc) == 0:
        return None
    uv, ok = camera.project_camera_points(pc)
    uv = uv[ok] + 0.5
    if len(uv) == 0:
        return None
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    hull = cv2.convexHull(uv.astype(np.float32))
    return Amodal((float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])), float(cv2.contourArea(hull)))


def clip_box(
    bounds: tuple[float, float, float, float], width: int, height: int
) -> tuple[tuple[float, float, float, float], float]:
    """The box clipped to the image, and the share of its area outside the image (truncation)."""
    u0, v0, u1, v1 = bounds
    c = (
        min(max(u0, 0.0), width),
        min(max(v0, 0.0), height),
        min(max(u1, 0.0), width),
        min(max(v1, 0.0), height),
    )
    area = max(u1 - u0, 0.0) * max(v1 - v0, 0.0)
    inside = (c[2] - c[0]) * (c[3] - c[1])
    return c, (1.0 - inside / area) if area > 0 else 0.0
