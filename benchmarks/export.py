"""Instance ground truth and dataset export (issue 25): what annotation costs a run, how fast the
exports go, and how many bytes an annotated frame takes.

    python benchmarks/export.py --json benchmarks/results/export_DATE.json [--cameras 11] [--duration 10] [--repeat 2] [--scenario S]

The same run (``--scenario``, default ``default``; ``humanoid_crossing`` has a person, so its
instance stream records keypoints too; seed 1, the first ``--cameras`` GPSS cameras at 960x540 and 5 Hz)
with ``cameras.streams=[rgb,semantic]`` and ``[rgb,semantic,instance]``, alternately (``--repeat``
pairs: load drifts, so each pair runs close in time); frames per second = camera frames recorded
/ the run's simulation wall time (``sim.wall_s``: start-up left out). Then the instance run is
exported to COCO, YOLO, MOTChallenge and AI City (``python -m simlan_data.export``, process wall
time). History:
docs/benchmarks/datasets.md.

    python benchmarks/export.py --only lerobot --json benchmarks/results/export_DATE_lerobot.json [--cameras 11] [--duration 20]

measures the LeRobot export alone: one run with ``cameras.streams=[rgb]`` (the export needs no
instance stream), exported ``--repeat`` times; camera frames (ticks x cameras, each one decoded
and AV1-encoded) per second of the export process's wall time, and its peak memory (ru_maxrss).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import REPO, machine, run_cli

OFF, ON = "[rgb,semantic]", "[rgb,semantic,instance]"
INSTANCE_SUFFIXES = ("/instances/image_raw/compressed", "/instances/boxes", "/instances/keypoints")
KEYPOINT_SUFFIX = "/instances/keypoints"  # (scenes with people: --scenario humanoid_crossing)
INSTANCE_GLOBALS = ("/ground_truth/instances", "/ground_truth/boxes")


def run(
    root: Path, name: str, streams: str, cameras: int, duration_s: float, scenario: str = "default"
) -> dict[str, float]:
    out = root / name
    proc = run_cli(
        f"scenario={scenario}",
        f"duration_s={duration_s:g}",
        "progress=false",
        "seed=1",
        f"cameras.count={cameras}",
        f"cameras.streams={streams}",
        f"hydra.run.dir={out}",
    )
    if proc.returncode != 0:
        raise SystemExit(f"run {name} failed: {proc.stderr.strip().splitlines()[-1:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    return {"frames": metrics["sim.camera_frames"], "wall_s": metrics["sim.wall_s"], "dir": str(out)}


def instance_bytes(recording: Path) -> tuple[int, int, int]:
    """(bytes of the instance topics' messages, of which keypoints, annotated frames) of a recording."""
    from simlan_data.recording.reader import RecordingReader

    total = keypoints = frames = 0
    with RecordingReader(recording) as reader:
        topics = [t for t in reader.topics if t.endswith(INSTANCE_SUFFIXES) or t in INSTANCE_GLOBALS]
        for m in reader.messages(topics, raw=True):
            total += len(m.msg)
            keypoints += len(m.msg) if m.topic.endswith(KEYPOINT_SUFFIX) else 0
            frames += int(m.topic.endswith("/instances/boxes"))
    return total, keypoints, frames


def export_speed(run_dir: Path, fmt: str, out: Path) -> float:
    t0 = time.perf_counter()
    proc = run_cli(str(run_dir), "--format", fmt, "--out", str(out), module="simlan_data.export")
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"export {fmt} failed: {proc.stderr.strip()}")
    return wall


def lerobot_speed(run_dir: Path, out: Path) -> tuple[float, int, float]:
    """(wall s, frames exported, peak MiB) of one ``--format lerobot`` export process (its own
    maximum resident set, from wait4)."""
    cmd = [sys.executable, "-m", "simlan_data.export", str(run_dir), "--format", "lerobot", "--out", str(out)]
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            err.seek(0)
            raise SystemExit(f"export lerobot failed: {err.read().decode().strip()}")
    frames = json.loads((out / "meta" / "info.json").read_text())["total_frames"]
    return wall, frames, usage.ru_maxrss / 1024


