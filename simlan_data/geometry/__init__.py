"""Geometry: rotations, rigid transforms, the camera model and SIMLAN's calibration files."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "calibration": ["Calibration", "available_camera_ids", "load_calibration"],
        "camera": ["CameraModel", "distort_points", "linearize_depth", "opengl_projection"],
        "rotations": [
            "is_rotation_matrix",
            "matrix_from_quat",
            "matrix_from_rodrigues",
            "quat_from_matrix",
            "quat_from_rpy",
            "quat_from_yaw",
            "rodrigues_from_matrix",
            "rpy_from_quat",
            "wrap_angle",
            "yaw_from_matrix",
            "yaw_from_quat",
        ],
        "transforms": ["Transform"],
    },
)
