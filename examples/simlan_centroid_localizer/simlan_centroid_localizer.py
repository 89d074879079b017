"""A simlan_data localizer plug-in: ArUco marker centres on the floor plane, alpha-beta filtered.

An alternative to the built-in ``aruco`` localizer (ground-plane corner poses fused by inverse
variance, a unicycle EKF). Per camera frame it

1. detects the fleet's ArUco markers (DICT_5X5_1000, restricted to the fleet's ids) in the
   grey image with OpenCV's ``ArucoDetector``,
2. undistorts the four corners with the camera model and takes the marker's centre as the
   intersection of the square's diagonals (exact for a planar square under a pinhole camera),
3. intersects the centre's viewing ray with the horizontal plane at the marker's height, and the
   corners' rays too, for the yaw (the marker's x edges, and its y edges turned by -90 degrees),
4. averages the cameras that saw a marker (weights: side length in pixels squared; yaw on the
   circle) and moves from the marker to the robot's base_link by the marker's mount offset,

and runs a constant-velocity alpha-beta filter per robot over (x, y, yaw). Velocity commands are
not used (the filter is purely kinematic). Deterministic: no randomness, no wall clock, cameras
taken in the order given.

Select it with ``python -m simlan_data.run algorithms/localizer=centroid`` once this package is
installed (entry point ``centroid`` in the group ``simlan_data.algorithms``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.localization import PoseEstimate
from simlan_data.algorithms.markers import ARUCO_DICTIONARY, MarkerMount
from simlan_data.algorithms.roles import CameraFrame, LocalizerContext
from simlan_data.geometry.camera import CameraModel

__all__ = ["CentroidConfig", "CentroidLocalizer"]

NS_PER_S = 1_000_000_000
REFINEMENTS = {
    "none": cv2.aruco.CORNER_REFINE_NONE,
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
}


@dataclass(frozen=True)
class CentroidConfig:
    """The centroid localizer's settings (``algorithms.localizer.KEY=VALUE``)."""

    alpha: float = 0.9  # position gain of the alpha-beta filter, in (0, 1] (1: take each fix as is)
    beta: float = 0.5  # velocity gain, in [0, 1) (0: no velocity, the estimate holds still)
    unobserved_timeout_s: float = 0.5  # no fix for longer: the robot is unobserved
    lost_timeout_s: float = 1.5  # no fix for longer: no valid estimate; the next fix restarts the filter
    min_side_px: float = 8.0  # markers smaller than this (mean side, pixels) are too noisy to use
    gate_m: float = 1.0  # fixes farther than this from the prediction are outliers
    corner_refinement: str = "contour"  # OpenCV corner refinement: none | subpix | contour

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha <= 1.0:
            raise ValueError(f"alpha={self.alpha!r} is out of range: alpha must be in (0, 1]")
        if not 0.0 <= self.beta < 1.0:
            raise ValueError(f"beta={self.beta!r} is out of range: beta must be in [0, 1)")
        if not self.unobserved_timeout_s > 0:
            raise ValueError(f"unobserved_timeout_s={self.unobserved_timeout_s!r}: must be > 0")
        if not self.lost_timeout_s > 0:
            raise ValueError(f"lost_timeout_s={self.lost_timeout_s!r}: must be > 0")
        if self.lost_timeout_s < self.unobserved_timeout_s:
            raise ValueError(
                f"lost_timeout_s={self.lost_timeout_s!r}: must be >= unobserved_timeout_s ({self.unobserved_timeout_s!r})"
            )
        if not self.min_side_px > 0:
            raise ValueError(f"min_side_px={self.min_side_px!r}: must be > 0")
        if not self.gate_m > 0:
            raise ValueError(f"gate_m={self.gate_m!r}: must be > 0")
        if self.corner_refinement not in REFINEMENTS:
            raise ValueError(
                f"corner_refinement={self.corner_refinement!r}: expected one of {', '.join(REFINEMENTS)}"
            )


@dataclass(frozen=True)
class _Sighting:
    """One camera's marker pose on the floor plane (marker centre, marker yaw) and its weight."""

    camera_id: str
    x_m: float
    y_m: float
    yaw_rad: float
    side_px: float


