"""Benchmark of issue 20 (open platform): the built-ins unchanged by the plug-in seam, ABA.

    python benchmarks/plugin_seam.py [--old COMMIT] [--duration-s S] [--pairs N] [--json FILE]

Runs the default scenario (``python -m simlan_data.run duration_s=S``) with the code of an old
commit (a ``git worktree`` put first on PYTHONPATH) and with this checkout, alternately
old, new, new, old, ... (a steady drift of the host's speed cancels out), and reports:

- the real-time factor of each run, the medians and their ratio (new / old);
- whether every metric that is not a timing (localization, navigation, collisions, recording
  message counts) is equal between old and new: the same seed must give the same behaviour.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TIMING = ("wall_s", "cpu_s", "rtf", "_ms", "threads", "bytes")  # metric names that measure time or size


def _is_timing(name: str) -> bool:
    return any(part in name for part in TIMING)


def run_once(code_dir: Path, out_dir: Path, duration_s: float) -> dict[str, float]:
    """One default run with the package at ``code_dir``; its metrics.json."""
    env = {**os.environ, "PYTHONPATH": str(code_dir)}
    cmd = [
        sys.executable,
        "-m",
        "simlan_data.run",
        f"duration_s={duration_s}",
        "progress=false",
        f"hydra.run.dir={out_dir}",
    ]
    subprocess.run(cmd, cwd=code_dir, env=env, check=True, capture_output=True, text=True)
    return json.loads((out_dir / "metrics.json").read_text())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="67820fb", help="the commit before the plug-in seam (default 67820fb)")
    ap.add_argument("--duration-s", type=float, default=20.0)
    ap.add_argument("--pairs", type=int, default=2, help="ABBA blocks (each: old, new, new, old)")
    ap.add_argument("--json", type=Path, help="write the figures here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="platform_bench_") as tmp:
        old_dir = Path(tmp) / "old"
        subprocess.run(["git", "worktree", "add", "--detach", str(old_dir), args.old], cwd=REPO, check=True)
        try:
            order = ["old", "new", "new", "old"] * args.pairs
            runs: dict[str, list[dict[str, float]]] = {"old": [], "new": []}
            load0 = os.getloadavg()[0]
            for i, which in enumerate(order):
                code = old_dir if which == "old" else REPO
                metrics = run_once(code, Path(tmp) / f"run{i}_{which}", args.duration_s)
                runs[which].append(metrics)
                print(f"{which}: RTF {metrics['sim.rtf']:.3f}", flush=True)
            load1 = os.getloadavg()[0]
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old_dir)], cwd=REPO, check=False)
    rtf = {k: [m["sim.rtf"] for m in v] for k, v in runs.items()}
    old_m, new_m = runs["old"][0], runs["new"][0]
    compared = sorted(k for k in old_m if not _is_timing(k) and k in new_m)
    differing = [k for k in compared if old_m[k] != new_m[k]]
    result = {
        "command": " ".join(sys.argv),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": f"{platform.node()} {os.cpu_count()} cores",
        "old": args.old,
        "new": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip(),
        "order": ["old", "new", "new", "old"] * args.pairs,
        "rtf": rtf,
        "rtf_median": {k: statistics.median(v) for k, v in rtf.items()},
        "rtf_ratio_new_over_old": statistics.median(rtf["new"]) / statistics.median(rtf["old"]),
        "load_average_1min": [load0, load1],
        "behaviour_metrics_compared": len(compared),
        "behaviour_metrics_differing": differing,
    }
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    return 0 if not differing else 1


if __name__ == "__main__":
    sys.exit(main())
