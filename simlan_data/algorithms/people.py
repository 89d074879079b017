"""Camera-based positions of people (who carry no marker): detect, fuse, track.

Data flow per camera tick::

    segmentation image per camera --class humanoid (53)--> connected blobs (cv2)
        |  each blob's pixels -> rays (camera model, with distortion) -> floor plane z = 0
        v
    foot point: the blob's floor point nearest the camera's nadir (the body above the feet
        projects further out), moved one body radius outwards; a blob whose floor projection is
        much shorter than a whole person's would be (legs or head hidden behind a shelf, cut by
        the image border) is dropped: its foot point would be wrong --> detections per camera
        v
    fuse across cameras (greedy clusters) --> positions (recorded on /people/detections)
        v
    PersonTracker (constant-velocity Kalman filter per track) --> people at every control tick

The segmentation image stands in for a person detector: it sees only what a camera sees (no
person outside coverage or behind a shelf), and the position comes from the camera models, never
from ground truth. Pure numpy/OpenCV.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.safety import Mover
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel

HUMANOID_LABEL = 53


@dataclass
class PeopleParams:
    """Person detection from the cameras (the run's ``people`` section; the replay reads the recorded one)."""

    enabled: bool = True
    min_pixels: int = 12  # smaller blobs are ignored
    max_pixels: int = 400  # pixels per blob used for the foot point (subsampled, deterministic)
    body_radius_m: float = 0.15  # feet edge -> body centre
    cluster_m: float = 0.8  # detections of several cameras closer than this are one person
    gate_m: float = 1.5  # a detection this close to a track's prediction updates it
    max_age_s: float = 1.0  # a track not seen for longer is dropped
    radius_m: float = 0.36  # bounding circle of a person (the humanoid footprint)
    height_m: float = 1.7  # a whole person's height, for the completeness check
    min_extent: float = 0.6  # a blob must span this share of a whole person's floor projection

    def __post_init__(self) -> None:
        if (
            self.min_pixels < 1
            or not 0 <= self.body_radius_m <= 1
            or self.cluster_m <= 0
            or self.max_age_s <= 0
        ):
            raise ConfigError.invalid(
                "people",
                dataclasses.asdict(self),
                "min_pixels >= 1, body_radius_m within 0..1, cluster_m and max_age_s > 0",
                "use the defaults",
            )


@dataclass(frozen=True)
class PersonDetection:
    camera_id: str
    x_m: float
    y_m: float
    pixels: int


class PersonDetector:
    """Blobs of the humanoid class in each camera's segmentation image -> floor positions."""

    def __init__(self, cameras: dict[str, CameraModel], params: PeopleParams | None = None) -> None:
        self.cameras = cameras
        self.params = params or PeopleParams()

    def detect(self, camera_id: str, labels: NDArray[np.uint8]) -> list[PersonDetection]:
        p = self.params
        mask = (labels == HUMANOID_LABEL).astype(np.uint8)
        if not mask.any():
            return []
        count, blobs, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        cam = self.cameras[camera_id]
        nadir = cam.position[:2]
        height = float(cam.position[2])
        out = []
        for i in range(1, count):
            area = int(stats[i, cv2.CC_STAT_AREA])
            if area < p.min_pixels:
                continue
            x, y, w, h = (
                int(stats[i, k])
                for k in (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT)
            )
            if x <= 0 or y <= 0 or x + w >= labels.shape[1] or y + h >= labels.shape[0]:
                continue  # cut by the image border
            vs, us = np.nonzero(blobs[y : y + h, x : x + w] == i)
            step = max(1, len(us) // p.max_pixels)
            uv = np.stack([us[::step] + x, vs[::step] + y], axis=1).astype(np.float64)
            floor, ok = cam.intersect_plane_z(uv, 0.0)
            if not ok.all():
                continue  # reaches into the lens's invalid border
            floor = floor[:, :2]
            d = np.linalg.norm(floor - nadir, axis=1)
            d_near, d_far = float(np.quantile(d, 0.05)), float(np.quantile(d, 0.95))
            near = floor[d <= d_near + 1e-9]
            foot = near.mean(axis=0)
            outward = floor.mean(axis=0) - nadir
            n = float(np.hypot(outward[0], outward[1]))
            centre = foot + (outward / n) * p.body_radius_m if n > 1e-6 else foot
            # a whole person of height h standing at D projects onto the floor from D to D*H/(H-h)
            dist = float(np.hypot(*(centre - nadir)))
            if height > p.height_m and dist > 1.0:
                whole = dist * p.height_m / (height - p.height_m)
                if d_far - d_near < p.min_extent * whole:
                    continue  # partly hidden: the lowest visible point need not be a foot
            out.append(PersonDetection(camera_id, float(centre[0]), float(centre[1]), area))
        return out


def fuse_people(detections: Sequence[PersonDetection], cluster_m: float) -> list[tuple[float, float]]:
    """One position per person: detections of different cameras closer than ``cluster_m`` merged
    (weighted by blob size), largest blobs first; deterministic."""
    order = sorted(detections, key=lambda d: (-d.pixels, d.camera_id, d.x_m, d.y_m))
    clusters: list[list[PersonDetection]] = []
    for det in order:
        for cluster in clusters:
            seed = cluster[0]
            if np.hypot(det.x_m - seed.x_m, det.y_m - seed.y_m) <= cluster_m and all(
                c.camera_id != det.camera_id for c in cluster
            ):
                cluster.append(det)
                break
        else:
            clusters.append([det])
    out = []
    for cluster in clusters:
        w = np.array([c.pixels for c in cluster], dtype=float)
        xy = np.array([[c.x_m, c.y_m] for c in cluster])
        x, y = (w @ xy) / w.sum()
        out.append((float(x), float(y)))
    return sorted(out)


@dataclass
class _Track:
    track_id: int
    x: NDArray[np.float64]  # x, y, vx, vy
    P: NDArray[np.float64]
    t_ns: int
    last_seen_ns: int
    hits: int = 1


@dataclass
class PersonTracker:
    """Constant-velocity Kalman filter per person, nearest-neighbour association."""

    params: PeopleParams = field(default_factory=PeopleParams)
    accel_noise_mps2: float = 1.0
    meas_sigma_m: float = 0.1
    _tracks: list[_Track] = field(default_factory=list)
    _next_id: int = 0

    def _predict(self, tr: _Track, t_ns: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        dt = (t_ns - tr.t_ns) / NS_PER_S
        if dt <= 0:
            return tr.x.copy(), tr.P.copy()
        F = np.eye(4)
        F[0, 2] = F[1, 3] = dt
        G = np.array([[0.5 * dt**2, 0], [0, 0.5 * dt**2], [dt, 0], [0, dt]])
        Q = G @ G.T * self.accel_noise_mps2**2
        return F @ tr.x, F @ tr.P @ F.T + Q

    def update(self, t_ns: int, positions: Sequence[tuple[float, float]]) -> None:
        """Fuse one camera tick's people positions (stamp of the images)."""
        p = self.params
        self._tracks = [tr for tr in self._tracks if (t_ns - tr.last_seen_ns) <= p.max_age_s * NS_PER_S]
        predicted = {tr.track_id: self._predict(tr, t_ns) for tr in self._tracks}
        pairs = sorted(
            (
                float(np.hypot(px - predicted[tr.track_id][0][0], py - predicted[tr.track_id][0][1])),
                i,
                tr.track_id,
            )
            for i, (px, py) in enumerate(positions)
            for tr in self._tracks
        )
        used_det: set[int] = set()
        used_tr: set[int] = set()
        by_id = {tr.track_id: tr for tr in self._tracks}
        R = np.eye(2) * self.meas_sigma_m**2
        H = np.eye(2, 4)
        for dist, i, tid in pairs:
            if dist > p.gate_m or i in used_det or tid in used_tr:
                continue
            used_det.add(i)
            used_tr.add(tid)
            x, P = predicted[tid]
            z = np.asarray(positions[i], dtype=float)
            S = H @ P @ H.T + R
            K = P @ H.T @ np.linalg.inv(S)
            tr = by_id[tid]
            tr.x = x + K @ (z - H @ x)
            tr.P = (np.eye(4) - K @ H) @ P
            tr.t_ns, tr.last_seen_ns = t_ns, t_ns
            tr.hits += 1
        for i, (px, py) in enumerate(positions):
            if i in used_det:
                continue
            self._tracks.append(
                _Track(
                    self._next_id,
                    np.array([px, py, 0.0, 0.0]),
                    np.diag([self.meas_sigma_m**2, self.meas_sigma_m**2, 1.0, 1.0]),
                    t_ns,
                    t_ns,
                )
            )
            self._next_id += 1

    def people(self, t_ns: int) -> list[Mover]:
        """Every tracked person predicted to ``t_ns``."""
        out = []
        for tr in self._tracks:
            if (t_ns - tr.last_seen_ns) > self.params.max_age_s * NS_PER_S:
                continue
            x, _ = self._predict(tr, t_ns)
            out.append(
                Mover(
                    f"person_{tr.track_id}",
                    float(x[0]),
                    float(x[1]),
                    float(x[2]),
                    float(x[3]),
                    self.params.radius_m,
                )
            )
        return out
