"""Learning curve of the one-camera model on MediaPipe's landmarks (issue 26 item 1, data size).

    python benchmarks/posemap_curve.py [--sizes 1000 3000 10000] [--camera 502] [--workers 2]
                                       [--workdir DIR] [--json FILE]

Through the real commands, in ``--workdir`` (existing runs are reused):

1. one MediaPipe dataset of ``--camera`` alone with the largest size (the fast path:
   ``posemap.workers``, the person crop);
2. for each size N its first N samples (the same bodies: sample ids < N) as a dataset of their own,
   and the one-camera model of the video round trip on it (``posemap.cameras=[CAM]
   posemap.features=image``, [256, 256, 256], 80 epochs, the kinematic fit);
3. every model scored on the same held-out bodies: the test split of the largest dataset (split by
   sample id, so no model trained on any of them), the learned model alone and with the fit, beside
   the mean pose of its training data.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from posemap import dataset, load_avg, one_camera_model, train

from common import REPO, write_result
from simlan_data.algorithms.posemap.dataset import read_dataset, split_of, write_dataset
from simlan_data.algorithms.posemap.training import TrainedMapper

SIMLAN = {"mlp": 0.359, "autogluon": 0.2465}


def subset(workdir: Path, full: str, n: int) -> str:
    """The first ``n`` samples of the dataset ``full`` as a dataset directory of their own."""
    name = f"{full}_first{n}"
    if not (workdir / name / "dataset.parquet").exists():
        data = read_dataset(str(workdir / full))
        part = data.subset(data.sample_ids < n)
        made = ("format", "samples", "sha256", "cameras", "estimator", "joint_names", "landmark_names")
        part.meta = {k: v for k, v in data.meta.items() if k not in made}  # (write_dataset writes those anew)
        write_dataset(workdir / name, part)
        (workdir / name / "metrics.json").write_text(json.dumps({"posemap.dataset.samples": float(n)}) + "\n")
    return name


def score(model: Path, workdir: Path, full: str) -> dict:
    """The model on the largest dataset's test split: learned alone, with the fit, the mean pose."""
    data = read_dataset(str(workdir / full))
    out: dict = {}
    for key, refine in (("learned", False), ("fit", True)):
        mapper = TrainedMapper(str(model), refine=refine)
        part = data.select_cameras(mapper.cameras)
        info = mapper.info["split"]
        split = split_of(
            part.sample_ids, val_fraction=info["val_fraction"], test_fraction=info["test_fraction"]
        )
        test = split == "test"
        t0 = time.perf_counter()
        pred = mapper.predict(part.landmarks[test])
        out[f"{key}_mae_rad"] = float(np.abs(pred - part.joints[test]).mean())
        out[f"{key}_s"] = time.perf_counter() - t0
        out["test_samples"] = int(test.sum())
        detected = part.landmarks[test, 0, :, 3].max(axis=1) > 0
        out[f"{key}_mae_rad_detected"] = float(np.abs(pred[detected] - part.joints[test][detected]).mean())
        out["test_detected_fraction"] = float(detected.mean())
    mean_pose = TrainedMapper(str(model), refine=False).mapper.y_norm
    assert mean_pose is not None  # (the MLPs standardise their targets)
    out["mean_pose_mae_rad"] = float(np.abs(np.asarray(mean_pose.mean)[None] - data.joints[test]).mean())
    return out


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 3000, 10000])
    parser.add_argument("--camera", default="502")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--workdir", type=Path, default=REPO / "recordings" / "posemap_curve")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if min(args.sizes) < 10 or args.workers < 0:
        raise SystemExit(
            f"invalid --sizes {' '.join(map(str, args.sizes))} / --workers {args.workers}: "
            "every size needs >= 10 samples (train, validation and test splits), workers >= 0"
        )
    args.workdir.mkdir(parents=True, exist_ok=True)
    load_before = load_avg()
    cam, largest = args.camera, max(args.sizes)
    full = f"mediapipe_{cam}_{largest}"
    made = dataset(args.workdir, full, f"posemap.samples={largest}", "posemap.estimator=mediapipe",
                   f"cameras.ids=[{cam}]", f"posemap.workers={args.workers}")  # fmt: skip
    one_camera, keys = one_camera_model(cam)
    rows = {}
    for n in sorted(args.sizes):
        name = full if n == largest else subset(args.workdir, full, n)
        trained = train(args.workdir, name, f"one_camera_{cam}", one_camera, keys)
        rows[n] = {
            "train_run": trained,
            **score(args.workdir / f"{name}__one_camera_{cam}", args.workdir, full),
        }
        print(n, json.dumps({k: v for k, v in rows[n].items() if k != "train_run"}), flush=True)
    figures = [
        {
            "id": f"posemap_mediapipe_curve_{n}",
            "figure": f"one-camera model ({cam}) on MediaPipe's landmarks, trained on {n} samples, "
            f"MAE on the same {r['test_samples']} held-out bodies (learned alone)",
            "value": round(r["learned_mae_rad"], 4),
            "unit": "rad",
            "target": "<= 0.20 rad (issue 26)",
            "baseline": f"its mean pose {r['mean_pose_mae_rad']:.4f} rad; SIMLAN: MLP {SIMLAN['mlp']}, AutoGluon {SIMLAN['autogluon']}",
            "note": f"with the kinematic fit {r['fit_mae_rad']:.4f} rad; views where MediaPipe found the person "
            f"{r['test_detected_fraction'] * 100:.1f} % (learned alone on those {r['learned_mae_rad_detected']:.4f})",
        }
        for n, r in rows.items()
    ]  # fmt: skip
    body = {
        "dataset": made,
        "rows": {str(n): r for n, r in rows.items()},
        "figures": figures,
    }
    command = (
        f"python benchmarks/posemap_curve.py --sizes {' '.join(map(str, args.sizes))} "
        f"--camera {cam} --workers {args.workers}"
    )
    return write_result(command, "docs/benchmarks/posemap.md", (load_before, load_avg()), body, args.json)


if __name__ == "__main__":
    sys.exit(main())
