"""Exposure over time: motion blur and rolling shutter from sub-frames (issue 24).

A camera integrates light over its exposure, and a rolling-shutter camera starts each row a line
time after the one above it. Here a camera tick at ``t`` renders ``K`` sub-frames: every moving
agent is put where it was ``d`` seconds earlier (its base pose moved back along its current
linear and angular velocity: exact for the constant speeds and turn rates of a few milliseconds),
every camera renders, and the agents are put back exactly (pose and velocity, so the physics
never sees it: ``tests/test_sensors_run.py`` compares the ground truth with and without). The
sub-frames span the latest row's exposure ``[t - E, t]`` plus the readout of the rows above
``(H - 1) * line_time``; image row ``r`` (counted from the top) ends its exposure at
``t - (H - 1 - r) * line_time`` and is the mean of the sub-frames within its window (the nearest
one where none is). So a moving edge blurs by speed x exposure and shears by speed x line time
per row, in pixels at the agent's distance, and nothing moves where nothing moved.

``K`` follows the motion: one sub-frame per ``px_per_sample`` pixels that the fastest agent moves
in any camera over the window, at most ``max_samples``; with less than that much motion ``K = 1``
and the frame is the ordinary render at ``t`` (no cost). Depth and labels are the sub-frame at
``t`` (ground truth at the stamp's instant).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simlan_data.config.sensors import ShutterConfig
from simlan_data.geometry.camera import CameraModel
from simlan_data.sim.agents import Agent
from simlan_data.sim.rendering import CameraImages
from simlan_data.world._pybullet import pb

MOVING_MPS = 1e-3  # slower than this (m/s, or rad/s times the agent's reach) counts as standing


@dataclass(frozen=True)
class _Motion:
    """An agent's base state at the tick, to move it back along (``expose`` restores the whole
    simulation afterwards)."""

    body: int
    client: int
    pos: tuple[float, float, float]
    orn: tuple[float, float, float, float]
    lin: tuple[float, float, float]
    ang: tuple[float, float, float]
    reach_m: float

    def speed_mps(self) -> float:
        return math.hypot(*self.lin) + math.hypot(*self.ang) * self.reach_m

    def place(self, back_s: float) -> None:
        """Put the base where it was ``back_s`` seconds before the tick (constant velocities)."""
        pos = [p - v * back_s for p, v in zip(self.pos, self.lin, strict=True)]
        rot = pb.getQuaternionFromAxisAngle(
            self.ang if any(self.ang) else (0.0, 0.0, 1.0), -math.hypot(*self.ang) * back_s
        )
        _, orn = pb.multiplyTransforms((0, 0, 0), rot, (0, 0, 0), self.orn)
        pb.resetBasePositionAndOrientation(self.body, pos, orn, physicsClientId=self.client)


def moving(agents: Sequence[Agent]) -> list[_Motion]:
    out = []
    for a in agents:
        pos, orn = pb.getBasePositionAndOrientation(a.body, physicsClientId=a.client)
        lin, ang = pb.getBaseVelocity(a.body, physicsClientId=a.client)
        lo, hi = np.asarray(pb.getAABB(a.body, -1, physicsClientId=a.client))
        m = _Motion(
            a.body,
            a.client,
            tuple(pos),
            tuple(orn),
            tuple(lin),
            tuple(ang),
            float(np.linalg.norm(hi - lo) / 2),
        )
        if m.speed_mps() > MOVING_MPS:
            out.append(m)
    return out


def window_s(cfg: ShutterConfig, exposure_s: float, height: int) -> float:
    """How far back the sub-frames reach: the exposure plus the readout of the rows above the last."""
    return exposure_s + (height - 1) * cfg.line_time_s


def samples(
    cfg: ShutterConfig, motions: Sequence[_Motion], cameras: Sequence[CameraModel], span_s: float
) -> int:
    """Sub-frames needed: the fastest agent's image motion over ``span_s`` in pixels, per sample."""
    worst = 0.0
    for m in motions:
        for cam in cameras:
            depth = float(np.linalg.norm(np.asarray(m.pos) - cam.position))
            worst = max(worst, m.speed_mps() * span_s * float(cam.K[0, 0]) / max(depth, 0.5))
    if worst <= cfg.px_per_sample:
        return 1
    return min(cfg.max_samples, math.ceil(worst / cfg.px_per_sample) + 1)


