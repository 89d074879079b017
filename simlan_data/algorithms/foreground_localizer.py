"""A marker-free localizer (``foreground``): background subtraction, multi-view fusion, EKF.

RGB only: it reads the camera images and a background plate per camera (the empty warehouse as
each camera sees it; packaged for the GPSS cameras at 960x540), never a marker, depth or label.

Data flow per camera tick (live and replay run exactly this)::

    JPEG per camera --decode--> max over channels |image - plate| > threshold --> mask
        v
    per robot height h (the top of its body, from its mount): planes through the body
    (h x ``planes``), every camera's mask sampled at the cells of one grid on each plane (camera
    model, lens distortion included) --> per cell: cameras that see it, cameras that see
    foreground there --> occupied where enough agree, on every plane
        v
    blobs (connected columns) --> each robot the blob nearest its prediction (one blob per
    robot, Hungarian) --> the blob's centre
        v
    fix: base_link = centre - its offset in base_link (the mount's, or measured) turned by
    the yaw (measured from the robot's way while it drives, else turned on as commanded)
        --> the marker localizer's per-robot EKF (commands predict between fixes)

Identity: robots look alike, so each one is first found near where it starts
(``start_poses``: what GPSS's fleet knows of its parked robots) and then followed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from simlan_data.algorithms.background import background_dir, foreground_mask
from simlan_data.algorithms.localization import Localizer, LocalizerParams, PoseEstimate
from simlan_data.algorithms.localization_filter import PoseFix
from simlan_data.algorithms.markers import MarkerMount
from simlan_data.algorithms.roles import CameraFrame, LocalizerContext
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import wrap_angle

DEFAULT_BACKGROUND = "gpss_960x540"
KEY = "algorithms.localizer."
COARSE = 4  # the cells' pixels are projected on a grid this much coarser, then interpolated


@dataclass(frozen=True)
class ForegroundConfig(LocalizerParams):
    """The filter's keys are the marker localizer's (inherited: timeouts, noise, gate, delay,
    bias); its marker keys (method, corners, roi_margin_px, full_search_every, min_side_px)
    are unused here."""

    background: str = DEFAULT_BACKGROUND  # a folder of <camera_id>.jpg|png, or a packaged name
    threshold: int = 25  # a pixel is foreground where a colour channel differs more (0..255)
    cell_m: float = 0.04  # fusion grid cell
    min_cameras: int = 2  # an occupied cell is foreground in at least so many cameras (or in
    # every camera that sees it, where fewer do)
    min_fraction: float = 0.6  # and in at least this fraction of the cameras that see it
    min_area_m2: float = 0.04  # smaller blobs are noise
    gate_m: float = 1.0  # a robot takes the nearest blob within this of its prediction
    max_range_m: float = 14.0  # a camera's cells: floor points at most this far from under it
    heading_window_s: float = 0.6  # yaw is measured from the blob's way over this long
    heading_min_m: float = 0.15  # while it moved at least this far (else not measured)
    heading_min_mps: float = 0.3  # and drives at least this fast, as commanded
    sigma_yaw_rad: float = 0.1  # a measured yaw's uncertainty (and a start pose's)
    sigma_turned_rad: float = 0.3  # a yaw turned on as commanded from the last one measured
    sigma_xy_m: float = 0.03  # a fix's position uncertainty (1 sigma)
    merged_ratio: float = 1.6  # a blob this much larger than the robot's at its start: merged
    planes: tuple[float, ...] = (0.2, 0.5, 0.8)  # fusion planes, as fractions of a robot's height
    # (its mount's height_m: the top of its body)
    calibrate: bool = False  # where the blob's centre lies on the robot: the top of its body
    # (under its mount; False) or measured at the start pose (True: a start pose off by d, or a
    # start poorly covered by the cameras, shifts every estimate of it)
    start_poses: tuple[float, ...] = ()  # x, y, yaw per robot, in the robots' order
    # (agents.* order); empty: a single robot takes the largest blob

    def __post_init__(self) -> None:
        super().__post_init__()
        checks = [
            ("threshold", self.threshold, 0 < self.threshold < 255, "use 25"),
            ("cell_m", self.cell_m, 0.005 <= self.cell_m <= 0.5, "use 0.04"),
            ("min_cameras", self.min_cameras, self.min_cameras >= 1, "use 2"),
            ("min_fraction", self.min_fraction, 0 < self.min_fraction <= 1, "use 0.6"),
            ("gate_m", self.gate_m, self.gate_m > 0, "use 1.0"),
            ("sigma_xy_m", self.sigma_xy_m, self.sigma_xy_m > 0, "use 0.03"),
            (
                "start_poses",
                list(self.start_poses),
                len(self.start_poses) % 3 == 0,
                "give x, y, yaw per robot",
            ),
        ]
        for name, value, ok, fix in checks:
            if not ok:
                raise ConfigError.invalid(KEY + name, value, "out of range", fix)
        if not self.planes or not all(0 < f <= 1.5 for f in self.planes):
            raise ConfigError.invalid(
                KEY + "planes", list(self.planes), "fractions in (0, 1.5]", "use [0.2, 0.5, 0.8]"
            )
        object.__setattr__(self, "start_poses", tuple(float(v) for v in self.start_poses))
        object.__setattr__(self, "planes", tuple(float(v) for v in self.planes))


def load_plates(name: str, cameras: Mapping[str, CameraModel]) -> dict[str, NDArray[np.uint8]]:
    """Each camera's background plate (BGR); refused if missing or sized unlike the camera."""
    folder = background_dir(name)
    plates = {}
    for cid, cam in cameras.items():
        found = [p for p in (folder / f"{cid}.jpg", folder / f"{cid}.png") if p.is_file()]
        image = cv2.imread(str(found[0]), cv2.IMREAD_COLOR) if found else None
        if image is None:
            raise ConfigError.invalid(
                KEY + "background",
                name,
                f"no plate {cid}.jpg or .png in {folder}",
                "make one (docs/plugins.md)",
            )
        if image.shape[:2] != (cam.height, cam.width):
            raise ConfigError.invalid(
                KEY + "background",
                name,
                f"plate {cid} is {image.shape[1]}x{image.shape[0]}, the camera {cam.width}x{cam.height}",
                "use plates made at the cameras' size",
            )
        plates[cid] = np.asarray(image, dtype=np.uint8)
    return plates


