"""Camera rendering: RGB, metric depth, semantic labels and instance ids, with lens distortion, layered.

Data flow per camera frame::

    static layer (rendered once, agents absent):               boxes of bodies that moved
    RGB, depth, labels                                             | project to canvas
          |                                                        v
          v                                                 regions of interest
    ideal pinhole canvas  <-- restore the regions from the static layer
          |               <-- dynamic layer: the client rendered in each region (off-axis
          |                   projection), its nearer pixels composited over the static layer
          v
    cv2.remap with the camera's distortion maps --> distorted RGB / depth / labels (image size)

The canvas is an ideal (undistorted) pinhole image with the camera's focal length, large enough
to cover every valid ray of the distorted image. A region render uses the same projection
shifted to the region, so it equals the full render pixel for pixel. A dynamic pixel replaces
the static one where it is nearer (or the static layer saw nothing there): with the warehouse's
meshes still in the client the region shows the whole scene and composites to the same image;
the simulation removes them once the static layers exist (``sim/dynamic_layer.py``), so region
renders draw only what moves. Cameras that see no moved body reuse their previous output.
``layered=False`` renders the whole canvas every frame (the baseline the layered path is measured
and tested against).

With the ``instance`` stream the label layer holds PyBullet's body id + 1 (uint16) instead of the
class id: compositing and distortion (nearest neighbour) treat it alike, and the output's class
labels and instance ids are two lookups of it (``LabelTable``s), from the one segmentation pass.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.geometry.camera import CameraModel, linearize_depth, opengl_projection
from simlan_data.sim.pybullet_client import Client
from simlan_data.world._pybullet import pb

EGL_MAX_TILE = (1024, 768)  # PyBullet's EGL window size: larger requests are upsampled, so tile
CANVAS_MARGIN_PX = 3
# measured (benchmarks/perf.py): a region render's fixed cost equals about this many pixels of
# region; closer regions are cheaper rendered as one
RENDER_CALL_COST_PX = 40_000
STREAMS = ("rgb", "depth", "semantic")  # (the default; "instance" is asked for by name)

Rect = tuple[int, int, int, int]  # u0, v0, u1, v1 (exclusive), in canvas pixels
# corner index = 4 * ix + 2 * iy + iz over (lo, hi) per axis; edges join corners differing in one bit
_BOX_EDGES = [(i, i ^ bit) for i in range(8) for bit in (1, 2, 4) if i < i ^ bit]
_CORNER_BITS = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)])  # (8, 3): lo/hi per axis
Aabb = tuple[Sequence[float], Sequence[float]]
Layers = tuple[np.ndarray, np.ndarray, "np.ndarray | None"]  # rgb, depth (m, 0 = nothing), labels


@dataclass
class CameraImages:
    """One camera frame: any of the streams may be None if not rendered."""

    rgb: NDArray[np.uint8] | None
    depth_m: NDArray[np.float32] | None
    labels: NDArray[np.uint8] | None
    changed: bool = True
    instances: NDArray[np.uint16] | None = None  # instance (track) ids, 0 = none (stream "instance")


class LabelTable:
    """Body id -> semantic class id (or instance id: ``dtype=np.uint16``) lookup, growing as bodies
    are added."""

    def __init__(self, dtype: type[np.unsignedinteger] = np.uint8) -> None:
        self._lut = np.zeros(1, dtype=dtype)  # index = body id + 1 (PyBullet's background is -1)

    def set(self, body: int, label: int) -> None:
        if body + 1 >= len(self._lut):
            grown = np.zeros(max(body + 2, 2 * len(self._lut)), dtype=self._lut.dtype)
            grown[: len(self._lut)] = self._lut
            self._lut = grown
        self._lut[body + 1] = label

    def apply(self, seg: NDArray[np.int32]) -> NDArray[np.uint8]:
        idx = np.clip(seg + 1, 0, len(self._lut) - 1)
        return self._lut[idx]

    def apply_index(self, index: NDArray[Any]) -> NDArray[Any]:
        """Look up an image of body id + 1 (0 = background), as the instance mode's layers hold."""
        return np.take(self._lut, index, mode="clip")  # (clip: 1.5x faster than np.minimum + index)


