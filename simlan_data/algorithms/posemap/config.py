"""Typed config of the pose mapping: the tasks (``posemap.*``: dataset generation, training, the
drive) and the built-in pose mapper's own parameters (``algorithms.posemap.*``, name ``trained``).

Part of :class:`simlan_data.config.schema.Config`; checked when the config is built, every failure a
one-line ConfigError naming the key, the value and the fix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from simlan_data.errors import ConfigError

TASKS = ("none", "dataset", "train")
ESTIMATORS = ("projection", "mediapipe")
OCCLUSIONS = ("depth", "rays")
MODELS = ("mlp", "fusion", "gbm")
FEATURES = ("image", "rig")
LOSSES = ("auto", "mse", "l1")
REFINES = ("none", "fit")
CROPS = ("person", "full")
POOLS = ("loky", "ray")


def _bad(key: str, value: Any, why: str, fix: str) -> ConfigError:
    return ConfigError.invalid(f"posemap.{key}", value, why, fix)


@dataclass
class PosemapConfig:
    """Pose mapping: landmarks of a person -> the humanoid's 47 joint targets (issue 6)."""

    # what python -m simlan_data.run does: none (simulate a scenario), dataset, train
    task: str = "none"
    # --- dataset generation (task=dataset; cameras: the cameras group, default humanoid_capture)
    samples: int = 1000
    estimator: str = "projection"  # projection | mediapipe
    occlusion: str = "depth"  # projection estimator: depth (rendered depth image) | rays (ray casts)
    noise_px: float = 1.0  # projection estimator: pixel noise of visible landmarks (sigma)
    hidden_noise_px: float = 8.0  # ... of landmarks it cannot see (reported, as MediaPipe guesses them)
    limit_scale: float = 0.8  # random joints within this fraction of the limits (SIMLAN: 0.8)
    position: list[float] = field(default_factory=lambda: [5.3, -10.0, 0.0])  # support-arm base x, y, yaw
    mediapipe_python: str = ".venv-mediapipe/bin/python"
    save_images: int = 0  # keep the first N samples' camera images (PNG, landmarks drawn)
    crop: str = "person"  # MediaPipe sees: person (the body's projected box + crop_margin) | full (the image)
    crop_margin: float = 0.25  # added on every side of the person crop, x the box's larger side
    workers: int = 1  # worker processes, each with its own renderer and estimator; 0: one per core
    pool: str = "loky"  # workers on: loky (this machine's cores, joblib) | ray (a Ray cluster, ray_address)
    ray_address: str = ""  # pool=ray: the cluster ("auto": the one `ray start` made; "": a local one)
    # --- training (task=train)
    dataset: str = ""  # dataset run directory or its dataset.parquet
    model: str = "fusion"  # mlp (SIMLAN's baseline, one camera) | fusion (all cameras) | gbm
    cameras: list[str] = field(default_factory=list)  # cameras the model reads; [] = all (mlp: the first)
    features: str = "rig"  # image (landmarks as the estimator gives them) | rig (+ rays in the rig's frame)
    hidden: list[int] = field(default_factory=lambda: [504, 476, 479])  # SIMLAN's MLP
    width: int = 0  # > 0: hidden = [width] * layers (for sweeps)
    layers: int = 3
    dropout: float = 0.1
    loss: str = (
        "auto"  # mse | l1 (the median: what the MAE rewards) | auto: mse for mlp (SIMLAN), l1 otherwise
    )
    lr: float = 1e-3
    weight_decay: float = 0.0
    epochs: int = 200
    batch_size: int = 256
    val_fraction: float = 0.1
    test_fraction: float = 0.15
    gbm_iterations: int = 300
    threads: int = 2
    # (the kinematic fit trained with the model: algorithms.posemap.refine, see TrainedMapperParams)
    # --- drive (a simulation run whose humanoid follows a landmark stream through the pose mapper
    # algorithms.posemap: the built-in's model is algorithms.posemap.model)
    drive: str = ""  # landmark source: dataset (dir or parquet) or a recording with landmark topics
    motion: list[str] = field(default_factory=list)  # without drive: motion files posed in turn
    motion_period_s: float = 2.0
    namespace: str = "robot_agent_1"  # the posed humanoid driven by drive/motion
    landmarks_rate_hz: float = 0.0  # > 0: the live projection estimator publishes landmarks per camera
    # --- drive from images or a video (experiment=posemap_video): MediaPipe Pose on every frame,
    # then the pose mapper as for posemap.drive (a model of one camera)
    source: str = ""  # a video file, an image, or a folder of images
    source_fps: float = 0.0  # frames per second of the source; 0: a video's own, cameras.rate_hz for images

    @property
    def hidden_layers(self) -> list[int]:
        return [self.width] * self.layers if self.width > 0 else list(self.hidden)

    def check(self) -> None:
        if self.task not in TASKS:
            raise _bad(
                "task",
                self.task,
                f"expected one of {', '.join(TASKS)}",
                "use an experiment: posemap_dataset, posemap_train",
            )
        if self.estimator not in ESTIMATORS:
            raise _bad(
                "estimator", self.estimator, f"expected one of {', '.join(ESTIMATORS)}", "use projection"
            )
        if self.occlusion not in OCCLUSIONS:
            raise _bad("occlusion", self.occlusion, f"expected one of {', '.join(OCCLUSIONS)}", "use depth")
        if self.model not in MODELS:
            raise _bad("model", self.model, f"expected one of {', '.join(MODELS)}", "use fusion")
        if self.loss not in LOSSES:
            raise _bad("loss", self.loss, f"expected one of {', '.join(LOSSES)}", "use auto")
        if self.features not in FEATURES:
            raise _bad("features", self.features, f"expected one of {', '.join(FEATURES)}", "use rig")
        if not 0 <= self.samples <= 10_000_000:
            raise _bad(
                "samples", self.samples, "must be within 0..10,000,000", "use e.g. posemap.samples=1000"
            )
        if self.task == "dataset" and self.samples == 0:
            raise _bad(
                "samples",
                self.samples,
                "a dataset needs at least one sample",
                "use e.g. posemap.samples=1000",
            )
        if not 0 < self.limit_scale <= 1:
            raise _bad("limit_scale", self.limit_scale, "must be within (0, 1]", "use 0.8 (SIMLAN)")
        for key in ("noise_px", "hidden_noise_px"):
            if not 0 <= getattr(self, key) <= 100:
                raise _bad(key, getattr(self, key), "must be within 0..100 px", "use e.g. 1.0")
        if len(self.position) != 3 or not all(_is_number(v) for v in self.position):
            raise _bad(
                "position", list(self.position), "expected [x_m, y_m, yaw_rad]", "use [5.3, -10.0, 0.0]"
            )
        # (every element checked for its type too: OmegaConf lets `posemap.hidden=[[]]` through)
        hidden = self.hidden_layers
        if not hidden or not all(_is_int(h) and h > 0 for h in hidden):
            raise _bad(
                "hidden", list(self.hidden), "need at least one layer, every width > 0", "use [504, 476, 479]"
            )
        if not 1 <= self.layers <= 8:
            raise _bad("layers", self.layers, "must be within 1..8", "use 3")
        if not 0 <= self.dropout < 1:
            raise _bad("dropout", self.dropout, "must be within [0, 1)", "use 0.1")
        if not 0 < self.lr <= 1:
            raise _bad("lr", self.lr, "must be within (0, 1]", "use 1e-3")
        if not 1 <= self.epochs <= 100_000:
            raise _bad("epochs", self.epochs, "must be within 1..100000", "use 200")
        if not 1 <= self.batch_size <= 1_000_000:
            raise _bad("batch_size", self.batch_size, "must be within 1..1000000", "use 256")
        if not (
            0 < self.test_fraction < 1
            and 0 <= self.val_fraction < 1
            and self.val_fraction + self.test_fraction < 1
        ):
            raise _bad(
                "test_fraction/val_fraction",
                (self.test_fraction, self.val_fraction),
                "need 0 < test, 0 <= val and test + val < 1",
                "use test_fraction=0.15 val_fraction=0.1",
            )
        if self.task == "train" and not self.dataset:
            raise _bad(
                "dataset",
                self.dataset,
                "training needs a dataset",
                "set posemap.dataset=<dataset run directory>",
            )
        if not 0 < self.motion_period_s <= 3600:
            raise _bad("motion_period_s", self.motion_period_s, "must be within (0, 3600] s", "use 2.0")
        if not 0 <= self.landmarks_rate_hz <= 100:
            raise _bad(
                "landmarks_rate_hz", self.landmarks_rate_hz, "must be within 0..100 Hz (0: off)", "use 5"
            )
        if not (math.isfinite(self.source_fps) and 0 <= self.source_fps <= 240):
            raise _bad(
                "source_fps",
                self.source_fps,
                "must be within 0..240 frames per second (0: a video's own rate)",
                "use e.g. 30, or 0",
            )
        if self.source and self.drive:
            raise _bad(
                "source",
                self.source,
                f"posemap.drive={self.drive} is set too: the humanoid follows one source",
                "give posemap.source (images, video) or posemap.drive (landmarks), not both",
            )
        if self.crop not in CROPS:
            raise _bad("crop", self.crop, f"expected one of {', '.join(CROPS)}", "use person")
        if not (math.isfinite(self.crop_margin) and 0 <= self.crop_margin <= 2):
            raise _bad(
                "crop_margin", self.crop_margin, "must be within 0..2 (x the box's larger side)", "use 0.25"
            )
        if not 0 <= self.workers <= 1024:
            raise _bad("workers", self.workers, "must be within 0..1024 (0: one per core)", "use 1, or 0")
        if self.pool not in POOLS:
            raise _bad("pool", self.pool, f"expected one of {', '.join(POOLS)}", "use loky")
        if not 1 <= self.threads <= 64:
            raise _bad("threads", self.threads, "must be within 1..64", "use 2")


