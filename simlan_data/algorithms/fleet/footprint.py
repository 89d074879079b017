"""Where a robot's footprint can be while it follows a route: regions made of capsules.

A capsule is a segment grown by a radius. A robot driving straight from ``a`` to ``b`` stays in the
capsule whose segment runs from its tail at ``a`` to its nose at ``b`` with its half width as
radius (its real rectangle, lengthwise a little more). Turning in place it stays in the circle of
its reach (footprint circumradius about base_link, the point it turns about). Two regions conflict
when some pair of their capsules comes closer than the two radii plus a margin: the exact distance
between segments, so two long robots side by side in an aisle keep their widths apart, not their
lengths.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Region = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]  # p (n,2), q (n,2), r (n,)


@dataclass(frozen=True)
class Shape:
    """A robot's footprint as the planner sees it (base_link frame, metres)."""

    back_m: float  # x of the tail (negative)
    front_m: float  # x of the nose
    half_width_m: float
    reach_m: float  # the circle it sweeps turning in place
    tolerance_m: float = 0.0  # how much half_width_m and reach_m were grown (tracking error)

    @classmethod
    def of(cls, footprint_m: tuple[float, float, float, float], *, tolerance_m: float = 0.0) -> Shape:
        """``footprint_m`` (x0, x1, y0, y1) grown by ``tolerance_m`` (tracking error) on every side."""
        x0, x1, y0, y1 = footprint_m
        half = max(abs(y0), abs(y1))
        reach = float(np.hypot(max(abs(x0), abs(x1)), half))
        return cls(min(x0, 0.0), max(x1, 0.0), half + tolerance_m, reach + tolerance_m, tolerance_m)

    def reversed(self) -> Shape:
        """The same footprint facing the other way (a robot reversing sweeps what it would
        driving forwards with this shape)."""
        return Shape(-self.front_m, -self.back_m, self.half_width_m, self.reach_m, self.tolerance_m)


def region(*parts: Region) -> Region:
    """The union of regions."""
    return (
        np.concatenate([p[0] for p in parts]),
        np.concatenate([p[1] for p in parts]),
        np.concatenate([p[2] for p in parts]),
    )


def circle(shape: Shape, xy: NDArray[np.float64]) -> Region:
    """Turning in place at ``xy``."""
    c = np.asarray(xy, dtype=float)[None, :]
    return c, c.copy(), np.array([shape.reach_m])


def pose(shape: Shape, xy: NDArray[np.float64], yaw_rad: float) -> Region:
    """Standing at ``xy`` facing ``yaw_rad``."""
    d = np.array([np.cos(yaw_rad), np.sin(yaw_rad)])
    c = np.asarray(xy, dtype=float)
    return (c + shape.back_m * d)[None, :], (c + shape.front_m * d)[None, :], np.array([shape.half_width_m])


def drive(shape: Shape, a: NDArray[np.float64], b: NDArray[np.float64]) -> Region:
    """Driving forward in a straight line from ``a`` to ``b`` (standing at ``b`` included)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    length = float(np.linalg.norm(b - a))
    if length < 1e-9:
        return circle(shape, a)
    d = (b - a) / length
    return (a + shape.back_m * d)[None, :], (b + shape.front_m * d)[None, :], np.array([shape.half_width_m])


def segment_distances(
    p1: NDArray[np.float64], q1: NDArray[np.float64], p2: NDArray[np.float64], q2: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(n, m) distances between segments p1q1 (n) and p2q2 (m), exact (0 where they cross)."""
    return pair_distances(p1[:, None, :], q1[:, None, :], p2[None, :, :], q2[None, :, :])


def pair_distances(
    p1: NDArray[np.float64], q1: NDArray[np.float64], p2: NDArray[np.float64], q2: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distances between segments p1[i]q1[i] and p2[i]q2[i] (arrays broadcast), exact (0 where
    they cross)."""
    d = np.minimum(
        np.minimum(_point_segment(p1, p2, q2), _point_segment(q1, p2, q2)),
        np.minimum(_point_segment(p2, p1, q1), _point_segment(q2, p1, q1)),
    )
    return np.where(_crossing(p1, q1, p2, q2), 0.0, d)


def _point_segment(
    x: NDArray[np.float64], p: NDArray[np.float64], q: NDArray[np.float64]
) -> NDArray[np.float64]:
    seg = q - p
    den = np.maximum(np.sum(seg * seg, axis=-1), 1e-18)
    t = np.clip(np.sum((x - p) * seg, axis=-1) / den, 0.0, 1.0)
    return np.linalg.norm(x - (p + t[..., None] * seg), axis=-1)


def _crossing(
    a0: NDArray[np.float64], a1: NDArray[np.float64], b0: NDArray[np.float64], b1: NDArray[np.float64]
) -> NDArray[np.bool_]:
    def cross(o: NDArray[np.float64], u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        return (u[..., 0] - o[..., 0]) * (v[..., 1] - o[..., 1]) - (u[..., 1] - o[..., 1]) * (
            v[..., 0] - o[..., 0]
        )

    d1, d2 = cross(b0, b1, a0), cross(b0, b1, a1)
    d3, d4 = cross(a0, a1, b0), cross(a0, a1, b1)
    return (d1 * d2 < 0) & (d3 * d4 < 0)


def conflict(a: Region, b: Region, margin_m: float) -> bool:
    """Whether the two regions come closer than ``margin_m``."""
    if not len(a[2]) or not len(b[2]):
        return False
    dist = segment_distances(a[0], a[1], b[0], b[1])
    return bool((dist < a[2][:, None] + b[2][None, :] + margin_m).any())
