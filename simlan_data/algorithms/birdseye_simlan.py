"""SIMLAN's bird's-eye view, re-implemented as the baseline (vectorized, same arithmetic).

SIMLAN (release 5.1.5, package camera_bird_eye_view) runs one projection node per camera and
one stitcher node::

    ground grid: np.arange(start, end, 0.02) in x and y at z = 0 (grid corners, not centres)
    per camera:  uv = K (R P + t) / z, no lens distortion, no check that P is in front
                 sample the greyscale image at int(u), int(v) (truncation) if 0 < u < w, 0 < v < h,
                 else 0; min-max normalize the camera's grid to 0..255 (cv2.NORM_MINMAX, uint8)
    stitcher:    mean over ALL cameras (those that do not see a point contribute 0),
                 min-max normalize to 0..255, flip vertically (north up)

The result lies on our canvas (same region and resolution; SIMLAN's grid points sit half a pixel,
1 cm at 50 px/m, south-west of our pixel centres, which is part of its error). SIMLAN loops over
the grid in Python per pixel; this version vectorizes the same operations.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.birdseye import CanvasSpec
from simlan_data.geometry.camera import CameraModel


class SimlanBirdseye:
    """SIMLAN's projection + stitching for a fixed camera set on a canvas."""

    def __init__(self, cameras: Sequence[CameraModel], spec: CanvasSpec) -> None:
        self.cameras, self.spec = list(cameras), spec
        H, W = spec.height, spec.width
        res = spec.m_per_px
        xs = spec.x_m[0] + res * np.arange(W)
        ys = spec.y_m[0] + res * np.arange(H)
        xx, yy = np.meshgrid(xs, ys[::-1])  # flipped: row 0 is the northern edge, as after cv2.flip
        pts = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=0)  # (3, N), z = 0 always
        self._index: list[NDArray[np.intp]] = []
        self._inside: list[NDArray[np.bool_]] = []
        for cam in self.cameras:
            R, t = cam.camera_from_world.rotation, cam.camera_from_world.translation
            pc = R @ pts + t[:, None]
            with np.errstate(divide="ignore", invalid="ignore"):
                p = cam.K @ (pc / pc[2])
            u, v = p[0], p[1]
            inside = (u > 0) & (u < cam.width) & (v > 0) & (v < cam.height)
            iu = np.where(inside, u, 0).astype(np.intp)
            iv = np.where(inside, v, 0).astype(np.intp)
            self._index.append((iv * cam.width + iu).reshape(H, W))
            self._inside.append(inside.reshape(H, W))
        self.coverage = np.logical_or.reduce(self._inside)

    def project_each(self, frames: Sequence[NDArray[np.uint8]]) -> list[NDArray[np.uint8]]:
        """Every camera's grid image (uint8, min-max normalized), as SIMLAN's projection nodes."""
        out = []
        for frame, index, inside in zip(frames, self._index, self._inside):
            grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
            values = np.where(inside, grey.ravel()[index], 0).astype(np.float64)
            out.append(cv2.normalize(values, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8))  # type: ignore[call-overload]
        return out

    def stitch(self, frames: Sequence[NDArray[np.uint8]]) -> NDArray[np.uint8]:
        """Greyscale canvas (H, W) uint8, as SIMLAN's stitcher publishes it."""
        means = np.mean(self.project_each(frames), axis=0)
        return cv2.normalize(means, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)  # type: ignore[call-overload]

    @property
    def inside(self) -> list[NDArray[np.bool_]]:
        """Per camera: canvas pixels it samples (inside its image under the pinhole model)."""
        return self._inside
