"""Tracker trajectories (SIMLAN's replay format) as poses over time: interpolation and yaw faking.

A tracker reports, at each of its stamps, the objects it sees: ``(id, x, y, z, yaw)``. Objects
come and go between stamps. :class:`Tracks` holds them as arrays (stamp x object, NaN where an
object is absent) and answers where each object is at any time:

- between two stamps that both have the object: linear in x, y, z and in yaw (along the shorter
  arc);
- after a stamp that has it and before one that does not (the tracker's last sighting): held at
  that stamp's pose until the next stamp, where it is gone;
- at or after a stamp that lacks it (and before the next that has it): absent (``None``).

Yaw: the file's where it gives one that changes; where an object's yaw is missing (``NaN``) or
constant over all its stamps while it moves (a tracker that reports no heading, as the example
file does), it is estimated from the motion as SIMLAN's ``orientation_faker`` does: the heading
towards the next position at least ``min_move_m`` away, approached per stamp by a low-pass step
(``smoothing``) but at most ``max_step_rad``; no such position: the previous heading. Upstream
starts from a configured heading (0) and adds pi (its models face -x); ours face +x and start
from the first heading of the motion, so a robot does not spin in place at the start.

Pure numpy: no simulator, no file format (the JSON is parsed in ``simlan_data.config.trajectory``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["Tracks", "fake_yaw", "wrap_angle"]

NS_PER_MS = 1_000_000


def wrap_angle(a: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """Angles in [-pi, pi)."""
    return np.mod(np.asarray(a, dtype=np.float64) + np.pi, 2 * np.pi) - np.pi


def fake_yaw(
    xy: NDArray[np.float64], *, min_move_m: float = 0.02, smoothing: float = 0.3, max_step_rad: float = 0.5
) -> NDArray[np.float64]:
    """Headings of one object's successive positions ``xy`` (n x 2), from its motion (see module)."""
    n = len(xy)
    out = np.zeros(n)
    heading: float | None = None
    for i in range(n):
        target = _heading_to_next(xy, i, min_move_m)
        if heading is None:  # the first heading of the motion (0 if it never moves)
            heading = 0.0 if target is None else target
            for j in range(i + 1):
                out[j] = heading
            continue
        if target is not None:
            diff = float(wrap_angle(target - heading))
            step = math.copysign(max_step_rad, diff) if abs(diff) > max_step_rad else smoothing * diff
            heading = float(wrap_angle(heading + step))
        out[i] = heading
    return out


def _heading_to_next(xy: NDArray[np.float64], i: int, min_move_m: float) -> float | None:
    d = xy[i + 1 :] - xy[i]
    far = np.nonzero(np.hypot(d[:, 0], d[:, 1]) >= min_move_m)[0]
    if len(far) == 0:
        return None
    dx, dy = d[far[0]]
    return math.atan2(dy, dx)