def lerobot_only(args: argparse.Namespace, root: Path) -> dict:
    """The LeRobot export's figure: one rgb run, ``--repeat`` exports, the median."""
    recorded = run(root, "rgb", "[rgb]", args.cameras, args.duration)
    walls, peaks, frames = [], [], 0
    for i in range(max(args.repeat, 1)):
        wall, frames, peak = lerobot_speed(Path(str(recorded["dir"])), root / f"lerobot{i}")
        walls.append(wall)
        peaks.append(peak)
    wall = statistics.median(walls)
    camera_frames = frames * args.cameras
    setup = f"default scenario, {args.cameras} cameras 960x540 at 5 Hz, {args.duration:g} s, rgb"
    return {
        "command": f"python benchmarks/export.py --only lerobot --cameras {args.cameras} --duration {args.duration:g} --repeat {args.repeat} --json FILE",
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
        "history": "docs/benchmarks/datasets.md",
        "setup": setup,
        "run": recorded,
        "export": {
            "lerobot": {
                "wall_s": [round(w, 2) for w in walls],
                "frames": frames,
                "peak_mib": [round(p) for p in peaks],
            }
        },
        "figures": [
            {
                "id": "dataset_lerobot_export_fps",
                "figure": f"LeRobot export speed (every camera frame decoded and AV1-encoded by SVT-AV1, LeRobot's settings; {setup})",
                "value": round(camera_frames / wall, 1),
                "unit": "frames/s",
                "note": f"{frames} LeRobot frames x {args.cameras} videos; median of {len(walls)}, whole process incl. start-up; peak memory {max(peaks):.0f} MiB",
                "history": "docs/benchmarks/datasets.md",
            }
        ],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", type=Path, required=True)
    parser.add_argument("--cameras", type=int, default=11)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument(
        "--scenario", default="default", help="scenario of the runs (humanoid_crossing: with keypoints)"
    )
    parser.add_argument("--only", choices=["lerobot"], help="measure this export alone (its own figure)")
    args = parser.parse_args()
    root = Path(tempfile.mkdtemp(prefix="bench_export_"))
    try:
        if args.only == "lerobot":
            result = lerobot_only(args, root)
            args.json.write_text(json.dumps(result, indent=1) + "\n")
            print(json.dumps(result["export"]))
            return
        runs: dict[str, list[dict[str, float]]] = {"off": [], "on": []}
        for i in range(args.repeat):
            for key, streams in (("off", OFF), ("on", ON)):
                runs[key].append(run(root, f"{key}{i}", streams, args.cameras, args.duration, args.scenario))
        fps = {k: statistics.median(r["frames"] / r["wall_s"] for r in v) for k, v in runs.items()}
        last_on = Path(str(runs["on"][-1]["dir"]))
        size, keypoint_size, annotated = instance_bytes(last_on / "recording")
        export = {}
        for fmt in ("coco", "yolo", "mot", "aicity"):
            wall = export_speed(last_on, fmt, root / f"export_{fmt}")
            export[fmt] = {"wall_s": round(wall, 2), "frames_per_s": round(annotated / wall, 1)}
        cost = 1 - fps["on"] / fps["off"]
        setup = f"{args.scenario} scenario, {args.cameras} cameras 960x540 at 5 Hz, {args.duration:g} s, rgb+semantic"
        scenario_arg = "" if args.scenario == "default" else f" --scenario {args.scenario}"
        result = {
            "command": f"python benchmarks/export.py{scenario_arg} --cameras {args.cameras} --duration {args.duration:g} --repeat {args.repeat} --json FILE",
            "machine": machine(),
            "date": datetime.date.today().isoformat(),
            "history": "docs/benchmarks/datasets.md",
            "setup": setup,
            "runs": runs,
            "frames_per_s": fps,
            "instance_bytes": size,
            "keypoint_bytes": keypoint_size,
            "annotated_frames": annotated,
            "export": export,
            "figures": [
                {
                    "id": "dataset_annotated_fps",
                    "figure": f"annotated camera frames per second (stream instance on; {setup})",
                    "value": round(fps["on"], 1),
                    "unit": "frames/s",
                    "baseline": f"instance off: {fps['off']:.1f} frames/s ({cost:.0%} slower with it)",
                    "note": f"median of {args.repeat} alternating pairs; frames / simulation wall time",
                    "history": "docs/benchmarks/datasets.md",
                },
                {
                    "id": "dataset_export_fps",
                    "figure": "dataset export speed, COCO (JPEG bytes copied, RLE masks)",
                    "value": export["coco"]["frames_per_s"],
                    "unit": "frames/s",
                    "note": f"YOLO: {export['yolo']['frames_per_s']} frames/s; whole process incl. start-up, {annotated} frames",
                    "history": "docs/benchmarks/datasets.md",
                },
                {
                    "id": "dataset_tracking_export_fps",
                    "figure": "tracking export speed, MOTChallenge (per-camera sequences, JPEG bytes copied)",
                    "value": export["mot"]["frames_per_s"],
                    "unit": "frames/s",
                    "note": f"AI City text (no images): {export['aicity']['frames_per_s']} frames/s; whole process incl. start-up, {annotated} frames",
                    "history": "docs/benchmarks/datasets.md",
                },
                {
                    "id": "dataset_bytes_per_frame",
                    "figure": "recorded instance ground truth per annotated frame (16-bit PNG ids + 2D boxes, with the 3D boxes shared)",
                    "value": round(size / max(annotated, 1) / 1024, 1),
                    "unit": "KiB",
                    "history": "docs/benchmarks/datasets.md",
                },
            ],
        }
        if keypoint_size:
            result["figures"].append(
                {
                    "id": "dataset_keypoint_bytes_per_frame",
                    "figure": "recorded keypoints per annotated frame (every person's 33 landmarks: pixels + COCO visibility)",
                    "value": round(keypoint_size / max(annotated, 1)),
                    "unit": "bytes",
                    "note": f"{setup}; included in the instance ground truth's bytes",
                    "history": "docs/benchmarks/datasets.md",
                }
            )
        if args.scenario != "default":  # figures of its own beside the default scenario's: the
            # annotation cost and the COCO export (with keypoints where it has people); the
            # other exports and the instance bytes tell nothing the default scenario's do not
            own = ("dataset_annotated_fps", "dataset_export_fps", "dataset_keypoint_bytes_per_frame")
            result["figures"] = [f for f in result["figures"] if f["id"] in own]
            for figure in result["figures"]:
                if not figure["id"].startswith("dataset_keypoint"):
                    figure["id"] += f"_{args.scenario}"
                    if args.scenario not in figure["figure"]:
                        figure["figure"] += f" ({args.scenario})"
        args.json.write_text(json.dumps(result, indent=1) + "\n")
        keys = ("frames_per_s", "export", "instance_bytes", "keypoint_bytes", "annotated_frames")
        print(json.dumps({k: result[k] for k in keys}))
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
