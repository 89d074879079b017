"""Train and score a pose mapper: ``python -m simlan_data.run experiment=posemap_train posemap.dataset=...``.

dataset.parquet --> split by sample id (train / val / test) --> features (mlp: one camera's
x, y, z as SIMLAN; fusion, gbm: posemap.features of posemap.cameras) --> fit (val picks the
epoch) --> [algorithms.posemap.refine=fit: the kinematic fit's prior and noise model] --> predict
test --> posemap.* metrics --> model/ (weights + model.json) and metrics.json, posemap_report.md in
the run directory.
"""

from __future__ import annotations

import logging
import platform
import time
from dataclasses import asdict
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np

from simlan_data import __version__
from simlan_data.algorithms.posemap.config import PosemapConfig, TrainedMapperParams
from simlan_data.algorithms.posemap.dataset import PoseDataset, read_dataset, split_of
from simlan_data.algorithms.posemap.features import Rig, build_features
from simlan_data.algorithms.posemap.fit import FitParams, Refiner, pixel_noise
from simlan_data.algorithms.posemap.metrics import evaluate
from simlan_data.algorithms.posemap.models import MAPPERS, PoseMapper, TrainParams, load_mapper
from simlan_data.constants import METRICS_FILENAME
from simlan_data.errors import ConfigError
from simlan_data.metrics_io import write_metrics
from simlan_data.world.skeleton import JOINT_NAMES

log = logging.getLogger(__name__)

MODEL_DIRNAME = "model"
REPORT_NAME = "posemap_report.md"


