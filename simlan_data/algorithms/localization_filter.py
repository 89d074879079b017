"""The per-agent filter of the camera localization: a unicycle EKF over fused marker fixes.

Split from :mod:`simlan_data.algorithms.localization` (which re-exports both names).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simlan_data.constants import NS_PER_S
from simlan_data.geometry.rotations import wrap_angle


@dataclass(frozen=True)
class PoseFix:
    """A fused base_link pose in map from one frame set (image stamp)."""

    namespace: str
    stamp_ns: int
    x_m: float
    y_m: float
    yaw_rad: float
    sigma_xy_m: float
    sigma_yaw_rad: float
    cameras: tuple[str, ...]


class UnicycleEKF:
    """Extended Kalman filter over (x, y, yaw, v, w) of a differential-drive robot.

    Between fixes the robot moves as commanded when its velocity commands are known (the central
    GPSS node sent them), else at constant speed and yaw rate; the process noise covers how
    well the robot tracks them. With ``accel_mps2`` > 0 its speed reaches a new command at that
    rate (a robot stopped by its safety layer brakes over a few centimetres: a filter that
    stopped at once would fall behind by as much), else at once.
    """

    def __init__(self, accel_noise: float, yaw_accel_noise: float, accel_mps2: float = 0.0) -> None:
        self.accel_mps2 = float(accel_mps2)
        self.q = np.array([accel_noise**2, yaw_accel_noise**2])
        self._Q = np.diag(self.q)
        self.x = np.zeros(5)
        self.P = np.eye(5)
        self.t_ns: int | None = None
        self.commands: list[tuple[int, float, float]] = []  # (from t_ns, v, w), time-ordered
        # the last prediction from the current state: (t_ns, x, P) there. A later prediction whose
        # segments pass through t_ns (a command starts there) goes on from it: the same steps on
        # the same numbers as from the start, so the same result to the last bit
        self._memo: tuple[int, NDArray[np.float64], NDArray[np.float64]] | None = None

    def command(self, t_ns: int, v: float, w: float) -> None:
        if self._memo is not None and t_ns < self._memo[0]:
            self._memo = None  # (out of order: the memo's segments did not know this command)
        self.commands.append((t_ns, v, w))
        if self.t_ns is not None:  # keep the command active at the filter's time and later ones
            while len(self.commands) >= 2 and self.commands[1][0] <= self.t_ns:
                self.commands.pop(0)

    def _propagate(
        self, x: NDArray[np.float64], P: NDArray[np.float64], dt: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        # the unicycle moved by dt and its Jacobians, each sine and cosine computed once (the same
        # floating-point operations as before: replays of older recordings equal their live runs)
        px, py, th, v, w = x
        s, c = np.sin(th), np.cos(th)
        F = np.eye(5)
        F[0, 2], F[0, 3] = -v * s * dt, c * dt
        F[1, 2], F[1, 3] = v * c * dt, s * dt
        F[2, 4] = dt
        G = np.array([[0.5 * c * dt**2, 0], [0.5 * s * dt**2, 0], [0, 0.5 * dt**2], [dt, 0], [0, dt]])
        moved = np.array([px + v * c * dt, py + v * s * dt, th + w * dt, v, w])
        return moved, F @ P @ F.T + G @ self._Q @ G.T

    def _predicted(self, t_ns: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        assert self.t_ns is not None
        if t_ns <= self.t_ns:
            return self.x.copy(), self.P.copy()
        memo = self._memo
        if memo is not None and memo[0] == t_ns:
            return memo[1].copy(), memo[2].copy()
        x, P = self.x, self.P
        cuts = [c[0] for c in self.commands if self.t_ns < c[0] < t_ns]
        if memo is not None and memo[0] in cuts:
            cuts = cuts[cuts.index(memo[0]) + 1 :]
            times = [memo[0], *cuts, t_ns]
            x, P = memo[1], memo[2]
        else:
            times = [self.t_ns, *cuts, t_ns]
        x = x.copy()
        for a, b in itertools.pairwise(times):
            active = [c for c in self.commands if c[0] <= a]
            if active:
                x, P = self._follow(x, P, (b - a) / NS_PER_S, active[-1][1], active[-1][2])
            else:
                x, P = self._propagate(x, P, (b - a) / NS_PER_S)
        self._memo = (t_ns, x.copy(), P.copy())
        return x, P

    def _follow(
        self, x: NDArray[np.float64], P: NDArray[np.float64], dt: float, v_cmd: float, w_cmd: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Move by ``dt`` under the command (v_cmd, w_cmd): the speed reaches v_cmd at
        ``accel_mps2`` (at once if 0), travelling at the ramp's mean speed while it changes."""
        x[4] = w_cmd
        gap = v_cmd - float(x[3])
        if self.accel_mps2 <= 0 or gap == 0.0:
            x[3] = v_cmd
            return self._propagate(x, P, dt)
        ramp_s = abs(gap) / self.accel_mps2
        h = min(dt, ramp_s)
        v_end = v_cmd if h == ramp_s else float(x[3]) + np.copysign(self.accel_mps2 * h, gap)
        x[3] = 0.5 * (float(x[3]) + v_end)  # (a straight ramp's distance exactly)
        x, P = self._propagate(x, P, h)
        x[3] = v_end
        if dt > h:
            x, P = self._propagate(x, P, dt - h)
        return x, P

    def _command_at(self, t_ns: int) -> tuple[float, float] | None:
        active = [c for c in self.commands if c[0] <= t_ns]
        return (active[-1][1], active[-1][2]) if active else None

    def reset(self, fix: PoseFix) -> None:
        self._memo = None
        # a robot first seen (or found again) moves as last commanded, if known: starting it from
        # rest would make the filter brake it, then lag behind while the speed ramps up again
        v, w = (self._command_at(fix.stamp_ns) or (0.0, 0.0)) if self.accel_mps2 > 0 else (0.0, 0.0)
        self.x = np.array([fix.x_m, fix.y_m, fix.yaw_rad, v, w])
        self.P = np.diag([fix.sigma_xy_m**2, fix.sigma_xy_m**2, fix.sigma_yaw_rad**2, 1.0, 1.0])
        self.t_ns = fix.stamp_ns

    def update(self, fix: PoseFix, gate_sigma: float) -> bool:
        """Predict to the fix's stamp and fuse it; False (and no change) if gated out."""
        x, P = self._predicted(fix.stamp_ns)
        innovation = np.array([fix.x_m - x[0], fix.y_m - x[1], float(wrap_angle(fix.yaw_rad - x[2]))])
        R = np.diag([fix.sigma_xy_m**2, fix.sigma_xy_m**2, fix.sigma_yaw_rad**2])
        S = P[:3, :3] + R
        if float(innovation @ np.linalg.solve(S, innovation)) > gate_sigma**2:
            return False
        K = P[:, :3] @ np.linalg.inv(S)
        self._memo = None
        self.x = x + K @ innovation
        self.x[2] = float(wrap_angle(self.x[2]))
        self.P = (np.eye(5) - K[:, :3] @ np.eye(3, 5)) @ P
        self.P = 0.5 * (self.P + self.P.T)
        self.t_ns = fix.stamp_ns
        return True

    def at(self, t_ns: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """State and covariance extrapolated to ``t_ns`` (the filter itself is unchanged)."""
        return self._predicted(t_ns)
