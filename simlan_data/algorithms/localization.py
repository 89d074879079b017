"""Camera-based localization of marker-carrying agents (GPSS): detect, fuse, filter.

Data flow per camera tick (live and replay run exactly this)::

    JPEG bytes per camera --search plan (tracked: regions around each predicted marker;
        |                   untracked agent: the full frame)--> decode (grey) -> ArUco detect
        v
    detections -> per-camera marker pose (ground constraint or PnP) -> fusion across cameras
        v
    fix (base_link pose in map, image stamp) --(processing delay)--> per-agent EKF (unicycle,
        constant velocity) --> estimate at every control tick: pose, covariance, age, observed

Pure numpy/OpenCV: no simulator, no file format.
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections import deque
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.localization_filter import PoseFix, UnicycleEKF
from simlan_data.algorithms.marker_refinement import refine_corners
from simlan_data.algorithms.markers import (
    POSE_METHODS,
    Detection,
    MarkerDetector,
    MarkerMount,
    MarkerObservation,
    fuse,
    marker_corners_in_marker_frame,
)
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel, distort_points
from simlan_data.geometry.rotations import wrap_angle
from simlan_data.geometry.transforms import Transform
from simlan_data.imaging.jpeg_regions import decode_gray_regions

Roi = tuple[int, int, int, int]
CORNER_METHODS = ("pattern", "contour")
# Search regions are planned from the tracks predicted at an image's stamp; images stamped within
# this of the instant last predicted share that prediction (cameras with their own clocks and
# delays: 11 EKF extrapolations a tick otherwise, for regions that move by well under a pixel:
# 10 ms at 2 m/s is 2 cm, under a pixel at 8 m; the regions' margins are roi_margin_px + 3 sigma)
PLAN_SHARE_NS = 10_000_000


def _decode_gray(data: NDArray[np.uint8] | None) -> NDArray[np.uint8]:
    """A whole JPEG decoded to grey."""
    if data is None:
        raise ValueError("an image search needs the JPEG bytes or a grey image")
    return np.asarray(cv2.imdecode(data, cv2.IMREAD_GRAYSCALE), dtype=np.uint8)


def _one_of(key: str, value: str, choices: Collection[str], default: str) -> None:
    """A choice key's value must be one of ``choices`` (the fix names ``default``)."""
    if value not in choices:
        raise ConfigError.invalid(key, value, f"expected one of {', '.join(choices)}", f"set {key}={default}")


@dataclass(frozen=True)
class LocalizerParams:
    method: str = "ground"  # ground (ray / marker-plane intersection) | pnp (IPPE_SQUARE)
    corners: str = "pattern"  # pattern (contour corners aligned to the whole marker pattern, ECC:
    # standing yaw within 0.25 deg) | contour (ArUco's contour fit alone: up to 0.9 deg of yaw per
    # camera near headings along the pixel grid, held while a robot stands; 2.5x less CPU per frame)
    unobserved_timeout_s: float = 0.5  # no fix for longer: the agent is unobserved
    lost_timeout_s: float = 1.5  # no fix for longer: estimate withheld, full-frame search
    processing_delay_s: float = 0.0  # image capture -> fix usable by the filter
    accel_noise_mps2: float = 0.25  # how far the robot strays from its commanded speed (m/s^2)
    yaw_accel_noise_rps2: float = 0.4  # and from its commanded yaw rate (rad/s^2)
    accel_mps2: float = 7.5  # how fast a robot reaches a new commanded speed where its marker
    # mount does not say (m/s^2; 0: at once). A robot told to stop brakes over v^2 / 2a: 6.7 cm
    # from 1 m/s for a pallet truck (7.5 m/s^2, measured); a filter that stops at once falls that
    # far behind and gates out the next fixes (docs/benchmarks/gpss.md)
    gate_sigma: float = 8.0  # fixes farther than this (Mahalanobis) from the prediction are outliers
    reset_after_rejected: int = 3  # so many outliers in a row: the filter is wrong (a robot stopped
    # by a collision), restart it from the next fix
    roi_margin_px: int = 24
    full_search_every: int = (
        5  # while an agent is untracked, search each camera's whole image every n-th frame (staggered)
    )
    min_side_px: float = 8.0  # smaller detections are too noisy to use
    bias_m: tuple[float, float] = (0.0, 0.0)  # fault injection: added to every fix

    def __post_init__(self) -> None:
        key = "algorithms.localizer."
        _one_of(key + "method", self.method, POSE_METHODS, "ground")
        _one_of(key + "corners", self.corners, CORNER_METHODS, "pattern")
        if not self.unobserved_timeout_s > 0:
            raise ConfigError.invalid(
                key + "unobserved_timeout_s", self.unobserved_timeout_s, "must be > 0", "use 0.5"
            )
        if self.lost_timeout_s < self.unobserved_timeout_s:
            raise ConfigError.invalid(
                key + "lost_timeout_s",
                self.lost_timeout_s,
                f"must be >= {key}unobserved_timeout_s",
                "use 1.5",
            )
        if not 0 <= self.processing_delay_s <= 5:
            raise ConfigError.invalid(
                key + "processing_delay_s", self.processing_delay_s, "must be within 0..5 s", "use 0"
            )
        if not self.accel_mps2 >= 0:
            raise ConfigError.invalid(
                key + "accel_mps2", self.accel_mps2, "must be >= 0 (0: at once)", "use 7.5"
            )
        if len(self.bias_m) != 2:
            raise ConfigError.invalid(
                key + "bias_m", list(self.bias_m), "expected [x_m, y_m]", "use [0.0, 0.0]"
            )
        object.__setattr__(self, "bias_m", (float(self.bias_m[0]), float(self.bias_m[1])))


