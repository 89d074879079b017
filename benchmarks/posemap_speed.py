"""Speed of MediaPipe pose-dataset generation (issue 26 item 2): profile, person crop, worker pool.

    python benchmarks/posemap_speed.py [--samples 200] [--profile-samples 30] [--workdir DIR] [--json FILE]

1. Profile (in this process, ``--profile-samples`` bodies, cameras 500-503): per view the render
   (PyBullet EGL region render + compositing + lens distortion), MediaPipe's ``process()`` alone
   (timed in its own environment on the same images) and the pipe round trip (one image per
   request, and ``PIPE_WINDOW`` at a time), on the full frame and on the person crop.
2. Through the real command, the same ``--samples`` seeded bodies each time (a fresh run directory):
   the baseline (``posemap.workers=1 posemap.crop=full``), the person crop, the crop with
   ``posemap.workers=2`` (joblib's loky, both cores) and ``posemap.pool=ray`` (a local Ray cluster of
   2 workers). Samples per second from each run's metrics (the workers' setup left out) and from
   the command's wall time; detection rate and MediaPipe's landmark error against the skeleton's
   (a projection dataset of the same bodies without noise: pixel distance, landmarks the skeleton
   shows and those it hides), and whether the landmarks equal the serial run's.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from posemap import load_avg

from common import REPO, run_cli, write_result
from simlan_data.algorithms.posemap.dataset import read_dataset
from simlan_data.algorithms.posemap.estimators import PIPE_WINDOW, MediaPipeEstimator
from simlan_data.config.validation import compose_config
from simlan_data.sim.posemap_dataset import CaptureRig
from simlan_data.world.skeleton import sample_joints

MP_PYTHON = REPO / ".venv-mediapipe" / "bin" / "python"
PROCESS_ONLY = """
import sys, time, numpy as np, mediapipe as mp
pose = mp.solutions.pose.Pose(static_image_mode=True, model_complexity=1, min_detection_confidence=0.5)
out = {}
for name in sys.argv[1:]:
    images = list(np.load(name, allow_pickle=True))
    pose.process(images[0])
    t0 = time.perf_counter()
    for image in images:
        pose.process(image)
    out[name] = (time.perf_counter() - t0) / len(images)
