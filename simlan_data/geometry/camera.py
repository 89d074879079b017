"""Pinhole camera with OpenCV's 5-parameter distortion (k1 k2 p1 p2 k3) and fixed extrinsics.

Conventions:
- Pixel coordinates follow OpenCV: the centre of pixel (i, j) is (u, v) = (i, j), u right, v down.
- The camera (optical) frame follows OpenCV/REP-103: x right, y down, z forward.
- ``camera_from_world`` is SIMLAN's (rot_mat, t_vec): x_cam = R x_world + t.
- OpenGL matrices (for PyBullet) are 4x4 in column-major order, as ``getCameraImage`` expects.

Strong barrel distortion makes the polynomial radial model fold back beyond a radius (for the
GPSS cameras at about r = 1.3, i.e. near the image border). Pixels whose ray would lie beyond
``valid_radius`` have no valid ray: they are masked, as a real camera's vignetted corners.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, overload

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from simlan_data.geometry.rotations import FloatArray
from simlan_data.geometry.transforms import Transform

# Slope d(r_distorted)/d(r) below which the radial model is considered no longer valid: beyond it
# one output pixel would stretch over more than 10 pixels of the ideal image.
MIN_RADIAL_SLOPE = 0.1

# undistort_pixels works on so many points or fewer one point at a time in plain floats
SCALAR_MAX_POINTS = 8

_GL_FROM_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def _newton_terms(
    x: Any, y: Any, xd: Any, yd: Any, k1: float, k2: float, p1: float, p2: float, k3: float
) -> tuple[Any, Any, Any]:
    """One Newton step of inverting OpenCV's distortion at (x, y) towards (xd, yd): the Jacobian's
    determinant and the two numerators of the step (floats or arrays alike, the same operations in
    the same order, so the scalar and the vectorized path agree to the last bit)."""
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dR = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    ex = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
    ey = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
    a = radial + 2.0 * x * x * dR + 2.0 * p1 * y + 6.0 * p2 * x
    b = 2.0 * x * y * dR + 2.0 * p1 * x + 2.0 * p2 * y
    d = radial + 2.0 * y * y * dR + 6.0 * p1 * y + 2.0 * p2 * x
    return a * d - b * b, d * ex - b * ey, a * ey - b * ex


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A calibrated camera: intrinsics K, distortion D, image size and pose in the world."""

    camera_id: str
    width: int
    height: int
    K: FloatArray
    D: FloatArray
    camera_from_world: Transform
    frame_id: str = field(default="")

    def __post_init__(self) -> None:
        if not self.frame_id:
            object.__setattr__(self, "frame_id", f"camera_{self.camera_id}_optical_frame")

    # ----------------------------------------------------------------------------------- pose
    @cached_property
    def world_from_camera(self) -> Transform:
        return self.camera_from_world.inverse()

    @cached_property
    def position(self) -> FloatArray:
        """Camera centre in the world, -R^T t."""
        return self.world_from_camera.translation

    @property
    def projection_matrix(self) -> FloatArray:
        """P = K [R | t] (3x4), pixels from homogeneous world points, without distortion."""
        rt = np.hstack([self.camera_from_world.rotation, self.camera_from_world.translation[:, None]])
        return self.K @ rt

    # ------------------------------------------------------------------------------ intrinsics
    def scaled(self, width: int, height: int) -> CameraModel:
        """Return the same camera at another image resolution (pixel-centre aware scaling)."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, 0] *= sx
        K[1, 1] *= sy
        K[0, 2] = (self.K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * sy - 0.5
        return replace(self, width=int(width), height=int(height), K=K)

    @cached_property
    def valid_radius(self) -> float:
        """Largest normalized undistorted radius where the radial model is still monotonic."""
        k1, k2, _, _, k3 = (float(x) for x in self.D[:5])
        # slope(r) = 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 ; find its first r > 0 below MIN_RADIAL_SLOPE
        coeffs = [7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0 - MIN_RADIAL_SLOPE]  # in s = r^2
        roots = np.roots(coeffs) if any(abs(c) > 0 for c in coeffs[:3]) else np.array([])
        real = [r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 0]
        return float(np.sqrt(min(real))) if real else float("inf")

    @cached_property
    def normalized_bounds(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1): a box of ideal normalized coordinates that holds every ray reaching the
        image (its border undistorted, 2 % wider; the valid radius's square where the border lies
        beyond it). A point outside projects outside the image: a cheap test before OpenCV."""
        w, h = self.width - 1.0, self.height - 1.0
        t = np.linspace(0.0, 1.0, 65)
        border = np.concatenate(
            [
                np.column_stack([t * w, 0 * t]),
                np.column_stack([t * w, h + 0 * t]),
                np.column_stack([0 * t, t * h]),
                np.column_stack([w + 0 * t, t * h]),
            ]
        )
        xy, ok = self.undistort_pixels(border)
        r = self.valid_radius
        if not ok.all() or not np.isfinite(xy).all():
            return (-r, r, -r, r)
        x0, y0 = xy.min(axis=0)
        x1, y1 = xy.max(axis=0)
        mx, my = 0.02 * (x1 - x0), 0.02 * (y1 - y0)
        return (float(x0 - mx), float(x1 + mx), float(y0 - my), float(y1 + my))

    # ------------------------------------------------------------------------------ projection
    def world_to_camera(self, points_world: ArrayLike) -> FloatArray:
        return self.camera_from_world.apply(points_world)

    def project(
        self, points_world: ArrayLike, *, distort: bool = True
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Project world points (N, 3) to pixels (N, 2).

        Returns the pixels and a mask of points in front of the camera whose ray lies inside the
        valid model radius (pixels of other points are meaningless).
        """
        pts_cam = np.atleast_2d(self.world_to_camera(points_world))
        return self.project_camera_points(pts_cam, distort=distort)

    def project_camera_points(
        self, pts_cam: ArrayLike, *, distort: bool = True
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        pts = np.atleast_2d(np.asarray(pts_cam, dtype=float))
        z = pts[:, 2]
        front = z > 1e-9
        safe_z = np.where(front, z, 1.0)
        xy = pts[:, :2] / safe_z[:, None]
        ok = front & (np.hypot(xy[:, 0], xy[:, 1]) <= self.valid_radius)
        if distort:
            uv = self.distort_normalized(xy)
        else:
            uv = xy * [self.K[0, 0], self.K[1, 1]] + [self.K[0, 2], self.K[1, 2]]
        return uv, ok

    def distort_normalized(self, xy: ArrayLike) -> FloatArray:
        """Map ideal normalized coordinates (N, 2) to distorted pixels (N, 2) with OpenCV."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        pts = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
        uv, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K, self.D)
        return np.asarray(uv, dtype=np.float64).reshape(-1, 2)

    def undistort_pixels(self, uv: ArrayLike) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Map distorted pixels (N, 2) to ideal normalized coordinates (N, 2).

        Newton's method on the full model (radial + tangential), started from the exact inverse
        of the radial part on its monotonic branch. Returns the coordinates and a mask of pixels
        that have a valid ray (inside ``valid_radius``, re-projecting within 1e-3 px).
        """
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        if len(uv) <= SCALAR_MAX_POINTS:
            return self._undistort_few(uv)
        fx, fy, cx, cy, skew = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2], self.K[0, 1]
        yd = (uv[:, 1] - cy) / fy
        xd = (uv[:, 0] - cx - skew * yd) / fx
        target = np.stack([xd, yd], axis=1)
        k1, k2, p1, p2, k3 = (float(c) for c in self.D[:5])
        r_tab, rd_tab = self._radial_table
        rd = np.hypot(xd, yd)
        candidate = rd <= rd_tab[-1]
        r0 = np.interp(rd[candidate], rd_tab, r_tab)
        rdc = rd[candidate]
        scale = np.divide(r0, rdc, out=np.ones_like(rdc), where=rdc > 1e-12)
        xdc, ydc = xd[candidate], yd[candidate]
        x, y = xdc * scale, ydc * scale
        for _ in range(8):
            det, num_x, num_y = _newton_terms(x, y, xdc, ydc, k1, k2, p1, p2, k3)
            det = np.where(np.abs(det) < 1e-12, 1e-12, det)
            step_x = num_x / det
            step_y = num_y / det
            x = x - step_x
            y = y - step_y
            if np.max(np.abs(step_x) + np.abs(step_y), initial=0.0) < 1e-13:
                break
        x_all = np.zeros_like(xd)
        y_all = np.zeros_like(yd)
        x_all[candidate], y_all[candidate] = x, y
        x, y = x_all, y_all
        xy = np.stack([x, y], axis=1)
        finite = np.all(np.isfinite(xy), axis=1)
        xy = np.where(finite[:, None], xy, 0.0)
        residual_px = np.hypot(*((self._distort_numpy(xy) - target) * [fx, fy]).T)
        ok = finite & candidate & (np.hypot(xy[:, 0], xy[:, 1]) <= self.valid_radius) & (residual_px < 1e-3)
        return xy, ok

    def _undistort_few(self, uv: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """:meth:`undistort_pixels` for a few points (a marker's corners) in plain floats.

        The same Newton iteration per point; on four points numpy's per-call overhead made it
        about ten times slower than this (and it ran for every marker seen).
        """
        fx, fy, cx, cy, skew, k1, k2, p1, p2, k3 = self._float_params
        r_tab, rd_tab = self._radial_table_lists
        rd_max, valid_radius = rd_tab[-1], self.valid_radius
        out = np.zeros((len(uv), 2))
        ok = np.zeros(len(uv), dtype=bool)
        for i, (u, v) in enumerate(uv.tolist()):
            yd = (v - cy) / fy
            xd = (u - cx - skew * yd) / fx
            rd = math.hypot(xd, yd)
            if not rd <= rd_max:
                continue
            j = min(max(bisect.bisect_right(rd_tab, rd), 1), len(rd_tab) - 1)
            r0 = r_tab[j - 1] + (r_tab[j] - r_tab[j - 1]) * (rd - rd_tab[j - 1]) / (rd_tab[j] - rd_tab[j - 1])
            scale = r0 / rd if rd > 1e-12 else 1.0
            x, y = xd * scale, yd * scale
            for _ in range(8):
                det, num_x, num_y = _newton_terms(x, y, xd, yd, k1, k2, p1, p2, k3)
                if abs(det) < 1e-12:
                    det = 1e-12
                step_x = num_x / det
                step_y = num_y / det
                x, y = x - step_x, y - step_y
                if abs(step_x) + abs(step_y) < 1e-13:
                    break
            if not (math.isfinite(x) and math.isfinite(y)):
                continue
            x_re, y_re = distort_points(x, y, k1, k2, p1, p2, k3)
            ex, ey = (x_re - xd) * fx, (y_re - yd) * fy
            out[i] = x, y
            ok[i] = math.hypot(x, y) <= valid_radius and math.hypot(ex, ey) < 1e-3
        return out, ok

    @cached_property
    def _float_params(self) -> tuple[float, ...]:
        """fx, fy, cx, cy, skew, k1, k2, p1, p2, k3 as Python floats."""
        K, D = self.K, self.D
        k1, k2, p1, p2, k3 = (float(c) for c in D[:5])
        return (
            float(K[0, 0]),
            float(K[1, 1]),
            float(K[0, 2]),
            float(K[1, 2]),
            float(K[0, 1]),
            k1,
            k2,
            p1,
            p2,
            k3,
        )

    @cached_property
    def _radial_table_lists(self) -> tuple[list[float], list[float]]:
        r_tab, rd_tab = self._radial_table
        return r_tab.tolist(), rd_tab.tolist()

    @cached_property
    def _radial_table(self) -> tuple[FloatArray, FloatArray]:
        """Undistorted radius -> distorted radius on the monotonic branch (Newton's start)."""
        k1, k2, _, _, k3 = (float(c) for c in self.D[:5])
        r_tab = np.linspace(0.0, min(self.valid_radius, 10.0), 4097)
        return r_tab, r_tab * (1.0 + k1 * r_tab**2 + k2 * r_tab**4 + k3 * r_tab**6)

    def _distort_numpy(self, xy: FloatArray) -> FloatArray:
        """Apply the distortion to normalized coordinates, in normalized units (no K)."""
        return np.stack(distort_points(xy[:, 0], xy[:, 1], *self._float_params[5:]), axis=1)

    def pixel_rays(self, uv: ArrayLike, *, distorted: bool = True) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Return unit rays in the camera frame (N, 3) through pixels, and their validity."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        if distorted:
            xy, ok = self.undistort_pixels(uv)
        else:
            xy = (uv - [self.K[0, 2], self.K[1, 2]]) / [self.K[0, 0], self.K[1, 1]]
            ok = np.ones(len(uv), dtype=bool)
        rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True), ok

    def intersect_plane_z(
        self, uv: ArrayLike, z_m: float, *, distorted: bool = True
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Intersect pixel rays with the horizontal world plane z = ``z_m``; (N, 3) and validity."""
        rays_cam, ok = self.pixel_rays(uv, distorted=distorted)
        rays_w = rays_cam @ self.world_from_camera.rotation.T
        origin = self.position
        dz = rays_w[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z_m - origin[2]) / dz
        ok = ok & np.isfinite(s) & (s > 0)
        s = np.where(ok, s, 0.0)
        return origin + s[:, None] * rays_w, ok

    # ------------------------------------------------------------- a few points, plain floats
    # A marker has four corners: numpy's per-call overhead on arrays that small cost about five
    # times the arithmetic (the ground-constraint pose of every marker seen, ~0.2 ms each, most
    # of it with the GIL held). The same model as the array methods above; results agree with
    # them to rounding (tests/test_camera.py).

    @cached_property
    def _pose_floats(
        self,
    ) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """camera_from_world R (row-major) and t, world_from_camera R (row-major) and the centre."""
        cw, wc = self.camera_from_world, self.world_from_camera
        return (
            tuple(cw.rotation.ravel().tolist()),
            tuple(cw.translation.tolist()),
            tuple(wc.rotation.ravel().tolist()),
            tuple(self.position.tolist()),
        )

    def intersect_plane_z_few(
        self, uv: list[tuple[float, float]] | FloatArray, z_m: float
    ) -> list[tuple[float, float]] | None:
        """:meth:`intersect_plane_z` of a few distorted pixels: their (x, y) on the plane
        z = ``z_m``, or None if any of them has no valid ray or meets the plane behind the camera."""
        xy, ok = self._undistort_few(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        if not ok.all():
            return None
        _, _, (r00, r01, r02, r10, r11, r12, r20, r21, r22), (ox, oy, oz) = self._pose_floats
        out = []
        for x, y in xy.tolist():
            dz = r20 * x + r21 * y + r22  # the ray (x, y, 1) in the world
            if dz == 0.0:
                return None
            s = (z_m - oz) / dz
            if not (math.isfinite(s) and s > 0.0):
                return None
            out.append((ox + s * (r00 * x + r01 * y + r02), oy + s * (r10 * x + r11 * y + r12)))
        return out

    def project_few(self, points_world: list[tuple[float, float, float]]) -> list[tuple[float, float]] | None:
        """:meth:`project` of a few world points to distorted pixels (as ``cv2.projectPoints``:
        fx, fy, cx, cy and k1 k2 p1 p2 k3), or None if any is behind the camera or outside the
        valid radius."""
        (a00, a01, a02, a10, a11, a12, a20, a21, a22), (tx, ty, tz), _, _ = self._pose_floats
        fx, fy, cx, cy, _, k1, k2, p1, p2, k3 = self._float_params
        valid_radius = self.valid_radius
        out = []
        for px, py, pz in points_world:
            z = a20 * px + a21 * py + a22 * pz + tz
            if not z > 1e-9:
                return None
            x = (a00 * px + a01 * py + a02 * pz + tx) / z
            y = (a10 * px + a11 * py + a12 * pz + ty) / z
            if not math.hypot(x, y) <= valid_radius:
                return None
            xd, yd = distort_points(x, y, k1, k2, p1, p2, k3)
            out.append((fx * xd + cx, fy * yd + cy))
        return out

    # ------------------------------------------------------------------------------- OpenGL
    def opengl_view(self) -> list[float]:
        """World -> OpenGL eye matrix, column-major (PyBullet's viewMatrix)."""
        return (_GL_FROM_CV @ self.camera_from_world.matrix()).T.ravel().tolist()


@overload
def distort_points(
    x: float, y: float, k1: float, k2: float, p1: float, p2: float, k3: float
) -> tuple[float, float]: ...


@overload
def distort_points(
    x: FloatArray,
    y: FloatArray,
    k1: float | FloatArray,
    k2: float | FloatArray,
    p1: float | FloatArray,
    p2: float | FloatArray,
    k3: float | FloatArray,
) -> tuple[FloatArray, FloatArray]: ...


def distort_points(x: Any, y: Any, k1: Any, k2: Any, p1: Any, p2: Any, k3: Any) -> tuple[Any, Any]:
    """The radial + tangential model on normalized coordinates: distorted (x, y), normalized.

    Floats (one point, as the few-point methods use it) or arrays; the coefficients broadcast
    against ``x`` and ``y`` (several cameras at once)."""
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )


def opengl_projection(K: ArrayLike, width: int, height: int, *, near_m: float, far_m: float) -> list[float]:
    """OpenGL projection for an OpenCV K and image size, column-major (PyBullet's projectionMatrix).

    Pixel (i, j) of the rendered (top-row-first) image is the pixel centre (u, v) = (i, j) of K.
    A region of interest is rendered by shifting the principal point: K with cx - u0, cy - v0.
    """
    K = np.asarray(K, dtype=float)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    P = np.zeros((4, 4))
    P[0, 0] = 2.0 * fx / width
    P[0, 1] = -2.0 * K[0, 1] / width
    P[0, 2] = 1.0 - 2.0 * (cx + 0.5) / width
    P[1, 1] = 2.0 * fy / height
    P[1, 2] = 2.0 * (cy + 0.5) / height - 1.0
    P[2, 2] = -(far_m + near_m) / (far_m - near_m)
    P[2, 3] = -2.0 * far_m * near_m / (far_m - near_m)
    P[3, 2] = -1.0
    return P.T.ravel().tolist()


def linearize_depth(
    depth_buffer: NDArray[np.floating], *, near_m: float, far_m: float
) -> NDArray[np.float32]:
    """Convert an OpenGL depth buffer in [0, 1] to metric z-depth; background (1.0) becomes 0."""
    d = depth_buffer.astype(np.float64)
    z = far_m * near_m / (far_m - (far_m - near_m) * d)
    z[d >= 1.0] = 0.0
    return z.astype(np.float32)
