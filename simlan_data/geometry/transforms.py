"""Rigid transforms (SE(3)) as frozen dataclasses; names say which frame maps to which.

``world_from_camera`` maps points expressed in the camera frame into the world frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from simlan_data.geometry.rotations import (
    FloatArray,
    matrix_from_quat,
    quat_from_matrix,
    quat_from_rpy,
    yaw_from_matrix,
)


@dataclass(frozen=True)
class Transform:
    """A rigid transform ``p_target = rotation @ p_source + translation``."""

    rotation: FloatArray
    translation: FloatArray
    # the quaternion it was made from, if any (saves a matrix -> quaternion conversion)
    quat_xyzw: FloatArray | None = field(default=None, compare=False, repr=False)

    @staticmethod
    def identity() -> Transform:
        return Transform(np.eye(3), np.zeros(3))

    @staticmethod
    def from_quat(translation: ArrayLike, quat_xyzw: ArrayLike) -> Transform:
        q = np.asarray(quat_xyzw, dtype=float)
        q = q / np.sqrt(q @ q)
        return Transform(
            matrix_from_quat(q), np.asarray(translation, dtype=float).copy(), -q if q[3] < 0 else q
        )

    @staticmethod
    def from_xyz_rpy(xyz: ArrayLike, rpy: ArrayLike) -> Transform:
        return Transform.from_quat(xyz, quat_from_rpy(*np.asarray(rpy, dtype=float)))

    @staticmethod
    def from_pose2d(x_m: float, y_m: float, yaw_rad: float, z_m: float = 0.0) -> Transform:
        c, s = np.cos(yaw_rad), np.sin(yaw_rad)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return Transform(rot, np.array([x_m, y_m, z_m], dtype=float))

    @staticmethod
    def from_matrix(matrix: ArrayLike) -> Transform:
        m = np.asarray(matrix, dtype=float)
        return Transform(m[:3, :3].copy(), m[:3, 3].copy())

    def matrix(self) -> FloatArray:
        out = np.eye(4)
        out[:3, :3] = self.rotation
        out[:3, 3] = self.translation
        return out

    def quat(self) -> FloatArray:
        """Quaternion (x, y, z, w) with w >= 0."""
        return self.quat_xyzw if self.quat_xyzw is not None else quat_from_matrix(self.rotation)

    def yaw(self) -> float:
        return yaw_from_matrix(self.rotation)

    def inverse(self) -> Transform:
        rot_t = self.rotation.T
        return Transform(rot_t, -rot_t @ self.translation)

    def __matmul__(self, other: Transform) -> Transform:
        return Transform(self.rotation @ other.rotation, self.rotation @ other.translation + self.translation)

    def apply(self, points: ArrayLike) -> FloatArray:
        """Map points (N, 3) or (3,) from the source frame into the target frame."""
        pts = np.asarray(points, dtype=float)
        return pts @ self.rotation.T + self.translation
