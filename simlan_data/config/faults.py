"""Camera faults injected into what the algorithms believe: dropped images, a wrong calibration.

The world, the rendering and the recording stay true; only the camera set the localizer (and the
bird's-eye stitcher) are given changes::

    recorded cameras (camera_info + /tf_static)  --CameraFaults-->  believed cameras
        dropped:   removed (their images never reach the algorithm)
        yaw error: rotated about the vertical through the camera centre by yaw_error_deg

A live run takes the faults from its ``faults`` config section; a replay takes the recorded
section, overridden by its options (``--set drop_cameras=[163]``), so that a replay of a faulty
run reproduces it and a clean recording can be replayed with a fault.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform

# replay options handled here (every algorithm that takes cameras honours them)
CAMERA_FAULT_OPTIONS = ("drop_cameras", "yaw_error_deg", "yaw_error_cameras")


def _ids(value: Any, where: str) -> frozenset[str]:
    if value is None:
        return frozenset()
    if isinstance(value, (int, str)):
        value = [value]
    if not isinstance(value, (list, tuple)):
        raise ConfigError(
            f"invalid {where}={value!r}", "faults", "expected a list of camera ids", f"e.g. {where}=[163]"
        )
    return frozenset(str(v) for v in value)


@dataclass(frozen=True)
class CameraFaults:
    """Which cameras the algorithms lose and which they believe rotated, by how much."""

    drop: frozenset[str] = frozenset()
    yaw_error_deg: float = 0.0
    yaw_error_cameras: frozenset[str] = frozenset()

    @classmethod
    def from_settings(
        cls, config: Mapping[str, Any], options: Mapping[str, Any] | None = None
    ) -> CameraFaults:
        """The run's ``faults`` section (a config dict), each key overridden by ``options``."""
        merged = {
            **dict(config.get("faults") or {}),
            **{k: v for k, v in (options or {}).items() if k in CAMERA_FAULT_OPTIONS},
        }
        try:
            yaw = float(merged.get("yaw_error_deg", 0.0))
        except (TypeError, ValueError):
            raise ConfigError(
                f"invalid yaw_error_deg={merged.get('yaw_error_deg')!r}",
                "faults",
                "expected degrees",
                "e.g. yaw_error_deg=1.0",
            ) from None
        return cls(
            _ids(merged.get("drop_cameras"), "drop_cameras"),
            yaw,
            _ids(merged.get("yaw_error_cameras"), "yaw_error_cameras"),
        )

    @property
    def active(self) -> bool:
        return bool(self.drop) or (self.yaw_error_deg != 0.0 and bool(self.yaw_error_cameras))

    def describe(self) -> str:
        parts = []
        if self.drop:
            parts.append(f"cameras {', '.join(sorted(self.drop))} dropped")
        if self.yaw_error_deg and self.yaw_error_cameras:
            parts.append(
                f"{self.yaw_error_deg:g} deg yaw error on camera {', '.join(sorted(self.yaw_error_cameras))}"
            )
        return "; ".join(parts) or "none"

    def apply(self, cameras: Mapping[str, CameraModel], *, where: str = "faults") -> dict[str, CameraModel]:
        """The cameras as the algorithms believe them (order kept).

        Raises:
            ConfigError: a fault names a camera that is not there.
        """
        unknown = sorted((self.drop | self.yaw_error_cameras) - set(cameras))
        if unknown:
            raise ConfigError(
                f"unknown camera {unknown[0]} in the injected faults",
                where,
                f"the cameras are {', '.join(cameras)}",
                "name one of them",
            )
        out = {}
        for cid, cam in cameras.items():
            if cid in self.drop:
                continue
            out[cid] = with_yaw_error(cam, self.yaw_error_deg) if cid in self.yaw_error_cameras else cam
        return out


def with_yaw_error(camera: CameraModel, yaw_deg: float) -> CameraModel:
    """The camera rotated by ``yaw_deg`` about the world's vertical through its centre.

    A calibration whose extrinsic yaw is off by that much: the camera still sits where it is, but
    every ray it casts is turned, so a point at horizontal distance d lands about d * yaw_rad off.
    """
    if yaw_deg == 0.0:
        return camera
    c = camera.position
    turn = Transform.from_pose2d(0.0, 0.0, float(np.radians(yaw_deg)))
    about_centre = (
        Transform.from_pose2d(c[0], c[1], 0.0, c[2]) @ turn @ Transform.from_pose2d(-c[0], -c[1], 0.0, -c[2])
    )
    return replace(camera, camera_from_world=(about_centre @ camera.world_from_camera).inverse())
