"""Rotation conversions (matrix, Rodrigues vector, quaternion, yaw) through scipy.

Quaternions are (x, y, z, w) like ROS and scipy. Rodrigues vectors are axis * angle like OpenCV.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@cache
def _rotation() -> Any:
    """scipy's ``Rotation``, imported on first use: scipy.spatial takes 0.2 s to import, and the
    command line's help and config errors import this module without rotating anything."""
    from scipy.spatial.transform import Rotation

    return Rotation


def matrix_from_quat(quat_xyzw: ArrayLike) -> FloatArray:
    """Return the 3x3 rotation matrix of a unit quaternion (x, y, z, w) (or (N, 3, 3) of (N, 4)).

    A single quaternion takes the closed form (scipy's per-call overhead dominates the simulation
    loop otherwise); batches go through scipy. Tests check both agree.
    """
    q = np.asarray(quat_xyzw, dtype=float)
    if q.shape != (4,):
        return _rotation().from_quat(q).as_matrix()
    x, y, z, w = q / np.sqrt(q @ q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_from_matrix(matrix: ArrayLike) -> FloatArray:
    """Return the quaternion (x, y, z, w) of a rotation matrix, with w >= 0."""
    quat = _rotation().from_matrix(np.asarray(matrix, dtype=float)).as_quat()
    return np.where(quat[..., 3:4] < 0, -quat, quat)


def matrix_from_rodrigues(rotvec: ArrayLike) -> FloatArray:
    """Return the rotation matrix of a Rodrigues (axis-angle) vector, as cv2.Rodrigues does."""
    return _rotation().from_rotvec(np.asarray(rotvec, dtype=float).reshape(-1, 3)).as_matrix().squeeze()


def rodrigues_from_matrix(matrix: ArrayLike) -> FloatArray:
    """Return the Rodrigues vector of a rotation matrix."""
    return _rotation().from_matrix(np.asarray(matrix, dtype=float)).as_rotvec()


def quat_from_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """Return the quaternion of extrinsic roll-pitch-yaw (URDF/SDF convention: R = Rz Ry Rx)."""
    return _rotation().from_euler("xyz", [roll_rad, pitch_rad, yaw_rad]).as_quat()


def rpy_from_quat(quat_xyzw: ArrayLike) -> FloatArray:
    """Return extrinsic (roll, pitch, yaw) in radians of a quaternion."""
    return _rotation().from_quat(np.asarray(quat_xyzw, dtype=float)).as_euler("xyz")


def quat_from_yaw(yaw_rad: float) -> FloatArray:
    """Return the quaternion of a rotation about z."""
    half = 0.5 * yaw_rad
    return np.array([0.0, 0.0, np.sin(half), np.cos(half)])


def yaw_from_quat(quat_xyzw: ArrayLike) -> float:
    """Return the heading (rotation about world z) of a quaternion, in radians."""
    x, y, z, w = np.asarray(quat_xyzw, dtype=float)
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def yaw_from_matrix(matrix: ArrayLike) -> float:
    """Return the heading of a rotation matrix (direction of its x axis in the xy plane)."""
    m = np.asarray(matrix, dtype=float)
    return float(np.arctan2(m[1, 0], m[0, 0]))


def wrap_angle(angle_rad: ArrayLike) -> FloatArray:
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(angle_rad, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi


def is_rotation_matrix(matrix: ArrayLike, *, tol: float = 1e-6) -> bool:
    """Return True if ``matrix`` is orthonormal with determinant +1 within ``tol``."""
    m = np.asarray(matrix, dtype=float)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        return False
    return bool(np.allclose(m.T @ m, np.eye(3), atol=tol) and abs(np.linalg.det(m) - 1.0) < tol)
