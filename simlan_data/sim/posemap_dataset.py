"""Generate a pose-mapping dataset: random body configurations seen by the humanoid-capture cameras.

    python -m simlan_data.run experiment=posemap_dataset posemap.samples=N

Per sample::

    q ~ U(limit_scale x joint limits)  (seeded)  --> pose the humanoid (PyBullet, kinematic)
      --> landmark world positions (numpy FK of the same skeleton)
      --> per camera: render the humanoid's region only (layered renderer: static warehouse baked
          once) or cast rays (occlusion=rays)  --> estimator (projection | MediaPipe)
      --> landmarks (cameras, 33, 4) + q  --> dataset.parquet (polars)

Deterministic per seed: the joint samples and the estimator's noise come from seeded generators,
and the renderer is deterministic. Writes into the run directory ``dataset.parquet``,
``dataset.json``, ``metrics.json`` (``posemap.dataset.*``) and optionally a few images.
"""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from simlan_data.algorithms.posemap.dataset import PoseDataset, write_dataset
from simlan_data.algorithms.posemap.estimators import CameraView, PoseEstimator, make_estimator
from simlan_data.config.schema import Config
from simlan_data.constants import METRICS_FILENAME
from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel
from simlan_data.imaging.image_files import write_image
from simlan_data.metrics_io import write_metrics
from simlan_data.sim.agents import spawn_agent
from simlan_data.sim.humanoid import PosedHumanoidAgent
from simlan_data.sim.pybullet_client import Client, connect
from simlan_data.sim.rendering import CameraRenderer, LabelTable
from simlan_data.sim.scene import load_cameras
from simlan_data.world._pybullet import pb
from simlan_data.world.agent_types import AGENT_TYPES
from simlan_data.world.builder import build_world
from simlan_data.world.layout import load_layout
from simlan_data.world.skeleton import LANDMARK_INSIDE_M, NUM_LANDMARKS, sample_joints

log = logging.getLogger(__name__)

RAY_TOLERANCE_M = 0.03  # as the projection estimator's depth tolerance


def camera_meta(cam: CameraModel) -> dict:
    return {
        "id": cam.camera_id,
        "width": cam.width,
        "height": cam.height,
        "K": cam.K.tolist(),
        "D": cam.D.ravel().tolist(),
        "world_from_camera": cam.world_from_camera.matrix().tolist(),
    }


class CaptureRig:
    """The warehouse, the humanoid on its support arm and the cameras, ready to pose and look."""

    def __init__(self, cfg: Config, *, need_images: bool) -> None:
        pm = cfg.posemap
        self.cameras, _ = load_cameras(cfg)
        placements = load_layout(cfg.world.layout, cfg.world.fidelity)
        self.client: Client = connect(cfg.render.backend, software_gl_threads=cfg.render.software_gl_threads)
        try:
            cid = self.client.id
            labels = LabelTable()
            with tempfile.TemporaryDirectory(prefix="simlan_world_") as mesh_dir:
                world = build_world(cid, placements, {}, mesh_dir=Path(mesh_dir))
            for body, label in world.labels.items():
                labels.set(body, label)
            self.renderers: list[CameraRenderer] = []
            if need_images:
                self.renderers = [
                    CameraRenderer(
                        self.client,
                        cam,
                        labels,
                        distort=cfg.cameras.distortion,
                        near_m=cfg.cameras.near_m,
                        far_m=cfg.cameras.far_m,
                        layered=True,
                    )
                    for cam in self.cameras
                ]
                for r in self.renderers:  # the warehouse without the humanoid, once
                    r.render_static()
            agent = spawn_agent(
                cid, pm.namespace, AGENT_TYPES["posed_humanoid"], pose=list(pm.position), marker_id=None
            )
            assert isinstance(agent, PosedHumanoidAgent)
            self.humanoid = agent
            labels.set(agent.body, agent.label)
        except BaseException:
            self.client.disconnect()
            raise

    def views(self, q: np.ndarray, *, rays: bool) -> list[CameraView]:
        """Pose the body at ``q`` and return what each camera sees."""
        self.humanoid.set_joints(q)
        world = self.humanoid.landmarks_world()
        if self.renderers:
            box = self.humanoid.aabb()
            out = []
            for r in self.renderers:
                images = r.render([box])
                out.append(CameraView(r.camera, images.rgb, images.depth_m, world))
            return out
        if rays:
            return [self._ray_view(cam, world) for cam in self.cameras]
        return [CameraView(cam, None, None, world) for cam in self.cameras]

    def _ray_view(self, cam: CameraModel, world: np.ndarray) -> CameraView:
        """Occlusion by ray casts from the camera centre (the body's collision shapes are its visuals)."""
        origin = cam.position
        hits = pb.rayTestBatch(
            [origin.tolist()] * NUM_LANDMARKS, world.tolist(), physicsClientId=self.client.id
        )
        dist = np.linalg.norm(world - origin, axis=1)
        first = np.array([h[2] for h in hits]) * dist
        hidden = np.array([h[0] >= 0 for h in hits]) & (first < dist - LANDMARK_INSIDE_M - RAY_TOLERANCE_M)
        return CameraView(cam, None, None, world, hidden=hidden)

    def close(self) -> None:
        self.client.disconnect()


