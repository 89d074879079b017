"""Benchmark of GPSS localization and navigation (issue 3).

    python benchmarks/gpss.py [--scenarios single_truck,multi_robot]
                              [--resolutions 960x540,1920x1080] [--methods ground,pnp]
                              [--live-pnp] [--out-dir DIR] [--json FILE]

1. Closed loop: runs every scenario at every camera resolution (robots steer on the camera
   estimate, ground-constraint poses) and reads each run's metrics.json: localization ATE, yaw
   error, availability, goals reached, collisions, real-time factor. ``--live-pnp`` adds closed-loop
   runs that steer on PnP poses (960x540).
2. Open loop, same frames: replays every recording through the localizer with each pose method
   (``python -m simlan_data.replay REC --set method=M``), pinned to one core with taskset, and
   reads the accuracy, the localizer's time per processed frame (median; full-frame searches and
   region searches separately) and the replay speed.

Prints markdown for docs/benchmarks/gpss.md and writes the raw numbers as JSON.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine, run_cli, table


def replay(recording: Path, out: Path, method: str) -> dict[str, float]:
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    proc = run_cli(
        str(recording),
        "--out",
        str(out),
        "--set",
        f"method={method}",
        module="simlan_data.replay",
        prefix=pin,
    )
    if proc.returncode != 0:
        raise SystemExit(f"replay of {recording} failed: {proc.stderr.strip()}")
    metrics = json.loads((out / "metrics.json").read_text())
    for mode in ("full", "roi"):
        metrics[f"frames_{mode}"] = metrics.get(f"replay.localization.frames_{mode}", 0.0)
        metrics[f"frame_ms_median_{mode}"] = metrics.get(
            f"replay.localization.frame_ms_median_{mode}", float("nan")
        )
    return metrics


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenarios", default="single_truck,multi_robot")
    ap.add_argument("--resolutions", default="960x540,1920x1080")
    ap.add_argument("--methods", default="ground,pnp")
    ap.add_argument("--live-pnp", action="store_true", help="also steer on PnP poses (960x540)")
    ap.add_argument("--out-dir", type=Path, default=None, help="keep the runs here (default: a temp dir)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    out_dir = args.out_dir or Path(tempfile.mkdtemp(prefix="simlan_gpss_bench_"))
    out_dir.mkdir(parents=True, exist_ok=True)
    scenarios = args.scenarios.split(",")
    resolutions = args.resolutions.split(",")
    methods = args.methods.split(",")

    live: dict[str, dict] = {}
    jobs = [(s, r, "ground") for s in scenarios for r in resolutions]
    if args.live_pnp:
        jobs += [(s, resolutions[0], "pnp") for s in scenarios]
    for scenario, res, method in jobs:
        w, h = res.split("x")
        name = f"{scenario}_{res}_{method}"
        run_dir = out_dir / name
        if not (run_dir / "metrics.json").exists():
            proc = run_cli(
                f"scenario={scenario}",
                f"cameras.width={w}",
                f"cameras.height={h}",
                f"algorithms.localizer.method={method}",
                f"hydra.run.dir={run_dir}",
                "progress=false",
            )
            if proc.returncode != 0:
                raise SystemExit(f"run {name} failed: {proc.stderr.strip()}")
        live[name] = json.loads((run_dir / "metrics.json").read_text())
        print(f"ran {name}", file=sys.stderr)

    replays: dict[str, dict] = {}
    for scenario in scenarios:
        for res in resolutions:
            recording = out_dir / f"{scenario}_{res}_ground" / "recording"
            for method in methods:
                key = f"{scenario}_{res}_{method}"
                replays[key] = replay(recording, out_dir / f"replay_{key}", method)
                print(f"replayed {key}", file=sys.stderr)

    def mm(v: float) -> str:
        return f"{v * 1000:.1f}"

    rows = []
    for name, m in live.items():
        scenario, res, method = name.rsplit("_", 2)
        rows.append(
            [
                scenario,
                res,
                method,
                mm(m["localization.ate_xy_rmse_m"]),
                mm(m["localization.ate_xy_max_m"]),
                f"{m['localization.yaw_rmse_deg']:.2f}",
                f"{m['localization.availability']:.4f}",
                f"{m['navigation.goals_reached']:.0f}/{m['navigation.goals_total']:.0f}",
                f"{m['navigation.collisions']:.0f}",
                f"{m['sim.rtf']:.2f}",
            ]
        )
    print(f"Machine: {machine()}\n")
    print("Closed loop (robots steer on the camera estimate):\n")
    print(
        table(
            [
                "scenario",
                "cameras",
                "poses",
                "ATE RMSE (mm)",
                "ATE max (mm)",
                "yaw RMSE (deg)",
                "availability",
                "goals",
                "collisions",
                "RTF",
            ],
            rows,
        )
    )
    rows = []
    for key, m in replays.items():
        scenario, res, method = key.rsplit("_", 2)
        rows.append(
            [
                scenario,
                res,
                method,
                mm(m["localization.ate_xy_rmse_m"]),
                mm(m["localization.ate_xy_max_m"]),
                f"{m['localization.yaw_rmse_deg']:.2f}",
                f"{m['localization.availability']:.4f}",
                f"{m.get('frame_ms_median_roi', float('nan')):.2f} ({m.get('frames_roi', 0):.0f})",
                f"{m.get('frame_ms_median_full', float('nan')):.2f} ({m.get('frames_full', 0):.0f})",
                f"{m['replay.localization.frame_ms_median']:.2f}",
                f"{m['replay.speed_x_realtime']:.1f}x",
            ]
        )
    print("\nOpen loop, the same recorded frames through each pose method (replay, one core):\n")
    print(
        table(
            [
                "recording",
                "cameras",
                "poses",
                "ATE RMSE (mm)",
                "ATE max (mm)",
                "yaw RMSE (deg)",
                "availability",
                "ms/frame, regions (frames)",
                "ms/frame, full (frames)",
                "ms/frame, all",
                "replay speed",
            ],
            rows,
        )
    )
    if args.json:
        args.json.write_text(json.dumps({"machine": machine(), "live": live, "replay": replays}, indent=1))
    print(f"\nruns in {out_dir}", file=sys.stderr)


if __name__ == "__main__":
    main()
