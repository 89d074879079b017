"""Geometry: rotations, rigid transforms, the camera model and SIMLAN's calibration files."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.geometry` stays light (rotations and transforms do not load cv2).
_EXPORTS: dict[str, str] = {
    "Calibration": "calibration",
    "available_camera_ids": "calibration",
    "load_calibration": "calibration",
    "CameraModel": "camera",
    "distort_points": "camera",
    "linearize_depth": "camera",
    "opengl_projection": "camera",
    "is_rotation_matrix": "rotations",
    "matrix_from_quat": "rotations",
    "matrix_from_rodrigues": "rotations",
    "quat_from_matrix": "rotations",
    "quat_from_rpy": "rotations",
    "quat_from_yaw": "rotations",
    "rodrigues_from_matrix": "rotations",
    "rpy_from_quat": "rotations",
    "wrap_angle": "rotations",
    "yaw_from_matrix": "rotations",
    "yaw_from_quat": "rotations",
    "Transform": "transforms",
}

__all__ = [
    "Calibration",
    "CameraModel",
    "Transform",
    "available_camera_ids",
    "distort_points",
    "is_rotation_matrix",
    "linearize_depth",
    "load_calibration",
    "matrix_from_quat",
    "matrix_from_rodrigues",
    "opengl_projection",
    "quat_from_matrix",
    "quat_from_rpy",
    "quat_from_yaw",
    "rodrigues_from_matrix",
    "rpy_from_quat",
    "wrap_angle",
    "yaw_from_matrix",
    "yaw_from_quat",
]


def __getattr__(name: str) -> Any:
    """Import the defining module on first use of a public name (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
