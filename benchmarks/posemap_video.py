"""Round trip of the video drive (issue 26 item 3): a video the twin renders of known joints, driven from.

    python benchmarks/posemap_video.py [--samples 20000] [--mediapipe-samples 3000] [--camera 502] [--duration 8]
                                       [--workdir DIR] [--json FILE]

Through the real commands, in ``--workdir`` (existing runs are reused):

1. a projection dataset (ray occlusion) and a one-camera model of ``--camera`` (image features,
   the kinematic fit): ``experiment=posemap_train posemap.cameras=[CAM] posemap.features=image``;
   with ``--mediapipe-samples`` also a MediaPipe dataset of that camera alone and the same model on it;
2. ``experiment=posemap_motion cameras.ids=[CAM]``: the humanoid takes SIMLAN's motions, its joint
   states are the truth; the camera's recorded JPEG frames become ``motion.mp4`` (OpenCV, mp4v, at
   the camera rate);
3. ``experiment=posemap_video posemap.source=motion.mp4``: MediaPipe Pose on every frame -> the
   model -> the humanoid in a new run;
4. the driven joint states at frame k's time against the motion's at frame k's stamp: MAE over
   frames and the 47 joints; beside it the same model on the motion run's projection landmarks
   (``experiment=posemap_drive posemap.drive=<motion run>``: what ideal landmarks give) and the
   model's mean pose. Steps 3-4 run for each model.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from posemap import dataset, load_avg, one_camera_model, train

from common import REPO, run_cli, write_result
from simlan_data.algorithms.posemap.training import TrainedMapper
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader

JOINTS = schema.agent_topics("robot_agent_1")["joint_states"].name
COMMON = ("progress=false",)


def run(name: str, workdir: Path, *args: str) -> Path:
    out = workdir / name
    if not (out / "metrics.json").exists():
        proc = run_cli(*args, *COMMON, f"hydra.run.dir={out}", timeout=3600)
        if proc.returncode != 0:
            raise SystemExit(f"{name} failed:\n{proc.stderr}")
    return out


def joint_states(recording: Path) -> dict[int, np.ndarray]:
    """Log time (from the first joint state) -> the 47 joint positions."""
    with RecordingReader(recording) as bag:
        rows = {m.stamp_ns: np.asarray(m.msg.position, dtype=np.float64) for m in bag.messages([JOINTS])}
    t0 = min(rows)
    return {t - t0: q for t, q in rows.items()}


def write_video(recording: Path, camera: str, fps: float, path: Path) -> list[int]:
    """The camera's recorded colour frames as an mp4; returns their log times."""
    topic = schema.camera_topics(camera, rgb="jpeg", depth=None, semantic=None)["rgb"].name
    stamps: list[int] = []
    writer = None
    with RecordingReader(recording) as bag:
        for m in bag.messages([topic]):
            bgr = cv2.imdecode(np.frombuffer(bytes(m.msg.data), np.uint8), cv2.IMREAD_COLOR)
            if writer is None:
                size = (bgr.shape[1], bgr.shape[0])
                writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, size)
            writer.write(bgr)
            stamps.append(m.stamp_ns)
    if writer is None:
        raise SystemExit(f"no {topic} in {recording}")
    writer.release()
    return stamps