@dataclass(frozen=True)
class PoseEstimate:
    """The filter's pose at a control tick."""

    namespace: str
    stamp_ns: int
    x_m: float
    y_m: float
    yaw_rad: float
    speed_mps: float
    yaw_rate_rps: float
    covariance: NDArray[np.float64]  # 3x3 over (x, y, yaw)
    last_fix_ns: int
    observed: bool  # a fix within unobserved_timeout_s
    valid: bool  # a fix within lost_timeout_s
    cameras: tuple[str, ...] = ()  # cameras of the newest fix

    @property
    def age_s(self) -> float:
        """Time since the newest fix's images were taken; never below 0: a camera whose clock runs
        ahead (sensors.timing) stamps its images in the future, and the fix is then just new
        (a negative age would read as "never seen", the safety layer's sentinel)."""
        return max(0.0, (self.stamp_ns - self.last_fix_ns) / NS_PER_S)


@dataclass
class _Track:
    mount: MarkerMount
    ekf: UnicycleEKF
    last_fix_ns: int | None = None
    last_cameras: tuple[str, ...] = ()
    fixes: int = 0
    rejected: int = 0
    rejected_in_row: int = 0


class ImageSearch(NamedTuple):
    """What the localizer found in one camera image (see :meth:`Localizer.detect`)."""

    detections: list[Detection]  # every marker of the fleet found, sorted by id
    observations: list[MarkerObservation]  # their poses as this camera sees them (the usable ones)
    seconds: float  # time spent: decoding, searching, poses


@dataclass(frozen=True)
class _TickPredictions:
    untracked: bool  # some agent is not tracked (full searches are due)
    tracks: list[tuple[MarkerMount, NDArray[np.float64], Transform]]  # mount, covariance, marker pose
    corners: NDArray[np.float64]  # (4 x tracks, 3) their marker corners in map


@dataclass(frozen=True)
class _CameraArrays:
    """The cameras' poses and limits as arrays, in ``Localizer.cameras`` order (for planning)."""

    R: NDArray[np.float64]  # (C, 3, 3) camera from world
    t: NDArray[np.float64]  # (C, 3)
    position: NDArray[np.float64]  # (C, 3) centres in the world
    valid_radius: NDArray[np.float64]  # (C,)
    focal: NDArray[np.float64]  # (C, 2) fx, fy
    centre: NDArray[np.float64]  # (C, 2) cx, cy
    distortion: NDArray[np.float64]  # (C, 5) k1, k2, p1, p2, k3
    size: NDArray[np.float64]  # (C, 2) width, height


@dataclass
class FrameTiming:
    """Processing time of one camera image by the localizer."""

    camera_id: str
    stamp_ns: int
    mode: str  # "full" or "roi"
    seconds: float
    detections: int


