"""Geometry of the safety conditions: zones, stopping distance, swept footprints, CPA and TTC.

Pure shapely/numpy functions over poses and velocities. The safety tree (``safety.py``) evaluates
them on estimates; the evaluation evaluates the same functions on ground truth to tell when a
hazard really began (``evaluation/safety_metrics.py``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from shapely import affinity
from shapely.geometry import LineString, Point, Polygon, box
from shapely.ops import unary_union
from shapely.validation import explain_validity

from simlan_data.errors import ConfigError

Footprint = tuple[float, float, float, float]  # x0, x1, y0, y1 in base_link
Pose2D = tuple[float, float, float]  # x_m, y_m, yaw_rad in map

# ------------------------------------------------------------------------------------ zones


@dataclass(frozen=True)
class Zone:
    """A restricted area: a simple polygon in the map frame, for some robots or all."""

    name: str
    polygon: Polygon
    namespaces: tuple[str, ...] = ()  # robots it applies to; empty: every robot

    def applies_to(self, namespace: str) -> bool:
        return not self.namespaces or namespace in self.namespaces

    @property
    def points(self) -> list[tuple[float, float]]:
        return [(float(x), float(y)) for x, y in list(self.polygon.exterior.coords)[:-1]]


def make_zone(
    name: str, points: Sequence[Sequence[float]], namespaces: Sequence[str] = (), *, where: str
) -> Zone:
    """A zone from its corners (in order around it); ConfigError naming ``where`` if unusable."""
    if not name:
        raise ConfigError(f"invalid {where}.name=''", "config", "every zone needs a name", "add name: ...")
    try:
        pts = [[float(v) for v in p] for p in points]
        corners_ok = all(len(p) == 2 for p in pts)
    except (TypeError, ValueError):
        corners_ok = False
    if not corners_ok:
        raise ConfigError(
            f"invalid {where}.polygon={list(points)}",
            "config",
            "every corner must be [x_m, y_m] in the map frame",
            "give two numbers per corner",
        )
    if len({(float(x), float(y)) for x, y in pts}) < 3:
        raise ConfigError(
            f"invalid {where}.polygon={pts}",
            "config",
            f"zone '{name}' needs at least 3 distinct corners",
            "give the corners of the area in order around it",
        )
    poly = Polygon([(float(x), float(y)) for x, y in pts])
    if not poly.is_valid or poly.area <= 1e-9:
        why = explain_validity(poly) if not poly.is_valid else "it has no area"
        raise ConfigError(
            f"invalid {where}.polygon={pts}",
            "config",
            f"zone '{name}' is not a simple polygon ({why})",
            "list the corners in order around the area, without crossing edges",
        )
    return Zone(name, poly, tuple(namespaces))


# -------------------------------------------------------------------------------- footprints


def footprint_polygon(pose: Pose2D, footprint: Footprint, *, grow_m: float = 0.0) -> Polygon:
    x, y, yaw = pose
    x0, x1, y0, y1 = footprint
    rect = box(x0 - grow_m, y0 - grow_m, x1 + grow_m, y1 + grow_m)
    return affinity.translate(affinity.rotate(rect, yaw, origin=(0, 0), use_radians=True), x, y)


def tail_first(pose: Pose2D, footprint: Footprint) -> tuple[Pose2D, Footprint]:
    """The same rectangle described facing the other way (heading + pi): a robot driving backwards
    moves "forwards" in this description, so sweeps and rollouts need no sign of their own."""
    x0, x1, y0, y1 = footprint
    return (pose[0], pose[1], pose[2] + np.pi), (-x1, -x0, -y1, -y0)


def footprint_centre(pose: Pose2D, footprint: Footprint) -> NDArray[np.float64]:
    """Centre of the footprint rectangle in the map (base_link need not be at the centre)."""
    x, y, yaw = pose
    x0, x1, y0, y1 = footprint
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([x + c * cx - s * cy, y + s * cx + c * cy])


def circumradius(footprint: Footprint) -> float:
    """Radius of the circle about the footprint's centre that holds the whole footprint."""
    x0, x1, y0, y1 = footprint
    return float(np.hypot(0.5 * (x1 - x0), 0.5 * (y1 - y0)))


def centre_velocity(
    pose: Pose2D, footprint: Footprint, speed_mps: float, yaw_rate_rps: float
) -> NDArray[np.float64]:
    """Velocity of the footprint's centre of a unicycle moving at (v, w) along its heading."""
    x, y, yaw = pose
    centre = footprint_centre(pose, footprint)
    r = centre - np.array([x, y])
    return speed_mps * np.array([np.cos(yaw), np.sin(yaw)]) + yaw_rate_rps * np.array([-r[1], r[0]])


# ---------------------------------------------------------------------------- stopping and sweeps


def stopping_distance_m(speed_mps: float, decel_mps2: float, reaction_s: float) -> float:
    """Distance to standstill: driving on for the reaction time, then braking at ``decel_mps2``."""
    v = abs(speed_mps)
    return v * reaction_s + v * v / (2.0 * decel_mps2)


