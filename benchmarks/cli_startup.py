"""Start-up time of the run command, beside a bare Hydra app, in the same run.

    python benchmarks/cli_startup.py [--repeat 9] [--src DIR] [--json FILE]

Median wall time (process start to exit, ``--repeat`` times each, interleaved) of:

- a bare Hydra app's ``--help`` (``@hydra.main`` with no config: the floor for a Hydra CLI);
- ``python -m simlan_data.run --help``: the first one (an empty help cache: composed, then
  stored) and a later one (served from the cache, ``simlan_data.apps.help_cache``);
- a config error: ``duration_s=abc`` (a bad value) and ``durration_s=1`` (a typo'd key), exit 2.

``--src DIR`` also times another checkout (e.g. ``git worktree add /tmp/old <commit>``) with this
venv, in the same rounds, so before and after share the machine's load.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

from common import REPO, machine, table

BARE_APP = """
import hydra
from omegaconf import DictConfig

@hydra.main(version_base="1.3", config_path=None, config_name=None)
def app(cfg: DictConfig) -> None:
    pass

if __name__ == "__main__":
    app()
"""
CASES = {
    "--help (first: composed)": (["--help"], 0),
    "--help (later: cached)": (["--help"], 0),
    "config error: duration_s=abc": (["duration_s=abc"], 2),
    "config error: durration_s=1 (typo'd key)": (["durration_s=1"], 2),
}


def _time(cmd: list[str], cwd: Path, env: dict[str, str], want: int) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != want:
        raise SystemExit(f"{cmd}: exit {proc.returncode}, expected {want}: {proc.stderr[-500:]}")
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=9)
    parser.add_argument("--src", type=Path, help="another checkout, timed in the same rounds")
    parser.add_argument(
        "--json", type=Path, default=REPO / "benchmarks" / "results" / f"cli_startup_{date.today()}.json"
    )
    args = parser.parse_args()
    env = {k: v for k, v in os.environ.items() if k not in ("HYDRA_FULL_ERROR", "PYTHONPATH")}
    trees = {"this checkout": REPO} | ({f"--src {args.src}": args.src.resolve()} if args.src else {})
    times: dict[tuple[str, str], list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        bare = Path(tmp) / "bare_app.py"
        bare.write_text(BARE_APP)
        for _ in range(args.repeat):
            times.setdefault(("bare Hydra app", "--help"), []).append(
                _time([sys.executable, str(bare), "--help"], Path(tmp), env, 0)
            )
            for label, tree in trees.items():
                tree_env = env | {"PYTHONPATH": str(tree)}
                for case, (argv, want) in CASES.items():
                    cmd = [sys.executable, "-m", "simlan_data.run", *argv, f"hydra.run.dir={tmp}/never"]
                    if argv == ["--help"]:
                        cmd = cmd[:-1]
                    cache = Path(tmp) / label.replace("/", "_") / ("warm" if "cached" in case else "cold")
                    if "first" in case:
                        shutil.rmtree(cache, ignore_errors=True)
                    elif "cached" in case and not cache.exists():
                        _time(cmd, tree, tree_env | {"SIMLAN_DATA_CACHE_DIR": str(cache)}, want)  # fill it
                    case_env = tree_env | {"SIMLAN_DATA_CACHE_DIR": str(cache)}
                    times.setdefault((label, case), []).append(_time(cmd, tree, case_env, want))
    rows = [
        {
            "code": label,
            "command": case,
            "median_s": round(statistics.median(ts), 3),
            "min_s": round(min(ts), 3),
            "runs": len(ts),
        }
        for (label, case), ts in times.items()
    ]
    result = {
        "command": "python benchmarks/cli_startup.py " + " ".join(sys.argv[1:]),
        "machine": machine(),
        "date": str(date.today()),
        "load_average": os.getloadavg(),
        "rows": rows,
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(
        table(
            ["code", "command", "median (s)", "min (s)", "runs"],
            [[r["code"], f"`{r['command']}`", r["median_s"], r["min_s"], r["runs"]] for r in rows],
        )
    )
    print(f"load average {result['load_average']}; -> {args.json}")


if __name__ == "__main__":
    main()