@dataclass(frozen=True)
class TrainedMapperParams:
    """The built-in pose mapper ``trained`` (``algorithms.posemap.*``): a trained model, then the
    kinematic fit of the skeleton to every camera's landmarks (:mod:`.fit`).

    Training (``experiment=posemap_train``) reads ``refine`` and the fit's parameters too: with
    ``refine=fit`` it measures the fit's prior (the learned model's held-out errors) and noise model
    and saves them with the model. Running (drive, replay), ``refine=fit`` applies a model's saved fit
    with these iterations and restarts (a model trained with ``refine=none`` has none: the learned
    map alone); ``refine=none`` maps with the learned model alone.
    """

    model: str = ""  # a trained model directory (a train run directory or its model/); running needs one
    refine: str = "fit"  # none | fit
    refine_iterations: int = 15
    refine_starts: int = 8  # 1 + random restarts of the arms where the fit stays far off

    def __post_init__(self) -> None:
        key = "algorithms.posemap."
        if self.refine not in REFINES:
            raise ConfigError.invalid(
                key + "refine", self.refine, f"expected one of {', '.join(REFINES)}", "use fit (or none)"
            )
        if not 1 <= self.refine_iterations <= 1000:
            raise ConfigError.invalid(
                key + "refine_iterations", self.refine_iterations, "must be within 1..1000", "use 15"
            )
        if not 1 <= self.refine_starts <= 100:
            raise ConfigError.invalid(
                key + "refine_starts", self.refine_starts, "must be within 1..100", "use 8"
            )


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
