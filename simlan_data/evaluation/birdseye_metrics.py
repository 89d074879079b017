"""Quality of a bird's-eye canvas against an orthographic ground-truth render of the same scene.

Every measure is on the same canvas, for any method (ours in colour, SIMLAN's in grey):

- floor pixels: the ground truth sees floor (classes floor, floor_marking) and so does every
  camera covering the pixel (objects above the floor shift by parallax in an oblique view; where
  any camera sees such an object, the pixel is left out for every method alike);
- ground control points are used where the truth is floor and at least one camera sees that
  floor (a method that shows another camera's obstacle there pays for it);
- PSNR (colour and grey) and SSIM (grey, Wang et al.'s Gaussian 11x11 window) on floor pixels;
- ground control points: the floor-slab joint crossings (world positions from the layout): a
  25x25 px ground-truth patch around each is located in the canvas by normalized cross-correlation
  within +-2 m, refined to sub-pixel; the error is the distance to where it should be (px, cm);
- coverage: share of the canvas seen by at least one camera;
- seam error: RMS grey-level difference between any two cameras' projections where both see
  the floor (what a seam between them shows).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray
from skimage.metrics import structural_similarity

from simlan_data.algorithms.birdseye import (
    BirdseyeStitcher,
    CanvasSpec,
    Footprint,
    camera_footprint,
    project_footprints,
)
from simlan_data.geometry.camera import CameraModel
from simlan_data.world.labels import SEMANTIC_CLASSES
from simlan_data.world.layout import Placement
from simlan_data.world.models import BUILDING_X_M, BUILDING_Y_M, SLAB_M, model_spec

FLOOR_CLASSES = (SEMANTIC_CLASSES["floor"], SEMANTIC_CLASSES["floor_marking"])
SLAB_MODEL = "ground_visual_updated"  # the slab floor; its layout pose moves the joints
GCP_HALF_PX = 12  # template 25x25 px (0.5 m at 50 px/m)
GCP_SEARCH_M = 2.0  # joint crossings are 5 m apart, line ends 6 m: no other match in reach
GCP_MIN_SCORE = 0.5  # normalized correlation below this: the point is not found


def grey(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    return image if image.ndim == 2 else cast(NDArray[np.uint8], cv2.cvtColor(image, cv2.COLOR_RGB2GRAY))


def slab_joint_crossings(placements: Sequence[Placement], spec: CanvasSpec) -> NDArray[np.float64]:
    """World (x, y) of the floor-slab joint crossings inside the canvas (N, 2).

    The slabs tile the building's floor from its south-west corner in 5 m steps; the slab model
    is placed at its layout pose (SIMLAN's ``ground_visual_updated`` at x 1.3, y -1.4).
    """
    slab = next((p for p in placements if p.model == SLAB_MODEL), None)
    if slab is None:
        return np.zeros((0, 2))
    ox, oy, _ = slab.xyz_m
    yaw = slab.rpy_rad[2]
    xs = np.arange(BUILDING_X_M[0] + SLAB_M, BUILDING_X_M[1], SLAB_M)
    ys = np.arange(BUILDING_Y_M[0] + SLAB_M, BUILDING_Y_M[1], SLAB_M)
    xx, yy = np.meshgrid(xs, ys)
    c, s = np.cos(yaw), np.sin(yaw)
    wx = ox + c * xx.ravel() - s * yy.ravel()
    wy = oy + s * xx.ravel() + c * yy.ravel()
    return _inside(np.stack([wx, wy], axis=1), spec)


def marking_line_ends(placements: Sequence[Placement], spec: CanvasSpec) -> NDArray[np.float64]:
    """World (x, y) of the ends of painted floor lines inside the canvas (N, 2)."""
    pts = []
    for p in placements:
        spec_ = model_spec(p.model)
        if spec_ is None or spec_.semantic != "floor_marking" or not spec_.parts:
            continue
        lo = min(part.xyz[0] - part.size[0] for part in spec_.parts)
        hi = max(part.xyz[0] + part.size[0] for part in spec_.parts)
        yaw = p.rpy_rad[2]
        for end in (lo, hi):
            pts.append((p.xyz_m[0] + np.cos(yaw) * end, p.xyz_m[1] + np.sin(yaw) * end))
    return _inside(np.array(pts).reshape(-1, 2), spec)


def ground_control_points(placements: Sequence[Placement], spec: CanvasSpec) -> NDArray[np.float64]:
    """Slab joint crossings and floor-line ends inside the canvas, world (x, y) (N, 2)."""
    return np.vstack([slab_joint_crossings(placements, spec), marking_line_ends(placements, spec)])


def _inside(xy: NDArray[np.float64], spec: CanvasSpec) -> NDArray[np.float64]:
    margin = (GCP_HALF_PX + 2) * spec.m_per_px + GCP_SEARCH_M
    x, y = xy[:, 0], xy[:, 1]
    keep = (
        (x > spec.x_m[0] + margin)
        & (x < spec.x_m[1] - margin)
        & (y > spec.y_m[0] + margin)
        & (y < spec.y_m[1] - margin)
    )
    return xy[keep]


def floor_views(
    gt_labels: NDArray[np.uint8],
    camera_labels: Sequence[tuple[tuple[slice, slice], NDArray[np.uint8], NDArray[np.bool_]]],
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Floor pixels seen by every covering camera, and by at least one (both where the truth is floor).

    ``camera_labels``: per camera (canvas window (rows, cols), its labels projected there, where
    it covers the canvas). Neither mask depends on how a method blends the cameras.
    """
    truth = np.isin(gt_labels, FLOOR_CLASSES)
    every = truth.copy()
    some = np.zeros(gt_labels.shape, dtype=bool)
    for (rows, cols), labels, covers in camera_labels:
        floor = np.isin(labels, FLOOR_CLASSES)
        every[rows, cols] &= ~(covers & ~floor)
        some[rows, cols] |= covers & floor
    return every & some, truth & some


def psnr(image: NDArray[np.uint8], truth: NDArray[np.uint8], mask: NDArray[np.bool_]) -> float:
    """Peak signal-to-noise ratio (dB, peak 255) over the masked pixels (all channels)."""
    if not mask.any():
        return float("nan")
    diff = image[mask].astype(np.float64) - truth[mask].astype(np.float64)
    mse = float(np.mean(diff * diff))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)


