"""Camera-based positions of people (who carry no marker): detect, fuse, track.

Data flow per camera tick::

    colour image per camera (people.detector=rgb, the default)
        |  |image - plate| (plate: the empty warehouse, gain-normalized per colour channel)
        |  minus each robot's body box (its estimated pose, footprint and height, projected)
        v
    person mask per camera  <-- or: segmentation image, class humanoid (53)
        |                        (people.detector=segmentation_oracle: the upper bound)
        v
    connected blobs (cv2); each blob's pixels -> rays (camera model, with distortion) -> floor z = 0
        v
    foot point: the blob's floor point nearest the camera's nadir (the body above the feet
        projects further out), moved one body radius outwards; a blob whose floor projection is
        much shorter than a whole person's would be (legs or head hidden behind a shelf, cut by
        the image border, or a low object: a box, a distractor) is dropped --> detections
        v
    fuse across cameras (greedy clusters) --> positions (recorded on /people/detections)
        v
    PersonTracker (constant-velocity Kalman filter per track) --> people at every control tick

The RGB detector reads the colour image only (no labels, no depth); the oracle reads the rendered
segmentation, so it sees every visible person and nothing else: the suites compare the two
(benchmarks/people.py, docs/safety.md). Both see only what a camera sees (no person outside
coverage or behind a shelf), and positions come from the camera models, never from ground truth.
Pure numpy/OpenCV.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.background import AdaptiveBackground, background_dir, read_plate
from simlan_data.algorithms.safety import Mover
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel

log = logging.getLogger(__name__)

HUMANOID_LABEL = 53
MISMATCH_SHARE = 0.2  # a first frame this much foreground: the plate shows another scene
WALK_MPS = 0.3  # a track this fast for WALK_UPDATES updates in a row has walked: a person, not
WALK_UPDATES = 5  # clutter (whose track may hop once between blobs, then stands)
RGB, ORACLE = "rgb", "segmentation_oracle"
DETECTORS = (RGB, ORACLE)
Footprint = tuple[float, float, float, float]  # x0, x1, y0, y1 in base_link
Pose2D = tuple[float, float, float]  # x, y, yaw in map


@dataclass
class PeopleParams:
    """Person detection from the cameras (the run's ``people`` section; the replay reads the recorded one)."""

    enabled: bool = True
    detector: str = RGB  # rgb: colour images against background plates | segmentation_oracle:
    # the rendered segmentation (an upper bound, not a detector)
    background: str = "gpss_960x540"  # rgb: plates (a folder of <camera_id>.jpg|png, or a packaged name)
    threshold: int = 30  # rgb: foreground where a colour channel differs more from the plate (0..255)
    robot_height_m: float = 2.2  # rgb: a robot's body box (footprint, this tall) is not a person
    robot_margin_m: float = 0.25  # rgb: the box grown by this (its pose is a control tick old)
    absorb_frames: int = 5  # rgb: foreground unchanged for this many frames of a camera joins its
    # background (a recoloured shelf, a sunlit patch, a moved box), except where robots or people
    # who walked within protect_s are; 0: the plate alone
    protect_s: float = 10.0  # rgb: a person who stands still longer joins the background (lost);
    # bounds how long a ghost (an absorbed person who left, on a floor unlike the plate) lasts
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
        if self.detector not in DETECTORS:
            raise ConfigError.invalid(
                "people.detector", self.detector, f"known: {', '.join(DETECTORS)}", "use people.detector=rgb"
            )
        rgb_keys = ("threshold", "robot_height_m", "robot_margin_m", "absorb_frames", "protect_s")
        if (
            not 0 < self.threshold < 255
            or self.robot_height_m <= 0
            or self.robot_margin_m < 0
            or not 0 <= self.absorb_frames <= 250
            or self.protect_s < 0
        ):
            raise ConfigError.invalid(
                "people",
                {k: getattr(self, k) for k in rgb_keys},
                "threshold within 1..254, robot_height_m > 0, robot_margin_m >= 0, absorb_frames within 0..250, protect_s >= 0",
                "use the defaults",
            )
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


def segmentation_mask(labels: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """The oracle's person mask: the rendered humanoid class."""
    return (labels == HUMANOID_LABEL).astype(np.uint8)


def load_person_plates(name: str, cameras: Mapping[str, CameraModel]) -> dict[str, NDArray[np.uint8]]:
    """The background plates ``name`` has for ``cameras``, at their resolution (a camera without
    one is left out: its first frame becomes its background, see ``PersonDetector.rgb_mask``)."""
    folder = background_dir(name)
    plates = {}
    for cid, cam in cameras.items():
        plate = read_plate(folder, cid, cam.width, cam.height)
        if plate is not None:
            plates[cid] = plate
    return plates


class PersonDetector:
    """Blobs of a person mask per camera -> floor positions. The mask comes from the colour image
    (``rgb``: foreground against the plate, robots' boxes removed) or from the segmentation
    (``segmentation_oracle``)."""

    def __init__(
        self,
        cameras: Mapping[str, CameraModel],
        params: PeopleParams | None = None,
        robots: Mapping[str, Footprint] | None = None,
    ) -> None:
        self.cameras = dict(cameras)
        self.params = params or PeopleParams()
        self.robots = dict(robots or {})  # robot namespace -> footprint (rgb: removed from the mask)
        plates = (
            load_person_plates(self.params.background, self.cameras) if self.params.detector == RGB else {}
        )
        p = self.params
        self.backgrounds = {
            cid: AdaptiveBackground(plate, p.threshold, p.absorb_frames) for cid, plate in plates.items()
        }
        self._checked: set[str] = set()  # cameras whose first frame was compared with the plate

    def detect(
        self,
        camera_id: str,
        *,
        labels: NDArray[np.uint8] | None = None,
        bgr: NDArray[np.uint8] | None = None,
        robot_poses: Mapping[str, Pose2D] | None = None,
        people_xy: Sequence[tuple[float, float]] = (),
    ) -> list[PersonDetection]:
        """One camera's people, from the input the detector reads (none given: none found).
        ``robot_poses``: where the robots are believed (rgb: removed); ``people_xy``: people
        being tracked (rgb: never absorbed into the background)."""
        if self.params.detector == ORACLE:
            return [] if labels is None else self.detect_mask(camera_id, segmentation_mask(labels))
        if bgr is None:
            return []
        mask = self.rgb_mask(camera_id, bgr, robot_poses or {}, people_xy)
        if camera_id not in self._checked:  # once per camera: plates of another scene?
            self._checked.add(camera_id)
            share = float(mask.mean())
            if share > MISMATCH_SHARE:
                log.warning(
                    "people.background: camera %s differs from its plate in %.0f %% of its pixels (plates of "
                    "another world or fidelity?): make plates of this scene or use "
                    "people.detector=segmentation_oracle (docs/safety.md)",
                    camera_id,
                    100 * share,
                )
        return self.detect_mask(camera_id, mask)

    def rgb_mask(
        self,
        camera_id: str,
        bgr: NDArray[np.uint8],
        robot_poses: Mapping[str, Pose2D],
        people_xy: Sequence[tuple[float, float]] = (),
    ) -> NDArray[np.uint8]:
        """Foreground against the camera's background, less what the robots at ``robot_poses``
        cover; neither they nor the people at ``people_xy`` are absorbed into the background."""
        p, cam = self.params, self.cameras[camera_id]
        robots = np.zeros(bgr.shape[:2], np.uint8)
        for ns, pose in sorted(robot_poses.items()):
            footprint = self.robots.get(ns)
            if (
                footprint is not None
                and (hull := self._box_hull(cam, footprint, pose, p.robot_height_m)) is not None
            ):
                cv2.fillConvexPoly(robots, hull, 1)
        protected = robots.copy()
        r = p.radius_m
        for x, y in people_xy:
            if (hull := self._box_hull(cam, (-r, r, -r, r), (x, y, 0.0), p.height_m + 0.2)) is not None:
                cv2.fillConvexPoly(protected, hull, 1)
        if camera_id not in self.backgrounds:  # no plate (another camera set): its first frame
            self._checked.add(camera_id)  # (not compared with itself)
            log.info(
                "people: camera %s has no plate in people.background=%s: its first frame is its background "
                "(what stands there then is found once it moves)",
                camera_id,
                p.background,
            )
            self.backgrounds[camera_id] = AdaptiveBackground(bgr.copy(), p.threshold, p.absorb_frames)
        mask = self.backgrounds[camera_id].foreground(bgr, protected)
        mask[robots > 0] = 0
        return mask

    def _box_hull(
        self, cam: CameraModel, footprint: Footprint, pose: Pose2D, height_m: float
    ) -> NDArray[np.int32] | None:
        """The image outline (convex hull, pixels) of a box on the floor (``footprint`` at ``pose``
        grown by ``robot_margin_m``, ``height_m`` tall), or None if it lies behind the camera."""
        m = self.params.robot_margin_m
        x0, x1, y0, y1 = footprint
        # corners and edge midpoints: the lens bends the box's edges
        gx, gy, gz = np.meshgrid(
            np.linspace(x0 - m, x1 + m, 3),
            np.linspace(y0 - m, y1 + m, 3),
            np.linspace(0.0, height_m, 3),
        )
        c, s = np.cos(pose[2]), np.sin(pose[2])
        xs, ys = gx.ravel(), gy.ravel()
        pts = np.stack([pose[0] + c * xs - s * ys, pose[1] + s * xs + c * ys, gz.ravel()], axis=1)
        uv, front = cam.project(pts)
        if not front.any():
            return None
        uv = np.clip(uv[front], -1e5, 1e5)
        return np.asarray(cv2.convexHull(np.round(uv).astype(np.int32)), dtype=np.int32)

    def detect_mask(self, camera_id: str, mask: NDArray[np.uint8]) -> list[PersonDetection]:
        """The people in one camera's person mask (1: person pixel)."""
        p = self.params
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
            if x <= 0 or y <= 0 or x + w >= mask.shape[1] or y + h >= mask.shape[0]:
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
    walking: int = 0  # updates in a row at WALK_MPS or faster
    walked_ns: int | None = None  # the last update at which it had walked WALK_UPDATES in a row


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
            tr.walking = tr.walking + 1 if np.hypot(tr.x[2], tr.x[3]) >= WALK_MPS else 0
            if tr.walking >= WALK_UPDATES:
                tr.walked_ns = t_ns
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

    def walked(self, t_ns: int) -> list[tuple[float, float]]:
        """Where the tracks that walked (WALK_MPS or faster for WALK_UPDATES updates in a row)
        within ``protect_s`` before ``t_ns`` were last updated: people, not clutter (the RGB
        detector does not absorb them into its background while they stand)."""
        horizon = round(self.params.protect_s * NS_PER_S)
        return [
            (float(tr.x[0]), float(tr.x[1]))
            for tr in self._tracks
            if tr.walked_ns is not None and t_ns - tr.walked_ns <= horizon
        ]

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