def round_trip(
    workdir: Path,
    name: str,
    model: Path,
    motion: Path,
    video: Path,
    stamps: list[int],
    scene: tuple[str, ...],
    rate: float,
) -> dict:
    """Drive from the video and from the motion's projection landmarks with ``model``; score both."""
    driven_run = run(f"{name}__video_drive", workdir, "experiment=posemap_video", f"posemap.source={video}",
                     f"algorithms.posemap.model={model}", *scene)  # fmt: skip
    ideal_run = run(f"{name}__landmark_drive", workdir, "experiment=posemap_drive", f"posemap.drive={motion}",
                    f"algorithms.posemap.model={model}", *scene)  # fmt: skip
    truth_by_t, driven_by_t = joint_states(motion / "recording"), joint_states(driven_run / "recording")
    video_metrics = json.loads((driven_run / "metrics.json").read_text())
    period_ns = round(1e9 / rate)
    frames = [
        k for k in range(int(video_metrics["posemap.source.frames"])) if stamps[k] - stamps[0] in truth_by_t
    ]
    truth = np.stack([truth_by_t[stamps[k] - stamps[0]] for k in frames])
    driven = np.stack([driven_by_t[k * period_ns] for k in frames])
    mean_pose = TrainedMapper(str(model), refine=False).mapper.y_norm
    return {
        "mae_rad": float(np.abs(driven - truth).mean()),
        "frames_compared": len(frames),
        "projection_landmarks_drive_mae_rad": json.loads((ideal_run / "metrics.json").read_text())[
            "posemap.drive.mae_rad"
        ],
        "mean_pose_mae_rad": float(np.abs(np.asarray(mean_pose.mean)[None] - truth).mean())
        if mean_pose
        else None,
        "model_test_mae_rad": json.loads((model / "metrics.json").read_text()).get("posemap.mae_rad"),
        "video": {k: v for k, v in video_metrics.items() if k.startswith("posemap.")},
    }


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--samples", type=int, default=20000)
    parser.add_argument(
        "--mediapipe-samples", type=int, default=0, help="also a model on MediaPipe's landmarks"
    )
    parser.add_argument("--camera", default="502")
    parser.add_argument("--duration", type=float, default=8.0)
    parser.add_argument("--rate", type=float, default=5.0, help="camera rate = the video's frame rate")
    parser.add_argument("--workdir", type=Path, default=REPO / "recordings" / "posemap_video")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    load_before = load_avg()
    cam = args.camera
    one_camera, train_keys = one_camera_model(cam)
    models = {}
    dataset(args.workdir, "dataset", f"posemap.samples={args.samples}", "posemap.occlusion=rays")
    train(args.workdir, "dataset", f"one_camera_{cam}", one_camera, train_keys)
    models["projection"] = args.workdir / f"dataset__one_camera_{cam}"
    if args.mediapipe_samples > 0:
        dataset(args.workdir, "mediapipe_dataset", f"posemap.samples={args.mediapipe_samples}",
                "posemap.estimator=mediapipe", f"cameras.ids=[{cam}]")  # fmt: skip
        train(args.workdir, "mediapipe_dataset", f"one_camera_{cam}", one_camera, train_keys)
        models["mediapipe"] = args.workdir / f"mediapipe_dataset__one_camera_{cam}"
    scene = (f"cameras.ids=[{cam}]", f"cameras.rate_hz={args.rate:g}", f"duration_s={args.duration:g}")
    motion = run(
        "motion",
        args.workdir,
        "experiment=posemap_motion",
        f"posemap.landmarks_rate_hz={args.rate:g}",
        *scene,
    )
    video = args.workdir / "motion.mp4"
    stamps = write_video(motion / "recording", cam, args.rate, video)
    results = {name: round_trip(args.workdir, name, model, motion, video, stamps, scene, args.rate)
               for name, model in models.items()}  # fmt: skip
    first = results["projection"]
    figures = [
        {
            "id": f"posemap_video_roundtrip_mae_{name}",
            "figure": f"video round trip: twin renders SIMLAN's motions on camera {cam} to mp4, MediaPipe Pose "
            f"-> one-camera model (trained on {name} landmarks) + fit -> driven humanoid, joint MAE against the rendered joints",
            "value": round(r["mae_rad"], 4),
            "unit": "rad",
            "baseline": f"same model on the projection landmarks of the same run: {r['projection_landmarks_drive_mae_rad']:.4f} rad; "
            f"its mean pose {r['mean_pose_mae_rad']:.4f} rad",
            "note": f"{r['frames_compared']} frames at {args.rate:g} Hz, person found in "
            f"{r['video'].get('posemap.source.detected_fraction', 0):.2f} of them",
        }
        for name, r in results.items()
    ]
    body = {
        "frames_compared": first["frames_compared"],
        "models": results,
        "figures": figures,
    }
    command = (
        "python benchmarks/posemap_video.py "
        f"--samples {args.samples} --mediapipe-samples {args.mediapipe_samples} --camera {cam} "
        f"--duration {args.duration:g} --rate {args.rate:g}"
    )
    return write_result(command, "docs/benchmarks/posemap.md", (load_before, load_avg()), body, args.json)


if __name__ == "__main__":
    sys.exit(main())