def ssim(image_grey: NDArray[np.uint8], truth_grey: NDArray[np.uint8], mask: NDArray[np.bool_]) -> float:
    """Mean SSIM (Gaussian window, sigma 1.5) over the masked pixels."""
    if not mask.any():
        return float("nan")
    _, smap = structural_similarity(
        truth_grey,
        image_grey,
        data_range=255,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        full=True,
    )
    return float(smap[mask].mean())


@dataclass
class GcpResult:
    """Offsets (px) of ground control points found in a canvas; NaN where not found."""

    offsets_px: NDArray[np.float64]  # (N, 2)
    scores: NDArray[np.float64]  # (N,) normalized correlation peak

    @property
    def found(self) -> NDArray[np.bool_]:
        return np.isfinite(self.offsets_px[:, 0])

    def errors_px(self) -> NDArray[np.float64]:
        return np.hypot(self.offsets_px[:, 0], self.offsets_px[:, 1])


def _subpixel(a: float, b: float, c: float) -> float:
    den = a - 2.0 * b + c
    return 0.0 if abs(den) < 1e-12 else float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))


def locate_gcps(
    image_grey: NDArray[np.uint8],
    truth_grey: NDArray[np.uint8],
    points_px: NDArray[np.float64],
    *,
    search_px: int,
) -> GcpResult:
    """Find each ground-truth patch around ``points_px`` (col, row) in ``image_grey``."""
    h = GCP_HALF_PX
    offsets = np.full((len(points_px), 2), np.nan)
    scores = np.zeros(len(points_px))
    for i, (col, row) in enumerate(points_px):
        c, r = round(col), round(row)
        tpl = truth_grey[r - h : r + h + 1, c - h : c + h + 1].astype(np.float32)
        win = image_grey[r - h - search_px : r + h + search_px + 1, c - h - search_px : c + h + search_px + 1]
        if tpl.shape != (2 * h + 1, 2 * h + 1) or win.shape != (2 * (h + search_px) + 1,) * 2:
            continue
        if float(win.std()) < 1.0:  # flat (black, uncovered): nothing to find
            continue
        ncc = cv2.matchTemplate(win.astype(np.float32), tpl, cv2.TM_CCOEFF_NORMED)
        _, peak, _, (px, py) = cv2.minMaxLoc(ncc)
        scores[i] = peak
        if peak < GCP_MIN_SCORE:
            continue
        ix, iy = px - search_px, py - search_px
        # sub-pixel: ECC (enhanced correlation coefficient) translation from the integer peak;
        # a parabola through the correlation peak is biased towards whole pixels
        m = 4
        inp = image_grey[r + iy - h - m : r + iy + h + m + 1, c + ix - h - m : c + ix + h + m + 1]
        warp = np.array([[1.0, 0.0, m], [0.0, 1.0, m]], dtype=np.float32)
        try:
            _, warp = cv2.findTransformECC(  # type: ignore[call-overload]  # (stubs: no mask is allowed)
                tpl,
                inp.astype(np.float32),
                warp,
                cv2.MOTION_TRANSLATION,
                (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4),
                None,
                1,
            )
            dx, dy = float(warp[0, 2]) - m, float(warp[1, 2]) - m
        except cv2.error:  # ECC did not converge: keep the parabola's estimate
            dx = (
                _subpixel(ncc[py, px - 1], ncc[py, px], ncc[py, px + 1]) if 0 < px < ncc.shape[1] - 1 else 0.0
            )
            dy = (
                _subpixel(ncc[py - 1, px], ncc[py, px], ncc[py + 1, px]) if 0 < py < ncc.shape[0] - 1 else 0.0
            )
        if abs(dx) > 2 or abs(dy) > 2:  # ECC wandered off: the integer peak stands
            dx = dy = 0.0
        # where the patch was cut does not matter: the shift between truth and image does
        offsets[i] = (ix + dx, iy + dy)
    return GcpResult(offsets, scores)


