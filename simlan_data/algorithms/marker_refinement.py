"""Sub-pixel marker corners from the whole marker pattern (template alignment, ECC).

ArUco's contour refinement fits a line to the thresholded contour pixels of each of the marker's
four outer sides. An edge within a few degrees of the pixel grid is a staircase with one or two
steps over the marker's 20-40 px, so the fitted line leans towards the grid: on rendered 960x540
frames (the renderer samples pixel centres, no anti-aliasing) the yaw of one camera's marker
pose was off by up to 0.9 degrees at such headings (0.35 degrees RMS over all headings), and a
standing robot keeps that one error for as long as it stands (docs/benchmarks/gpss.md, issue 23).

Here the contour corners only start an alignment of the marker's known pattern: the image
around the marker is resampled into the marker plane (through the camera's distortion model and
the homography of the contour corners), and OpenCV's ECC (enhanced correlation coefficient,
invariant to gain and offset) finds the affine correction that best maps the ideal pattern onto
it (a full homography measured the same: the perspective is in the starting homography; it took
twice the time). Every cell boundary of the code takes part, each at another sub-pixel phase, so
the aliasing of the sides mostly averages out: 0.18 degrees RMS per camera on the same frames
(a small marker, seen obliquely, its sides within a degree of the grid, can still be 0.6 off:
the point-sampled render holds no more). The result is refused
(the contour corners stay) where the pattern leaves the searched pixels, the correlation is poor
(occlusion) or the corners would move by more than half a cell.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.markers import ARUCO_DICTIONARY, Detection
from simlan_data.geometry.camera import CameraModel, distort_points

PX_PER_CELL = 4  # resampled pattern: 4 px per cell (measured: 8 px per cell gave the same yaw, 2x the time)
REACH_CELLS = (
    4.25  # the patch, from the centre: the marker (7 cells wide), 3/4 of its white quiet zone (1 cell)
)
MIN_CORRELATION = 0.75  # below: something covers the marker, keep the contour corners
MAX_SHIFT_CELLS = 0.5  # a larger correction is a wrong alignment, keep the contour corners
_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 5, 1e-5)  # (it starts within a pixel)
_BLUR = 3  # ECC's Gaussian smoothing (px of the patch): widens the basin over cell edges

_SIDE = round(2 * REACH_CELLS * PX_PER_CELL)  # patch side in px
_MASK = np.full((_SIDE, _SIDE), 255, dtype=np.uint8)  # (every patch pixel counts)
_CELLS = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY).markerSize + 2  # code and border: 7


def _patch_px(cells: NDArray[np.float64]) -> NDArray[np.float64]:
    """Marker-plane points in cells from the centre (x right, y down) -> patch pixel coordinates
    (pixel centres at integers)."""
    return (cells + REACH_CELLS) * PX_PER_CELL - 0.5


# the outer corners in OpenCV's order (TL, TR, BR, BL), in the patch
_CORNERS = _patch_px(_CELLS / 2 * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]))
_GRID = np.stack(
    [a.ravel() for a in np.meshgrid(np.arange(_SIDE, dtype=np.float64), np.arange(_SIDE, dtype=np.float64))]
    + [np.ones(_SIDE * _SIDE)]
)  # (3, side^2): homogeneous patch pixels, row by row


@functools.lru_cache(maxsize=64)
def _template(marker_id: int) -> NDArray[np.float32]:
    """The ideal pattern of ``marker_id`` in the patch: code and border, white quiet zone."""
    dictionary = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY)
    n = _CELLS
    cells = np.full((n + 2, n + 2), 255, dtype=np.uint8)
    cells[1:-1, 1:-1] = cv2.aruco.generateImageMarker(dictionary, marker_id, n)
    big = cv2.resize(cells, ((n + 2) * PX_PER_CELL,) * 2, interpolation=cv2.INTER_NEAREST)
    start = round(((n + 2) / 2 - REACH_CELLS) * PX_PER_CELL)
    return big[start : start + _SIDE, start : start + _SIDE].astype(np.float32)


def _to_pixels(
    camera: CameraModel, H: NDArray[np.float64], points: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Homogeneous patch points (3, N) through H (patch -> normalized image) and the lens: (N, 2) px."""
    w = H @ points
    k1, k2, p1, p2, k3 = (float(c) for c in np.ravel(camera.D)[:5])
    xd, yd = distort_points(w[0] / w[2], w[1] / w[2], k1, k2, p1, p2, k3)
    K = camera.K
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


def refine_corners(
    camera: CameraModel, det: Detection, pixels: NDArray[np.uint8], origin: tuple[int, int] = (0, 0)
) -> Detection:
    """``det`` with its corners aligned to the marker's pattern in ``pixels`` (grey; its top-left
    pixel is ``origin`` of the image), or ``det`` itself where the alignment is refused."""
    xy, ok = camera.undistort_pixels(det.corners_px)
    if not ok.all():
        return det
    H = cv2.getPerspectiveTransform(_CORNERS.astype(np.float32), xy.astype(np.float32)).astype(np.float64)
    uv = _to_pixels(camera, H, _GRID) - np.asarray(origin, dtype=np.float64)
    height, width = pixels.shape[:2]
    if uv.min() < 0 or uv[:, 0].max() > width - 1 or uv[:, 1].max() > height - 1:
        return det
    maps = uv.astype(np.float32).reshape(_SIDE, _SIDE, 2)
    patch = cv2.remap(pixels, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR).astype(np.float32)
    try:
        rho, W = cv2.findTransformECC(
            _template(det.marker_id),
            patch,
            np.eye(2, 3, dtype=np.float32),
            cv2.MOTION_AFFINE,
            _CRITERIA,
            _MASK,
            _BLUR,
        )
    except cv2.error:  # no convergence (a flat or covered patch)
        return det
    corners = np.vstack([_CORNERS.T, np.ones(4)])
    refined = _to_pixels(camera, H @ np.vstack([W.astype(np.float64), [0.0, 0.0, 1.0]]), corners)
    shift = float(np.max(np.hypot(*(refined - det.corners_px).T)))
    cell_px = float(np.mean(np.hypot(*(det.corners_px - np.roll(det.corners_px, 1, axis=0)).T))) / _CELLS
    if rho < MIN_CORRELATION or not np.isfinite(refined).all() or shift > MAX_SHIFT_CELLS * cell_px:
        return det
    return Detection(det.camera_id, det.marker_id, refined)
