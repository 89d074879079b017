"""The marker-free localizer (``foreground``) beside the marker localizer (``aruco``).

    python benchmarks/markerfree.py [--duration 20] [--json FILE]

1. multi_robot (four robots), the 12 GPSS cameras at 960x540, colour only, closed loop on the
   ArUco localizer; its recording replayed through ``aruco`` and through ``foreground`` (open
   loop: the same images and commands): ATE and yaw RMSE of each;
2. default (one pallet truck), closed loop on ``foreground`` (the robot steers on it): ATE, yaw
   RMSE, availability, and its replay's difference to the live estimates.

Writes benchmarks/results/markerfree_<date>.json (figures for BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import tempfile
from pathlib import Path

from common import REPO, machine, run_cli

MULTI_START = (
    "[-20.0,1.5,0.0,24.0,-0.7,3.14159,-4.0,-1.2,0.7,20.0,1.0,3.1416]"  # conf/agents/four_robots.yaml
)
SINGLE_START = "[-16.0,0.4,0.0]"  # conf/agents/single_truck.yaml
COMMON = ["cameras=gpss_all", "streams=rgb", "progress=false"]


def _ok(proc: object, what: str) -> None:
    if getattr(proc, "returncode", 1) != 0:
        sys.exit(f"error: {what} failed:\n{getattr(proc, 'stderr', '')[-2000:]}")


def replay(recording: Path, out: Path, *sets: str) -> dict[str, float]:
    """The localization replay's metrics (``--set`` options: another localizer and its keys)."""
    args = [str(recording), "--algorithms", "localization", "--out", str(out)]
    for s in sets:
        args += ["--set", s]
    _ok(run_cli(*args, module="simlan_data.replay"), f"replay {sets}")
    return json.loads((out / "metrics.json").read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="markerfree_"))
    multi = tmp / "multi"
    _ok(
        run_cli("scenario=multi_robot", f"duration_s={args.duration}", *COMMON, f"hydra.run.dir={multi}"),
        "run",
    )
    aruco = replay(multi / "recording", tmp / "aruco")
    fg = replay(multi / "recording", tmp / "fg", "localizer=foreground", f"start_poses={MULTI_START}")
    single = tmp / "single"
    _ok(
        run_cli(
            "scenario=default",
            f"duration_s={args.duration}",
            *COMMON,
            "algorithms/localizer=foreground",
            f"algorithms.localizer.start_poses={SINGLE_START}",
            f"hydra.run.dir={single}",
        ),
        "closed-loop run",
    )
    live = json.loads((single / "metrics.json").read_text())
    again = replay(single / "recording", tmp / "single_replay")
    key = "localization.{}"
    per_robot = {
        ns: {
            "aruco_ate_m": aruco[f"localization.{ns}.ate_xy_rmse_m"],
            "foreground_ate_m": fg[f"localization.{ns}.ate_xy_rmse_m"],
            "foreground_yaw_deg": fg[f"localization.{ns}.yaw_rmse_deg"],
            "foreground_availability": fg[f"localization.{ns}.availability"],
        }
        for ns in ("robot_agent_1", "robot_agent_2", "robot_agent_3", "robot_agent_4")
    }
    date = datetime.date.today().isoformat()
    history = "docs/benchmarks/markerfree.md"
    cmd = "python benchmarks/markerfree.py"
    note_multi = f"{args.duration:g} s of multi_robot, 12 cameras 960x540, rgb only; replayed open loop"
    figures = [
        {"id": "markerfree_ate_multi", "figure": "marker-free localizer (foreground): ATE RMSE, four robots (multi_robot)",
         "value": round(fg[key.format("ate_xy_rmse_m")], 3), "unit": "m", "target": "<= 0.05 m",
         "baseline": f"aruco on the same images: {aruco[key.format('ate_xy_rmse_m')]:.3f} m",
         "note": note_multi + "; per robot " + ", ".join(
             f"{ns[-1]}: {v['foreground_ate_m']:.2f} m" for ns, v in per_robot.items()),
         "history": history},
        {"id": "markerfree_yaw_multi", "figure": "marker-free localizer (foreground): yaw RMSE, four robots (multi_robot)",
         "value": round(fg[key.format("yaw_rmse_deg")], 1), "unit": "deg",
         "baseline": f"aruco: {aruco[key.format('yaw_rmse_deg')]:.2f} deg", "note": note_multi, "history": history},
        {"id": "markerfree_ate_closed_loop", "figure": "marker-free localizer steering one pallet truck (default): ATE RMSE",
         "value": round(live[key.format("ate_xy_rmse_m")], 3), "unit": "m", "target": "<= 0.05 m",
         "note": (f"yaw RMSE {live[key.format('yaw_rmse_deg')]:.1f} deg, availability "
                  f"{live[key.format('availability')]:.2f}, goals reached {live.get('navigation.goals_reached', 0):.0f}; "
                  f"replay - live {again.get('replay.localization.max_diff_to_live_m', float('nan'))} m"),
         "history": history},
    ]  # fmt: skip
    result = {
        "command": cmd,
        "machine": machine(),
        "date": date,
        "history": history,
        "duration_s": args.duration,
        "per_robot": per_robot,
        "closed_loop": {k: v for k, v in live.items() if k.startswith(("localization.", "navigation."))},
        "replay_max_diff_to_live_m": again.get("replay.localization.max_diff_to_live_m"),
        "figures": figures,
    }
    out = args.json or REPO / "benchmarks" / "results" / f"markerfree_{date}.json"
    out.write_text(json.dumps(result, indent=1) + "\n")
    for f in figures:
        print(f"{f['figure']}: {f['value']} {f['unit']} ({f.get('baseline', '')}; {f.get('note', '')})")
    print(f"-> {out}")


if __name__ == "__main__":
    main()