def usable_gcps(
    points_px: NDArray[np.float64],
    truth_grey: NDArray[np.uint8],
    gt_labels: NDArray[np.uint8],
    floor_seen: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """Points whose ground-truth patch is textured floor that some camera sees as floor."""
    h = GCP_HALF_PX
    ok = np.zeros(len(points_px), dtype=bool)
    floor = np.isin(gt_labels, FLOOR_CLASSES)
    for i, (col, row) in enumerate(points_px):
        c, r = round(col), round(row)
        sl = (slice(r - h, r + h + 1), slice(c - h, c + h + 1))
        patch = truth_grey[sl]
        if patch.shape != (2 * h + 1, 2 * h + 1):
            continue
        ok[i] = bool(floor[sl].all() and floor_seen[sl].mean() > 0.95 and patch.std() > 3.0)
    return ok


def seam_rms(
    projections: Sequence[tuple[tuple[slice, slice], NDArray[np.uint8], NDArray[np.bool_]]],
    mask: NDArray[np.bool_],
) -> float:
    """RMS grey difference over every pair of cameras seeing the same floor pixel.

    Uses sum over pairs (a_i - a_j)^2 = n * sum a_i^2 - (sum a_i)^2 per pixel.
    """
    s1 = np.zeros(mask.shape)
    s2 = np.zeros(mask.shape)
    n = np.zeros(mask.shape)
    for (rows, cols), image, covers in projections:
        g = grey(image).astype(np.float64) * covers
        s1[rows, cols] += g
        s2[rows, cols] += g * g
        n[rows, cols] += covers
    sel = mask & (n >= 2)
    if not sel.any():
        return float("nan")
    ssd = n[sel] * s2[sel] - s1[sel] ** 2
    pairs = n[sel] * (n[sel] - 1) / 2
    return float(np.sqrt(max(0.0, ssd.sum()) / pairs.sum()))


def distortion_displacement_cm(
    cameras: Sequence[CameraModel], spec: CanvasSpec, *, step_px: int = 10
) -> NDArray[np.float64]:
    """What ignoring the lens distortion costs, by the camera model alone.

    For floor points each camera sees (every ``step_px``-th canvas pixel), the pinhole model
    samples the image at K [R|t] P; the real lens shows there the floor point Q whose ray passes
    through that pixel. Returns |P - Q| in cm for every (camera, point) whose pinhole pixel falls
    inside the image (all points pooled).
    """
    out = []
    for cam in cameras:
        fp = camera_footprint(cam, spec)
        if fp is None:
            continue
        rr, cc = np.nonzero(fp.valid[::step_px, ::step_px])
        rows = rr * step_px + fp.rows.start
        cols = cc * step_px + fp.cols.start
        x, y = spec.pixel_to_world(cols, rows)
        pts = np.stack([x, y, np.full_like(x, spec.plane_z_m)], axis=1)
        uv, _ = cam.project(pts, distort=False)
        inside = (
            (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height - 1)
        )
        q, ok = cam.intersect_plane_z(uv[inside], spec.plane_z_m)
        d = np.hypot(*(q[:, :2] - pts[inside, :2]).T) * 100.0
        # rays through pixels without a valid ray (beyond the lens model) show nothing: count as far off
        out.append(np.where(ok, d, np.inf))
    return np.concatenate(out) if out else np.zeros(0)


Window = tuple[slice, slice]
FULL = (slice(None), slice(None))


class CameraViews:
    """Where each camera sees the canvas: its lookup table (footprint), and the canvas any camera
    sees (``coverage``). The floor masks and seam error of a stitcher that does not expose its own
    (``project_each`` and ``coverage``, as :class:`BirdseyeStitcher` does) come from these."""

    def __init__(self, cameras: Sequence[CameraModel], spec: CanvasSpec) -> None:
        self.footprints: list[Footprint | None] = [camera_footprint(c, spec) for c in cameras]
        self.coverage = np.zeros((spec.height, spec.width), dtype=bool)
        for fp in self.footprints:
            if fp is not None:
                self.coverage[fp.rows, fp.cols] |= fp.valid

    def project_each(
        self, frames: Sequence[NDArray[np.uint8]], *, interpolation: int = cv2.INTER_LINEAR
    ) -> list[tuple[Footprint, NDArray[np.uint8]] | None]:
        """Every camera's own projection onto its canvas window."""
        return project_footprints(self.footprints, frames, interpolation=interpolation)


def stitcher_projections(
    stitcher: BirdseyeStitcher | CameraViews, frames: Sequence[NDArray[np.uint8]], *, nearest: bool = False
) -> list[tuple[Window, NDArray[np.uint8], NDArray[np.bool_]]]:
    """Every camera's own projection with its window and coverage (for masks and seam error)."""
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return [
        ((fp.rows, fp.cols), img, fp.valid)
        for fp, img in filter(None, stitcher.project_each(frames, interpolation=interp))
    ]


@dataclass
class MethodScores:
    """Per-frame measures of one method, pooled over frames."""

    psnr_rgb: list[float]
    psnr_grey: list[float]
    ssim: list[float]
    seam_rms: list[float]
    gcp_offsets_px: list[NDArray[np.float64]]
    coverage: float = float("nan")


class QualityEvaluator:
    """Score canvases of several methods against one ground truth, frame after frame."""

    def __init__(
        self,
        spec: CanvasSpec,
        truth_rgb: NDArray[np.uint8],
        truth_labels: NDArray[np.uint8],
        gcp_world: NDArray[np.float64],
    ) -> None:
        self.spec, self.truth_rgb, self.truth_labels = spec, truth_rgb, truth_labels
        self.truth_grey = grey(truth_rgb)
        self.gcp_world = gcp_world
        self.gcp_px = (
            np.stack(spec.world_to_pixel(gcp_world[:, 0], gcp_world[:, 1]), axis=1)
            if len(gcp_world)
            else np.zeros((0, 2))
        )
        self.search_px = round(GCP_SEARCH_M * spec.px_per_m)
        self.methods: dict[str, MethodScores] = {}
        self.floor_fraction: list[float] = []
        self.gcp_usable: list[int] = []
        self._mask: NDArray[np.bool_] | None = None
        self._usable: NDArray[np.bool_] = np.zeros(0, dtype=bool)

    def begin_frame(
        self, camera_labels: Sequence[tuple[Window, NDArray[np.uint8], NDArray[np.bool_]]]
    ) -> None:
        """Set the floor masks of a frame from the cameras' projected labels (method-independent)."""
        every, seen = floor_views(self.truth_labels, camera_labels)
        self._mask = every
        self._usable = usable_gcps(self.gcp_px, self.truth_grey, self.truth_labels, seen)
        self.floor_fraction.append(float(every.mean()))
        self.gcp_usable.append(int(self._usable.sum()))

    def add(
        self,
        method: str,
        canvas: NDArray[np.uint8],
        coverage: NDArray[np.bool_],
        projections: Sequence[tuple[Window, NDArray[np.uint8], NDArray[np.bool_]]],
    ) -> None:
        """Score one method's canvas of the current frame."""
        if self._mask is None:
            raise RuntimeError("begin_frame() first")
        mask = self._mask
        s = self.methods.setdefault(method, MethodScores([], [], [], [], []))
        s.coverage = float(coverage.mean())
        g = grey(canvas)
        s.psnr_rgb.append(psnr(canvas, self.truth_rgb, mask) if canvas.ndim == 3 else float("nan"))
        s.psnr_grey.append(psnr(g, self.truth_grey, mask))
        s.ssim.append(ssim(g, self.truth_grey, mask))
        s.seam_rms.append(seam_rms(projections, mask))
        found = locate_gcps(g, self.truth_grey, self.gcp_px[self._usable], search_px=self.search_px)
        s.gcp_offsets_px.append(found.offsets_px)

    def summary(self) -> dict[str, dict[str, float]]:
        """Per method: mean PSNR/SSIM/seam over frames, GCP error pooled over frames."""
        out: dict[str, dict[str, float]] = {}
        cm_per_px = 100.0 * self.spec.m_per_px
        for name, s in self.methods.items():
            offsets = np.vstack(s.gcp_offsets_px) if s.gcp_offsets_px else np.zeros((0, 2))
            err = np.hypot(offsets[:, 0], offsets[:, 1])
            found = np.isfinite(err)
            # points not found within the search radius count as at least that far off
            pooled = np.where(found, err, np.inf)
            out[name] = {
                "psnr_db": float(np.nanmean(s.psnr_rgb)) if np.isfinite(s.psnr_rgb).any() else float("nan"),
                "psnr_grey_db": float(np.nanmean(s.psnr_grey)),
                "ssim": float(np.nanmean(s.ssim)),
                "seam_rms": float(np.nanmean(s.seam_rms)),
                "coverage": s.coverage,
                "gcp_count": float(len(err)),
                "gcp_found": float(found.sum()),
                "gcp_median_px": float(np.median(pooled)) if len(err) else float("nan"),
                "gcp_median_cm": float(np.median(pooled)) * cm_per_px if len(err) else float("nan"),
                "gcp_p90_cm": float(np.percentile(pooled, 90, method="higher")) * cm_per_px
                if len(err)
                else float("nan"),
            }
        return out
