"""Benchmark of the pose mapping (issue 6): accuracy of the models beside SIMLAN's figures.

    python benchmarks/posemap.py [--samples 30000] [--mediapipe-samples 3000] [--workdir DIR] [--json FILE]

Through the real commands (python -m simlan_data.run ...), in ``--workdir`` (default
recordings/posemap_benchmark; existing datasets and models there are reused, so a re-run only
does what is missing):

1. datasets: the projection estimator (ray occlusion) with ``--samples``; MediaPipe Pose 0.10.14 on
   the rendered images with ``--mediapipe-samples`` (same seed: its bodies are the projection
   dataset's first samples); generation speed of both occlusion modes on 200 samples;
2. models on each: our re-implementation of SIMLAN's single-camera MLP (camera 500, x, y, z,
   hidden [504, 476, 479]), gradient boosting on one camera (AutoGluon's stand-in), and the
   multi-view fusion MLP on cameras 500-503, alone and followed by the kinematic fit
   (``algorithms.posemap.refine=fit``); the fit's information bound (started from and pulled towards the
   true joints: what no estimate from these landmarks can beat by much);
3. prints markdown for docs/benchmarks/posemap.md (SIMLAN's reported 0.2465 rad AutoGluon and 0.359 rad MLP
   beside ours) and the raw JSON. Accuracy figures do not depend on load; timed ones do.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))  # this checkout's simlan_data
from common import REPO, machine, run_cli, table
from simlan_data.algorithms.posemap.ambiguity import ambiguity_floor, curve_medians, curve_tangents
from simlan_data.algorithms.posemap.dataset import PoseDataset, read_dataset, split_of
from simlan_data.algorithms.posemap.fit import Refiner, posterior_cov
from simlan_data.algorithms.posemap.metrics import evaluate
from simlan_data.algorithms.posemap.training import TrainedMapper, rig_of
from simlan_data.world.skeleton import JOINT_NAMES, sampling_box

SIMLAN = {"autogluon": 0.2465, "mlp": 0.359}
FUSION = [
    "posemap.model=fusion",
    "posemap.epochs=60",
    "posemap.batch_size=512",
    "posemap.hidden=[256,256]",
    "posemap.dropout=0.0",
    "posemap.lr=0.003",
]
MODELS = {
    # name: (overrides, what); the same epochs and batch for both MLPs
    "simlan_mlp": (
        [
            "posemap.model=mlp",
            "posemap.cameras=[500]",
            "posemap.epochs=12",
            "posemap.batch_size=512",
            "algorithms.posemap.refine=none",
        ],
        "SIMLAN's MLP re-implemented: camera 500, x, y, z, [504, 476, 479], dropout 0.1, Adam, MSE",
    ),
    "gbm_1cam": (
        [
            "posemap.model=gbm",
            "posemap.cameras=[500]",
            "posemap.features=image",
            "posemap.gbm_iterations=100",
            "posemap.loss=mse",
            "posemap.threads=1",
            "algorithms.posemap.refine=none",
        ],
        "gradient boosting per joint, camera 500 (AutoGluon's stand-in)",
    ),
    "fusion": (
        [*FUSION, "algorithms.posemap.refine=none"],
        "multi-view fusion MLP (L1), cameras 500-503, rig features, 2 x 256, learned alone",
    ),
    "fusion_fit": (
        [*FUSION, "algorithms.posemap.refine=fit"],
        "the same fusion MLP + kinematic fit to all 4 cameras (algorithms.posemap.refine=fit)",
    ),
}


def dump_raw(raw: dict, path: Path | None) -> None:
    """The raw figures as a JSON block for docs/benchmarks/posemap.md, and into ``path`` if given."""
    text = json.dumps(raw, indent=1, sort_keys=True)
    print("\n```json\n" + text + "\n```")
    if path:
        path.write_text(text + "\n")


def one_camera_model(cam: str) -> tuple[list[str], list[str]]:
    """The one-camera model of the video round trip and the learning curve: its shape, its training."""
    shape = [f"posemap.cameras=[{cam}]", "posemap.features=image", "posemap.width=256", "posemap.layers=3"]
    return shape, ["posemap.dropout=0.0", "posemap.lr=0.003", "posemap.epochs=80", "progress=false"]


def load_avg() -> str:
    one, five, fifteen = os.getloadavg()
    return f"{one:.1f} / {five:.1f} / {fifteen:.1f}"


def dataset(workdir: Path, name: str, *args: str) -> dict:
    run = workdir / name
    if not (run / "dataset.parquet").exists():
        proc = run_cli(
            "experiment=posemap_dataset", *args, "progress=false", f"hydra.run.dir={run}", timeout=4 * 3600
        )
        if proc.returncode != 0:
            raise SystemExit(f"dataset {name} failed:\n{proc.stderr}")
    return json.loads((run / "metrics.json").read_text())


def train(workdir: Path, data: str, name: str, overrides: list[str], extra: list[str]) -> dict:
    run = workdir / f"{data}__{name}"
    if not (run / "model" / "model.json").exists():
        proc = run_cli(
            "experiment=posemap_train",
            f"posemap.dataset={workdir / data}",
            *overrides,
            *extra,
            f"hydra.run.dir={run}",
            timeout=4 * 3600,
        )
        if proc.returncode != 0:
            raise SystemExit(f"training {name} on {data} failed:\n{proc.stderr}")
    return json.loads((run / "metrics.json").read_text())


def model_and_split(model_run: Path, dataset_dir: Path) -> tuple[TrainedMapper, PoseDataset, np.ndarray]:
    """A trained model, a dataset in its cameras' order, and the model's split of that dataset."""
    mapper = TrainedMapper(str(model_run))
    data = read_dataset(str(dataset_dir)).select_cameras(mapper.cameras)
    info = mapper.info["split"]
    split = split_of(data.sample_ids, val_fraction=info["val_fraction"], test_fraction=info["test_fraction"])
    return mapper, data, split


def transfer(model_run: Path, dataset_dir: Path) -> dict:
    """A model trained on projection landmarks, scored on MediaPipe's landmarks of bodies it never
    trained on (the samples outside its training split; same seed, same bodies): SIMLAN's claim
    that the estimator behaves alike on simulated and real images, tested from the other side."""
    mapper, data, split = model_and_split(model_run, dataset_dir)
    unseen = split != "train"
    out = evaluate(
        mapper.predict(data.landmarks[unseen]), data.joints[unseen], data.joints[~unseen].mean(axis=0)
    )
    out["posemap.test.samples"] = float(unseen.sum())
    return out


def fit_bound(model_run: Path, dataset_dir: Path, n: int = 2000) -> dict:
    """The fit with the truth as its start and prior (the learned model's per-joint sigma): how
    far the landmarks alone leave the joints, i.e. roughly the best any estimate can do here."""
    mapper, data, split = model_and_split(model_run, dataset_dir)
    te = np.flatnonzero(split == "test")[:n]
    refiner = Refiner.from_dict(mapper.info["refine"], rig_of(mapper.spec))
    y = data.joints[te]
    q = refiner(data.landmarks[te], y)
    return {"posemap.mae_rad": float(np.abs(q - y).mean()), "samples": len(te)}


def information_bound(model_run: Path, dataset_dir: Path, floor: dict[str, float], n: int = 2000) -> dict:
    """What the landmarks leave, whatever the estimator, on n test samples of the projection
    estimator (its noise model): at the true joints, the Laplace posterior ``fit.posterior_cov``.

    - ``ideal``: a simulated ideal estimator: the truth plus an error drawn from that posterior,
      without its part along the unrecoverable curves (conditioned on it), then the curve
      medians (:mod:`ambiguity`), within the sampling box;
    - ``floor_plus_laplace``: the perfect-landmark floor for the 16 ambiguous joints plus a
      Gaussian posterior's MAE (0.798 sigma, at most the box's w / 4) for the other 31
      (optimistic: it treats the ambiguous groups as noise-free).
    Approximate (a Gaussian posterior; the box's information as a Gaussian's); a
    real estimate has to find the posterior first, so it can only be worse."""
    mapper, data, split = model_and_split(model_run, dataset_dir)
    te = np.flatnonzero(split == "test")[:n]
    refiner = Refiner.from_dict(mapper.info["refine"], rig_of(mapper.spec))
    lo, hi = sampling_box(refiner.params.limit_scale)
    rng = np.random.default_rng(0)
    ideal, sd = [], []
    for s in range(0, len(te), 250):
        y = data.joints[te[s : s + 250]].astype(np.float64)
        cov = posterior_cov(data.landmarks[te[s : s + 250]], refiner.rig, y, refiner.params)
        eps = (np.linalg.cholesky(cov) @ rng.standard_normal((len(y), len(lo), 1)))[..., 0]
        T = curve_tangents(y)  # eps given no error along the curves: eps - S T (T' S T)^-1 T' eps
        ST = cov @ T
        Tt = T.transpose(0, 2, 1)
        eps = eps - (ST @ np.linalg.solve(Tt @ ST, Tt @ eps[..., None]))[..., 0]
        ideal.append(np.clip(curve_medians(y + eps, limit_scale=refiner.params.limit_scale), lo, hi) - y)
        sd.append(np.sqrt(np.einsum("nii->ni", cov)))
    ideal_joint = np.abs(np.concatenate(ideal)).mean(axis=0)
    laplace = np.minimum(0.798 * np.concatenate(sd), (hi - lo) / 4).mean(axis=0)
    joints = {nm: float(floor.get(nm, laplace[i])) for i, nm in enumerate(JOINT_NAMES)}
    return {
        "ideal.mae_rad": float(ideal_joint.mean()),
        "ideal.joints": {nm: float(v) for nm, v in zip(JOINT_NAMES, ideal_joint)},
        "floor_plus_laplace.mae_rad": sum(joints.values()) / len(joints),
        "floor_plus_laplace.joints": joints,
        "samples": len(te),
    }


def worst_joints(m: dict, n: int = 5) -> str:
    joints = sorted(
        (k for k in m if k.startswith("posemap.joint.") and k.endswith(".mae_rad")), key=lambda k: -m[k]
    )
    return ", ".join(f"{k.split('.')[2]} {m[k]:.3f}" for k in joints[:n])


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--samples", type=int, default=30000)
    parser.add_argument("--mediapipe-samples", type=int, default=120)
    parser.add_argument("--workdir", type=Path, default=REPO / "recordings" / "posemap_benchmark")
    parser.add_argument("--extra", nargs="*", default=[], help="overrides for every training run")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    raw: dict = {
        "machine": machine(),
        "load_before": load_avg(),
        "samples": args.samples,
        "mediapipe_samples": args.mediapipe_samples,
    }

    speed_rays = dataset(
        args.workdir, "speed_rays", "posemap.samples=200", "posemap.occlusion=rays", "seed=100"
    )
    speed_depth = dataset(
        args.workdir, "speed_depth", "posemap.samples=200", "posemap.occlusion=depth", "seed=100"
    )
    raw["speed"] = {"rays": speed_rays, "depth": speed_depth}
    data = {
        "projection": dataset(
            args.workdir, "projection", f"posemap.samples={args.samples}", "posemap.occlusion=rays"
        )
    }
    if args.mediapipe_samples > 0:
        data["mediapipe"] = dataset(
            args.workdir,
            "mediapipe",
            f"posemap.samples={args.mediapipe_samples}",
            "posemap.estimator=mediapipe",
        )
    raw["datasets"] = data
    results: dict[str, dict[str, dict]] = {}
    for d in data:
        results[d] = {name: train(args.workdir, d, name, ov, args.extra) for name, (ov, _) in MODELS.items()}
    if "mediapipe" in data:
        results["mediapipe (model trained on projection)"] = {
            name: transfer(args.workdir / f"projection__{name}", args.workdir / "mediapipe")
            for name in ("simlan_mlp", "fusion", "fusion_fit")
        }
    raw["results"] = {
        d: {n: {k: v for k, v in m.items() if ".joint." not in k} for n, m in r.items()}
        for d, r in results.items()
    }
    raw["worst_joints"] = {d: {n: worst_joints(m) for n, m in r.items()} for d, r in results.items()}
    raw["fit_bound"] = fit_bound(args.workdir / "projection__fusion_fit", args.workdir / "projection")
    floor = ambiguity_floor()
    raw["ambiguity_floor"] = floor
    raw["ambiguity_floor_mae_rad"] = sum(floor.values()) / 47
    raw["information_bound"] = information_bound(
        args.workdir / "projection__fusion_fit", args.workdir / "projection", floor
    )
    raw["load_after"] = load_avg()

    print(
        f"Command: `python benchmarks/posemap.py --samples {args.samples} --mediapipe-samples {args.mediapipe_samples}`\n"
    )
    print(
        f"Machine: {raw['machine']}; load average (1/5/15 min) {raw['load_before']} before, {raw['load_after']} after (shared cores)\n"
    )
    rows = []
    for d, r in results.items():
        for name, m in r.items():
            n_test = int(m["posemap.test.samples"])
            simlan = (
                f"{SIMLAN['mlp']}"
                if name == "simlan_mlp"
                else (f"{SIMLAN['autogluon']}" if name == "gbm_1cam" else "-")
            )
            rows.append(
                [
                    d,
                    MODELS[name][1],
                    f"{m['posemap.mae_rad']:.4f}",
                    f"{m['posemap.mae_deg']:.2f}",
                    f"{m['posemap.mse_rad2']:.4f}",
                    f"{m['posemap.mpjpe_m'] * 100:.1f}",
                    f"{m['posemap.baseline.mean_pose.mae_rad']:.4f}",
                    simlan,
                    n_test,
                    f"{m['posemap.inference_us_per_sample']:.1f}"
                    if "posemap.inference_us_per_sample" in m
                    else "-",
                ]
            )
    print(
        table(
            [
                "estimator",
                "model",
                "MAE rad",
                "MAE deg",
                "MSE rad^2",
                "MPJPE cm",
                "mean-pose MAE rad",
                "SIMLAN reported MAE rad",
                "test samples",
                "inference us/sample",
            ],
            rows,
        )
    )
    print()
    print(
        table(
            ["dataset generation (4 cameras, 960x540)", "samples/s", "landmarks visible"],
            [
                [
                    "projection, occlusion by ray casts",
                    f"{speed_rays['posemap.dataset.samples_per_s']:.1f}",
                    f"{speed_rays['posemap.dataset.visible_fraction']:.3f}",
                ],
                [
                    "projection, occlusion by the rendered depth (humanoid region only)",
                    f"{speed_depth['posemap.dataset.samples_per_s']:.1f}",
                    f"{speed_depth['posemap.dataset.visible_fraction']:.3f}",
                ],
            ]
            + (
                [
                    [
                        "MediaPipe Pose 0.10.14 on the rendered images",
                        f"{data['mediapipe']['posemap.dataset.samples_per_s']:.2f}",
                        f"{data['mediapipe']['posemap.dataset.visible_fraction']:.3f} (person found in {data['mediapipe']['posemap.dataset.detected_fraction']:.3f} of the views)",
                    ]
                ]
                if "mediapipe" in data
                else []
            ),
        )
    )
    print()
    print(
        f"Ambiguity floor: with perfect landmarks the 16 joints of the 4 ambiguous groups (shoulder xyz + elbow y, "
        f"knee z + ankle xyz, per side) cannot be recovered better than a summed MAE of {sum(floor.values()):.3f} rad, "
        f"i.e. {raw['ambiguity_floor_mae_rad']:.4f} rad on the 47-joint mean; per joint: "
        + ", ".join(f"{k} {v:.3f}" for k, v in floor.items())
        + "\n"
    )
    bound = raw["information_bound"]
    worst = sorted(bound["ideal.joints"].items(), key=lambda kv: -kv[1])
    print(
        f"Information bound (projection estimator, its noise model, {bound['samples']} test samples, "
        f"Laplace posterior at the true joints): a simulated ideal estimator (the truth plus the "
        f"posterior's error off the unrecoverable curves, then the curve medians) gets "
        f"{bound['ideal.mae_rad']:.4f} rad; the perfect-landmark floor plus 0.798 sigma on the other 31 joints "
        f"{bound['floor_plus_laplace.mae_rad']:.4f} rad (optimistic). Ideal estimator per joint, worst: "
        + ", ".join(f"{k} {v:.3f}" for k, v in worst[:12])
        + f". Not a bound: the fit started from and pulled towards the true joints gives "
        f"{raw['fit_bound']['posemap.mae_rad']:.4f} rad (it is told the truth where the landmarks say nothing).\n"
    )
    for d, r in raw["worst_joints"].items():
        for name, text in r.items():
            print(f"- worst joints, {d} / {name}: {text}")
    dump_raw(raw, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
