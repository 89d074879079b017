"""Bird's-eye view: stitch calibrated, distorted camera images onto a horizontal world plane.

A canvas is a grid over the plane z = ``plane_z_m`` in the map frame: column j, row i is the
world point (x_min + (j + 0.5) / px_per_m, y_max - (i + 0.5) / px_per_m), north (+y) up.

Setup (once per camera set and canvas)::

    canvas pixel centres (world) --cv2.projectPoints with K, D--> camera pixels (lookup table)
        valid where the ray lies inside the lens model's valid radius and inside the image
        score = camera pixels per canvas pixel (|det J|: high when the camera sees the point
                close and head-on, low at grazing angles and in the compressed lens periphery)
    primary camera per canvas pixel = best score away from footprint edges
    weights: 1 in the primary region, ramps of ``feather_m`` across region borders, faded
             towards each footprint edge; quantized to integers summing to 256

Per frame::

    frames --copy--> atlas (one image holding every camera)
        --cv2.remap (fixed-point maps, one call)--> canvas from each pixel's primary camera
        --cv2.remap of the other 1-3 cameras at the seam pixels only--> integer blend --> canvas

Only cameras whose lookup table is valid at a pixel are blended there; pixels no camera sees stay
black. The class is pure numpy + OpenCV: it never imports the simulator or a file format.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel

MAX_CANVAS_PIXELS = 64_000_000  # 192 MB per RGB canvas: beyond that a typo, not a wish
MAX_PX_PER_M = 1000.0  # 1 mm pixels; the cameras resolve about 1.5 cm on the floor
MAX_SEAM_CAMERAS = 4  # cameras blended at one pixel (the weakest beyond that are dropped)
WEIGHT_ONE = 256  # integer weights of a pixel sum to this (8 fractional bits)
MIN_WEIGHT = 4  # a camera with less than 4/256 of a pixel is dropped there
OUTSIDE = -1000.0  # map coordinate of "no camera": remap's constant border (black)
SEAM_ROW = 4096  # seam pixels are remapped as rows of this many pixels
_RGB = np.dtype((np.void, 3))  # one RGB pixel as a scalar: scatters 3x faster than (N, 3) rows


@dataclass(frozen=True)
class CanvasSpec:
    """A bird's-eye canvas: a world region on the plane z = ``plane_z_m`` and its resolution.

    Raises:
        ConfigError: the region is empty or not finite, the resolution absurd, or the canvas
            too large. ``where`` names the configuration the values came from.
    """

    x_m: tuple[float, float] = (-8.0, 34.0)
    y_m: tuple[float, float] = (-10.0, 10.0)
    px_per_m: float = 50.0
    plane_z_m: float = 0.0
    prefix: str = "birdseye"
    where: str = "config"

    def __post_init__(self) -> None:
        p = self.prefix
        for name in ("x_m", "y_m"):
            value = getattr(self, name)
            try:
                object.__setattr__(self, name, tuple(float(v) for v in value))
            except (TypeError, ValueError):
                self._bad(name, value, "expected [min, max] in metres", f"use e.g. {p}.{name}=[-10,10]")
        for name in ("px_per_m", "plane_z_m"):
            try:
                object.__setattr__(self, name, float(getattr(self, name)))
            except (TypeError, ValueError):
                self._bad(name, getattr(self, name), "expected a number", f"use e.g. {p}.{name}=50")
        for name, rng in (("x_m", self.x_m), ("y_m", self.y_m)):
            if len(rng) != 2 or not all(math.isfinite(v) for v in rng):
                self._bad(name, list(rng), "expected [min, max] in metres", f"use e.g. {p}.{name}=[-10,10]")
            if not rng[1] > rng[0]:
                self._bad(
                    name,
                    list(rng),
                    "empty region (max must exceed min)",
                    f"give {p}.{name}=[min,max] with min < max",
                )
        if not (math.isfinite(self.px_per_m) and 0 < self.px_per_m <= MAX_PX_PER_M):
            self._bad(
                "px_per_m",
                self.px_per_m,
                f"must be within (0, {MAX_PX_PER_M:g}] pixels per metre",
                f"use e.g. {p}.px_per_m=50 (2 cm pixels)",
            )
        if not (math.isfinite(self.plane_z_m) and -5.0 <= self.plane_z_m <= 20.0):
            self._bad(
                "plane_z_m",
                self.plane_z_m,
                "must be within -5..20 m",
                f"use {p}.plane_z_m=0 (floor) or 1.3 (marker plane)",
            )
        w, h = self.width, self.height
        if w < 2 or h < 2:
            self._bad(
                "px_per_m",
                self.px_per_m,
                f"the canvas would be {w}x{h} pixels",
                "raise the resolution or enlarge the region",
            )
        if w * h > MAX_CANVAS_PIXELS:
            self._bad(
                "px_per_m",
                self.px_per_m,
                f"the canvas would be {w}x{h} = {w * h / 1e6:.0f} Mpx (limit {MAX_CANVAS_PIXELS / 1e6:.0f} Mpx)",
                "lower the resolution or shrink the region",
            )

    def _bad(self, name: str, value: object, why: str, fix: str) -> None:
        raise ConfigError.invalid(f"{self.prefix}.{name}", value, why, fix, where=self.where)

    @property
    def width(self) -> int:
        return round((self.x_m[1] - self.x_m[0]) * self.px_per_m)

    @property
    def height(self) -> int:
        return round((self.y_m[1] - self.y_m[0]) * self.px_per_m)

    @property
    def m_per_px(self) -> float:
        return 1.0 / self.px_per_m

    def pixel_to_world(self, cols: NDArray, rows: NDArray) -> tuple[NDArray, NDArray]:
        """World x, y of canvas pixel coordinates (pixel centres at integers)."""
        x = self.x_m[0] + (np.asarray(cols, dtype=np.float64) + 0.5) / self.px_per_m
        y = self.y_m[1] - (np.asarray(rows, dtype=np.float64) + 0.5) / self.px_per_m
        return x, y

    def world_to_pixel(self, x: NDArray, y: NDArray) -> tuple[NDArray, NDArray]:
        """Canvas (col, row) of world x, y (fractional)."""
        col = (np.asarray(x, dtype=np.float64) - self.x_m[0]) * self.px_per_m - 0.5
        row = (self.y_m[1] - np.asarray(y, dtype=np.float64)) * self.px_per_m - 0.5
        return col, row

    def world_points(self, rows: slice, cols: slice) -> NDArray[np.float64]:
        """World points (h, w, 3) of the canvas pixel centres in a window."""
        c = np.arange(cols.start, cols.stop)
        r = np.arange(rows.start, rows.stop)
        x, y = self.pixel_to_world(c, r)
        xx, yy = np.meshgrid(x, y)
        return np.stack([xx, yy, np.full_like(xx, self.plane_z_m)], axis=-1)


def image_valid_mask(camera: CameraModel) -> NDArray[np.bool_]:
    """Pixels of a distorted image that have a ray (inside the lens model's valid radius).

    The radial model folds back beyond ``valid_radius``; the distorted radius reached there
    bounds the valid pixels (the tangential terms of these lenses move it by < 0.01 px). One
    pixel of margin is removed, so a bilinear sample never touches the black border.
    """
    K = camera.K
    r = camera.valid_radius
    h, w = camera.height, camera.width
    if not math.isfinite(r):
        return np.ones((h, w), dtype=bool)
    k1, k2, _, _, k3 = (float(c) for c in camera.D[:5])
    rd_max = r * (1.0 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    yd = (v - K[1, 2]) / K[1, 1]
    xd = (u - K[0, 2] - K[0, 1] * yd) / K[0, 0]
    mask = (np.hypot(xd, yd) < rd_max).astype(np.uint8)
    return cv2.erode(mask, np.ones((3, 3), np.uint8), borderValue=1).astype(bool)


def project_points(
    camera: CameraModel, points_world: NDArray[np.float64], *, distort: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """``CameraModel.project`` (cv2.projectPoints' model: k1 k2 p1 p2 k3, no skew) in numpy.

    Ten times faster than cv2.projectPoints on millions of points (the lookup tables of a
    canvas); tests hold the two equal. The validity mask is the real lens's either way: with
    ``distort=False`` the pixels are the pinhole's (distortion ignored, SIMLAN's model).
    """
    pc = camera.world_to_camera(points_world)
    z = pc[:, 2]
    front = z > 1e-9
    safe = np.where(front, z, 1.0)
    x, y = pc[:, 0] / safe, pc[:, 1] / safe
    r2 = x * x + y * y
    ok = front & (r2 <= camera.valid_radius**2)
    if distort:
        k1, k2, p1, p2, k3 = (float(c) for c in camera.D[:5])
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        x, y = (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    K = camera.K
    return np.stack([K[0, 0] * x + K[0, 2], K[1, 1] * y + K[1, 2]], axis=1), ok


@dataclass
class Footprint:
    """Where one camera sees the canvas: lookup table and score within a canvas window."""

    camera_id: str
    rows: slice
    cols: slice
    map_x: NDArray[np.float32]  # camera pixel column of each canvas pixel of the window
    map_y: NDArray[np.float32]
    valid: NDArray[np.bool_]
    density: NDArray[np.float32]  # camera pixels per canvas pixel (0 where invalid)


def camera_footprint(
    camera: CameraModel, spec: CanvasSpec, *, distort: bool = True, margin_px: int = 2
) -> Footprint | None:
    """Lookup table of one camera on the canvas (None if it sees none of it).

    With ``distort=False`` the lens distortion is ignored (the pinhole model), to measure what
    that costs; validity still follows the real lens.
    """
    h, w = camera.height, camera.width
    step = max(4, min(w, h) // 64)
    us = np.r_[np.arange(0, w, step), w - 1]
    vs = np.r_[np.arange(0, h, step), h - 1]
    uu, vv = np.meshgrid(us, vs)
    ground, ok = camera.intersect_plane_z(np.stack([uu.ravel(), vv.ravel()], 1), spec.plane_z_m)
    if distort and not ok.any():
        return None
    if not distort:  # the pinhole footprint of the same image
        ground, ok = camera.intersect_plane_z(
            np.stack([uu.ravel(), vv.ravel()], 1), spec.plane_z_m, distorted=False
        )
        if not ok.any():
            return None
    col, row = spec.world_to_pixel(ground[ok, 0], ground[ok, 1])
    # the sampled rays bound the footprint up to the sampling step: widen by the local spacing
    c0 = max(0, int(np.floor(col.min())) - margin_px - 64)
    c1 = min(spec.width, int(np.ceil(col.max())) + margin_px + 65)
    r0 = max(0, int(np.floor(row.min())) - margin_px - 64)
    r1 = min(spec.height, int(np.ceil(row.max())) + margin_px + 65)
    if c0 >= c1 or r0 >= r1:
        return None
    rows, cols = slice(r0, r1), slice(c0, c1)
    pts = spec.world_points(rows, cols).reshape(-1, 3)
    uv, front = project_points(camera, pts, distort=distort)
    shape = (r1 - r0, c1 - c0)
    map_x = uv[:, 0].reshape(shape).astype(np.float32)
    map_y = uv[:, 1].reshape(shape).astype(np.float32)
    good = front.reshape(shape) & np.isfinite(map_x) & np.isfinite(map_y)
    good &= (map_x >= 0) & (map_x < w - 1) & (map_y >= 0) & (map_y < h - 1)
    # all four bilinear neighbours must have a ray
    img_ok = image_valid_mask(camera)
    ok4 = img_ok[:-1, :-1] & img_ok[1:, :-1] & img_ok[:-1, 1:] & img_ok[1:, 1:]
    iu = np.clip(np.nan_to_num(map_x, nan=0.0), 0, w - 2).astype(np.int32)
    iv = np.clip(np.nan_to_num(map_y, nan=0.0), 0, h - 2).astype(np.int32)
    good &= ok4[iv, iu]
    if not good.any():
        return None
    mx, my = map_x.astype(np.float64), map_y.astype(np.float64)
    gx_u, gy_u = np.gradient(mx, axis=1), np.gradient(mx, axis=0)
    gx_v, gy_v = np.gradient(my, axis=1), np.gradient(my, axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        det = np.abs(gx_u * gy_v - gy_u * gx_v)
    # rays near the horizon project far away: their (invalid) neighbours must not overflow float32
    density = np.where(good, np.minimum(np.nan_to_num(det, nan=0.0, posinf=1e6), 1e6), 0.0).astype(np.float32)
    map_x[~good] = OUTSIDE
    map_y[~good] = OUTSIDE
    return Footprint(camera.camera_id, rows, cols, map_x, map_y, good, density)


def project_footprints(
    footprints: Sequence[Footprint | None],
    frames: Sequence[NDArray[np.uint8]],
    *,
    interpolation: int = cv2.INTER_LINEAR,
) -> list[tuple[Footprint, NDArray[np.uint8]] | None]:
    """Every camera's own projection onto its canvas window (None where it sees none of it)."""
    out: list[tuple[Footprint, NDArray[np.uint8]] | None] = []
    for fp, frame in zip(footprints, frames):
        if fp is None:
            out.append(None)
            continue
        img = cv2.remap(frame, fp.map_x, fp.map_y, interpolation, borderMode=cv2.BORDER_CONSTANT)
        out.append((fp, cast(NDArray[np.uint8], img)))
    return out


def _smoothstep(x: NDArray) -> NDArray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass
class SeamPixels:
    """Canvas pixels blended from several cameras: flat indices, per-slot maps and weights."""

    index: NDArray[np.intp]  # (N,) flat canvas indices
    padded: NDArray[np.intp]  # (R * SEAM_ROW,) the same, padded to whole rows
    cameras: NDArray[np.int16]  # (n, N) camera index per slot, strongest (the primary) first
    weights: NDArray[np.uint16]  # (n, R, SEAM_ROW, 1) integer weights, summing to WEIGHT_ONE
    map1: NDArray[np.int16]  # ((n - 1) * R, SEAM_ROW, 2) fixed-point atlas maps of slots 1..n-1
    map2: NDArray[np.uint16]  # ((n - 1) * R, SEAM_ROW)


class BirdseyeStitcher:
    """Stitch frames of a fixed camera set onto a canvas (see the module docstring)."""

    def __init__(
        self,
        cameras: Sequence[CameraModel],
        spec: CanvasSpec,
        *,
        feather_m: float = 0.2,
        distort: bool = True,
    ) -> None:
        if not cameras:
            raise ValueError("no camera to stitch")
        self.cameras, self.spec, self.distort = list(cameras), spec, distort
        self.band_px = max(1.0, feather_m * spec.px_per_m)
        self.tile_w = max(c.width for c in cameras)
        self.tile_h = max(c.height for c in cameras)
        self.columns = math.ceil(math.sqrt(len(cameras)))
        n_rows = math.ceil(len(cameras) / self.columns)
        if self.columns * self.tile_w > 32000 or n_rows * self.tile_h > 32000:
            raise ValueError("too many or too large cameras for one atlas (fixed-point maps hold 32767 px)")
        self._atlas = np.zeros((n_rows * self.tile_h, self.columns * self.tile_w, 3), dtype=np.uint8)
        self.footprints: list[Footprint | None] = [
            camera_footprint(c, spec, distort=distort) for c in cameras
        ]
        self._build()

    # -------------------------------------------------------------------------------- setup
    def _offset(self, k: int) -> tuple[int, int]:
        return (k % self.columns) * self.tile_w, (k // self.columns) * self.tile_h

    def _build(self) -> None:
        """Primary camera, blend weights and remap tables of every canvas pixel.

        Per camera c: edge_c = smoothstep(distance to its footprint border / band), so a camera
        fades out before its image ends. Primary = argmax density_c * edge_c. Weight of c =
        ramp_c * edge_c, where ramp_c is 1 in c's primary region and falls to 0 at ``band`` px
        outside it: two cameras share a seam over 2 * band, symmetric about the region border.
        At most MAX_SEAM_CAMERAS cameras per pixel (the strongest), integer weights.
        """
        primary, edge_factor = self._primary_regions()
        self._coverage_and_density()
        slot_w, slot_c = self._blend_weights(primary, edge_factor)
        q = self._quantize(slot_w, slot_c)
        self._primary_map()
        self._seam_groups(q, slot_c, slot_w)

    def _primary_regions(self) -> tuple[NDArray[np.int16], list[NDArray[np.float32] | None]]:
        """Count the cameras per pixel; pick each pixel's primary camera and every camera's edge fade."""
        H, W = self.spec.height, self.spec.width
        band = self.band_px
        self.camera_count = np.zeros((H, W), dtype=np.uint8)
        best = np.zeros((H, W), dtype=np.float32)
        primary = np.full((H, W), -1, dtype=np.int16)
        edge_factor: list[NDArray[np.float32] | None] = []
        for k, fp in enumerate(self.footprints):
            if fp is None:
                edge_factor.append(None)
                continue
            self.camera_count[fp.rows, fp.cols] += fp.valid
            edge = cv2.distanceTransform(fp.valid.astype(np.uint8), cv2.DIST_L2, 5)
            factor = _smoothstep(edge / band).astype(np.float32)
            edge_factor.append(factor)
            eff = fp.density * np.maximum(factor, 1e-3 * fp.valid)
            b, p = best[fp.rows, fp.cols], primary[fp.rows, fp.cols]
            better = eff > b
            b[better] = eff[better]
            p[better] = k
        return primary, edge_factor

    def _coverage_and_density(self) -> None:
        """Mark the covered pixels and the density of the sharpest camera at each pixel."""
        H, W = self.spec.height, self.spec.width
        self.coverage = self.camera_count > 0
        self.density = np.zeros((H, W), dtype=np.float32)  # of the sharpest camera at each pixel
        for fp in self.footprints:
            if fp is not None:
                np.maximum(self.density[fp.rows, fp.cols], fp.density, out=self.density[fp.rows, fp.cols])

    def _blend_weights(
        self, primary: NDArray[np.int16], edge_factor: list[NDArray[np.float32] | None]
    ) -> tuple[NDArray[np.float32], NDArray[np.int16]]:
        """Weigh every camera by its ramp and fade; keep the strongest MAX_SEAM_CAMERAS per pixel."""
        H, W = self.spec.height, self.spec.width
        K = MAX_SEAM_CAMERAS
        band = self.band_px
        slot_w = np.zeros((H, W, K), dtype=np.float32)
        slot_c = np.full((H, W, K), -1, dtype=np.int16)
        for k, fp in enumerate(self.footprints):
            fade = edge_factor[k]
            if fp is None or fade is None:
                continue
            region = (primary[fp.rows, fp.cols] == k).astype(np.uint8)
            outside = cv2.distanceTransform(1 - region, cv2.DIST_L2, 5)
            ramp = np.clip(1.0 - outside / band, 0.0, 1.0)
            w = (ramp * np.maximum(fade, 1e-3) * fp.valid).astype(np.float32)
            sw, sc = slot_w[fp.rows, fp.cols], slot_c[fp.rows, fp.cols]
            m = w > 0
            weakest = np.argmin(sw[m], axis=1)
            cur = sw[m][np.arange(weakest.size), weakest]
            take = w[m] > cur
            ii = np.nonzero(m)
            ti = (ii[0][take], ii[1][take], weakest[take])
            sw[ti] = w[m][take]
            sc[ti] = k
        return slot_w, slot_c

    def _quantize(self, slot_w: NDArray[np.float32], slot_c: NDArray[np.int16]) -> NDArray[np.int32]:
        """Turn the weights into integers summing to WEIGHT_ONE; drop empty slots; set the primary."""
        H, W = self.spec.height, self.spec.width
        total = slot_w.sum(axis=2, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            q = np.where(total > 0, np.rint(WEIGHT_ONE * slot_w / total), 0).astype(np.int32)
        q[q < MIN_WEIGHT] = 0
        top = np.argmax(slot_w, axis=2)
        rr, cc = np.nonzero(total[..., 0] > 0)
        q[rr, cc, top[rr, cc]] += WEIGHT_ONE - q[rr, cc].sum(axis=1)
        slot_c[q == 0] = -1
        self.primary = np.where(total[..., 0] > 0, slot_c[np.arange(H)[:, None], np.arange(W), top], -1)
        return q

    def _primary_map(self) -> None:
        """Build one atlas map for every pixel, from its primary camera."""
        H, W = self.spec.height, self.spec.width
        map_x = np.full((H, W), OUTSIDE, dtype=np.float32)
        map_y = np.full((H, W), OUTSIDE, dtype=np.float32)
        for k, fp in enumerate(self.footprints):
            if fp is None:
                continue
            mine = self.primary[fp.rows, fp.cols] == k
            du, dv = self._offset(k)
            map_x[fp.rows, fp.cols][mine] = fp.map_x[mine] + du
            map_y[fp.rows, fp.cols][mine] = fp.map_y[mine] + dv
        self._primary_maps = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
        self._primary_float = (map_x, map_y)

    def _seam_groups(
        self, q: NDArray[np.int32], slot_c: NDArray[np.int16], slot_w: NDArray[np.float32]
    ) -> None:
        """Group the seam pixels (two or more cameras with a weight) by how many cameras blend there."""
        K = MAX_SEAM_CAMERAS
        n_cams = (q > 0).sum(axis=2).ravel()
        flat_q, flat_c, flat_w = q.reshape(-1, K), slot_c.reshape(-1, K), slot_w.reshape(-1, K)
        self.seams = []
        for n in range(2, K + 1):
            index = np.nonzero(n_cams == n)[0]
            if index.size == 0:
                continue
            # strongest first, as argmax chose the primary: slot 0 is what the canvas already shows
            order = np.argsort(-flat_w[index], axis=1, kind="stable")[:, :n]
            qs = np.take_along_axis(flat_q[index], order, axis=1).T.astype(np.uint16)  # (n, N)
            cs = np.take_along_axis(flat_c[index], order, axis=1).T  # (n, N)
            self.seams.append(self._seam_group(index, cs, qs))

    def _seam_group(self, index: NDArray[np.intp], cams: NDArray[np.int16], weights: NDArray) -> SeamPixels:
        """Atlas maps of seam pixels blended from ``len(cams)`` cameras each."""
        W = self.spec.width
        sx = np.full(cams.shape, OUTSIDE, dtype=np.float32)
        sy = np.full(cams.shape, OUTSIDE, dtype=np.float32)
        rows, cols = np.divmod(index, W)
        for k, fp in enumerate(self.footprints):
            if fp is None:
                continue
            du, dv = self._offset(k)
            for slot in range(cams.shape[0]):
                sel = np.nonzero(cams[slot] == k)[0]
                lr, lc = rows[sel] - fp.rows.start, cols[sel] - fp.cols.start
                sx[slot, sel] = fp.map_x[lr, lc] + du
                sy[slot, sel] = fp.map_y[lr, lc] + dv
        # remap's images are limited to 32767 columns: fold each pixel list into rows. Slot 0 is
        # the primary camera, already remapped into the canvas: only the others are sampled again
        pad = (-index.size) % SEAM_ROW

        def fold(a: NDArray, value: float) -> NDArray:
            return np.pad(a, ((0, 0), (0, pad)), constant_values=value).reshape(-1, SEAM_ROW)

        m1, m2 = cv2.convertMaps(fold(sx[1:], OUTSIDE), fold(sy[1:], OUTSIDE), cv2.CV_16SC2)
        w = fold(weights, 0).reshape(cams.shape[0], -1, SEAM_ROW, 1).astype(np.uint16)
        padded = np.pad(index, (0, pad), mode="edge")
        return SeamPixels(index, padded, cams, w, cast(NDArray[np.int16], m1), cast(NDArray[np.uint16], m2))

    # ------------------------------------------------------------------------------ per frame
    def _fill_atlas(self, frames: Sequence[NDArray[np.uint8]]) -> NDArray[np.uint8]:
        if len(frames) != len(self.cameras):
            raise ValueError(f"expected {len(self.cameras)} frames (one per camera), got {len(frames)}")
        channels = frames[0].shape[2] if frames[0].ndim == 3 else 1
        atlas = self._atlas if channels == 3 else self._label_atlas()
        for k, (frame, cam) in enumerate(zip(frames, self.cameras)):
            if frame.shape[:2] != (cam.height, cam.width):
                raise ValueError(
                    f"camera {cam.camera_id}: frame is {frame.shape[1]}x{frame.shape[0]}, expected {cam.width}x{cam.height}"
                )
            du, dv = self._offset(k)
            atlas[dv : dv + cam.height, du : du + cam.width] = frame
        return atlas

    def _label_atlas(self) -> NDArray[np.uint8]:
        if not hasattr(self, "_labels"):
            self._labels = np.zeros(self._atlas.shape[:2], dtype=np.uint8)
        return self._labels

    def stitch(self, frames: Sequence[NDArray[np.uint8]]) -> NDArray[np.uint8]:
        """Stitch one RGB frame per camera (in the cameras' order) into a new canvas (H, W, 3)."""
        atlas = self._fill_atlas(frames)
        m1, m2 = self._primary_maps
        canvas = cv2.remap(atlas, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        flat = canvas.reshape(-1).view(_RGB)
        for s in self.seams:
            others = cv2.remap(atlas, s.map1, s.map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            others = others.reshape(s.weights.shape[0] - 1, -1, SEAM_ROW, 3)
            primary = flat[s.padded].view(np.uint8).reshape(others.shape[1:])
            acc = primary * s.weights[0]  # uint16: the weighted sum stays < 256 * 255 + 128
            acc += (others * s.weights[1:]).sum(axis=0, dtype=np.uint16)
            acc += WEIGHT_ONE // 2
            blended = (acc >> 8).astype(np.uint8).reshape(-1).view(_RGB)
            np.put(flat, s.index, blended[: s.index.size])
        return cast(NDArray[np.uint8], canvas)

    def stitch_labels(self, labels: Sequence[NDArray[np.uint8]]) -> NDArray[np.uint8]:
        """Semantic labels on the canvas, nearest pixel of each pixel's primary camera."""
        atlas = self._fill_atlas(labels)
        if not hasattr(self, "_nearest_maps"):
            self._nearest_maps = cv2.convertMaps(*self._primary_float, cv2.CV_16SC2, nninterpolation=True)
        m1, m2 = self._nearest_maps
        return cast(
            NDArray[np.uint8], cv2.remap(atlas, m1, m2, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        )

    def project_each(
        self, frames: Sequence[NDArray[np.uint8]], *, interpolation: int = cv2.INTER_LINEAR
    ) -> list[tuple[Footprint, NDArray[np.uint8]] | None]:
        """Every camera's own projection onto its canvas window (for seam and per-camera metrics)."""
        return project_footprints(self.footprints, frames, interpolation=interpolation)

    @property
    def seam_fraction(self) -> float:
        """Share of the covered canvas blended from two or more cameras."""
        covered = int(self.coverage.sum())
        return sum(s.index.size for s in self.seams) / covered if covered else 0.0