def _versions() -> dict[str, str]:
    out = {"simlan_data": __version__, "python": platform.python_version()}
    for name in ("torch", "scikit-learn", "numpy", "polars"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def feature_spec(pm: PosemapConfig, data: PoseDataset, *, refine: bool = False) -> dict[str, Any]:
    """Which cameras and which features the model reads (saved with the model); ``refine``: the
    kinematic fit is trained too (it needs the cameras' calibrations)."""
    cameras = list(pm.cameras) if pm.cameras else list(data.cameras)
    if pm.model == "mlp":  # SIMLAN's baseline: one camera's x, y, z
        cameras, kind = cameras[:1], "simlan"
    else:
        kind = pm.features
    spec: dict[str, Any] = {"cameras": [str(c) for c in cameras], "features": kind}
    if kind == "rig" or refine:
        models = data.meta.get("camera_models")
        if not models:
            raise ConfigError(
                "dataset lacks camera models",
                "dataset.json",
                "rig features and algorithms.posemap.refine=fit need the cameras' calibrations",
                "regenerate the dataset or use posemap.features=image algorithms.posemap.refine=none",
            )
        spec["camera_models"] = [m for m in models if str(m["id"]) in spec["cameras"]]
        spec["position"] = data.meta.get("position", [5.3, -10.0, 0.0])
    return spec


def rig_of(spec: dict[str, Any]) -> Rig:
    return Rig.from_meta(spec["camera_models"], spec["cameras"], spec["position"])


def features_for(landmarks: np.ndarray, spec: dict[str, Any]) -> np.ndarray:
    """Model inputs of landmarks (N, C, 33, 4) in the spec's camera order."""
    return build_features(landmarks, spec["features"], rig_of(spec) if spec["features"] == "rig" else None)


def make_refiner(
    pm: PosemapConfig,
    fit: TrainedMapperParams,
    data: PoseDataset,
    spec: dict[str, Any],
    residuals: np.ndarray,
    train_landmarks: np.ndarray,
    train_joints: np.ndarray,
    seed: int,
) -> Refiner:
    """The kinematic fit after the learned model; it trusts the model per joint as far as the
    model's own held-out errors ``residuals`` (N, 47) say, and the landmarks as far as the
    estimator's noise (from the dataset) says."""
    rig = rig_of(spec)
    if data.meta.get("noise_px") is not None:  # the projection estimator: its declared noise
        noise = float(data.meta["noise_px"]), float(data.meta.get("hidden_noise_px") or 8.0)
    else:  # an estimator without one (MediaPipe): measured against the training split's skeletons
        noise = pixel_noise(train_landmarks, train_joints, rig)
    params = FitParams(
        noise_px=noise[0],
        hidden_noise_px=noise[1],
        iterations=fit.refine_iterations,
        starts=fit.refine_starts,
        limit_scale=float(data.meta.get("limit_scale", pm.limit_scale)),
        seed=seed,
    )
    return Refiner(rig, np.sqrt((residuals**2).mean(axis=0)), params)


def params_from(pm: PosemapConfig, seed: int) -> TrainParams:
    return TrainParams(
        hidden=pm.hidden_layers,
        dropout=pm.dropout,
        loss=("mse" if pm.model == "mlp" else "l1") if pm.loss == "auto" else pm.loss,
        lr=pm.lr,
        weight_decay=pm.weight_decay,
        epochs=pm.epochs,
        batch_size=pm.batch_size,
        gbm_iterations=pm.gbm_iterations,
        threads=pm.threads,
        seed=seed,
    )


def _timing(
    mapper: PoseMapper, spec: dict[str, Any], x: np.ndarray, landmarks: np.ndarray
) -> dict[str, float]:
    t0 = time.perf_counter()
    mapper.predict(x)
    batch_s = time.perf_counter() - t0
    singles = []
    for i in range(min(20, len(landmarks))):
        t1 = time.perf_counter()
        mapper.predict(features_for(landmarks[i : i + 1], spec))
        singles.append(time.perf_counter() - t1)
    return {
        "posemap.inference_us_per_sample": 1e6 * batch_s / max(1, len(x)),
        "posemap.latency_ms": 1e3 * float(np.median(singles)) if singles else 0.0,
    }


def write_report(path: Path, metrics: dict[str, float], info: dict[str, Any]) -> None:
    rows = sorted(JOINT_NAMES, key=lambda n: -metrics[f"posemap.joint.{n}.mae_rad"])
    lines = [
        f"# Pose mapper: {info['model']} on {', '.join(info['cameras'])} ({info['features']} features)",
        "",
        f"Dataset `{info['dataset']}` (sha256 {info['dataset_sha256'][:12]}, estimator {info['estimator']}),",
        f"{info['split_sizes']['train']} train / {info['split_sizes']['val']} val / {info['split_sizes']['test']} test samples (split by sample id).",
        "",
        "| metric | test | mean-pose baseline |",
        "| --- | --- | --- |",
        f"| MAE rad | {metrics['posemap.mae_rad']:.4f} | {metrics['posemap.baseline.mean_pose.mae_rad']:.4f} |",
        f"| MAE deg | {metrics['posemap.mae_deg']:.2f} | {metrics['posemap.baseline.mean_pose.mae_deg']:.2f} |",
        f"| MSE rad^2 | {metrics['posemap.mse_rad2']:.4f} | {metrics['posemap.baseline.mean_pose.mse_rad2']:.4f} |",
        f"| MPJPE m (33 landmarks, re-posed) | {metrics['posemap.mpjpe_m']:.4f} | {metrics['posemap.baseline.mean_pose.mpjpe_m']:.4f} |",
        f"| inference us/sample (batch) | {metrics['posemap.inference_us_per_sample']:.1f} | |",
        "",
        "Per joint, worst first:",
        "",
        "| joint | MAE rad | MAE deg | MSE rad^2 |",
        "| --- | --- | --- | --- |",
    ]
    for n in rows:
        lines.append(
            f"| {n} | {metrics[f'posemap.joint.{n}.mae_rad']:.4f} | {metrics[f'posemap.joint.{n}.mae_deg']:.2f} | {metrics[f'posemap.joint.{n}.mse_rad2']:.4f} |"
        )
    path.write_text("\n".join(lines) + "\n")


def _split(pm: PosemapConfig, data: PoseDataset) -> tuple[np.ndarray, dict[str, int]]:
    """Split the samples into train, val and test by their ids; refuse a dataset too small to train and test."""
    split = split_of(data.sample_ids, val_fraction=pm.val_fraction, test_fraction=pm.test_fraction)
    sizes = {s: int((split == s).sum()) for s in ("train", "val", "test")}
    if sizes["train"] < 2 or sizes["test"] < 1:
        raise ConfigError(
            "dataset too small",
            pm.dataset,
            f"{len(data)} samples give {sizes['train']} to train on and {sizes['test']} to test",
            "generate more samples (posemap.samples)",
        )
    return split, sizes


def _model_info(
    pm: PosemapConfig,
    data: PoseDataset,
    spec: dict[str, Any],
    sizes: dict[str, int],
    metrics: dict[str, float],
    refiner: Refiner | None,
    *,
    seed: int,
    config_yaml: str,
) -> dict[str, Any]:
    """Describe the trained model for its saved info: features, dataset, split, config, metrics, versions."""
    return {
        "model": pm.model,
        "cameras": spec["cameras"],
        "features": spec["features"],
        "feature_spec": spec,
        "dataset": str(Path(pm.dataset).resolve()),
        "dataset_sha256": data.sha256,
        "estimator": data.estimator,
        "split_sizes": sizes,
        "split": {
            "by": "sample_id (splitmix64 hash)",
            "val_fraction": pm.val_fraction,
            "test_fraction": pm.test_fraction,
        },
        "joint_names": list(JOINT_NAMES),
        "config": asdict(pm),
        "refine": refiner.to_dict() if refiner is not None else None,
        "config_yaml": config_yaml,
        "seed": seed,
        "metrics": {k: v for k, v in metrics.items() if ".joint." not in k},
        "versions": _versions(),
    }


def _print_summary(
    pm: PosemapConfig,
    run_dir: Path,
    data: PoseDataset,
    spec: dict[str, Any],
    sizes: dict[str, int],
    metrics: dict[str, float],
    refined: bool,
    fit_s: float,
) -> None:
    """Log what was trained: data, test errors against the mean pose, worst joints, timing, where it lies."""
    worst = sorted(JOINT_NAMES, key=lambda n: -metrics[f"posemap.joint.{n}.mae_rad"])[:3]
    worst_text = ", ".join(f"{n} {metrics['posemap.joint.' + n + '.mae_rad']:.3f}" for n in worst)
    log.info(
        "\n".join(
            [
                f"simlan_data: posemap {pm.model} ({spec['features']} features, cameras {', '.join(spec['cameras'])}) trained",
                f"  run directory  {run_dir}",
                f"  data           {sizes['train']} train / {sizes['val']} val / {sizes['test']} test samples, {data.estimator}, sha256 {data.sha256[:12]}",
                f"  test           MAE {metrics['posemap.mae_rad']:.4f} rad ({metrics['posemap.mae_deg']:.2f} deg), MSE {metrics['posemap.mse_rad2']:.4f} rad^2, MPJPE {metrics['posemap.mpjpe_m'] * 100:.1f} cm",
                f"  mean pose      MAE {metrics['posemap.baseline.mean_pose.mae_rad']:.4f} rad (the baseline to beat)",
                *(
                    [
                        f"  refine=fit     learned model alone MAE {metrics['posemap.learned.mae_rad']:.4f} rad; fit {metrics['posemap.refine.ms_per_sample']:.1f} ms/sample, {100 * metrics['posemap.refine.restarted']:.0f} % restarted"
                    ]
                    if refined
                    else []
                ),
                f"  worst joints   {worst_text}",
                f"  fit            {fit_s:.1f} s; inference {metrics['posemap.inference_us_per_sample']:.1f} us/sample (batch), {metrics['posemap.latency_ms']:.2f} ms one sample",
                f"  model          {run_dir / MODEL_DIRNAME}  (report: {run_dir / REPORT_NAME})",
            ]
        )
    )


def train(
    pm: PosemapConfig,
    run_dir: Path,
    *,
    fit: TrainedMapperParams | None = None,
    seed: int = 0,
    config_yaml: str = "",
    progress: bool = True,
) -> dict[str, float]:
    """Train ``pm.model`` on ``pm.dataset`` and, with ``fit.refine=fit`` (the built-in mapper's
    ``algorithms.posemap``; default: its defaults), the kinematic fit after it; write model,
    metrics and report into ``run_dir``."""
    fit = fit if fit is not None else TrainedMapperParams()
    data = read_dataset(pm.dataset)
    spec = feature_spec(pm, data, refine=fit.refine == "fit")
    data = data.select_cameras(spec["cameras"])
    split, sizes = _split(pm, data)
    t0 = time.perf_counter()
    x = features_for(data.landmarks, spec)
    features_s = time.perf_counter() - t0
    y = data.joints
    tr, va, te = split == "train", split == "val", split == "test"
    mapper = MAPPERS[pm.model](params_from(pm, seed))
    t1 = time.perf_counter()
    mapper.fit(x[tr], y[tr], x[va], y[va], progress=progress)
    fit_s = time.perf_counter() - t1
    y_pred = mapper.predict(x[te])
    held_out = va if va.any() else tr
    val_pred = mapper.predict(x[held_out])
    refiner, refine_s = None, 0.0
    if fit.refine == "fit":
        refiner = make_refiner(pm, fit, data, spec, val_pred - y[held_out], data.landmarks[tr], y[tr], seed)
        learned = y_pred
        t2 = time.perf_counter()
        y_pred = refiner(data.landmarks[te], learned)
        refine_s = time.perf_counter() - t2
    metrics = evaluate(y_pred, y[te], y[tr].mean(axis=0))
    metrics["posemap.val.mae_rad"] = float(np.abs(val_pred - y[held_out]).mean())
    metrics.update(_timing(mapper, spec, x[te], data.landmarks[te]))
    if refiner is not None:
        metrics.update(
            {
                "posemap.learned.mae_rad": float(np.abs(learned - y[te]).mean()),
                "posemap.refine.ms_per_sample": 1e3 * refine_s / max(1, int(te.sum())),
                "posemap.refine.restarted": refiner.restarted / max(1, int(te.sum())),
                "posemap.inference_us_per_sample": metrics["posemap.inference_us_per_sample"]
                + 1e6 * refine_s / max(1, int(te.sum())),
            }
        )
    metrics.update(
        {
            "posemap.train.samples": float(sizes["train"]),
            "posemap.val.samples": float(sizes["val"]),
            "posemap.test.samples": float(sizes["test"]),
            "posemap.train.fit_s": fit_s,
            "posemap.train.features_s": features_s,
            "posemap.features": float(x.shape[1]),
        }
    )
    info = _model_info(pm, data, spec, sizes, metrics, refiner, seed=seed, config_yaml=config_yaml)
    mapper.save(run_dir / MODEL_DIRNAME, info)
    write_metrics(run_dir / METRICS_FILENAME, metrics)
    write_report(run_dir / REPORT_NAME, metrics, info)
    _print_summary(pm, run_dir, data, spec, sizes, metrics, refiner is not None, fit_s)
    return metrics


def train_from_config(
    pm: PosemapConfig, fit: TrainedMapperParams, run_dir: Path, *, seed: int, config_yaml: str
) -> dict[str, float]:
    return train(pm, run_dir, fit=fit, seed=seed, config_yaml=config_yaml, progress=True)


class TrainedMapper:
    """A saved model ready to map landmarks (C, 33, 4) of its cameras to joint targets.

    Args:
        path: a training run directory or its ``model/``.
        where: how the user named it, for error lines (``algorithms.posemap.model=...``).
        refine: apply the kinematic fit saved with the model (if it has one); False: the learned
            model alone.
        iterations, starts: the fit's iterations and restarts (default: as saved).
    Raises:
        ConfigError: no model there, or one that cannot be read (named, with the cause).
    """

    def __init__(
        self,
        path: str,
        *,
        where: str = "",
        refine: bool = True,
        iterations: int | None = None,
        starts: int | None = None,
    ) -> None:
        where = where or f"algorithms.posemap.model={path}"
        directory = Path(path)
        if (directory / MODEL_DIRNAME / "model.json").is_file():
            directory = directory / MODEL_DIRNAME
        if not (directory / "model.json").is_file():
            raise ConfigError(
                "model not found",
                where,
                "no model.json there",
                "give a training run directory or its model/ (python -m simlan_data.run experiment=posemap_train ...)",
            )
        try:
            self.mapper, self.info = load_mapper(directory)
            self.spec = self.info["feature_spec"]
            self.cameras: list[str] = [str(c) for c in self.spec["cameras"]]
        except Exception as err:  # json, torch, pickle and missing keys all mean the same to a user
            first = str(err).strip().splitlines()[0] if str(err).strip() else ""
            raise ConfigError(
                "model unreadable",
                where,
                f"{type(err).__name__}: {first}"[:300],
                "retrain it (python -m simlan_data.run experiment=posemap_train ...) or restore its files",
            ) from err
        self.directory = directory
        saved = self.info.get("refine") if refine else None
        if saved:
            params = dict(saved["params"])
            params.update(
                {k: v for k, v in (("iterations", iterations), ("starts", starts)) if v is not None}
            )
            saved = {**saved, "params": params}
        self.refine: dict[str, Any] | None = saved or None  # the fit as it runs (Refiner.to_dict)

    def predict(self, landmarks: np.ndarray, *, position: list[float] | None = None) -> np.ndarray:
        """Joint targets (N, 47) of landmarks (N, C, 33, 4) in ``self.cameras`` order.

        ``position``: where the support base stands (x, y, yaw) if not where the model was
        trained (rig features are expressed in the base's frame; other features ignore it).
        """
        spec = self.spec if position is None else {**self.spec, "position": list(position)}
        landmarks = np.asarray(landmarks, dtype=np.float32)
        q = self.mapper.predict(features_for(landmarks, spec))
        if self.refine:
            q = Refiner.from_dict(self.refine, rig_of(spec))(landmarks, q)
        return q