@dataclass(frozen=True)
class _CameraCells:
    """Where one camera's pixels fall on the fusion grid at one height: a sub-rectangle of the
    grid (rows r0:r1, cols c0:c1) and, per cell there, the pixel (map_x, map_y; -1: unseen)."""

    r0: int
    c0: int
    map_x: NDArray[np.float32]
    map_y: NDArray[np.float32]
    seen: NDArray[np.uint8]


@dataclass(frozen=True)
class FusionGrid:
    """A floor grid lifted to z = ``z_m``: origin (x0, y0), cell size, shape (rows = y, cols = x)."""

    x0: float
    y0: float
    cell_m: float
    rows: int
    cols: int
    z_m: float

    @classmethod
    def covering(
        cls, cameras: Sequence[CameraModel], z_m: float, cell_m: float, max_range_m: float
    ) -> FusionGrid:
        """The grid over every camera's view of the plane z = ``z_m`` (image edges sampled)."""
        pts = []
        for cam in cameras:  # (far floor points: seen at a grazing angle, blurred and occluded)
            u = np.linspace(0, cam.width - 1, 33)
            v = np.linspace(0, cam.height - 1, 19)
            uv = np.stack(np.meshgrid(u, v), -1).reshape(-1, 2)
            xyz, ok = cam.intersect_plane_z(uv, z_m)
            pts.append(xyz[ok & (np.linalg.norm(xyz[:, :2] - cam.position[:2], axis=1) < max_range_m), :2])
        xy = np.concatenate(pts) if pts else np.zeros((1, 2))
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        cols, rows = (np.ceil((hi - lo) / cell_m).astype(int) + 1).tolist()
        return cls(float(lo[0]), float(lo[1]), cell_m, rows, cols, z_m)

    def cells_of(self, cam: CameraModel, plate: NDArray[np.uint8], max_range_m: float) -> _CameraCells | None:
        """Where ``cam`` sees the grid within ``max_range_m`` of the point under it (cells whose
        pixel lies in the image and not in the black margin of its plate), or None."""
        r_lo, c_lo = self.cell(float(cam.position[0]) - max_range_m, float(cam.position[1]) - max_range_m)
        r_hi, c_hi = self.cell(float(cam.position[0]) + max_range_m, float(cam.position[1]) + max_range_m)
        r0, c0 = max(0, int(r_lo)), max(0, int(c_lo))
        r1, c1 = min(self.rows, int(r_hi) + 1), min(self.cols, int(c_hi) + 1)
        if r1 <= r0 or c1 <= c0:
            return None
        # the pixel of every COARSE-th cell, bilinearly upsampled (the map is smooth: 1/16 of the
        # projections, within a tenth of a pixel)
        rc, cc = np.mgrid[r0 : r1 + COARSE : COARSE, c0 : c1 + COARSE : COARSE]
        x, y = self.xy(rc.ravel(), cc.ravel())
        uv, front = cam.project(np.stack([x, y, np.full(rc.size, self.z_m)], -1))
        coarse = np.where(front[:, None], uv, -1e4).astype(np.float32).reshape(*rc.shape, 2)
        size = (coarse.shape[1] * COARSE, coarse.shape[0] * COARSE)
        big = cv2.resize(coarse, size, interpolation=cv2.INTER_LINEAR)
        off = (COARSE - 1) / 2  # (resize samples pixel centres; the coarse grid's first cell is cell 0)
        rows = np.arange(r1 - r0) + off
        cols = np.arange(c1 - c0) + off
        fine = cv2.remap(
            big, *np.meshgrid(cols.astype(np.float32), rows.astype(np.float32)), cv2.INTER_LINEAR
        )
        r, c = np.mgrid[r0:r1, c0:c1]
        x, y = self.xy(r, c)
        ok = np.hypot(x - cam.position[0], y - cam.position[1]) < max_range_m
        u, v = fine[..., 0], fine[..., 1]
        ok &= (u >= 0) & (u <= cam.width - 1) & (v >= 0) & (v <= cam.height - 1)
        ui = np.clip(np.rint(u), 0, cam.width - 1).astype(int)
        vi = np.clip(np.rint(v), 0, cam.height - 1).astype(int)
        ok &= plate[vi, ui].max(axis=-1) > 8  # the lens's black margin is never seen
        if not ok.any():
            return None
        map_x = np.where(ok, u, -1).astype(np.float32)
        map_y = np.where(ok, v, -1).astype(np.float32)
        return _CameraCells(r0, c0, map_x, map_y, ok.astype(np.uint8))

    def xy(self, row: Any, col: Any) -> tuple[Any, Any]:
        """The map point of a (fractional) cell, or of arrays of them."""
        return self.x0 + col * self.cell_m, self.y0 + row * self.cell_m

    def cell(self, x: float, y: float) -> tuple[float, float]:
        """The (fractional) cell, row and column, of a map point."""
        return (y - self.y0) / self.cell_m, (x - self.x0) / self.cell_m