@dataclass
class Localizer:
    """Localize agents from their markers in the images of fixed, calibrated cameras."""

    cameras: dict[str, CameraModel]
    mounts: list[MarkerMount]
    params: LocalizerParams = field(default_factory=LocalizerParams)

    def __post_init__(self) -> None:
        if self.params.method not in POSE_METHODS:
            raise ValueError(
                f"unknown localization method {self.params.method!r}; use one of {', '.join(POSE_METHODS)}"
            )
        self._pose = POSE_METHODS[self.params.method]
        self._by_marker = {m.marker_id: m for m in self.mounts}
        self._tracks = {
            m.namespace: _Track(
                m,
                UnicycleEKF(
                    self.params.accel_noise_mps2,
                    self.params.yaw_accel_noise_rps2,
                    self.params.accel_mps2 if m.accel_mps2 is None else m.accel_mps2,
                ),
            )
            for m in self.mounts
        }
        self._detector = MarkerDetector(marker_ids=sorted(self._by_marker))
        self._local = threading.local()  # a detector per worker thread (see detect)
        self._prediction_cache: dict[tuple[str, int], tuple] = {}
        self._tick_cache: dict[int, _TickPredictions] = {}
        self._slots = {c: i for i, c in enumerate(self.cameras)}
        self._geo: _CameraArrays | None = None
        self._frame_obs: list[MarkerObservation] = []
        self._frame_stamps: dict[str, int] = {}  # camera -> the stamp of its image in this frame set
        self._pending: deque[tuple[int, PoseFix]] = deque()  # (usable from, fix)
        self._full_cache: dict[tuple[str, bytes], tuple[list[Detection], list[MarkerObservation]]] = {}
        self._frames_seen: dict[str, int] = {}
        self._frame_index: dict[tuple[str, int], int] = {}
        self.timings: list[FrameTiming] = []
        self.last_detections: dict[str, list[Detection]] = {}
        self.last_observations: list[MarkerObservation] = []

    # ---------------------------------------------------------------------------- searching
    def _tracked(self, track: _Track, t_ns: int) -> bool:
        return (
            track.last_fix_ns is not None
            and (t_ns - track.last_fix_ns) <= self.params.lost_timeout_s * NS_PER_S
        )

    def search_plan(self, t_ns: int, camera_id: str) -> str | list[Roi]:
        """Where to search this camera's image at ``t_ns``.

        Regions around every tracked agent's predicted marker; the whole image if an agent is not
        tracked, on the first frame and then every ``full_search_every``-th frame of each camera
        (staggered across cameras, so that a lost or hidden robot costs a few full searches a
        second, not all of them).
        """
        return self.search_plans(t_ns, [camera_id])[0]

    def search_plans(self, t_ns: int, camera_ids: list[str]) -> list[str | list[Roi]]:
        """:meth:`search_plan` of several cameras' images of one instant, computed together
        (every tracked marker into every camera in one array; a replay plans a frame set so)."""
        predicted = self._tick_predictions(t_ns)
        every = self.params.full_search_every
        plans: list[str | list[Roi]] = []
        todo = []
        for cid in camera_ids:
            frame = self._frame_of(cid, t_ns)
            if predicted.untracked and (frame == 0 or (frame + self._slots[cid]) % every == 0):
                plans.append("full")
            else:
                plans.append([])
                if predicted.tracks:
                    todo.append(len(plans) - 1)
        if not todo:
            return plans
        # every tracked marker's corners into every camera at once; the ones fully in front and
        # inside the valid radius distorted to pixels (cheap rejection first)
        geo = self._camera_arrays()
        cams = np.array([self._slots[camera_ids[i]] for i in todo])
        n = len(predicted.tracks)
        pc = np.einsum("cij,pj->cpi", geo.R[cams], predicted.corners) + geo.t[cams][:, None, :]
        pc = pc.reshape(len(cams), n, 4, 3)
        front = (pc[..., 2] > 1e-9).all(axis=2)
        z = np.where(pc[..., 2:3] > 1e-9, pc[..., 2:3], 1.0)
        xy = pc[..., :2] / z
        seen = front & (np.hypot(xy[..., 0], xy[..., 1]) <= geo.valid_radius[cams][:, None, None]).all(axis=2)
        if not seen.any():
            return plans
        P = np.stack([P for _, P, _ in predicted.tracks])
        size = np.array([m.size_m for m, _, _ in predicted.tracks])
        sigma_m = np.sqrt(np.maximum(P[:, 0, 0], P[:, 1, 1])) + 0.5 * size * np.sqrt(P[:, 2, 2])
        markers = np.stack([marker.translation for _, _, marker in predicted.tracks])
        rng = np.linalg.norm(markers[None] - geo.position[cams][:, None], axis=2)  # (cameras, tracks)
        margin = self.params.roi_margin_px + 3.0 * sigma_m[None] * geo.focal[cams][:, :1] / np.maximum(
            rng, 1e-3
        )
        # the corners distorted to pixels (the camera model's radial + tangential terms, as
        # cv2.projectPoints; pixels only bound integer regions here), then each region's bounds
        xy = np.where(seen[..., None, None], xy, 0.0)
        d = geo.distortion[cams][:, None, None, :]  # (cameras, 1, 1, k1 k2 p1 p2 k3)
        xd, yd = distort_points(xy[..., 0], xy[..., 1], *(d[..., i] for i in range(5)))
        f, c = geo.focal[cams][:, None, None, :], geo.centre[cams][:, None, None, :]
        uv = np.stack([xd, yd], axis=-1) * f + c  # (cameras, tracks, 4, 2)
        lo = np.maximum(np.floor(uv.min(axis=2) - margin[..., None]), 0.0)
        hi = np.minimum(np.ceil(uv.max(axis=2) + margin[..., None]), geo.size[cams][:, None, :])
        keep = seen & ((hi - lo) >= 8).all(axis=2)
        boxes = np.concatenate([lo, hi], axis=2).astype(int)
        for row, k in zip(*(a.tolist() for a in np.nonzero(keep))):
            plan = plans[todo[row]]
            assert isinstance(plan, list)
            plan.append(tuple(boxes[row, k].tolist()))
        return plans

    def _frame_of(self, camera_id: str, t_ns: int) -> int:
        """This camera's frame number at ``t_ns`` (counted on first sight of each instant)."""
        frame = self._frame_index.get((camera_id, t_ns))
        if frame is None:
            frame = self._frames_seen.get(camera_id, 0)
            self._frames_seen[camera_id] = frame + 1
            self._frame_index = {k: v for k, v in self._frame_index.items() if k[0] != camera_id}
            self._frame_index[(camera_id, t_ns)] = frame
        return frame

    def _camera_arrays(self) -> _CameraArrays:
        if self._geo is None:
            cams = list(self.cameras.values())
            self._geo = _CameraArrays(
                R=np.stack([c.camera_from_world.rotation for c in cams]),
                t=np.stack([c.camera_from_world.translation for c in cams]),
                position=np.stack([c.position for c in cams]),
                valid_radius=np.array([c.valid_radius for c in cams]),
                focal=np.array([[c.K[0, 0], c.K[1, 1]] for c in cams]),
                centre=np.array([[c.K[0, 2], c.K[1, 2]] for c in cams]),
                distortion=np.array([np.ravel(c.D)[:5] for c in cams], dtype=float),  # as CameraModel
                size=np.array([[c.width, c.height] for c in cams], dtype=float),
            )
        return self._geo

    def _tick_predictions(self, t_ns: int) -> _TickPredictions:
        """Every tracked agent's predicted marker at ``t_ns`` (memoized for the cameras of one
        tick, also those stamped within ``PLAN_SHARE_NS``; cleared whenever the filter changes)."""
        hit = self._tick_cache.get(t_ns)
        if hit is None:  # the last instant predicted, if this image is within PLAN_SHARE_NS of it
            hit = next((v for k, v in self._tick_cache.items() if abs(k - t_ns) <= PLAN_SHARE_NS), None)
        if hit is None:
            tracks, corners = [], []
            for tr in self._tracks.values():
                if self._tracked(tr, t_ns):
                    _, P, marker, c = self._predicted_marker(tr, t_ns)
                    tracks.append((tr.mount, P, marker))
                    corners.append(c)
            hit = _TickPredictions(
                untracked=len(tracks) < len(self._tracks),
                tracks=tracks,
                corners=np.concatenate(corners) if corners else np.zeros((0, 3)),
            )
            self._tick_cache = {t_ns: hit}
        return hit

    def _predicted_marker(
        self, track: _Track, t_ns: int
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], Transform, NDArray[np.float64]]:
        """EKF state and covariance at ``t_ns``, the marker's pose and corners (map); memoized for
        the cameras of one tick (cleared whenever the filter changes)."""
        key = (track.mount.namespace, t_ns)
        hit = self._prediction_cache.get(key)
        if hit is None:
            x, P = track.ekf.at(t_ns)
            m = track.mount
            base = Transform.from_pose2d(float(x[0]), float(x[1]), float(x[2]))
            marker = base @ Transform.from_pose2d(m.offset_xy_m[0], m.offset_xy_m[1], 0.0, m.height_m)
            hit = (x, P, marker, marker.apply(marker_corners_in_marker_frame(m.size_m)))
            self._prediction_cache[key] = hit
        return hit

    def process_image(
        self, t_ns: int, camera_id: str, jpeg: bytes | None = None, gray: NDArray[np.uint8] | None = None
    ) -> list[Detection]:
        """Search one camera's image (JPEG bytes or a grey image) as planned; keep its observations."""
        plan = self.search_plan(t_ns, camera_id)
        if not plan:
            return []
        found = self.detect(camera_id, plan, jpeg=jpeg, gray=gray)
        self.observe_search(t_ns, camera_id, plan, found)
        return found.detections

    def detect(
        self,
        camera_id: str,
        plan: str | list[Roi],
        *,
        jpeg: bytes | NDArray[np.uint8] | None = None,
        gray: NDArray[np.uint8] | None = None,
    ) -> ImageSearch:
        """The image part of :meth:`process_image`: markers found as planned, their poses seen
        from this camera, and the seconds spent.

        A pure function of the image and the plan, safe to run on worker threads (each thread
        has its own detector; OpenCV releases the GIL) while the simulation renders on, or
        while a replay reads on.
        """
        t0 = time.perf_counter()
        data = None if jpeg is None else np.frombuffer(jpeg, dtype=np.uint8)
        key = (
            (camera_id, hashlib.blake2b(data.data, digest_size=16).digest())
            if (plan == "full" and data is not None)
            else None
        )
        cached = self._full_cache.get(key) if key is not None else None
        if cached is not None:
            return ImageSearch(cached[0], cached[1], time.perf_counter() - t0)
        detector = self._thread_detector()
        if isinstance(plan, str):  # "full"
            image = gray if gray is not None else _decode_gray(data)
            detections = [
                self._refined(camera_id, d, image, (0, 0)) for d in detector.detect(camera_id, image)
            ]
        else:
            # only the regions searched: same pixels as a whole decode (jpeg_regions), or None
            # for a JPEG without restart markers
            crops = decode_gray_regions(data, plan) if gray is None and data is not None else None
            if crops is None:
                whole = gray if gray is not None else _decode_gray(data)
                crops = [whole[v0:v1, u0:u1] for u0, v0, u1, v1 in plan]
            found: dict[int, Detection] = {}
            for roi, pixels in zip(plan, crops):
                for d in detector.detect_region(camera_id, pixels, (roi[0], roi[1])):
                    if d.marker_id not in found:
                        found[d.marker_id] = self._refined(camera_id, d, pixels, (roi[0], roi[1]))
            detections = [found[k] for k in sorted(found)]
        observations = self._poses(camera_id, detections)
        if key is not None:  # (a lost entry only costs a search again: the content is the same)
            self._full_cache = {k: v for k, v in self._full_cache.items() if k[0] != camera_id}
            self._full_cache[key] = (detections, observations)
        return ImageSearch(detections, observations, time.perf_counter() - t0)

    def _refined(
        self, camera_id: str, det: Detection, pixels: NDArray[np.uint8], origin: tuple[int, int]
    ) -> Detection:
        """``det`` with its corners aligned to the marker's pattern (``corners=pattern``; a
        marker of the fleet only: the others are not used)."""
        if self.params.corners != "pattern" or det.marker_id not in self._by_marker:
            return det
        return refine_corners(self.cameras[camera_id], det, pixels, origin)

    def _poses(self, camera_id: str, detections: list[Detection]) -> list[MarkerObservation]:
        """The usable marker poses of one camera's detections (known marker, valid, large enough)."""
        out = []
        for det in detections:
            mount = self._by_marker.get(det.marker_id)
            if mount is None:
                continue
            obs = self._pose(self.cameras[camera_id], det, mount)
            if obs is not None and obs.side_px >= self.params.min_side_px:
                out.append(obs)
        return out

    def _thread_detector(self) -> MarkerDetector:
        if threading.current_thread() is threading.main_thread():
            return self._detector
        detector: MarkerDetector | None = getattr(self._local, "detector", None)
        if detector is None:
            detector = self._local.detector = MarkerDetector(marker_ids=self._detector.marker_ids)
        return detector

    def observe_search(self, t_ns: int, camera_id: str, plan: str | list[Roi], found: ImageSearch) -> None:
        """The state part of :meth:`process_image`: this image's marker poses into the frame
        set's observations.

        Call in camera order (fusion sums in that order), with what :meth:`detect` returned for
        the same plan.
        """
        self._frame_obs.extend(found.observations)
        self._frame_stamps[camera_id] = t_ns
        self.last_detections[camera_id] = found.detections
        self.timings.append(
            FrameTiming(
                camera_id, t_ns, "full" if plan == "full" else "roi", found.seconds, len(found.detections)
            )
        )

    def close_frame(self, t_ns: int) -> list[PoseFix]:
        """Fuse the observations of this frame set into one fix per agent, stamped with the time
        its images say they were taken (the mean stamp of the cameras that saw the marker: with
        cameras on clocks of their own, sensors.timing, that is what a fix knows of its time)."""
        obs, self._frame_obs = self._frame_obs, []
        stamps, self._frame_stamps = self._frame_stamps, {}
        self.last_observations = obs
        fixes = []
        for marker_id in sorted({o.marker_id for o in obs}):
            mount = self._by_marker[marker_id]
            group = [o for o in obs if o.marker_id == marker_id]
            x, y, yaw, sxy, syaw = fuse(group)
            c, s = np.cos(yaw), np.sin(yaw)
            ox, oy = mount.offset_xy_m
            bx, by = self.params.bias_m
            seen = {o.camera_id for o in group}  # (a group is never empty)
            stamp = round(sum(stamps.get(cam, t_ns) for cam in seen) / len(seen))
            fix = PoseFix(
                mount.namespace,
                stamp,
                x - (c * ox - s * oy) + bx,
                y - (s * ox + c * oy) + by,
                yaw,
                sxy,
                syaw,
                tuple(sorted(o.camera_id for o in group)),
            )
            fixes.append(fix)
            self.queue_fix(t_ns, fix)
        return fixes

    def queue_fix(self, t_ns: int, fix: PoseFix) -> None:
        """Hand a fix of the camera tick ``t_ns`` to the filter: it is used from the first
        :meth:`estimate` at or after ``t_ns`` plus the processing delay (other localizers reuse
        this filter with fixes of their own)."""
        self._pending.append((t_ns + round(self.params.processing_delay_s * NS_PER_S), fix))

    # ----------------------------------------------------------------------------- filtering
    def estimate(self, t_ns: int) -> dict[str, PoseEstimate]:
        """Apply the fixes that are due, then every agent's pose at ``t_ns``."""
        self._prediction_cache.clear()
        self._tick_cache.clear()
        while self._pending and self._pending[0][0] <= t_ns:
            _, fix = self._pending.popleft()
            track = self._tracks[fix.namespace]
            if (
                track.last_fix_ns is None
                or not self._tracked(track, fix.stamp_ns)
                or track.rejected_in_row >= self.params.reset_after_rejected
            ):
                track.ekf.reset(fix)
            elif not track.ekf.update(fix, self.params.gate_sigma):
                track.rejected += 1
                track.rejected_in_row += 1
                continue
            track.rejected_in_row = 0
            track.last_fix_ns = fix.stamp_ns
            track.last_cameras = fix.cameras
            track.fixes += 1
        out = {}
        for ns, track in self._tracks.items():
            if track.last_fix_ns is None:
                continue
            x, P = track.ekf.at(t_ns)
            age = (t_ns - track.last_fix_ns) / NS_PER_S
            out[ns] = PoseEstimate(
                ns,
                t_ns,
                float(x[0]),
                float(x[1]),
                float(wrap_angle(x[2])),
                float(x[3]),
                float(x[4]),
                P[:3, :3].copy(),
                track.last_fix_ns,
                age <= self.params.unobserved_timeout_s,
                age <= self.params.lost_timeout_s,
                track.last_cameras,
            )
        return out

    @property
    def namespaces(self) -> list[str]:
        return list(self._tracks)

    def command(self, t_ns: int, namespace: str, linear_mps: float, angular_rps: float) -> None:
        """Tell the filter the velocity command a robot got at ``t_ns`` (used between fixes)."""
        track = self._tracks.get(namespace)
        if track is not None:
            self._prediction_cache.clear()
            self._tick_cache.clear()
            track.ekf.command(t_ns, linear_mps, angular_rps)

    def track_stats(self) -> dict[str, tuple[int, int]]:
        """Per agent: (fixes used, fixes rejected by the gate)."""
        return {ns: (t.fixes, t.rejected) for ns, t in self._tracks.items()}
