"""Generate a pose-mapping dataset: random body configurations seen by the humanoid-capture cameras.

    python -m simlan_data.run experiment=posemap_dataset posemap.samples=N

Per sample::

    q ~ U(limit_scale x joint limits)  (seeded)  --> pose the humanoid (PyBullet, kinematic)
      --> landmark world positions (numpy FK of the same skeleton)
      --> per camera: render the humanoid's region only (layered renderer: static warehouse baked
          once) or cast rays (occlusion=rays)  --> estimator (projection | MediaPipe on the
          person crop)  --> landmarks (cameras, 33, 4) + q  --> dataset.parquet (polars)

``posemap.workers`` > 1: consecutive slices of the samples in worker processes (joblib's loky, or
Ray tasks with ``posemap.pool=ray``), each with its own renderer and estimator; the joints are
drawn and the projection estimator's noise is added in the run itself, so the dataset is the same
for any worker count.

Deterministic per seed: the joint samples and the estimator's noise come from seeded generators,
and the renderer is deterministic. Writes into the run directory ``dataset.parquet``,
``dataset.json``, ``metrics.json`` (``posemap.dataset.*``) and optionally a few images.
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
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
from simlan_data.sim.dynamic_layer import StaticMeshes
from simlan_data.sim.humanoid import PosedHumanoidAgent
from simlan_data.sim.pybullet_client import Client, connect
from simlan_data.sim.rendering import Aabb, CameraRenderer, LabelTable
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
            person = pm.crop == "person" and pm.estimator == "mediapipe"
            self.crop_margin = pm.crop_margin if person else None
            self._last_box: Aabb | None = None
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
                # then only the humanoid is drawn: a region render costs per mesh in the client
                StaticMeshes(cid, world, labels).remove()
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
            # where the body was too: the last pose's pixels outside this box must go (a sample's
            # images thus depend on the sample before it too: a region spanning two poses
            # rasterizes a few edge pixels differently; a pool worker renders the sample before
            # its first, so every worker count gives the same images)
            moved = [box] if self._last_box is None else [self._last_box, box]
            self._last_box = box
            out = []
            for r in self.renderers:
                images = r.render(moved)
                crop = None if self.crop_margin is None else person_crop(r.camera, box, self.crop_margin)
                out.append(CameraView(r.camera, images.rgb, images.depth_m, world, crop=crop))
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


def person_crop(cam: CameraModel, box: Aabb, margin: float) -> tuple[int, int, int, int] | None:
    """Image rectangle (u0, v0, u1, v1) around the body's box, ``margin`` x its larger side added on
    every side; None when no part of the box is in front of the camera (the full image is used)."""
    lo, hi = np.asarray(box[0], dtype=float), np.asarray(box[1], dtype=float)
    t = np.linspace(0.0, 1.0, 5)  # a grid on the box: its distorted image bends
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    uv, ok = cam.project(lo + grid * (hi - lo))
    if not ok.any():  # (points beyond the lens's valid radius lie outside the image)
        return None
    (u0, v0), (u1, v1) = uv[ok].min(axis=0), uv[ok].max(axis=0)
    pad = margin * max(u1 - u0, v1 - v0)
    rect = (
        max(0, int(np.floor(u0 - pad))),
        max(0, int(np.floor(v0 - pad))),
        min(cam.width, int(np.ceil(u1 + pad))),
        min(cam.height, int(np.ceil(v1 + pad))),
    )
    return rect if rect[2] - rect[0] >= 2 and rect[3] - rect[1] >= 2 else None


def _draw(rgb: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    h, w = img.shape[:2]
    for x, y, _, v in landmarks:
        cv2.circle(
            img, (round(float(x) * w), round(float(y) * h)), 3, (0, 200, 0) if v > 0.5 else (0, 0, 220), -1
        )
    return img


@dataclass
class Chunk:
    """What one worker measured of consecutive samples."""

    measured: NDArray[np.float64]  # (n, cameras, 33, 4): the estimator's measure(), before finish()
    images: list[list[NDArray[np.uint8]]]  # per camera, of those samples below posemap.save_images
    renderer: str
    version: str
    setup_s: float


def generate_dataset(cfg: Config, run_dir: Path, *, progress: bool = True) -> dict[str, float]:
    """Generate ``posemap.samples`` samples into ``run_dir``; returns the metrics written."""
    pm = cfg.posemap
    _check_estimator(cfg)
    cfg = replace(cfg, posemap=replace(pm, mediapipe_python=str(Path(pm.mediapipe_python).absolute())))
    rng = np.random.default_rng(cfg.seed)
    q_all = sample_joints(rng, pm.samples, limit_scale=pm.limit_scale)
    workers = min(pm.workers or os.cpu_count() or 1, pm.samples)
    t0 = time.perf_counter()
    if workers == 1:
        chunks = [capture_chunk(cfg, q_all, 0, progress=progress)]
    else:
        chunks = _capture_pool(cfg, q_all, workers, progress=progress)
    wall_s = time.perf_counter() - t0
    cameras = load_cameras(cfg)[0]
    lm = _finish(cfg, np.concatenate([c.measured for c in chunks]), cameras)
    _save_images(run_dir / "images", [tiles for c in chunks for tiles in c.images], lm)
    setup_s = float(np.mean([c.setup_s for c in chunks]))
    data = PoseDataset(
        np.arange(pm.samples),
        [c.camera_id for c in cameras],
        lm,
        q_all,
        pm.estimator,
        _meta(cfg, cameras, chunks[0]),
    )
    digest = write_dataset(run_dir, data)
    metrics = _dataset_metrics(cfg, cameras, lm, wall_s, setup_s, workers)
    write_metrics(run_dir / METRICS_FILENAME, metrics)
    log.info(
        "\n".join(
            [
                f"simlan_data: posemap dataset ({pm.estimator}) finished",
                f"  run directory  {run_dir}",
                f"  dataset        {run_dir / 'dataset.parquet'}  ({pm.samples} samples x {len(cameras)} cameras, sha256 {digest[:12]})",
                f"  speed          {metrics['posemap.dataset.samples_per_s']:.1f} samples/s with {workers} worker(s) ({wall_s:.1f} s, setup {setup_s:.1f} s)",
                f"  landmarks      {metrics['posemap.dataset.visible_fraction'] * 100:.1f} % visible, person found in {metrics['posemap.dataset.detected_fraction'] * 100:.1f} % of the views",
                f"  next           python -m simlan_data.run experiment=posemap_train posemap.dataset={run_dir}",
            ]
        )
    )
    return metrics


def _check_estimator(cfg: Config) -> None:
    if cfg.posemap.estimator == "mediapipe" and cfg.posemap.occlusion == "rays":
        raise ConfigError(
            "invalid posemap.occlusion='rays'",
            "config",
            "MediaPipe needs rendered images",
            "use posemap.occlusion=depth",
        )


def _make_estimator(cfg: Config) -> PoseEstimator:
    pm = cfg.posemap
    return make_estimator(
        pm.estimator,
        seed=cfg.seed + 1,
        noise_px=pm.noise_px,
        hidden_noise_px=pm.hidden_noise_px,
        mediapipe_python=pm.mediapipe_python,
    )


def capture_chunk(
    cfg: Config,
    q: NDArray[np.float64],
    first: int,
    *,
    before: NDArray[np.float64] | None = None,
    progress: bool = False,
) -> Chunk:
    """Pose the humanoid at each of ``q`` (samples ``first``, ``first + 1``, ...) and measure its
    landmarks, in this process: the run's own or a pool worker's (its own renderer and estimator).
    ``before``: the sample before ``first``, rendered first as the serial run did."""
    pm = cfg.posemap
    rays = pm.estimator == "projection" and pm.occlusion == "rays"
    t0 = time.perf_counter()
    estimator = _make_estimator(cfg)
    try:
        rig = CaptureRig(cfg, need_images=not rays)
    except BaseException:
        estimator.close()
        raise
    setup_s = time.perf_counter() - t0
    measured = np.zeros((len(q), len(rig.cameras), NUM_LANDMARKS, 4))
    images: list[list[NDArray[np.uint8]]] = []
    try:
        with estimator:
            if before is not None:
                rig.views(before, rays=rays)
            bar = tqdm(
                range(len(q)), desc="posemap dataset", unit="sample", disable=None if progress else True
            )
            for j in bar:
                views = rig.views(q[j], rays=rays)
                measured[j] = estimator.measure(views)
                if first + j < pm.save_images and views[0].rgb is not None:
                    images.append([v.rgb.copy() for v in views if v.rgb is not None])
    finally:
        rig.close()
    renderer = "none (ray casts)" if rays else rig.client.backend
    return Chunk(measured, images, renderer, estimator.version, setup_s)


def _capture_pool(cfg: Config, q_all: NDArray[np.float64], workers: int, *, progress: bool) -> list[Chunk]:
    """Consecutive slices of the samples, one per worker (loky: this machine; ray: a cluster)."""
    from joblib import Parallel, delayed, parallel_config

    parts = np.array_split(np.arange(len(q_all)), workers)
    jobs = [
        delayed(capture_chunk)(cfg, q_all[idx], int(idx[0]), before=q_all[idx[0] - 1] if idx[0] else None)
        for idx in parts
    ]
    if cfg.posemap.pool == "ray":
        _start_ray(cfg.posemap.ray_address)
        with parallel_config(backend="ray", n_jobs=workers):  # (its backend returns lists only)
            return list(Parallel()(jobs))
    results = Parallel(n_jobs=workers, backend="loky", return_as="generator")(jobs)
    return list(tqdm(results, total=workers, desc="posemap dataset (workers)", unit="slice",
                     disable=None if progress else True))  # fmt: skip


def _start_ray(address: str) -> None:
    """Connect to (or start) the Ray cluster and register its joblib backend."""
    try:
        import ray
        from ray.util.joblib import register_ray
    except ImportError as err:
        raise ConfigError(
            "posemap.pool=ray needs Ray",
            "posemap.pool",
            f"cannot import it ({err})",
            "pip install -e '.[ray]', or use posemap.pool=loky",
        ) from err
    register_ray()
    if not ray.is_initialized():
        ray.init(address=address or None, log_to_driver=False)


def _finish(cfg: Config, measured: NDArray[np.float64], cameras: list[CameraModel]) -> NDArray[np.float32]:
    """The seeded last step of the estimator (the projection's noise), sample after sample."""
    if cfg.posemap.estimator != "projection":
        return measured.astype(np.float32)
    estimator = _make_estimator(cfg)
    return (
        np.stack([estimator.finish(m, cameras) for m in measured])
        if len(measured)
        else measured.astype(np.float32)
    )


def _save_images(image_dir: Path, samples: list[list[NDArray[np.uint8]]], lm: NDArray[np.float32]) -> None:
    """The first samples' camera images side by side, their landmarks drawn."""
    for i, views in enumerate(samples):
        image_dir.mkdir(parents=True, exist_ok=True)
        tiles = [_draw(rgb, lm[i, k]) for k, rgb in enumerate(views)]
        write_image(image_dir / f"sample_{i:05d}.png", np.hstack(tiles))


def _meta(cfg: Config, cameras: list[CameraModel], chunk: Chunk) -> dict[str, Any]:
    """Describe how the dataset was made (seed, occlusion, noise, renderer, crop, cameras)."""
    pm = cfg.posemap
    rays = pm.estimator == "projection" and pm.occlusion == "rays"
    projection = pm.estimator == "projection"
    return {
        "seed": cfg.seed,
        "limit_scale": pm.limit_scale,
        "occlusion": "rays" if rays else ("depth" if projection else "n/a"),
        "noise_px": pm.noise_px if projection else None,
        "hidden_noise_px": pm.hidden_noise_px if projection else None,
        "crop": None if projection else (pm.crop if pm.crop == "full" else f"person+{pm.crop_margin:g}"),
        "estimator_version": chunk.version,
        "position": list(pm.position),
        "renderer": chunk.renderer,
        "image_size": [cfg.cameras.width, cfg.cameras.height],
        "world_fidelity": cfg.world.fidelity,
        "camera_models": [camera_meta(c) for c in cameras],
    }


def _dataset_metrics(
    cfg: Config, cameras: list[CameraModel], lm: np.ndarray, wall_s: float, setup_s: float, workers: int
) -> dict[str, float]:
    """Measure the dataset: size, speed (the workers' setup left out), visible and detected fractions."""
    pm = cfg.posemap
    visible = lm[..., 3] > 0.5
    loop_s = wall_s - setup_s
    metrics: dict[str, float] = {
        "posemap.dataset.samples": float(pm.samples),
        "posemap.dataset.cameras": float(len(cameras)),
        "posemap.dataset.workers": float(workers),
        "posemap.dataset.samples_per_s": pm.samples / loop_s if loop_s > 0 else 0.0,
        "posemap.dataset.wall_s": wall_s,
        "posemap.dataset.setup_s": setup_s,
        "posemap.dataset.visible_fraction": float(visible.mean()),
        "posemap.dataset.detected_fraction": float((lm[..., 3] > 0).any(axis=2).mean()),
    }
    for k, cam in enumerate(cameras):
        metrics[f"posemap.dataset.visible_fraction.{cam.camera_id}"] = float(visible[:, k].mean())
    return metrics
