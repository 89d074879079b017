"""Ground truth for bird's-eye views: an orthographic top-down render of the scene on a canvas.

The canvas of :class:`~simlan_data.algorithms.birdseye.CanvasSpec` is rendered straight down with an
orthographic projection, in tiles of at most EGL's 1024x768 window; each tile has its own
frustum, so tile pixel centres are canvas pixel centres. Labels come from the segmentation mask.
``static_world`` builds the warehouse of a run's world config (settled as the run settles it),
without cameras or agents, for the replay's ground truth.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.birdseye import CanvasSpec
from simlan_data.config.schema import WorldConfig
from simlan_data.sim.pybullet_client import Client, connect
from simlan_data.sim.randomize import replay_placements, replay_world
from simlan_data.sim.rendering import EGL_MAX_TILE, LabelTable
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import WorldBodies, build_world
from simlan_data.world.layout import load_layout

EYE_HEIGHT_M = 50.0  # above the roofless 8 m building
NEAR_M, FAR_M = 1.0, 100.0  # linear depth in an orthographic view: 1.5 mm steps in 16 bits


@dataclass
class StaticWorld:
    """A PyBullet client holding the settled warehouse and its label table."""

    client: Client
    world: WorldBodies
    labels: LabelTable

    def close(self) -> None:
        self.client.disconnect()


def static_world(
    world_cfg: WorldConfig, *, backend: str = "auto", randomization: Mapping[str, Any] | None = None
) -> StaticWorld:
    """Build and settle the warehouse of ``world_cfg`` as ``Scene.build`` does, without agents;
    ``randomization`` (a recording's ``/simlan/randomization``) moves, tints and adds as the run did."""
    client = connect(backend)
    try:
        cid = client.id
        pb.setGravity(0.0, 0.0, -world_cfg.gravity_mps2, physicsClientId=cid)
        pb.setTimeStep(1.0 / world_cfg.physics_hz, physicsClientId=cid)
        pb.setPhysicsEngineParameter(deterministicOverlappingPairs=1, physicsClientId=cid)
        physics = dict(world_cfg.physics)
        placements = replay_placements(load_layout(world_cfg.layout, world_cfg.fidelity), randomization or {})
        with tempfile.TemporaryDirectory(prefix="simlan_world_") as mesh_dir:
            world = build_world(cid, placements, physics, mesh_dir=Path(mesh_dir))
        replay_world(cid, world, randomization or {})
        for _ in range(round(world_cfg.settle_s * world_cfg.physics_hz)):
            pb.stepSimulation(physicsClientId=cid)
        labels = LabelTable()
        for body, label in world.labels.items():
            labels.set(body, label)
    except BaseException:
        client.disconnect()
        raise
    return StaticWorld(client, world, labels)


def orthographic_projection(left: float, right: float, bottom: float, top: float) -> list[float]:
    """OpenGL orthographic projection (column-major), view-space extents in metres."""
    P = np.zeros((4, 4))
    P[0, 0] = 2.0 / (right - left)
    P[1, 1] = 2.0 / (top - bottom)
    P[2, 2] = -2.0 / (FAR_M - NEAR_M)
    P[0, 3] = -(right + left) / (right - left)
    P[1, 3] = -(top + bottom) / (top - bottom)
    P[2, 3] = -(FAR_M + NEAR_M) / (FAR_M - NEAR_M)
    P[3, 3] = 1.0
    return P.T.ravel().tolist()


def render_orthographic(
    client: Client, spec: CanvasSpec, labels: LabelTable
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Render the canvas straight down: RGB (H, W, 3) and semantic labels (H, W)."""
    H, W = spec.height, spec.width
    rgb = np.empty((H, W, 3), dtype=np.uint8)
    out_labels = np.empty((H, W), dtype=np.uint8)
    # eye above the origin looking down, image up = +y: view x = world x, view y = world y
    view = pb.computeViewMatrix([0.0, 0.0, EYE_HEIGHT_M], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    # TinyRenderer samples half a pixel off OpenGL's pixel centres (see rendering.CameraRenderer)
    shift_u, shift_v = (0.5, -0.5) if client.backend == "tiny" else (0.0, 0.0)
    tw, th = EGL_MAX_TILE if client.backend == "egl" else (W, H)
    m = spec.m_per_px
    for tv in range(0, H, th):
        for tu in range(0, W, tw):
            w, h = min(tw, W - tu), min(th, H - tv)
            left = spec.x_m[0] + (tu + shift_u) * m
            top = spec.y_m[1] - (tv + shift_v) * m
            proj = orthographic_projection(left, left + w * m, top - h * m, top)
            kwargs = (
                {"flags": pb.ER_USE_PROJECTIVE_TEXTURE}
                if client.backend == "egl"
                else {"renderer": pb.ER_TINY_RENDERER, "shadow": 0}
            )
            _, _, c, _, s = pb.getCameraImage(w, h, view, proj, physicsClientId=client.id, **kwargs)
            rgb[tv : tv + h, tu : tu + w] = np.asarray(c).reshape(h, w, 4)[..., :3]
            out_labels[tv : tv + h, tu : tu + w] = labels.apply(np.asarray(s).reshape(h, w).astype(np.int32))
    return rgb, out_labels