print(out)
"""
RUNS = {
    "baseline": ("serial, full frame", ["posemap.workers=1", "posemap.crop=full"]),
    "crop": ("serial, person crop", ["posemap.workers=1", "posemap.crop=person"]),
    "crop_loky2": ("person crop, 2 workers (joblib loky)", ["posemap.workers=2", "posemap.crop=person"]),
    "crop_ray2": (
        "person crop, 2 workers on a local Ray cluster",
        ["posemap.workers=2", "posemap.crop=person", "posemap.pool=ray"],
    ),
}


def profile(n: int, workdir: Path) -> dict:
    """Per view: render, MediaPipe alone, the pipe round trip; full frame and person crop."""
    cfg = compose_config(["experiment=posemap_dataset", "posemap.estimator=mediapipe"])
    rig = CaptureRig(cfg, need_images=True)
    q = sample_joints(np.random.default_rng(cfg.seed), n, limit_scale=cfg.posemap.limit_scale)
    full, crops, render_s = [], [], 0.0
    try:
        for i in range(n):
            t0 = time.perf_counter()
            views = rig.views(q[i], rays=False)
            render_s += time.perf_counter() - t0
            for v in views:
                u0, v0, u1, v1 = v.crop or (0, 0, v.camera.width, v.camera.height)
                full.append(v.rgb.copy())  # type: ignore[union-attr]
                crops.append(v.rgb[v0:v1, u0:u1].copy())  # type: ignore[index]
    finally:
        rig.close()
    out: dict = {"views": len(full), "render_ms": 1e3 * render_s / len(full)}
    names = {"full": workdir / "profile_full.npy", "crop": workdir / "profile_crop.npy"}
    for key, images in (("full", full), ("crop", crops)):
        arr = np.empty(len(images), dtype=object)
        arr[:] = images
        np.save(names[key], arr, allow_pickle=True)
        out[f"{key}_pixels"] = float(np.mean([im.shape[0] * im.shape[1] for im in images]))
    proc = subprocess.run([str(MP_PYTHON), "-c", PROCESS_ONLY, *map(str, names.values())],
                          capture_output=True, text=True, check=True)  # fmt: skip
    alone = eval(proc.stdout.strip().splitlines()[-1])  # a dict literal of our own script
    with MediaPipeEstimator(str(MP_PYTHON)) as est:
        for key, images in (("full", full), ("crop", crops)):
            assert isinstance(est, MediaPipeEstimator)
            est.estimate_images(images[:2])
            t0 = time.perf_counter()
            for image in images:
                est.estimate_images([image])
            one = (time.perf_counter() - t0) / len(images)
            t0 = time.perf_counter()
            est.estimate_images(images)
            window = (time.perf_counter() - t0) / len(images)
            process = alone[str(names[key])]
            out[key] = {"mediapipe_process_ms": 1e3 * process, "round_trip_ms": 1e3 * one,
                        "pipe_ms": 1e3 * (one - process), f"round_trip_window{PIPE_WINDOW}_ms": 1e3 * window}  # fmt: skip
    return out


def generate(workdir: Path, name: str, samples: int, *args: str) -> tuple[dict, float]:
    run = workdir / name
    t0 = time.perf_counter()
    proc = run_cli("experiment=posemap_dataset", f"posemap.samples={samples}", *args, "progress=false",
                   f"hydra.run.dir={run}", timeout=4 * 3600)  # fmt: skip
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"dataset {name} failed:\n{proc.stderr}")
    return json.loads((run / "metrics.json").read_text()), wall


def landmark_error(run: Path, truth: Path, among: np.ndarray | None = None) -> dict:
    """MediaPipe's landmarks against the skeleton's (noise-free projection), in pixels; ``among``:
    only these views (sample, camera)."""
    mp_data, ref = read_dataset(str(run)), read_dataset(str(truth))
    assert np.array_equal(mp_data.joints, ref.joints)
    size = np.array(mp_data.meta["image_size"], dtype=float)
    found = mp_data.landmarks[..., 3].max(axis=2) > 0
    if among is not None:
        found &= among
    err = np.linalg.norm((mp_data.landmarks[..., :2] - ref.landmarks[..., :2]) * size, axis=-1)
    seen = (ref.landmarks[..., 3] > 0.5) & found[..., None]
    hidden = (ref.landmarks[..., 3] <= 0.5) & (ref.landmarks[..., 0] != 0) & found[..., None]
    return {
        "detected_fraction": float(found.mean()),
        "seen_median_px": float(np.median(err[seen])),
        "seen_mean_px": float(err[seen].mean()),
        "hidden_median_px": float(np.median(err[hidden])),
        "views": int(found.size),
    }


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--profile-samples", type=int, default=30)
    parser.add_argument("--workdir", type=Path, default=REPO / "recordings" / "posemap_speed")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--runs", default=",".join(RUNS), help="which of the runs, comma-separated")
    args = parser.parse_args()
    unknown = [k for k in args.runs.split(",") if k not in RUNS]
    if unknown or args.samples < 1 or args.profile_samples < 1:
        raise SystemExit(
            f"invalid --runs {args.runs} / --samples {args.samples} / --profile-samples {args.profile_samples}: "
            f"runs are {','.join(RUNS)}, sample counts >= 1"
        )
    args.workdir.mkdir(parents=True, exist_ok=True)
    load_before = load_avg()
    prof = profile(args.profile_samples, args.workdir)
    print(json.dumps(prof, indent=1))
    truth = args.workdir / "skeleton"
    generate(args.workdir, "skeleton", args.samples, "posemap.noise_px=0", "posemap.hidden_noise_px=0")
    runs: dict = {}
    for key in args.runs.split(","):
        label, overrides = RUNS[key]
        metrics, wall = generate(args.workdir, key, args.samples, "posemap.estimator=mediapipe", *overrides)
        runs[key] = {"label": label, "overrides": overrides, "metrics": metrics, "command_wall_s": wall,
                     "command_samples_per_s": args.samples / wall,
                     "landmarks": landmark_error(args.workdir / key, truth)}  # fmt: skip
        print(key, json.dumps(runs[key], indent=1), flush=True)
    if "baseline" in runs and "crop" in runs:  # the same views: found on the full frame and in the crop
        both = np.logical_and(*(read_dataset(str(args.workdir / k)).landmarks[..., 3].max(axis=2) > 0
                                for k in ("baseline", "crop")))  # fmt: skip
        for key in ("baseline", "crop"):
            runs[key]["landmarks_found_in_both"] = landmark_error(args.workdir / key, truth, both)
    serial = read_dataset(str(args.workdir / "crop")).landmarks if "crop" in runs else None
    for key, r in runs.items():
        if serial is not None and key.startswith("crop_"):
            other = read_dataset(str(args.workdir / key)).landmarks
            r["equal_to_serial"] = bool(np.array_equal(other, serial))
            r["max_abs_diff_to_serial"] = float(np.abs(other - serial).max())
    figures = _figures(args, prof, runs)
    body = {
        "profile": prof,
        "runs": runs,
        "figures": figures,
    }
    command = f"python benchmarks/posemap_speed.py --samples {args.samples} --profile-samples {args.profile_samples}"
    return write_result(command, "docs/benchmarks/posemap.md", (load_before, load_avg()), body, args.json)


def _figures(args: argparse.Namespace, prof: dict, runs: dict) -> list[dict]:
    base = runs.get("baseline")
    out = []
    for key, r in runs.items():
        if key == "baseline" or base is None:
            continue
        m, lm, blm = r["metrics"], r["landmarks"], base["landmarks"]
        out.append({
            "id": f"posemap_mediapipe_dataset_speed_{key}",
            "figure": f"MediaPipe dataset generation, cameras 500-503, {r['label']}",
            "value": round(m["posemap.dataset.samples_per_s"], 2),
            "unit": "samples/s",
            "baseline": f"serial, full frame in the same run: {base['metrics']['posemap.dataset.samples_per_s']:.2f} samples/s "
            f"(person found in {blm['detected_fraction'] * 100:.1f} % of the views, seen landmarks {blm['seen_median_px']:.1f} px median from the skeleton's)",
            "note": f"{args.samples} samples; command wall time {r['command_samples_per_s']:.2f} samples/s with startup; "
            f"person found in {lm['detected_fraction'] * 100:.1f} %, seen landmarks {lm['seen_median_px']:.1f} px median, "
            f"hidden {lm['hidden_median_px']:.1f} px; profile per view: render {prof['render_ms']:.1f} ms, MediaPipe "
            f"{prof['full']['mediapipe_process_ms']:.1f} ms full frame / {prof['crop']['mediapipe_process_ms']:.1f} ms crop, "
            f"pipe {prof['full']['pipe_ms']:.1f} / {prof['crop']['pipe_ms']:.1f} ms",
        })  # fmt: skip
    if base is not None and "crop" in runs:
        c, b = runs["crop"]["landmarks"], base["landmarks"]
        cb, bb = runs["crop"]["landmarks_found_in_both"], base["landmarks_found_in_both"]
        out.append(
            {
                "id": "posemap_mediapipe_crop_detected",
                "figure": "MediaPipe Pose on the person crop (+25 % margin): person found, of the views of cameras 500-503",
                "value": round(100 * c["detected_fraction"], 1),
                "unit": "%",
                "baseline": f"full 960x540 frame, same bodies: {100 * b['detected_fraction']:.1f} %",
                "note": f"{c['views']} views",
            }
        )
        out.append({
            "id": "posemap_mediapipe_crop_landmark_px",
            "figure": "MediaPipe Pose on the person crop: landmarks the skeleton shows, median distance to the skeleton's, views found in both",
            "value": round(cb["seen_median_px"], 2),
            "unit": "px",
            "baseline": f"full frame: {bb['seen_median_px']:.2f} px (mean {bb['seen_mean_px']:.1f}, hidden landmarks {bb['hidden_median_px']:.1f} px median)",
            "note": f"crop: mean {cb['seen_mean_px']:.1f} px, hidden landmarks {cb['hidden_median_px']:.1f} px median; over all views each found: "
            f"crop {c['seen_median_px']:.2f} px, full {b['seen_median_px']:.2f} px",
        })  # fmt: skip
    return out


if __name__ == "__main__":
    sys.exit(main())
