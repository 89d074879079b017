"""Camera rendering: RGB, metric depth and semantic labels, with lens distortion, layered.

Data flow per camera frame::

    static layer (rendered once, movable bodies hidden)        movable bodies' AABBs
          |                                                        | project to canvas
          v                                                        v
    ideal pinhole canvas  <-- restore last frame's regions --  regions of interest
          |               <-- render full scene in each region (off-axis projection)
          v
    cv2.remap with the camera's distortion maps --> distorted RGB / depth / labels (image size)

The canvas is an ideal (undistorted) pinhole image with the camera's focal length, large enough
to cover every valid ray of the distorted image. A region render uses the same projection
shifted to the region, so it equals the full render pixel for pixel; cameras that see no movable
body reuse their previous output. ``layered=False`` renders the whole canvas every frame (the
baseline the layered path is measured and tested against).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from .._pybullet import pb
from ..geometry.camera import CameraModel, linearize_depth, opengl_projection
from .pybullet_client import Client

EGL_MAX_TILE = (1024, 768)  # PyBullet's EGL window size: larger requests are upsampled, so tile
CANVAS_MARGIN_PX = 3
RENDER_CALL_COST_PX = 40_000  # measured: a render call's fixed cost equals about this many pixels

Rect = tuple[int, int, int, int]  # u0, v0, u1, v1 (exclusive), in canvas pixels
# corner index = 4 * ix + 2 * iy + iz over (lo, hi) per axis; edges join corners differing in one bit
_BOX_EDGES = [(i, i ^ bit) for i in range(8) for bit in (1, 2, 4) if i < i ^ bit]
Aabb = tuple[Sequence[float], Sequence[float]]


@dataclass
class CameraImages:
    """One camera frame: any of the streams may be None if not rendered."""

    rgb: NDArray[np.uint8] | None
    depth_m: NDArray[np.float32] | None
    labels: NDArray[np.uint8] | None
    changed: bool = True


class LabelTable:
    """Body id -> semantic class id lookup, growing as bodies are added."""

    def __init__(self) -> None:
        self._lut = np.zeros(1, dtype=np.uint8)  # index = body id + 1 (PyBullet's background is -1)

    def set(self, body: int, label: int) -> None:
        if body + 1 >= len(self._lut):
            grown = np.zeros(max(body + 2, 2 * len(self._lut)), dtype=np.uint8)
            grown[: len(self._lut)] = self._lut
            self._lut = grown
        self._lut[body + 1] = label

    def apply(self, seg: NDArray[np.int32]) -> NDArray[np.uint8]:
        idx = np.clip(seg + 1, 0, len(self._lut) - 1)
        return self._lut[idx]


def merge_rects(rects: list[Rect], *, slack_px: int = 0) -> list[Rect]:
    """Merge rectangles that overlap, or whose union costs at most ``slack_px`` extra pixels.

    A render call has a fixed cost (about 40,000 pixels' worth here), so close regions are
    cheaper rendered as one.
    """

    def area(r: Rect) -> int:
        return max(0, r[2] - r[0]) * max(0, r[3] - r[1])

    out = sorted(rects)
    merged = True
    while merged and len(out) > 1:
        merged = False
        result: list[Rect] = []
        for r in out:
            for i, q in enumerate(result):
                union = (min(r[0], q[0]), min(r[1], q[1]), max(r[2], q[2]), max(r[3], q[3]))
                overlap = r[0] < q[2] and q[0] < r[2] and r[1] < q[3] and q[1] < r[3]
                if overlap or area(union) - area(r) - area(q) <= slack_px:
                    result[i] = union
                    merged = True
                    break
            else:
                result.append(r)
        out = sorted(result)
    return out


class CameraRenderer:
    """Render one calibrated camera from a PyBullet client."""

    def __init__(
        self,
        client: Client,
        camera: CameraModel,
        labels: LabelTable,
        *,
        distort: bool = True,
        near_m: float = 1.0,
        far_m: float = 100.0,
        layered: bool = True,
    ) -> None:
        self.client, self.camera, self.labels = client, camera, labels
        self.distort, self.near_m, self.far_m, self.layered = distort, near_m, far_m, layered
        self._view = camera.opengl_view()
        # TinyRenderer samples pixel centres half a pixel off OpenGL's convention (measured:
        # +0.5 px in u, -0.5 px in v); shifting the principal point puts them back
        self._tiny_shift = (0.5, -0.5) if client.backend == "tiny" else (0.0, 0.0)
        self._setup_canvas()
        self._static: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._canvas: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._dirty: list[Rect] = []
        self._last: CameraImages | None = None
        self.regions_rendered = 0
        self.pixels_rendered = 0

    # ------------------------------------------------------------------------------ geometry
    def _setup_canvas(self) -> None:
        cam = self.camera
        fx, fy = cam.K[0, 0], cam.K[1, 1]
        if not self.distort:
            self.canvas_K = cam.K.copy()
            self.canvas_size = (cam.width, cam.height)
            self.valid_mask = np.ones((cam.height, cam.width), dtype=bool)
            self._maps = None
            return
        u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
        xy, ok = cam.undistort_pixels(np.stack([u.ravel(), v.ravel()], axis=1))
        if not ok.any():
            raise ValueError(f"camera {cam.camera_id}: no pixel has a valid ray")
        lo, hi = xy[ok].min(axis=0), xy[ok].max(axis=0)
        m = CANVAS_MARGIN_PX
        K = np.array([[fx, cam.K[0, 1], m - fx * lo[0]], [0.0, fy, m - fy * lo[1]], [0.0, 0.0, 1.0]])
        width = int(np.ceil(fx * (hi[0] - lo[0]))) + 2 * m + 1
        height = int(np.ceil(fy * (hi[1] - lo[1]))) + 2 * m + 1
        self.canvas_K, self.canvas_size = K, (width, height)
        map_x = (K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]).astype(np.float32)
        map_y = (K[1, 1] * xy[:, 1] + K[1, 2]).astype(np.float32)
        map_x[~ok], map_y[~ok] = -10.0, -10.0  # outside the canvas: filled with 0 by remap
        shape = (cam.height, cam.width)
        self.valid_mask = ok.reshape(shape)
        fixed = cv2.convertMaps(map_x.reshape(shape), map_y.reshape(shape), cv2.CV_16SC2)
        nearest = cv2.convertMaps(
            map_x.reshape(shape), map_y.reshape(shape), cv2.CV_16SC2, nninterpolation=True
        )
        self._maps = (fixed, nearest)

    def canvas_rects(self, aabbs: Sequence[Aabb]) -> list[Rect]:
        """Canvas regions covered by world AABBs (each box clipped at the near plane)."""
        width, height = self.canvas_size
        rects: list[Rect] = []
        K, cam_from_world = self.canvas_K, self.camera.camera_from_world
        for lo, hi in aabbs:
            corners = np.array(
                [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
            )
            pc = cam_from_world.apply(corners)
            front = pc[:, 2] > self.near_m
            if not front.any():
                continue
            pts = pc[front]
            if not front.all():  # add where the box edges cross the near plane
                crossings = []
                for i, j in _BOX_EDGES:
                    if front[i] != front[j]:
                        s_ = (self.near_m - pc[i, 2]) / (pc[j, 2] - pc[i, 2])
                        crossings.append(pc[i] + s_ * (pc[j] - pc[i]))
                pts = np.vstack([pts, np.array(crossings)])
            u = K[0, 0] * pts[:, 0] / pts[:, 2] + K[0, 1] * pts[:, 1] / pts[:, 2] + K[0, 2]
            v = K[1, 1] * pts[:, 1] / pts[:, 2] + K[1, 2]
            u0, v0 = max(0, int(np.floor(u.min())) - 1), max(0, int(np.floor(v.min())) - 1)
            u1, v1 = min(width, int(np.ceil(u.max())) + 2), min(height, int(np.ceil(v.max())) + 2)
            if u0 < u1 and v0 < v1:
                rects.append((u0, v0, u1, v1))
        return merge_rects(rects, slack_px=RENDER_CALL_COST_PX)

    # ----------------------------------------------------------------------------- rendering
    def _render_rect(self, rect: Rect) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Render the full scene in a canvas rectangle: RGB, metric depth, labels."""
        u0, v0, u1, v1 = rect
        rgb = np.empty((v1 - v0, u1 - u0, 3), dtype=np.uint8)
        depth = np.empty((v1 - v0, u1 - u0), dtype=np.float32)
        labels = np.empty((v1 - v0, u1 - u0), dtype=np.uint8)
        tw, th = EGL_MAX_TILE if self.client.backend == "egl" else (u1 - u0, v1 - v0)
        for tv in range(v0, v1, th):
            for tu in range(u0, u1, tw):
                w, h = min(tw, u1 - tu), min(th, v1 - tv)
                K = self.canvas_K.copy()
                K[0, 2] -= tu + self._tiny_shift[0]
                K[1, 2] -= tv + self._tiny_shift[1]
                proj = opengl_projection(K, w, h, near_m=self.near_m, far_m=self.far_m)
                if self.client.backend == "egl":
                    _, _, c, d, s = pb.getCameraImage(
                        w,
                        h,
                        self._view,
                        proj,
                        flags=pb.ER_USE_PROJECTIVE_TEXTURE,
                        physicsClientId=self.client.id,
                    )
                else:
                    _, _, c, d, s = pb.getCameraImage(
                        w,
                        h,
                        self._view,
                        proj,
                        renderer=pb.ER_TINY_RENDERER,
                        shadow=0,
                        physicsClientId=self.client.id,
                    )
                c, d, s = (np.asarray(x) for x in (c, d, s))
                sl = (slice(tv - v0, tv - v0 + h), slice(tu - u0, tu - u0 + w))
                rgb[sl] = c.reshape(h, w, 4)[..., :3]
                depth[sl] = linearize_depth(d.reshape(h, w), near_m=self.near_m, far_m=self.far_m)
                labels[sl] = self.labels.apply(s.reshape(h, w).astype(np.int32))
                self.regions_rendered += 1
                self.pixels_rendered += w * h
        return rgb, depth, labels

    def _full_canvas(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        width, height = self.canvas_size
        return self._render_rect((0, 0, width, height))

    def render_static(self) -> None:
        """Render and keep the static layer (call while movable bodies are hidden)."""
        self._static = self._full_canvas()
        self._canvas = tuple(a.copy() for a in self._static)  # type: ignore[assignment]
        self._dirty = []
        self._last = None

    def _image_rect(self, rect: Rect) -> tuple[int, int, int, int]:
        """Bounding rectangle in the output image of the pixels that sample canvas ``rect``."""
        if self._maps is None:
            return rect
        u0, v0, u1, v1 = rect
        n = 24
        us, vs = np.linspace(u0 - 1, u1, n), np.linspace(v0 - 1, v1, n)
        border = np.concatenate(
            [
                np.stack([us, np.full(n, v0 - 1.0)], 1),
                np.stack([us, np.full(n, float(v1))], 1),
                np.stack([np.full(n, u0 - 1.0), vs], 1),
                np.stack([np.full(n, float(u1)), vs], 1),
            ]
        )
        K = self.canvas_K
        y = (border[:, 1] - K[1, 2]) / K[1, 1]
        x = (border[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        uv = self.camera.distort_normalized(np.stack([x, y], axis=1))
        cam = self.camera
        # the distortion is monotonic inside the valid radius: the border's image bounds the region
        return (
            max(0, int(np.floor(uv[:, 0].min())) - 2),
            max(0, int(np.floor(uv[:, 1].min())) - 2),
            min(cam.width, int(np.ceil(uv[:, 0].max())) + 3),
            min(cam.height, int(np.ceil(uv[:, 1].max())) + 3),
        )

    def _distort(
        self,
        canvas: tuple[np.ndarray, np.ndarray, np.ndarray],
        region: tuple[int, int, int, int] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distorted images of the canvas (of one output region if given)."""
        rgb, depth, labels = canvas
        if self._maps is None:
            if region is None:
                return rgb.copy(), depth.copy(), labels.copy()
            u0, v0, u1, v1 = region
            return rgb[v0:v1, u0:u1].copy(), depth[v0:v1, u0:u1].copy(), labels[v0:v1, u0:u1].copy()
        (m1, m2), (n1, n2) = self._maps
        if region is not None:
            u0, v0, u1, v1 = region
            m1, m2, n1, n2 = (None if m is None else m[v0:v1, u0:u1] for m in (m1, m2, n1, n2))
        return (
            cv2.remap(rgb, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0),
            cv2.remap(depth, n1, n2, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0),
            cv2.remap(labels, n1, n2, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0),
        )

    def _finish(
        self, canvas: tuple[np.ndarray, np.ndarray, np.ndarray], dirty: Sequence[Rect] | None = None
    ) -> CameraImages:
        """Distort the canvas into new output images; only ``dirty`` canvas regions if given."""
        last = self._last
        if dirty is None or last is None:
            out = CameraImages(*self._distort(canvas))
            out.changed = last is None or not (
                np.array_equal(out.rgb, last.rgb)
                and np.array_equal(out.depth_m, last.depth_m)
                and np.array_equal(out.labels, last.labels)
            )
        else:
            assert last.rgb is not None
            assert last.depth_m is not None
            assert last.labels is not None
            out = CameraImages(last.rgb.copy(), last.depth_m.copy(), last.labels.copy(), changed=False)
            for rect in dirty:
                u0, v0, u1, v1 = region = self._image_rect(rect)
                if u0 >= u1 or v0 >= v1:
                    continue
                for dst, new in zip((out.rgb, out.depth_m, out.labels), self._distort(canvas, region)):
                    if not out.changed and not np.array_equal(dst[v0:v1, u0:u1], new):
                        out.changed = True
                    dst[v0:v1, u0:u1] = new
        self._last = out
        return out

    def render(self, movable_aabbs: Sequence[Aabb] = ()) -> CameraImages:
        """Render the current scene; ``movable_aabbs`` bound every body that may have moved."""
        if not self.layered:
            return self._finish(self._full_canvas())
        if self._static is None or self._canvas is None:
            raise RuntimeError("render_static() must run before render() in layered mode")
        rects = self.canvas_rects(movable_aabbs)
        if not rects and not self._dirty and self._last is not None:
            last = self._last
            return CameraImages(last.rgb, last.depth_m, last.labels, changed=False)
        for u0, v0, u1, v1 in self._dirty:
            for layer, static in zip(self._canvas, self._static):
                layer[v0:v1, u0:u1] = static[v0:v1, u0:u1]
        for rect in rects:
            u0, v0, u1, v1 = rect
            for layer, new in zip(self._canvas, self._render_rect(rect)):
                layer[v0:v1, u0:u1] = new
        dirty = merge_rects(self._dirty + rects)
        self._dirty = rects
        return self._finish(self._canvas, dirty if self._last is not None else None)
