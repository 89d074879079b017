"""Time from SIGTERM / SIGINT to a finalized bag, on real runs of the default scenario.

    python benchmarks/shutdown.py [--trials N] [--json FILE]

Each trial starts ``python -m simlan_data.run`` (the default scenario: 11 cameras at 960x540,
RGB + depth + semantic, recording on), waits until its simulated clock passes a point that moves
from trial to trial, sends the signal and measures, from the signal:

- ``bag_s``: until ``recording/metadata.yaml`` exists (the bag is finalized: footer, summary);
- ``exit_s``: until the process exits (metrics.json, report.md and INTERRUPTED written);

and checks the exit code (143 / 130), the one stderr line, that the bag opens with the
independent ``mcap`` reader (summary present, every message's CRC checked) and that no
``RUNNING`` marker is left. The promise (README, reliability): the bag within 2 s.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import yaml
from mcap.reader import make_reader

from common import REPO, machine, table

RESULTS = REPO / "benchmarks" / "results"


def _clock(run_dir: Path) -> float:
    try:
        return float(yaml.safe_load((run_dir / "RUNNING").read_text())["simulated_s"])
    except (OSError, TypeError, KeyError, ValueError, yaml.YAMLError):
        return 0.0


def trial(run_dir: Path, sig: signal.Signals, at_s: float) -> dict[str, object]:
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    err_path = run_dir.parent / f"{run_dir.name}.stderr"
    with err_path.open("w") as err:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "simlan_data.run",
                "duration_s=120",
                "progress=false",
                f"hydra.run.dir={run_dir}",
            ],
            cwd=REPO,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=err,
        )
    while _clock(run_dir) < at_s:
        if proc.poll() is not None:
            raise SystemExit(f"run ended early: {err_path.read_text()}")
        time.sleep(0.01)
    sent = time.perf_counter()
    os.kill(proc.pid, sig)
    meta = run_dir / "recording" / "metadata.yaml"
    while not meta.exists() and proc.poll() is None:
        time.sleep(0.002)
    bag_s = time.perf_counter() - sent
    code = proc.wait(timeout=120)
    exit_s = time.perf_counter() - sent
    lines = [ln for ln in err_path.read_text().splitlines() if ln.strip()]
    with (run_dir / "recording" / "recording.mcap").open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        messages = sum(1 for _ in reader.iter_messages(log_time_order=False))
    ok = (
        code == 128 + sig
        and len(lines) == 1
        and summary is not None
        and summary.statistics is not None
        and summary.statistics.message_count == messages
        and meta.exists()
        and not (run_dir / "RUNNING").exists()
        and (run_dir / "INTERRUPTED").exists()
    )
    return {
        "signal": sig.name,
        "at_s": at_s,
        "bag_s": round(bag_s, 3),
        "exit_s": round(exit_s, 3),
        "exit_code": code,
        "messages": messages,
        "ok": ok,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=5, help="per signal (default 5)")
    parser.add_argument("--json", type=Path, default=RESULTS / f"shutdown_{date.today()}.json")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.trials):
            for sig in (signal.SIGTERM, signal.SIGINT):
                at = 0.5 + 2.0 * i  # early and later in a run (more buffered data)
                rows.append(trial(Path(tmp) / f"{sig.name}_{i}", sig, at))
                print(rows[-1], flush=True)
    worst = {k: max(float(r[k]) for r in rows) for k in ("bag_s", "exit_s")}  # type: ignore[arg-type]
    result = {
        "command": "python benchmarks/shutdown.py " + " ".join(sys.argv[1:]),
        "machine": machine(),
        "date": str(date.today()),
        "trials": rows,
        "ok": f"{sum(bool(r['ok']) for r in rows)}/{len(rows)}",
        "bag_s_max": worst["bag_s"],
        "exit_s_max": worst["exit_s"],
        "bag_s_median": sorted(float(r["bag_s"]) for r in rows)[len(rows) // 2],  # type: ignore[arg-type]
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(
        table(
            ["signal", "at (sim s)", "bag finalized (s)", "process exit (s)", "exit code", "ok"],
            [[r["signal"], r["at_s"], r["bag_s"], r["exit_s"], r["exit_code"], r["ok"]] for r in rows],
        )
    )
    print(
        f"ok {result['ok']}, bag within {worst['bag_s']:.3f} s, exit within {worst['exit_s']:.3f} s -> {args.json}"
    )


if __name__ == "__main__":
    main()