@dataclass(frozen=True)
class Blob:
    """Connected occupied columns of one robot height: their centre (map, weighted by the cameras
    that agree) and area."""

    x_m: float
    y_m: float
    area_m2: float


class _Layer:
    """One robot height's fusion on planes through the robot's body (each a fraction of its
    height): every camera's cells on each plane, the counts, the blobs. A column is occupied
    where it is on every plane: low parts (forks) and the floor around the body project onto
    the planes at different places, the body onto all of them."""

    def __init__(
        self,
        cameras: Mapping[str, CameraModel],
        plates: Mapping[str, NDArray[np.uint8]],
        height_m: float,
        config: ForegroundConfig,
    ) -> None:
        self.grid = FusionGrid.covering(list(cameras.values()), height_m, config.cell_m, config.max_range_m)
        self.config = config
        self.planes = [replace(self.grid, z_m=height_m * f) for f in config.planes]
        self.cells = [
            {cid: plane.cells_of(cam, plates[cid], config.max_range_m) for cid, cam in cameras.items()}
            for plane in self.planes
        ]
        self._seen: dict[tuple[str, ...], list[NDArray[np.uint8]]] = {}

    def seen(self, camera_ids: tuple[str, ...]) -> list[NDArray[np.uint8]]:
        """Per plane and cell, how many of these cameras see it (memoized per camera set)."""
        hit = self._seen.get(camera_ids)
        if hit is None:
            hit = []
            for cells_of in self.cells:
                count = np.zeros((self.grid.rows, self.grid.cols), np.uint8)
                for cid in camera_ids:
                    cells = cells_of.get(cid)
                    if cells is not None:
                        h, w = cells.seen.shape
                        count[cells.r0 : cells.r0 + h, cells.c0 : cells.c0 + w] += cells.seen
                hit.append(count)
            self._seen = {camera_ids: hit}
        return hit

    def blobs(self, masks: Mapping[str, NDArray[np.uint8]]) -> list[Blob]:
        """The blobs of one camera tick's foreground masks (cameras absent from ``masks``: unseen)."""
        g, cfg = self.grid, self.config
        occupied = np.ones((g.rows, g.cols), bool)
        weight = np.zeros((g.rows, g.cols), np.float64)
        for cells_of, seen in zip(self.cells, self.seen(tuple(masks))):
            fg = np.zeros((g.rows, g.cols), np.uint8)
            for cid, mask in masks.items():
                cells = cells_of.get(cid)
                if cells is None:
                    continue
                h, w = cells.seen.shape
                hit = np.asarray(
                    cv2.remap(mask, cells.map_x, cells.map_y, cv2.INTER_NEAREST, borderValue=0),
                    dtype=np.uint8,
                )
                fg[cells.r0 : cells.r0 + h, cells.c0 : cells.c0 + w] += hit & cells.seen
            occupied &= (fg >= np.minimum(seen, cfg.min_cameras)) & (fg >= cfg.min_fraction * seen) & (fg > 0)
            weight += fg
        n, labels, stats, _ = cv2.connectedComponentsWithStats(occupied.astype(np.uint8), connectivity=8)
        min_cells = cfg.min_area_m2 / g.cell_m**2
        out = []
        for k in range(1, n):
            if stats[k, cv2.CC_STAT_AREA] < min_cells:
                continue
            x, y, w, h = (int(stats[k, i]) for i in range(4))
            wk = weight[y : y + h, x : x + w] * (labels[y : y + h, x : x + w] == k)
            rr, cc = np.mgrid[y : y + h, x : x + w]
            total = float(wk.sum())
            bx, by = g.xy(float((rr * wk).sum()) / total, float((cc * wk).sum()) / total)
            out.append(Blob(bx, by, float(stats[k, cv2.CC_STAT_AREA]) * g.cell_m**2))
        return out


