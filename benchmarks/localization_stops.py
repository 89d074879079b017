"""Benchmark: the camera estimate through emergency stops, per agent type, before and after (issue 23).

    python benchmarks/localization_stops.py [--types pallet_truck,forklift,jackal]
                                            [--src DIR] [--out-dir DIR] [--json FILE]

Runs ``scenario=humanoid_crossing`` (the safety layer stops a robot for a person crossing in
front of it) once per agent type as robot_agent_1, all 11 GPSS cameras at 960x540, with this
checkout and, with ``--src DIR`` (e.g. ``git worktree add /tmp/loc_old <commit>``), with that
checkout in the same invocation (its own runs: the robots steer on each code's estimate). From
each recording: ATE RMSE and max, yaw RMSE (metrics.json), the largest position error within
0.5 s after each emergency stop (applied command from >= 0.5 m/s to standing) and the largest
error elsewhere. Writes JSON with a ``figures`` list for benchmarks/summary.py.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine
from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.metrics import emergency_stops, estimates_from_recording, ground_truth
from simlan_data.recording.reader import RecordingReader

NS = "robot_agent_1"
AFTER_S = 0.5


def run(src: Path, agent_type: str, out: Path) -> dict[str, float]:
    """One humanoid_crossing run of ``src``'s code with robot_agent_1 of ``agent_type``."""
    env = {k: v for k, v in os.environ.items() if k not in ("HYDRA_FULL_ERROR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(src)
    proc = subprocess.run(
        [sys.executable, "-m", "simlan_data.run", "scenario=humanoid_crossing", "progress=false",
         f"agents.robot_agent_1.type={agent_type}", f"hydra.run.dir={out}"],
        capture_output=True, text=True, cwd=src, env=env, timeout=1800,
    )  # fmt: skip
    if proc.returncode != 0:
        raise SystemExit(f"run of {agent_type} with {src} failed: {proc.stderr.strip()[-400:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    with RecordingReader(out / "recording") as reader:
        stops = emergency_stops(reader, NS)
        truth = {row[0]: row[1:3] for row in ground_truth(reader)[NS].iter_rows()}
        est = estimates_from_recording(reader, [NS])[NS].drop_nulls("x")
    near, far = [0.0], [0.0]
    for stamp, x, y in est.select("stamp_ns", "x", "y").iter_rows():
        if stamp in truth:
            err = math.dist((x, y), truth[stamp])
            after = any(0 <= stamp - s <= AFTER_S * NS_PER_S for s in stops)
            (near if after else far).append(err)
    return {
        "stops": len(stops),
        "ate_rmse_cm": 100 * metrics[f"localization.{NS}.ate_xy_rmse_m"],
        "ate_max_cm": 100 * metrics[f"localization.{NS}.ate_xy_max_m"],
        "yaw_rmse_deg": metrics[f"localization.{NS}.yaw_rmse_deg"],
        "stop_max_cm": 100 * max(near),
        "elsewhere_max_cm": 100 * max(far),
    }


def figures(rows: dict[str, dict[str, dict[str, float]]], src: str | None) -> list[dict]:
    """One figure per agent type: the largest error after a stop; ATE and yaw RMSE in its note."""
    out = []
    for kind, by_code in rows.items():
        now, old = by_code["this checkout"], by_code.get("old")
        base = (
            ""
            if old is None
            else (
                f"before ({src}): {old['stop_max_cm']:.1f} cm; ATE {old['ate_rmse_cm']:.2f} cm, yaw {old['yaw_rmse_deg']:.2f} deg"
            )
        )
        out.append(
            {"id": f"loc_stop_{kind}", "figure": f"{kind}: largest position error within {AFTER_S} s after an "
             "emergency stop (humanoid_crossing, 11 cameras 960x540)", "value": round(now["stop_max_cm"], 2),
             "unit": "cm", "target": "<= the normal error (2 cm)", "baseline": base,
             "note": f"ATE RMSE {now['ate_rmse_cm']:.2f} cm, yaw RMSE {now['yaw_rmse_deg']:.2f} deg; "
             f"elsewhere in the run at most {now['elsewhere_max_cm']:.1f} cm",
             "history": "docs/benchmarks/gpss.md"}
        )  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--types", default="pallet_truck,forklift,jackal")
    ap.add_argument("--src", type=Path, default=None, help="another checkout, run beside this one")
    ap.add_argument("--out-dir", type=Path, default=None, help="keep the runs here (default: a temp dir)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    codes = {"this checkout": REPO} | ({"old": args.src.resolve()} if args.src else {})
    rows: dict[str, dict[str, dict[str, float]]] = {}
    with tempfile.TemporaryDirectory(prefix="loc_stops_") as tmp:
        base = args.out_dir or Path(tmp)
        for kind in args.types.split(","):
            for label, src in codes.items():
                r = run(src, kind, base / f"{kind}_{label.replace(' ', '_')}")
                rows.setdefault(kind, {})[label] = r
                print(f"{kind:13s} {label:14s} " + " ".join(f"{k}={v:.3g}" for k, v in r.items()), flush=True)
    result = {
        "command": "python benchmarks/localization_stops.py"
        + (" --src DIR" if args.src else "")
        + " --json FILE",
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
        "history": "docs/benchmarks/gpss.md",
        "rows": rows,
        "figures": figures(rows, None if args.src is None else str(args.src)),
    }
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
