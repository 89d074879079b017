"""Benchmark of the V&V layer (issue 7): suite wall time sequential vs joblib, golden replay, inspect.

    python benchmarks/evals.py [--suite base] [--only CASE ...] [--seeds N] [--skip-sequential]
                               [--out-dir DIR] [--json FILE]

1. The suite, simulated and replayed, twice in the same run: sequential (Hydra's basic
   launcher, --jobs 1) and Hydra's joblib launcher with 2 workers (--jobs 2); wall time of the
   simulation stage, the replay stage and the whole command. Both must give the same verdicts
   and the same metrics (a run is a pure function of config and seed).
2. The golden suite (replays only): wall time with 1 and 2 workers.
3. ``python -m simlan_data.view --save``: wall time and .rrd size for a golden recording and for
   the first recording of the suite, beside the recording's own size.

Prints markdown for docs/benchmarks/evals.md and the raw numbers as JSON. The cores are shared: the load
average before and after is printed; timed figures depend on it.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine, table


def evals(*args: str) -> tuple[int, float, str]:
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "simlan_data.evals", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        check=False,
    )
    return proc.returncode, time.perf_counter() - t0, proc.stdout + proc.stderr


def _what(stdout: str) -> str:
    found = re.search(r"inspect: (\d+ cameras, \d+ images)", stdout)
    return found.group(1) if found else "?"


def inspect(recording: Path, rrd: Path) -> dict[str, float]:
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "simlan_data.view", str(recording), "--save", str(rrd)],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        check=False,
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"inspect of {recording} failed: {proc.stderr.strip()}")
    bag = recording / "recording" if (recording / "recording").is_dir() else recording
    return {
        "wall_s": wall,
        "rrd_mib": rrd.stat().st_size / 2**20,
        "recording_mib": sum(f.stat().st_size for f in bag.glob("*.mcap")) / 2**20,
        "summary": proc.stdout.strip()
        .splitlines()[0]
        .removeprefix("inspect: ")
        .split(", 1 agents")[0]
        .split(" agents")[0],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="base")
    ap.add_argument("--only", nargs="+", default=[])
    ap.add_argument("--seeds", type=int)
    ap.add_argument("--skip-sequential", action="store_true", help="only the joblib run")
    ap.add_argument("--out-dir", type=Path)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    out = args.out_dir or Path(tempfile.mkdtemp(prefix="bench_evals_"))
    load0 = os.getloadavg()[0]
    common = [
        args.suite,
        *(["--only", *args.only] if args.only else []),
        *(["--seeds", str(args.seeds)] if args.seeds else []),
    ]
    raw: dict[str, object] = {"machine": machine(), "suite": common}
    modes = [("joblib, 2 workers", ["--jobs", "2"], "joblib")]
    if not args.skip_sequential:
        modes.insert(
            0, ("sequential (basic launcher, 1 job)", ["--launcher", "basic", "--jobs", "1"], "sequential")
        )
    rows = []
    metrics = {}
    for label, extra, key in modes:
        run_out = out / f"suite_{key}"
        code, wall, text = evals(*common, *extra, "--out", str(run_out), "--no-report")
        timings = (
            json.loads((run_out / "timings.json").read_text()) if (run_out / "timings.json").is_file() else {}
        )
        if not timings:
            timings = {"simulate_s": float("nan"), "replay_s": float("nan")}
        raw[key] = {"exit": code, "command_s": wall, **timings}
        rows.append(
            [
                label,
                f"{timings.get('simulate_s', float('nan')):.0f}",
                f"{timings.get('replay_s', float('nan')):.0f}",
                f"{wall:.0f}",
                code,
            ]
        )
        if (run_out / "metrics.parquet").is_file():
            import polars as pl

            metrics[key] = pl.read_parquet(run_out / "metrics.parquet").filter(
                ~pl.col("metric").str.contains("wall|rtf|per_s|_ms|speed")
            )
        if code not in (0, 1):
            print(text, file=sys.stderr)
    same = None
    if len(metrics) == 2:
        a, b = (metrics[k].sort("case", "seed", "source", "metric") for k in ("sequential", "joblib"))
        same = a.equals(b)
        raw["same_metrics"] = same
    golden_rows = []
    for jobs in (1, 2):
        code, wall, _ = evals(
            "golden", "--jobs", str(jobs), "--out", str(out / f"golden_{jobs}"), "--no-report"
        )
        raw[f"golden_jobs{jobs}"] = {"exit": code, "command_s": wall}
        golden_rows.append([jobs, f"{wall:.1f}", code])
    inspected = {}
    first_run = next(iter(sorted((out / f"suite_{modes[-1][2]}" / "runs").glob("*/recording"))), None)
    for name, rec in (
        ("golden single_truck", REPO / "recordings" / "golden" / "single_truck"),
        ("suite run", first_run),
    ):
        if rec is not None:
            inspected[name] = inspect(rec, out / f"{name.replace(' ', '_')}.rrd")
    raw["inspect"] = inspected
    load1 = os.getloadavg()[0]
    raw["load_average"] = [load0, load1]
    print(f"Machine: {machine()}\n")
    print(f"Load average (1 min) {load0:.1f} before, {load1:.1f} after (2 cores, shared).\n")
    print(f"Suite: `python -m simlan_data.evals {' '.join(common)}`\n")
    print(table(["mode", "simulate s", "replay s", "whole command s", "exit code"], rows))
    if same is not None:
        print(f"\nSame metrics (non-timing) in both modes: {same}")
    print("\nGolden suite (replays only):\n")
    print(table(["workers", "whole command s", "exit code"], golden_rows))
    print("\nInspect (`python -m simlan_data.view REC --save FILE.rrd`):\n")
    print(
        table(
            ["recording", "what", "recording MiB", ".rrd MiB", "wall s"],
            [
                [k, v["summary"], f"{v['recording_mib']:.1f}", f"{v['rrd_mib']:.1f}", f"{v['wall_s']:.1f}"]
                for k, v in inspected.items()
            ],
        )
    )
    print("\n```\n" + json.dumps(raw, default=str) + "\n```")
    if args.json:
        args.json.write_text(json.dumps(raw, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