def offsets(span_s: float, k: int) -> NDArray[np.float64]:
    """Sub-frame times before the tick, earliest first; the last is the tick itself."""
    return np.linspace(span_s, 0.0, k) if k > 1 else np.zeros(1)


def row_weights(
    back_s: NDArray[np.float64], height: int, exposure_s: float, line_time_s: float
) -> NDArray[np.float32]:
    """(K, H): each image row's mean over the sub-frames ``back_s`` (seconds before the tick) within
    its exposure window; the nearest sub-frame where none falls in it."""
    end = (height - 1 - np.arange(height)) * line_time_s  # row r's exposure ends this long before t
    inside = (back_s[:, None] >= end[None, :] - 1e-12) & (
        back_s[:, None] <= end[None, :] + exposure_s + 1e-12
    )
    empty = ~inside.any(axis=0)
    if empty.any():
        centre = end[empty] + exposure_s / 2
        inside[np.abs(back_s[:, None] - centre[None, :]).argmin(axis=0), np.flatnonzero(empty)] = True
    w = inside.astype(np.float32)
    return w / w.sum(axis=0, keepdims=True)


def combine(frames: Sequence[NDArray[np.uint8]], weights: NDArray[np.float32]) -> NDArray[np.uint8]:
    """Row-weighted mean of the sub-frames (H, W, 3) as uint8."""
    acc = np.zeros(frames[0].shape, np.float32)
    for img, w in zip(frames, weights, strict=True):
        if w.any():
            acc += img.astype(np.float32) * w[:, None, None]
    return np.asarray(np.clip(np.rint(acc), 0, 255), dtype=np.uint8)


def expose(
    cfg: ShutterConfig,
    agents: Sequence[Agent],
    cameras: Sequence[CameraModel],
    exposures_s: Sequence[float],
    render_all: Callable[[], list[CameraImages]],
) -> tuple[list[CameraImages], int]:
    """Every camera's images over its exposure, and the sub-frames rendered (1: an ordinary render).

    ``render_all()`` renders every camera at the agents' current poses (the scene's moved boxes
    follow the sub-poses); ``exposures_s``: each camera's exposure time.
    """
    motions = moving(agents) if cfg.enabled else []
    span = (
        max(window_s(cfg, e, cam.height) for cam, e in zip(cameras, exposures_s, strict=True))
        if cameras
        else 0.0
    )
    k = samples(cfg, motions, cameras, span) if motions else 1
    if k == 1:
        return render_all(), 1
    back = offsets(span, k)
    subs: list[list[CameraImages]] = []
    client = motions[0].client
    state = pb.saveState(physicsClientId=client)  # the whole simulation, contacts included
    try:
        for d in back:
            for m in motions:
                m.place(float(d))
            subs.append(render_all())
    finally:
        pb.restoreState(stateId=state, physicsClientId=client)
        pb.removeState(state, physicsClientId=client)
    out = []
    for i, (cam, e) in enumerate(zip(cameras, exposures_s, strict=True)):
        last = subs[-1][i]
        if last.rgb is None:
            out.append(last)
            continue
        w = row_weights(back, cam.height, e, cfg.line_time_s)
        rgb = combine([s[i].rgb for s in subs], w)  # type: ignore[misc]
        changed = any(s[i].changed for s in subs)
        out.append(CameraImages(rgb, last.depth_m, last.labels, changed=changed, instances=last.instances))
    return out, k
