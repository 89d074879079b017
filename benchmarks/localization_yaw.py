"""Benchmark: the camera yaw of standing robots, per agent type and spot, before and after (issue 23).

    python benchmarks/localization_yaw.py [--types pallet_truck,forklift,jackal] [--spots NAME,...]
                                          [--yaws-deg 0,3,45,90] [--duration-s 2]
                                          [--src DIR] [--out-dir DIR] [--json FILE]

Each agent type stands still (no goals) with its marker at each spot (under a camera, between
cameras, near an image edge of the 960x540 GPSS cameras) at each heading, for a short run
(``python -m simlan_data.run``, the real simulator and localizer, the cameras that see the spot).
From each recording: the filtered estimate's yaw RMSE and mean error (bias) against ground
truth; and per camera, the raw single-camera marker yaw from the recorded frames with ArUco's
contour corners and with the corners aligned to the marker pattern (this checkout's
``refine_corners``), to see where the error arises. With ``--src DIR`` (e.g. ``git worktree add
/tmp/yawold <commit>``) the same cases run with that checkout too, in the same invocation.
Writes JSON with a ``figures`` list for benchmarks/summary.py.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine
from simlan_data.algorithms.marker_refinement import refine_corners
from simlan_data.algorithms.markers import MarkerDetector, MarkerMount, ground_constraint_pose
from simlan_data.evaluation.metrics import estimates_from_recording, ground_truth
from simlan_data.geometry.calibration import load_calibration
from simlan_data.geometry.rotations import wrap_angle
from simlan_data.geometry.transforms import Transform
from simlan_data.recording.cameras import cameras_in_recording
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.agent_types import AGENT_TYPES, MARKER_SIZE_M

NS = "robot_agent_1"
CAMERAS = list(range(160, 171))  # conf/cameras/gpss.yaml
WIDTH, HEIGHT = 960, 540
# marker centre (x, y) in the map: under a camera (its nadir), at its image centre, between two
# cameras, near the edge of an image
SPOTS = {
    "under_164": (19.0, 0.6),
    "issue_jackal_164": (18.5, 0.5),  # the Jackal of issue 23's follow-up (0.53 deg)
    "forklift_spawn": (20.8, 1.0),  # four_robots' forklift (20.0, 1.0, pi): its marker
    "centre_164": (16.7, 0.9),
    "near_centre_166": (22.3, 2.0),  # (under 166 stand shelves; the aisle is too narrow to turn a truck)
    "between_164_166": (21.0, 2.3),
    "under_163": (6.4, 1.0),
    "between_162_163": (0.4, 1.0),  # at the right edge of 163's image
    "under_161": (-15.5, 1.2),
}
TARGET_DEG = 0.5


def seeing_cameras(x: float, y: float, z: float, margin_px: float = 30.0) -> list[int]:
    """The GPSS cameras whose 960x540 image shows the point well inside its edges."""
    out = []
    for cid in CAMERAS:
        cam = load_calibration(cid).camera.scaled(WIDTH, HEIGHT)
        uv, ok = cam.project(np.array([[x, y, z]]))
        u, v = uv[0]
        if ok[0] and margin_px <= u <= WIDTH - margin_px and margin_px <= v <= HEIGHT - margin_px:
            out.append(cid)
    return out


def base_pose(kind: str, spot: tuple[float, float], yaw: float) -> tuple[float, float, float]:
    """base_link pose that puts the type's marker centre on ``spot`` at heading ``yaw``."""
    mx, my, _ = AGENT_TYPES[kind].marker_xyz or (0.0, 0.0, 0.0)
    c, s = math.cos(yaw), math.sin(yaw)
    return spot[0] - (c * mx - s * my), spot[1] - (s * mx + c * my), yaw