def merge_rects(rects: list[Rect], *, slack_px: int = 0) -> list[Rect]:
    """Merge rectangles that overlap, or whose union costs at most ``slack_px`` extra pixels.

    A render call has a fixed cost (see RENDER_CALL_COST_PX), so close regions are cheaper
    rendered as one.
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
    """Render one calibrated camera from a PyBullet client.

    ``streams`` says which outputs are needed: without ``semantic`` no segmentation pass runs
    (PyBullet's EGL renderer draws the scene twice for it) and ``labels`` is None; without
    ``depth`` the output ``depth_m`` is None (depth is still rendered: layers composite by it).
    With ``instance`` (and an ``instances`` table: body id -> instance id) the output carries
    ``instances`` as well, from the same segmentation pass.
    """

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
        streams: Sequence[str] = STREAMS,
        instances: LabelTable | None = None,
    ) -> None:
        self.client, self.camera, self.labels = client, camera, labels
        self.distort, self.near_m, self.far_m, self.layered = distort, near_m, far_m, layered
        self.instances = instances if "instance" in streams else None
        self.want_depth = "depth" in streams
        self.want_labels = "semantic" in streams or self.instances is not None
        self._public: CameraImages | None = None  # instance mode: the last output, looked up
        self._view = camera.opengl_view()
        self._setup_canvas()
        self._static: Layers | None = None
        self._canvas: Layers | None = None
        self._last: CameraImages | None = None
        self._depth: np.ndarray | None = None  # the last render's canvas depth (surface_depth_m)
        self.regions_rendered = 0
        self.pixels_rendered = 0

    # ------------------------------------------------------------------------------ geometry
    def _setup_canvas(self) -> None:
        cam = self.camera
        fx, fy = cam.K[0, 0], cam.K[1, 1]
        if not self.distort:
            self.canvas_K = cam.K.copy()
            self.canvas_size = (cam.width, cam.height)
            self.valid_mask: NDArray[np.bool_] = np.ones((cam.height, cam.width), dtype=bool)
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
        self.valid_mask = np.asarray(ok, dtype=bool).reshape(shape)
        fixed = cv2.convertMaps(map_x.reshape(shape), map_y.reshape(shape), cv2.CV_16SC2)
        nearest = cv2.convertMaps(
            map_x.reshape(shape), map_y.reshape(shape), cv2.CV_16SC2, nninterpolation=True
        )
        self._maps = (fixed, nearest)

    def canvas_rects(self, aabbs: Sequence[Aabb]) -> list[Rect]:
        """Canvas regions covered by world AABBs (each box clipped at the near plane)."""
        if len(aabbs) == 0:
            return []
        width, height = self.canvas_size
        cam_from_world = self.camera.camera_from_world
        boxes = np.asarray(aabbs, dtype=float).reshape(-1, 2, 3)
        corners = boxes[:, _CORNER_BITS, np.arange(3)]  # (N, 8, 3)
        pc = corners @ cam_from_world.rotation.T + cam_from_world.translation
        front = pc[..., 2] > self.near_m
        whole = front.all(axis=1)
        lo, hi = np.full((len(pc), 2), np.inf), np.full((len(pc), 2), -np.inf)
        if whole.any():  # the usual case: boxes in front of the camera, vectorized
            uv = self._project(pc[whole].reshape(-1, 3)).reshape(-1, 8, 2)
            lo[whole], hi[whole] = uv.min(axis=1), uv.max(axis=1)
        for i in np.flatnonzero(front.any(axis=1) & ~whole):  # add where edges cross the near plane
            pts, fr = pc[i], front[i]
            crossings = [
                pts[a] + (self.near_m - pts[a, 2]) / (pts[b, 2] - pts[a, 2]) * (pts[b] - pts[a])
                for a, b in _BOX_EDGES
                if fr[a] != fr[b]
            ]
            uv = self._project(np.vstack([pts[fr], np.array(crossings)]))
            lo[i], hi[i] = uv.min(axis=0), uv.max(axis=0)
        seen = np.isfinite(lo[:, 0])
        u0 = np.maximum(0, np.floor(lo[seen, 0]).astype(int) - 1)
        v0 = np.maximum(0, np.floor(lo[seen, 1]).astype(int) - 1)
        u1 = np.minimum(width, np.ceil(hi[seen, 0]).astype(int) + 2)
        v1 = np.minimum(height, np.ceil(hi[seen, 1]).astype(int) + 2)
        keep = (u0 < u1) & (v0 < v1)
        rects = [
            (int(a), int(b), int(c), int(d)) for a, b, c, d in zip(u0[keep], v0[keep], u1[keep], v1[keep])
        ]
        return merge_rects(rects, slack_px=RENDER_CALL_COST_PX)

    def surface_depth_m(self, points_cam: NDArray[np.float64]) -> NDArray[np.float32]:
        """The last render's depth (m, camera z; 0 = nothing drawn or off the canvas) along the
        rays to camera-frame points (N, 3) in front of the camera, at the nearest canvas pixel.

        The canvas is the undistorted image the output is remapped from, so this is the depth
        the output's depth image holds at the points' distorted pixels, without remapping it
        (the keypoints' occlusion test; it also works without the depth stream).
        """
        out = np.zeros(len(points_cam), dtype=np.float32)
        if self._depth is None or len(points_cam) == 0:
            return out
        front = points_cam[:, 2] > 0
        uv = np.rint(self._project(points_cam[front]))
        height, width = self._depth.shape
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
        rows, cols = uv[inside, 1].astype(int), uv[inside, 0].astype(int)
        depth = np.zeros(len(uv), dtype=np.float32)
        depth[inside] = self._depth[rows, cols]
        out[front] = depth
        return out

    def _project(self, pc: np.ndarray) -> np.ndarray:
        """Canvas pixels (N, 2) of camera-frame points (N, 3) in front of the camera."""
        K = self.canvas_K
        x, y = pc[:, 0] / pc[:, 2], pc[:, 1] / pc[:, 2]
        return np.stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]], axis=1)

    # ----------------------------------------------------------------------------- rendering
    def _render_rect(self, rect: Rect) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Render a canvas rectangle: RGB, metric depth (0 = nothing drawn), labels if wanted."""
        client, want_labels = self.client, self.want_labels
        u0, v0, u1, v1 = rect
        rgb = np.empty((v1 - v0, u1 - u0, 3), dtype=np.uint8)
        depth = np.empty((v1 - v0, u1 - u0), dtype=np.float32)
        by_body = self.instances is not None
        out_labels = (
            np.empty((v1 - v0, u1 - u0), dtype=np.uint16 if by_body else np.uint8) if want_labels else None
        )
        tw, th = EGL_MAX_TILE if client.backend == "egl" else (u1 - u0, v1 - v0)
        # TinyRenderer samples pixel centres half a pixel off OpenGL's convention (measured:
        # +0.5 px in u, -0.5 px in v); shifting the principal point puts them back
        shift = (0.5, -0.5) if client.backend == "tiny" else (0.0, 0.0)
        for tv in range(v0, v1, th):
            for tu in range(u0, u1, tw):
                w, h = min(tw, u1 - tu), min(th, v1 - tv)
                K = self.canvas_K.copy()
                K[0, 2] -= tu + shift[0]
                K[1, 2] -= tv + shift[1]
                proj = opengl_projection(K, w, h, near_m=self.near_m, far_m=self.far_m)
                if client.backend == "egl":
                    flags = pb.ER_USE_PROJECTIVE_TEXTURE | (0 if want_labels else pb.ER_NO_SEGMENTATION_MASK)
                    _, _, c, d, s = pb.getCameraImage(
                        w, h, self._view, proj, flags=flags, physicsClientId=client.id
                    )
                else:
                    _, _, c, d, s = pb.getCameraImage(
                        w,
                        h,
                        self._view,
                        proj,
                        renderer=pb.ER_TINY_RENDERER,
                        shadow=0,
                        physicsClientId=client.id,
                    )
                sl = (slice(tv - v0, tv - v0 + h), slice(tu - u0, tu - u0 + w))
                rgb[sl] = np.asarray(c).reshape(h, w, 4)[..., :3]
                depth[sl] = linearize_depth(np.asarray(d).reshape(h, w), near_m=self.near_m, far_m=self.far_m)
                if out_labels is not None:
                    seg = np.asarray(s).reshape(h, w).astype(np.int32)
                    out_labels[sl] = np.clip(seg + 1, 0, 65535) if by_body else self.labels.apply(seg)
                self.regions_rendered += 1
                self.pixels_rendered += w * h
        return rgb, depth, out_labels

    def _full_canvas(self) -> Layers:
        width, height = self.canvas_size
        return self._render_rect((0, 0, width, height))

    def render_static(self) -> None:
        """Render and keep the static layer (call while movable bodies are hidden)."""
        self._static = self._full_canvas()
        self._canvas = tuple(None if a is None else a.copy() for a in self._static)  # type: ignore[assignment]
        self._last = None

    def _composite(self, rect: Rect) -> None:
        """Canvas region = static layer, with the dynamic layer's nearer pixels over it."""
        assert self._static is not None and self._canvas is not None
        u0, v0, u1, v1 = rect
        sl = (slice(v0, v1), slice(u0, u1))
        rgb, depth, labels = self._canvas
        s_rgb, s_depth, s_labels = self._static
        d_rgb, d_depth, d_labels = self._render_rect(rect)
        behind = s_depth[sl]
        front = (d_depth > 0) & ((d_depth <= behind) | (behind == 0))
        rgb[sl] = np.where(front[..., None], d_rgb, s_rgb[sl])
        depth[sl] = np.where(front, d_depth, behind)
        if labels is not None and s_labels is not None and d_labels is not None:
            labels[sl] = np.where(front, d_labels, s_labels[sl])

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
        self, canvas: Layers, region: tuple[int, int, int, int] | None = None
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Distorted images of the canvas (of one output region if given); unwanted streams None."""
        rgb, depth, labels = canvas
        want_depth, want_labels = self.want_depth, self.want_labels and labels is not None
        if self._maps is None:
            u0, v0, u1, v1 = region if region is not None else (0, 0, rgb.shape[1], rgb.shape[0])
            sl = (slice(v0, v1), slice(u0, u1))
            return (
                rgb[sl].copy(),
                depth[sl].copy() if want_depth else None,
                labels[sl].copy() if want_labels and labels is not None else None,
            )
        (m1, m2), (n1, n2) = self._maps
        if region is not None:
            u0, v0, u1, v1 = region
            m1, m2, n1, n2 = (None if m is None else m[v0:v1, u0:u1] for m in (m1, m2, n1, n2))

        def nearest(a: np.ndarray) -> np.ndarray:
            return cv2.remap(a, n1, n2, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

        return (
            cv2.remap(rgb, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0),
            nearest(depth) if want_depth else None,
            nearest(labels) if want_labels and labels is not None else None,
        )

    def _finish(self, canvas: Layers, dirty: Sequence[Rect] | None = None) -> CameraImages:
        """Distort the canvas into new output images; only ``dirty`` canvas regions if given."""
        self._depth = canvas[1]
        last = self._last
        if dirty is None or last is None:
            out = CameraImages(*self._distort(canvas))
            out.changed = last is None or not all(
                a is None or b is None or np.array_equal(a, b)
                for a, b in ((out.rgb, last.rgb), (out.depth_m, last.depth_m), (out.labels, last.labels))
            )
        else:
            assert last.rgb is not None
            out = CameraImages(
                last.rgb.copy(),
                None if last.depth_m is None else last.depth_m.copy(),
                None if last.labels is None else last.labels.copy(),
                changed=False,
            )
            for rect in dirty:
                u0, v0, u1, v1 = region = self._image_rect(rect)
                if u0 >= u1 or v0 >= v1:
                    continue
                dsts: tuple[np.ndarray | None, ...] = (out.rgb, out.depth_m, out.labels)
                for dst, new in zip(dsts, self._distort(canvas, region)):
                    if dst is None or new is None:
                        continue
                    if not out.changed and not np.array_equal(dst[v0:v1, u0:u1], new):
                        out.changed = True
                    dst[v0:v1, u0:u1] = new
        self._last = out
        return out

    def render(self, moved_aabbs: Sequence[Aabb] = ()) -> CameraImages:
        """Render the current scene.

        ``moved_aabbs`` bound everything that looks different than in the last render: every
        body that moved since, where it was then and where it is now (``MovedAgents.boxes`` in
        ``sim/dynamic_layer.py`` keeps that account). Without any, the last images are reused.
        """
        if not self.layered:
            return self._lookup(self._finish(self._full_canvas()))
        if self._static is None or self._canvas is None:
            raise RuntimeError("render_static() must run before render() in layered mode")
        rects = self.canvas_rects(moved_aabbs)
        if not rects and self._last is not None:
            if self._public is not None:
                return replace(self._public, changed=False)
            last = self._last
            return CameraImages(last.rgb, last.depth_m, last.labels, changed=False)
        for rect in rects:
            self._composite(rect)
        return self._lookup(self._finish(self._canvas, rects if self._last is not None else None))

    def _lookup(self, out: CameraImages) -> CameraImages:
        """Instance mode: the class labels and instance ids of the body-id image (else ``out``)."""
        if self.instances is None or out.labels is None:
            return out
        body = out.labels
        self._public = CameraImages(
            out.rgb,
            out.depth_m,
            self.labels.apply_index(body).astype(np.uint8, copy=False),
            changed=out.changed,
            instances=self.instances.apply_index(body).astype(np.uint16, copy=False),
        )
        return self._public