def swept_rollout(
    pose: Pose2D,
    footprint: Footprint,
    speed_mps: float,
    yaw_rate_rps: float,
    *,
    decel_mps2: float,
    reaction_s: float,
    lookahead_m: float,
    step_m: float = 0.25,
) -> Polygon:
    """Footprint swept while a unicycle at (v, w) reacts, brakes to standstill and ``lookahead_m`` more.

    The robot keeps (v, w) for ``reaction_s``, then brakes at ``decel_mps2`` with its turn rate
    shrinking in proportion to its speed (it keeps its curvature). ``lookahead_m`` extends the sweep
    straight on in the direction of travel: a robot stopped at a boundary must not creep over it.
    """
    v, w = float(speed_mps), float(yaw_rate_rps)
    x, y, yaw = pose
    shapes = [footprint_polygon(pose, footprint)]
    brake_s = abs(v) / decel_mps2
    total_s = reaction_s + brake_s
    distance = stopping_distance_m(v, decel_mps2, reaction_s)
    n = max(2, int(np.ceil(max(distance / step_m, abs(w) * total_s / 0.15))))
    t_prev = 0.0
    for i in range(1, n + 1):
        t = total_s * i / n
        dt = t - t_prev
        t_mid = 0.5 * (t + t_prev)
        factor = 1.0 if t_mid <= reaction_s else max(0.0, 1.0 - (t_mid - reaction_s) / max(brake_s, 1e-9))
        yaw_mid = yaw + 0.5 * w * factor * dt
        x += v * factor * np.cos(yaw_mid) * dt
        y += v * factor * np.sin(yaw_mid) * dt
        yaw += w * factor * dt
        shapes.append(footprint_polygon((x, y, yaw), footprint))
        t_prev = t
    if lookahead_m > 0 and abs(v) > 1e-3:
        sign = 1.0 if v > 0 else -1.0
        ahead = (x + sign * lookahead_m * np.cos(yaw), y + sign * lookahead_m * np.sin(yaw), yaw)
        shapes.append(footprint_polygon(ahead, footprint))
    return _chain_hull(shapes)


def _chain_hull(shapes: list[Polygon]) -> Polygon:
    """Union of the convex hulls of consecutive footprints: the area swept between samples."""
    return unary_union([unary_union([a, b]).convex_hull for a, b in itertools.pairwise(shapes)])


def path_ahead(plan_xy: NDArray[np.float64], x: float, y: float, length_m: float) -> NDArray[np.float64]:
    """The part of a planned path from the point closest to (x, y), ``length_m`` long (N, 2)."""
    plan = np.asarray(plan_xy, dtype=float).reshape(-1, 2)
    if len(plan) < 2 or length_m <= 0:
        return np.array([[x, y]])
    line = LineString(plan)
    s0 = line.project(Point(x, y))
    s1 = min(line.length, s0 + length_m)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(plan, axis=0), axis=1))])
    inner = plan[(cum > s0) & (cum < s1)]
    start = np.asarray(line.interpolate(s0).coords[0])
    end = np.asarray(line.interpolate(s1).coords[0])
    return np.vstack([[x, y], start, inner, end])


def swept_path(
    pose: Pose2D, footprint: Footprint, path_xy: NDArray[np.float64], *, step_m: float = 0.25
) -> Polygon:
    """Footprint swept along ``path_xy`` (from the robot's position), heading along the path."""
    shapes = [footprint_polygon(pose, footprint)]
    path = np.asarray(path_xy, dtype=float)
    if len(path) >= 2:
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        if cum[-1] > 1e-6:
            for s in np.append(np.arange(step_m, cum[-1], step_m), cum[-1]):
                px = float(np.interp(s, cum, path[:, 0]))
                py = float(np.interp(s, cum, path[:, 1]))
                a = max(0.0, s - 0.3)
                b = min(cum[-1], s + 0.3)
                dx = np.interp(b, cum, path[:, 0]) - np.interp(a, cum, path[:, 0])
                dy = np.interp(b, cum, path[:, 1]) - np.interp(a, cum, path[:, 1])
                shapes.append(footprint_polygon((px, py, float(np.arctan2(dy, dx))), footprint))
    return _chain_hull(shapes) if len(shapes) > 1 else shapes[0]


# ------------------------------------------------------------------------------- CPA and TTC


@dataclass(frozen=True)
class Approach:
    """How two agents approach each other if both keep their velocities."""

    cpa_m: float  # distance between the centres at the closest point of approach
    t_cpa_s: float  # time to the closest point of approach (SIMLAN's TTC); < 0: moving apart
    ttc_s: float  # time until the bounding circles touch (<= t_cpa_s), or t_cpa_s if they never do
    distance_m: float  # distance between the centres now


def approach(
    p_self: NDArray[np.float64],
    v_self: NDArray[np.float64],
    p_other: NDArray[np.float64],
    v_other: NDArray[np.float64],
    contact_m: float,
) -> Approach:
    """Closest point of approach and time to collision of two constant-velocity agents.

    SIMLAN's rule: ``t_cpa = -(p . v) / |v|^2`` and ``cpa = |p + v t_cpa|`` on the relative
    position p and velocity v. SIMLAN's TTC is ``t_cpa``: for large robots at low speed the
    bodies touch well before the centres are closest, so the TTC here is the time the circles
    of radius ``contact_m`` (the sum of both bounding radii) first touch, when they do.
    """
    p = np.asarray(p_other, dtype=float) - np.asarray(p_self, dtype=float)
    v = np.asarray(v_other, dtype=float) - np.asarray(v_self, dtype=float)
    dist = float(np.hypot(p[0], p[1]))
    vv = float(v @ v)
    if vv < 1e-9:
        return Approach(dist, float("inf"), float("inf"), dist)
    t_cpa = -float(p @ v) / vv
    cpa = float(np.linalg.norm(p + v * t_cpa))
    ttc = t_cpa
    if t_cpa >= 0 and cpa < contact_m:
        if dist <= contact_m:
            ttc = 0.0
        else:  # |p + v t| = R, earlier root
            ttc = max(0.0, t_cpa - float(np.sqrt(max(contact_m**2 - cpa**2, 0.0) / vv)))
    return Approach(cpa, t_cpa, ttc, dist)