class _Track:
    """Alpha-beta filter over (x, y, yaw) with velocities (vx, vy, w); state at ``t_ns``."""

    def __init__(
        self, t_ns: int, z: tuple[float, float, float], cameras: tuple[str, ...], sigma: tuple[float, float]
    ) -> None:
        self.reset(t_ns, z, cameras, sigma)

    def reset(
        self, t_ns: int, z: tuple[float, float, float], cameras: tuple[str, ...], sigma: tuple[float, float]
    ) -> None:
        self.t_ns = self.last_fix_ns = t_ns
        self.pos = np.array(z, dtype=np.float64)
        self.vel = np.zeros(3)
        self.cameras, (self.sigma, self.sigma_yaw), self.rejected = cameras, sigma, 0

    def predicted(self, t_ns: int) -> NDArray[np.float64]:
        dt = (t_ns - self.t_ns) / NS_PER_S
        p = self.pos + self.vel * dt
        p[2] = _wrap(p[2])
        return p

    def update(
        self,
        t_ns: int,
        z: tuple[float, float, float],
        cameras: tuple[str, ...],
        sigma: tuple[float, float],
        cfg: CentroidConfig,
    ) -> None:
        dt = (t_ns - self.t_ns) / NS_PER_S
        if dt <= 0.0:  # (a second fix at the same time: take it as it is)
            self.reset(t_ns, z, cameras, sigma)
            return
        pred = self.predicted(t_ns)
        r = np.array(z, dtype=np.float64) - pred
        r[2] = _wrap(r[2])
        if math.hypot(r[0], r[1]) > cfg.gate_m:
            self.rejected += 1
            if self.rejected >= 3:  # the prediction is wrong, not the fixes: restart from this one
                self.reset(t_ns, z, cameras, sigma)
            return
        self.pos = pred + cfg.alpha * r
        self.pos[2] = _wrap(self.pos[2])
        self.vel = self.vel + (cfg.beta / dt) * r
        self.t_ns = self.last_fix_ns = t_ns
        self.cameras, (self.sigma, self.sigma_yaw), self.rejected = cameras, sigma, 0