def _draw(rgb: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    h, w = img.shape[:2]
    for x, y, _, v in landmarks:
        cv2.circle(
            img, (round(float(x) * w), round(float(y) * h)), 3, (0, 200, 0) if v > 0.5 else (0, 0, 220), -1
        )
    return img


def generate_dataset(cfg: Config, run_dir: Path, *, progress: bool = True) -> dict[str, float]:
    """Generate ``posemap.samples`` samples into ``run_dir``; returns the metrics written."""
    pm = cfg.posemap
    estimator = _make_estimator(cfg)
    rays = pm.estimator == "projection" and pm.occlusion == "rays"
    t0 = time.perf_counter()
    rig = CaptureRig(cfg, need_images=not rays)
    setup_s = time.perf_counter() - t0
    rng = np.random.default_rng(cfg.seed)
    q_all = sample_joints(rng, pm.samples, limit_scale=pm.limit_scale)
    lm = np.zeros((pm.samples, len(rig.cameras), NUM_LANDMARKS, 4), dtype=np.float32)
    t1 = time.perf_counter()
    try:
        with estimator:
            _capture(cfg, rig, estimator, q_all, lm, run_dir / "images", rays=rays, progress=progress)
    finally:
        rig.close()
    loop_s = time.perf_counter() - t1
    data = PoseDataset(
        np.arange(pm.samples),
        [c.camera_id for c in rig.cameras],
        lm,
        q_all,
        estimator.name,
        _meta(cfg, rig, estimator, rays),
    )
    digest = write_dataset(run_dir, data)
    metrics = _dataset_metrics(cfg, rig, lm, loop_s, setup_s)
    write_metrics(run_dir / METRICS_FILENAME, metrics)
    log.info(
        "\n".join(
            [
                f"simlan_data: posemap dataset ({estimator.name}) finished",
                f"  run directory  {run_dir}",
                f"  dataset        {run_dir / 'dataset.parquet'}  ({pm.samples} samples x {len(rig.cameras)} cameras, sha256 {digest[:12]})",
                f"  speed          {metrics['posemap.dataset.samples_per_s']:.1f} samples/s ({loop_s:.1f} s, setup {setup_s:.1f} s)",
                f"  landmarks      {metrics['posemap.dataset.visible_fraction'] * 100:.1f} % visible, person found in {metrics['posemap.dataset.detected_fraction'] * 100:.1f} % of the views",
                f"  next           python -m simlan_data.run experiment=posemap_train posemap.dataset={run_dir}",
            ]
        )
    )
    return metrics


def _make_estimator(cfg: Config) -> PoseEstimator:
    """Check the estimator and occlusion settings and build the estimator."""
    pm = cfg.posemap
    if pm.estimator == "mediapipe" and pm.occlusion == "rays":
        raise ConfigError(
            "invalid posemap.occlusion='rays'",
            "config",
            "MediaPipe needs rendered images",
            "use posemap.occlusion=depth",
        )
    return make_estimator(
        pm.estimator,
        seed=cfg.seed + 1,
        noise_px=pm.noise_px,
        hidden_noise_px=pm.hidden_noise_px,
        mediapipe_python=pm.mediapipe_python,
    )


def _capture(
    cfg: Config,
    rig: CaptureRig,
    estimator: PoseEstimator,
    q_all: np.ndarray,
    lm: np.ndarray,
    image_dir: Path,
    *,
    rays: bool,
    progress: bool,
) -> None:
    """Pose the humanoid for every sample, estimate its landmarks into ``lm``; save the first images."""
    pm = cfg.posemap
    for i in tqdm(
        range(pm.samples), desc="posemap dataset", unit="sample", disable=None if progress else True
    ):
        views = rig.views(q_all[i], rays=rays)
        lm[i] = estimator.estimate(views)
        if i < pm.save_images and views[0].rgb is not None:
            image_dir.mkdir(parents=True, exist_ok=True)
            tiles = [_draw(v.rgb, lm[i, k]) for k, v in enumerate(views) if v.rgb is not None]
            write_image(image_dir / f"sample_{i:05d}.png", np.hstack(tiles))


def _meta(cfg: Config, rig: CaptureRig, estimator: PoseEstimator, rays: bool) -> dict[str, Any]:
    """Describe how the dataset was made (seed, occlusion, noise, renderer, cameras)."""
    pm = cfg.posemap
    return {
        "seed": cfg.seed,
        "limit_scale": pm.limit_scale,
        "occlusion": "rays" if rays else ("depth" if pm.estimator == "projection" else "n/a"),
        "noise_px": pm.noise_px if pm.estimator == "projection" else None,
        "hidden_noise_px": pm.hidden_noise_px if pm.estimator == "projection" else None,
        "estimator_version": getattr(estimator, "version", ""),
        "position": list(pm.position),
        "renderer": rig.client.backend if not rays else "none (ray casts)",
        "image_size": [cfg.cameras.width, cfg.cameras.height],
        "world_fidelity": cfg.world.fidelity,
        "camera_models": [camera_meta(c) for c in rig.cameras],
    }


def _dataset_metrics(
    cfg: Config, rig: CaptureRig, lm: np.ndarray, loop_s: float, setup_s: float
) -> dict[str, float]:
    """Measure the dataset: size, speed, visible and detected fractions (overall and per camera)."""
    pm = cfg.posemap
    visible = lm[..., 3] > 0.5
    metrics: dict[str, float] = {
        "posemap.dataset.samples": float(pm.samples),
        "posemap.dataset.cameras": float(len(rig.cameras)),
        "posemap.dataset.samples_per_s": pm.samples / loop_s if loop_s > 0 else 0.0,
        "posemap.dataset.wall_s": loop_s,
        "posemap.dataset.setup_s": setup_s,
        "posemap.dataset.visible_fraction": float(visible.mean()),
        "posemap.dataset.detected_fraction": float((lm[..., 3] > 0).any(axis=2).mean()),
    }
    for k, cam in enumerate(rig.cameras):
        metrics[f"posemap.dataset.visible_fraction.{cam.camera_id}"] = float(visible[:, k].mean())
    return metrics