class ForegroundLocalizer:
    """Robots found as foreground seen by several cameras at their height, filtered by the EKF."""

    role: ClassVar[str] = "localizer"
    config_class: ClassVar[type] = ForegroundConfig

    def __init__(self, config: ForegroundConfig, context: LocalizerContext) -> None:
        self.config = config
        self.cameras = dict(context.cameras)
        self.robots: list[MarkerMount] = list(context.robots)
        if config.start_poses and len(config.start_poses) != 3 * len(self.robots):
            raise ConfigError.invalid(
                KEY + "start_poses",
                list(config.start_poses),
                f"{len(self.robots)} robots need {3 * len(self.robots)} values (x, y, yaw each)",
                "give one pose per robot, in the agents' order",
            )
        self.plates = load_plates(config.background, self.cameras)
        self.layers = {
            z: _Layer(self.cameras, self.plates, z, config) for z in sorted({m.height_m for m in self.robots})
        }
        # the marker localizer without cameras: its filter (tracks, EKF, timeouts, delay) alone
        self.filter = Localizer({}, self.robots, config)
        self.last_blobs: dict[float, list[Blob]] = {}
        self._ways: dict[str, list[tuple[int, float, float, float]]] = {m.namespace: [] for m in self.robots}
        self._commanded: dict[str, tuple[float, float]] = {}
        self._turn: dict[str, tuple[int, float, float]] = {}  # (since, turned so far, yaw rate)
        self._yaw_ref: dict[str, tuple[float, float]] = {}  # yaw last measured, turned then
        # where the blob's centre lies in base_link: the top of the body (the mount stands on
        # it), or measured at the start pose (calibrate)
        self.offsets: dict[str, tuple[float, float]] = {m.namespace: m.offset_xy_m for m in self.robots}
        self.areas: dict[str, float] = {}  # its blob's area there (larger blobs: merged, not used)
        self._samples: dict[str, list[tuple[float, float, float]]] = {m.namespace: [] for m in self.robots}
        self._moved: set[str] = set()  # robots commanded to move (no longer at their start pose)

    def foreground(self, frame: CameraFrame) -> NDArray[np.uint8]:
        """One image's foreground mask (1: differs from the plate), small specks removed."""
        return foreground_mask(
            frame.bgr, self.plates[frame.camera_id], self.config.threshold, normalize=False
        )

    def observe(self, t_ns: int, frames: Mapping[str, CameraFrame]) -> None:
        """One camera tick: foreground, fusion per height, one fix per robot found."""
        ids = [cid for cid in self.cameras if cid in frames]
        if not ids:
            return
        masks = {cid: self.foreground(frames[cid]) for cid in ids}
        stamp = round(sum(frames[c].stamp_ns for c in ids) / len(ids))
        predicted, tracked = self._predictions(stamp)
        self.last_blobs = {}
        for z, layer in self.layers.items():
            blobs = layer.blobs(masks)
            self.last_blobs[z] = blobs
            robots = [m for m in self.robots if m.height_m == z and m.namespace in predicted]
            for mount, blob in self._assign(robots, blobs, predicted):
                self._calibrate(mount, blob)
                fix = self._fix(
                    mount, blob, predicted[mount.namespace][2], stamp, tracked=mount.namespace in tracked
                )
                self.filter.queue_fix(t_ns, fix)

    def _predictions(self, t_ns: int) -> tuple[dict[str, tuple[float, float, float]], set[str]]:
        """Where each robot is expected (base_link x, y, yaw): tracked ones from the filter,
        never-seen ones from their start pose (or anywhere, for a lone robot without one)."""
        estimates = self.filter.estimate(t_ns)
        out, tracked = {}, set()
        for i, mount in enumerate(self.robots):
            e = estimates.get(mount.namespace)
            if e is not None and e.valid:
                out[mount.namespace] = (e.x_m, e.y_m, e.yaw_rad)
                tracked.add(mount.namespace)
            elif self.config.start_poses:
                x, y, yaw = self.config.start_poses[3 * i : 3 * i + 3]
                out[mount.namespace] = (x, y, yaw) if e is None else (e.x_m, e.y_m, e.yaw_rad)
            elif len(self.robots) == 1:
                out[mount.namespace] = (np.nan, np.nan, 0.0 if e is None else e.yaw_rad)
        return out, tracked

    def _assign(
        self,
        robots: list[MarkerMount],
        blobs: list[Blob],
        predicted: Mapping[str, tuple[float, float, float]],
    ) -> list[tuple[MarkerMount, Blob]]:
        """One blob per robot: the assignment of least total distance from each robot's predicted
        top to a blob, within ``gate_m`` (a lone robot without a prediction: the largest blob)."""
        if not robots or not blobs:
            return []
        cost = np.full((len(robots), len(blobs)), 1e6)
        bx = np.array([b.x_m for b in blobs])
        by = np.array([b.y_m for b in blobs])
        dist = {  # every predicted robot's distance from its top to each blob
            m.namespace: np.hypot(bx - tx, by - ty)
            for m in self.robots
            if m.namespace in predicted
            for tx, ty in [self._top(m, *predicted[m.namespace])]
        }
        for i, m in enumerate(robots):
            if np.isnan(predicted[m.namespace][0]):
                cost[i] = [-b.area_m2 for b in blobs]
                continue
            d = dist[m.namespace]
            # two robots merged: a blob much larger than this robot's own with another robot
            # expected within the gate too (one robot's blob that grew is not two robots)
            others = np.zeros(len(blobs), dtype=bool)
            for ns, other in dist.items():
                if ns != m.namespace:
                    others |= other <= self.config.gate_m
            area = self.areas.get(m.namespace)
            larger = np.array(
                [area is not None and b.area_m2 > self.config.merged_ratio * area for b in blobs]
            )
            cost[i] = np.where((d <= self.config.gate_m) & ~(larger & others), d, 1e6)
        rows, cols = linear_sum_assignment(cost)
        return [(robots[r], blobs[c]) for r, c in zip(rows.tolist(), cols.tolist()) if cost[r, c] < 1e6]

    def _calibrate(self, mount: MarkerMount, blob: Blob) -> None:
        """While a robot with a start pose stands there (never commanded to move): its blob's
        area and (``calibrate``) its centre in base_link, the mean over the frames so far."""
        ns = mount.namespace
        if ns in self._moved or not self.config.start_poses:
            return
        i = self.robots.index(mount)
        x, y, yaw = self.config.start_poses[3 * i : 3 * i + 3]
        c, s = np.cos(yaw), np.sin(yaw)
        dx, dy = blob.x_m - x, blob.y_m - y
        self._samples[ns].append((c * dx + s * dy, -s * dx + c * dy, blob.area_m2))
        ox, oy, area = np.mean(self._samples[ns], axis=0).tolist()
        self.areas[ns] = area
        if self.config.calibrate:
            self.offsets[ns] = (ox, oy)

    def _top(self, mount: MarkerMount, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The centre of a robot's blob in map, from its base_link pose."""
        c, s = np.cos(yaw), np.sin(yaw)
        ox, oy = self.offsets[mount.namespace]
        return x + c * ox - s * oy, y + s * ox + c * oy

    def _fix(self, mount: MarkerMount, blob: Blob, yaw: float, stamp_ns: int, *, tracked: bool) -> PoseFix:
        """The base_link pose under the blob: its offset turned by the robot's yaw, measured from
        its way while it drives, else the last one measured turned on as commanded since. (Not
        the filter's yaw: a base placed by the filter's yaw feeds its error back, the filter
        reading the swing of a misplaced base as a turn.)"""
        ns = mount.namespace
        turned = self._turned(ns, stamp_ns)
        since = self._yaw_ref.get(ns)
        ref = yaw if since is None else since[0] + turned - since[1]
        way = self._way(mount, stamp_ns, blob, ref)
        if way is not None:
            self._yaw_ref[ns] = (way, turned)
        elif since is None:
            self._yaw_ref[ns] = (ref, turned)
        measured = way is not None or not tracked
        yaw = ref if way is None else way
        tx, ty = self._top(mount, 0.0, 0.0, yaw)
        bx, by = self.config.bias_m
        return PoseFix(
            ns,
            stamp_ns,
            blob.x_m - tx + bx,
            blob.y_m - ty + by,
            yaw,
            self.config.sigma_xy_m,
            self.config.sigma_yaw_rad if measured else self.config.sigma_turned_rad,
            (),
        )

    def _turned(self, namespace: str, t_ns: int) -> float:
        """How far the robot was commanded to turn from its first command until ``t_ns`` (rad)."""
        t0, angle, w = self._turn.get(namespace, (t_ns, 0.0, 0.0))
        return angle + w * (t_ns - t0) / NS_PER_S

    def _way(self, mount: MarkerMount, stamp_ns: int, blob: Blob, yaw: float) -> float | None:
        """The heading of the robot's way over the last ``heading_window_s``: the chord of its
        base_link positions, turned on by the commanded yaw rate over half the window, reversed
        when driving backwards; None while it moved less than ``heading_min_m`` or drives slower
        than ``heading_min_mps``. The blob's chord less its offset's turn as commanded is the
        base's chord: a body behind the axle swings sideways while the robot turns, and taking
        the offset at the filter's yaws instead would feed a yaw error back into the chord."""
        ns = mount.namespace
        window_ns = round(self.config.heading_window_s * NS_PER_S)
        turned = self._turned(ns, stamp_ns)
        way = [p for p in self._ways[ns] if stamp_ns - p[0] <= window_ns]
        way.append((stamp_ns, blob.x_m, blob.y_m, turned))
        self._ways[ns] = way
        t0, x0, y0, turned0 = way[0]
        ox1, oy1 = self._top(mount, 0.0, 0.0, yaw)
        ox0, oy0 = self._top(mount, 0.0, 0.0, yaw - (turned - turned0))
        dx, dy = blob.x_m - x0 - (ox1 - ox0), blob.y_m - y0 - (oy1 - oy0)
        v, w = self._commanded.get(ns, (0.0, 0.0))
        if np.hypot(dx, dy) < self.config.heading_min_m or abs(v) < self.config.heading_min_mps:
            return None
        heading = float(np.arctan2(dy, dx)) + (np.pi if v < 0 else 0.0)
        return float(wrap_angle(heading + w * 0.5 * (stamp_ns - t0) / NS_PER_S))

    def command(self, t_ns: int, namespace: str, linear_mps: float, angular_rps: float) -> None:
        """A robot's velocity command: the filter predicts with it."""
        self._turn[namespace] = (t_ns, self._turned(namespace, t_ns), angular_rps)
        self._commanded[namespace] = (linear_mps, angular_rps)
        if linear_mps != 0.0 or angular_rps != 0.0:
            self._moved.add(namespace)
        self.filter.command(t_ns, namespace, linear_mps, angular_rps)

    def estimate(self, t_ns: int) -> dict[str, PoseEstimate]:
        """Every robot's filtered pose at ``t_ns``."""
        return self.filter.estimate(t_ns)