class CentroidLocalizer:
    """ArUco marker centres intersected with the marker plane, averaged over cameras, alpha-beta."""

    role: ClassVar[str] = "localizer"
    config_class: ClassVar[type] = CentroidConfig

    def __init__(self, config: CentroidConfig, context: LocalizerContext) -> None:
        self.config = config
        self.cameras: dict[str, CameraModel] = dict(context.cameras)
        self.robots: list[MarkerMount] = list(context.robots)
        self._by_id = {m.marker_id: m for m in self.robots}
        ids = sorted(self._by_id)
        full = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY)
        self._ids = np.asarray(ids, dtype=np.int64)
        self._detector: cv2.aruco.ArucoDetector | None = None
        if ids:  # only the fleet's codes: index i of this dictionary is marker id ids[i]
            dictionary = cv2.aruco.Dictionary(
                np.ascontiguousarray(full.bytesList[ids]), full.markerSize, full.maxCorrectionBits
            )
            params = cv2.aruco.DetectorParameters()
            params.minMarkerPerimeterRate = 0.02
            params.perspectiveRemovePixelPerCell = 8
            params.cornerRefinementMethod = REFINEMENTS[config.corner_refinement]
            self._detector = cv2.aruco.ArucoDetector(dictionary, params)
        self._tracks: dict[str, _Track] = {}
        self.commands: dict[str, tuple[int, float, float]] = {}  # kept, not used by the filter

    # ------------------------------------------------------------------------ the protocol
    def observe(self, t_ns: int, frames: Mapping[str, CameraFrame]) -> None:
        """Detect in every frame (in the order given), fuse per robot, update its filter."""
        seen: dict[str, list[_Sighting]] = {}
        for camera_id, frame in frames.items():
            camera = self.cameras.get(camera_id)
            if camera is None or self._detector is None:
                continue
            gray = frame.gray
            if gray is None or gray.size == 0:
                continue
            for marker_id, corners in self._detect(gray):
                mount = self._by_id[marker_id]
                sighting = self._sighting(camera, corners, mount)
                if sighting is not None:
                    seen.setdefault(mount.namespace, []).append(sighting)
        for mount in self.robots:
            sightings = seen.get(mount.namespace)
            if sightings:
                self._fix(t_ns, mount, sightings)

    def command(self, t_ns: int, namespace: str, linear_mps: float, angular_rps: float) -> None:
        """Remember the command (the constant-velocity filter does not predict with it)."""
        self.commands[namespace] = (t_ns, float(linear_mps), float(angular_rps))

    def estimate(self, t_ns: int) -> dict[str, PoseEstimate]:
        """Every robot seen at least once, extrapolated at constant velocity to ``t_ns``."""
        out: dict[str, PoseEstimate] = {}
        cfg = self.config
        for mount in self.robots:
            track = self._tracks.get(mount.namespace)
            if track is None:
                continue
            p = track.predicted(max(t_ns, track.t_ns))
            age_s = (t_ns - track.last_fix_ns) / NS_PER_S
            yaw = float(p[2])
            speed = float(track.vel[0] * math.cos(yaw) + track.vel[1] * math.sin(yaw))
            # the fix's scatter, growing while it coasts (1 m/s^2, 1 rad/s^2 of unknown acceleration)
            grow = 0.5 * max(age_s, 0.0) ** 2
            var_xy = track.sigma**2 + grow**2
            var_yaw = track.sigma_yaw**2 + grow**2
            out[mount.namespace] = PoseEstimate(
                namespace=mount.namespace,
                stamp_ns=t_ns,
                x_m=float(p[0]),
                y_m=float(p[1]),
                yaw_rad=yaw,
                speed_mps=speed,
                yaw_rate_rps=float(track.vel[2]),
                covariance=np.diag([var_xy, var_xy, var_yaw]),
                last_fix_ns=track.last_fix_ns,
                observed=age_s <= cfg.unobserved_timeout_s,
                valid=age_s <= cfg.lost_timeout_s,
                cameras=track.cameras,
            )
        return out

    # ------------------------------------------------------------------------- the steps
    def _detect(self, gray: NDArray[np.uint8]) -> list[tuple[int, NDArray[np.float64]]]:
        """(marker id, corners (4, 2) TL TR BR BL in distorted pixels) of the fleet's markers."""
        assert self._detector is not None
        corners, idx, _ = self._detector.detectMarkers(gray)
        if idx is None:
            return []
        found = [
            (int(self._ids[i]), np.asarray(c, dtype=np.float64).reshape(4, 2))
            for c, i in zip(corners, idx.ravel())
        ]
        return sorted(found, key=lambda f: (f[0], float(f[1][0, 0]), float(f[1][0, 1])))

    def _sighting(
        self, camera: CameraModel, corners: NDArray[np.float64], mount: MarkerMount
    ) -> _Sighting | None:
        side_px = float(np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)))
        if side_px < self.config.min_side_px:
            return None
        xy, ok = camera.undistort_pixels(corners)  # ideal normalized image coordinates
        if not ok.all():
            return None
        h = np.concatenate([xy, np.ones((4, 1))], axis=1)
        # the square's centre: where its diagonals TL-BR and TR-BL cross (homogeneous lines)
        centre = np.cross(np.cross(h[0], h[2]), np.cross(h[1], h[3]))
        if abs(centre[2]) < 1e-12:
            return None
        rays = np.vstack([centre / centre[2], h])  # centre, TL, TR, BR, BL; (x, y, 1) in the camera
        points = _on_plane(camera, rays, mount.height_m)
        if points is None:
            return None
        c, tl, tr, br, bl = points
        ax = (tr - tl) + (br - bl)  # marker x
        ay = (tl - bl) + (tr - br)  # marker y; turned by -90 degrees it is along x too
        na, nb = math.hypot(*ax), math.hypot(*ay)
        if na == 0.0 or nb == 0.0:
            return None
        vx, vy = ax[0] / na + ay[1] / nb, ax[1] / na - ay[0] / nb
        return _Sighting(camera.camera_id, float(c[0]), float(c[1]), math.atan2(vy, vx), side_px)

    def _fix(self, t_ns: int, mount: MarkerMount, sightings: list[_Sighting]) -> None:
        w = np.array([s.side_px**2 for s in sightings])
        mx = float(np.dot(w, [s.x_m for s in sightings]) / w.sum())
        my = float(np.dot(w, [s.y_m for s in sightings]) / w.sum())
        yaws = np.array([s.yaw_rad for s in sightings])
        yaw = float(math.atan2(float(np.dot(w, np.sin(yaws))), float(np.dot(w, np.cos(yaws)))))
        # from the marker's centre to base_link (the marker is mounted axis-aligned, offset)
        ox, oy = mount.offset_xy_m
        cy, sy = math.cos(yaw), math.sin(yaw)
        z = (mx - (cy * ox - sy * oy), my - (sy * ox + cy * oy), yaw)
        # a quarter pixel at the marker's corners, fewer or smaller views: more scatter (x, y and yaw)
        sigma_xy = 0.25 * mount.size_m / float(np.sqrt(w.sum()))
        sigma = (sigma_xy, 2.0 * sigma_xy / mount.size_m)
        cameras = tuple(s.camera_id for s in sightings)
        track = self._tracks.get(mount.namespace)
        if track is None:
            self._tracks[mount.namespace] = _Track(t_ns, z, cameras, sigma)
        elif (t_ns - track.last_fix_ns) / NS_PER_S > self.config.lost_timeout_s:
            track.reset(t_ns, z, cameras, sigma)
        else:
            track.update(t_ns, z, cameras, sigma, self.config)


def _on_plane(camera: CameraModel, rays_cam: NDArray[np.float64], z_m: float) -> NDArray[np.float64] | None:
    """(x, y) where camera rays (N, 3) meet the world plane z = ``z_m``; None if one misses it."""
    wc = camera.world_from_camera
    rays = rays_cam @ wc.rotation.T
    origin = wc.translation
    dz = rays[:, 2]
    if np.any(dz == 0.0):
        return None
    s = (z_m - origin[2]) / dz
    if not np.all(np.isfinite(s) & (s > 0.0)):
        return None
    return origin[:2] + s[:, None] * rays[:, :2]


def _wrap(angle: float) -> float:
    return float(math.atan2(math.sin(angle), math.cos(angle)))