def run(
    src: Path, kind: str, pose: tuple[float, float, float], cameras: list[int], duration_s: float, out: Path
) -> str | None:
    """One standing run of ``src``'s code; the error text where the run was refused."""
    env = {k: v for k, v in os.environ.items() if k not in ("HYDRA_FULL_ERROR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(src)
    proc = subprocess.run(
        [sys.executable, "-m", "simlan_data.run", "progress=false", f"duration_s={duration_s}", "streams=rgb",
         f"cameras.ids=[{','.join(map(str, cameras))}]", f"agents.robot_agent_1.type={kind}",
         f"agents.robot_agent_1.pose=[{pose[0]:.4f},{pose[1]:.4f},{pose[2]:.6f}]",
         "agents.robot_agent_1.goals=[]", f"hydra.run.dir={out}"],
        capture_output=True, text=True, cwd=src, env=env, timeout=600,
    )  # fmt: skip
    if proc.returncode != 0:
        return proc.stderr.strip()[-300:] or f"exit {proc.returncode}"
    return None


def filtered_yaw(out: Path) -> dict[str, float]:
    """The estimate's yaw error over the run: RMSE and mean (bias), degrees."""
    with RecordingReader(out / "recording") as reader:
        truth = {row[0]: row[3] for row in ground_truth(reader)[NS].iter_rows()}
        est = estimates_from_recording(reader, [NS])[NS].drop_nulls("x")
    err = [
        math.degrees(wrap_angle(yaw - truth[s]))
        for s, yaw in est.select("stamp_ns", "yaw").iter_rows()
        if s in truth
    ]
    if not err:
        return {"yaw_rmse_deg": float("nan"), "yaw_bias_deg": float("nan"), "estimates": 0}
    return {
        "yaw_rmse_deg": float(np.sqrt(np.mean(np.square(err)))),
        "yaw_bias_deg": float(np.mean(err)),
        "estimates": len(err),
    }


def per_camera(out: Path, kind: str) -> dict[str, dict[str, float]]:
    """Per camera: mean single-camera marker yaw error (deg) over the recorded frames with the
    contour corners and with the pattern-aligned corners, and the marker's side in pixels."""
    t = AGENT_TYPES[kind]
    assert t.marker_xyz is not None
    mount = MarkerMount(NS, 1, MARKER_SIZE_M, t.marker_xyz[2], (t.marker_xyz[0], t.marker_xyz[1]))
    detector = MarkerDetector()
    rows: dict[str, list[tuple[float, float, float]]] = {}
    with RecordingReader(out / "recording") as reader:
        cams = cameras_in_recording(reader)
        truth = {row[0]: row[1:] for row in ground_truth(reader)[NS].iter_rows()}
        for m in reader.messages([f"/camera_{c}/image_raw/compressed" for c in cams]):
            cid = m.topic.split("/")[1].removeprefix("camera_")
            gray = np.asarray(
                cv2.imdecode(np.frombuffer(bytes(m.msg.data), np.uint8), cv2.IMREAD_GRAYSCALE), np.uint8
            )
            found = [d for d in detector.detect(cid, gray) if d.marker_id == 1]
            if not found or m.stamp_ns not in truth:
                continue
            x, y, yaw = truth[m.stamp_ns]
            marker_yaw = (
                Transform.from_pose2d(x, y, yaw) @ Transform.from_pose2d(*mount.offset_xy_m, 0.0)
            ).yaw()
            errs = []
            for det in (found[0], refine_corners(cams[cid], found[0], gray)):
                obs = ground_constraint_pose(cams[cid], det, mount)
                errs.append(
                    float("nan") if obs is None else math.degrees(wrap_angle(obs.yaw_rad - marker_yaw))
                )
            rows.setdefault(cid, []).append((errs[0], errs[1], float(obs.side_px) if obs else float("nan")))
    return {
        cid: {
            "contour_deg": round(float(np.mean([r[0] for r in v])), 3),
            "pattern_deg": round(float(np.mean([r[1] for r in v])), 3),
            "side_px": round(float(np.mean([r[2] for r in v])), 1),
        }
        for cid, v in sorted(rows.items())
    }


def summarize(cases: list[dict], label: str) -> dict[str, dict[str, Any]]:
    """Per agent type, over every spot and heading run with ``label``'s code: the largest yaw
    RMSE and bias and where, and the RMS of all errors."""
    out: dict[str, dict[str, Any]] = {}
    for kind in dict.fromkeys(c["type"] for c in cases):
        mine = [c for c in cases if c["type"] == kind and label in c["codes"]]
        if not mine:
            continue
        worst = max(mine, key=lambda c: c["codes"][label]["yaw_rmse_deg"])
        out[kind] = {
            "cases": len(mine),
            "max_yaw_rmse_deg": round(worst["codes"][label]["yaw_rmse_deg"], 3),
            "worst": f"{worst['spot']} at {worst['yaw_deg']:g} deg",
            "max_abs_bias_deg": round(max(abs(c["codes"][label]["yaw_bias_deg"]) for c in mine), 3),
            "rms_deg": round(
                float(np.sqrt(np.mean([c["codes"][label]["yaw_rmse_deg"] ** 2 for c in mine]))), 3
            ),
        }
    return out


def figures(
    summary: dict[str, dict[str, dict[str, Any]]], n_spots: int, yaws: list[float], src: str | None
) -> list[dict]:
    """One figure per agent type: the largest yaw RMSE of a standing robot over the spots and headings."""
    out = []
    for kind, now in summary["this checkout"].items():
        old = summary.get("old", {}).get(kind)
        base = (
            ""
            if old is None
            else (
                f"before ({src}): {old['max_yaw_rmse_deg']:.2f} deg ({old['worst']}), RMS {old['rms_deg']:.2f} deg"
            )
        )
        out.append(
            {"id": f"loc_yaw_standing_{kind}", "figure": f"{kind} standing: largest yaw RMSE over {n_spots} spots x "
             f"{len(yaws)} headings (under, between and at the edge of the 960x540 GPSS cameras)",
             "value": now["max_yaw_rmse_deg"], "unit": "deg", "target": f"<= {TARGET_DEG} deg", "baseline": base,
             "note": f"worst at {now['worst']}; RMS over all {now['rms_deg']:.2f} deg, largest bias {now['max_abs_bias_deg']:.2f} deg",
             "history": "docs/benchmarks/gpss.md"}
        )  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--types", default="pallet_truck,forklift,jackal")
    ap.add_argument("--spots", default=",".join(SPOTS))
    ap.add_argument("--yaws-deg", default="0,3,45,90")
    ap.add_argument("--duration-s", type=float, default=2.0)
    ap.add_argument("--src", type=Path, default=None, help="another checkout, run beside this one")
    ap.add_argument("--out-dir", type=Path, default=None, help="keep the runs here (default: a temp dir)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    codes = {"this checkout": REPO} | ({"old": args.src.resolve()} if args.src else {})
    yaws = [float(v) for v in args.yaws_deg.split(",")]
    spots = args.spots.split(",")
    cases: list[dict] = []
    refused: list[str] = []
    with tempfile.TemporaryDirectory(prefix="loc_yaw_") as tmp:
        base = args.out_dir or Path(tmp)
        for kind in args.types.split(","):
            height = (AGENT_TYPES[kind].marker_xyz or (0.0, 0.0, 0.0))[2]
            for spot in spots:
                cams = seeing_cameras(*SPOTS[spot], height)
                for yaw_deg in yaws:
                    pose = base_pose(kind, SPOTS[spot], math.radians(yaw_deg))
                    case = {"type": kind, "spot": spot, "yaw_deg": yaw_deg, "cameras": cams, "codes": {}}
                    for label, src in codes.items():
                        out = base / f"{kind}_{spot}_{yaw_deg:g}_{label.replace(' ', '_')}"
                        error = run(src, kind, pose, cams, args.duration_s, out)
                        if error is not None:
                            refused.append(f"{kind} {spot} {yaw_deg:g}: {error.splitlines()[-1]}")
                            break
                        case["codes"][label] = filtered_yaw(out)
                        if label == "this checkout":
                            case["per_camera"] = per_camera(out, kind)
                    if case["codes"]:
                        cases.append(case)
                        print(f"{kind:13s} {spot:16s} {yaw_deg:5g} " + "  ".join(
                            f"{k}: rmse {v['yaw_rmse_deg']:.3f} bias {v['yaw_bias_deg']:+.3f}" for k, v in case["codes"].items()
                        ) + f"  per camera {case.get('per_camera')}", flush=True)  # fmt: skip
    summary = {label: summarize(cases, label) for label in codes}
    for label, per_type in summary.items():
        for kind, s in per_type.items():
            print(f"{label:14s} {kind:13s} {s}")
    result = {
        "command": "python benchmarks/localization_yaw.py"
        + (" --src DIR" if args.src else "")
        + " --json FILE",
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
        "history": "docs/benchmarks/gpss.md",
        "spots": {s: SPOTS[s] for s in spots},
        "yaws_deg": yaws,
        "duration_s": args.duration_s,
        "refused": refused,
        "summary": summary,
        "cases": cases,
        "figures": figures(summary, len(spots), yaws, None if args.src is None else str(args.src)),
    }
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