@dataclass
class Tracks:
    """Objects' poses at a tracker's stamps (NaN where absent), with stamps relative to the first."""

    ids: list[int]  # in order of first appearance
    stamps_ns: NDArray[np.int64]  # (S,), from 0, increasing
    xyz: NDArray[np.float64]  # (S, N, 3)
    yaw: NDArray[np.float64]  # (S, N); NaN: absent or not given
    t0_ms: int = 0  # the file's first time_stamp

    @staticmethod
    def from_rows(stamps_ms: list[int], rows: list[list[tuple[int, float, float, float, float]]]) -> Tracks:
        """From the file's stamps (ms) and per stamp its ``(id, x, y, z, yaw)`` rows (yaw may be NaN)."""
        ids: list[int] = []
        for stamp_rows in rows:
            for r in stamp_rows:
                if r[0] not in ids:
                    ids.append(r[0])
        col = {oid: k for k, oid in enumerate(ids)}
        xyz = np.full((len(stamps_ms), len(ids), 3), np.nan)
        yaw = np.full((len(stamps_ms), len(ids)), np.nan)
        for s, stamp_rows in enumerate(rows):
            for oid, x, y, z, a in stamp_rows:
                xyz[s, col[oid]] = (x, y, z)
                yaw[s, col[oid]] = a
        stamps = (np.asarray(stamps_ms, dtype=np.int64) - stamps_ms[0]) * NS_PER_MS
        return Tracks(ids, stamps, xyz, yaw, t0_ms=int(stamps_ms[0]))

    @property
    def duration_s(self) -> float:
        return float(self.stamps_ns[-1]) / 1e9

    def present(self, k: int) -> NDArray[np.bool_]:
        """Which objects stamp ``k`` has."""
        return ~np.isnan(self.xyz[k, :, 0])

    def first_pose(self, oid: int) -> tuple[float, float, float]:
        """Where object ``oid`` is first seen: ``(x, y, yaw)`` (its spawn pose)."""
        j = self.ids.index(oid)
        k = int(np.nonzero(~np.isnan(self.xyz[:, j, 0]))[0][0])
        return float(self.xyz[k, j, 0]), float(self.xyz[k, j, 1]), float(self.yaw[k, j])

    def with_yaw_from_motion(self, **faker: float) -> Tracks:
        """A copy whose yaw is the file's where it varies, else faked from the motion (:func:`fake_yaw`)."""
        yaw = self.yaw.copy()
        for j in range(len(self.ids)):
            seen = np.nonzero(~np.isnan(self.xyz[:, j, 0]))[0]
            given = self.yaw[seen, j]
            if len(seen) > 1 and not np.isnan(given).any() and np.ptp(given) > 1e-9:
                continue  # the file's yaw changes: keep it
            if len(seen) == 1 and not np.isnan(given).any():
                continue  # one sighting with a yaw: keep it
            yaw[seen, j] = fake_yaw(self.xyz[seen, j, :2], **faker)
        return Tracks(self.ids, self.stamps_ns, self.xyz, yaw, t0_ms=self.t0_ms)

    def at(self, t_ns: int) -> list[tuple[float, float, float, float] | None]:
        """Every object's ``(x, y, z, yaw)`` at ``t_ns`` (None: absent), as the module describes."""
        k = int(np.searchsorted(self.stamps_ns, t_ns, side="right")) - 1
        k = min(max(k, 0), len(self.stamps_ns) - 1)
        nxt = min(k + 1, len(self.stamps_ns) - 1)
        span = float(self.stamps_ns[nxt] - self.stamps_ns[k])
        f = 0.0 if span <= 0 else min(max((t_ns - float(self.stamps_ns[k])) / span, 0.0), 1.0)
        out: list[tuple[float, float, float, float] | None] = []
        for j in range(len(self.ids)):
            if np.isnan(self.xyz[k, j, 0]):
                out.append(None)
                continue
            p, a = self.xyz[k, j], float(np.nan_to_num(self.yaw[k, j]))
            if nxt != k and not np.isnan(self.xyz[nxt, j, 0]) and f > 0:
                p = p + f * (self.xyz[nxt, j] - p)
                a = a + f * float(wrap_angle(float(np.nan_to_num(self.yaw[nxt, j], nan=a)) - a))
            out.append((float(p[0]), float(p[1]), float(p[2]), float(wrap_angle(a))))
        return out

    def velocities(self, t_ns: int) -> list[tuple[float, float]]:
        """Every object's ``(v, w)`` at ``t_ns``: the constant velocity of the interpolation between the
        stamps around ``t_ns`` (``v`` along the object's heading, signed; ``w`` its turn rate), zero
        where the object is held or absent. What a robot on that motion is commanded (upstream's
        ``scenario_replay`` feeds the tracker's velocities as ``cmd_vel`` the same way)."""
        k = min(max(int(np.searchsorted(self.stamps_ns, t_ns, side="right")) - 1, 0), len(self.stamps_ns) - 1)
        nxt = min(k + 1, len(self.stamps_ns) - 1)
        span_s = float(self.stamps_ns[nxt] - self.stamps_ns[k]) / 1e9
        out = []
        for j, pose in enumerate(self.at(t_ns)):
            if pose is None or span_s <= 0 or np.isnan(self.xyz[k, j, 0]) or np.isnan(self.xyz[nxt, j, 0]):
                out.append((0.0, 0.0))
                continue
            dx, dy = (self.xyz[nxt, j, :2] - self.xyz[k, j, :2]) / span_s
            a0 = float(np.nan_to_num(self.yaw[k, j]))
            dyaw = float(wrap_angle(float(np.nan_to_num(self.yaw[nxt, j], nan=a0)) - a0))
            out.append((float(dx * math.cos(pose[3]) + dy * math.sin(pose[3])), dyaw / span_s))
        return out
