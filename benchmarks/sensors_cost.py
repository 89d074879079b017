"""Benchmark: what realistic cameras cost (issue 24): the default run with every effect on beside
the same run without, measured alternately, back to back.

    python benchmarks/sensors_cost.py [--repeats 3] [--duration 60] [--json FILE]

Variants, interleaved in every repeat: ``sensors=ideal`` (the baseline), ``sensors=realistic``
(every effect at its default strength), and each effect group alone (photometric, timing,
drift, shutter), so a cost can be put where it is. Per run: the real-time factor (``sim.rtf``), the
CPU time of the run's process per simulated second (user + system; it moves less with whatever
else the machine runs) and of its simulation thread alone (``sim.main_thread_cpu_s``: the serial
part, which bounds the real-time factor on an idle machine); medians over the repeats. The
issue's target: realistic at most 15 % slower than ideal. On a shared machine the ratio of the
alternating runs is the figure: per repeat each variant against that repeat's ideal run, the
median of those ratios (the load moves less within a repeat than across repeats); the ratio of
the median RTFs is given beside it, and the load average before and after.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import resource
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine, run_cli, table

GROUPS = ("photometric", "timing", "drift", "shutter")
VARIANTS = {
    "ideal": ["sensors=ideal"],
    "realistic": ["sensors=realistic"],
    # each group of sensors=realistic alone
    **{g: ["sensors=realistic", *(f"sensors.{o}.enabled=false" for o in GROUPS if o != g)] for g in GROUPS},
}


def one(out: Path, name: str, duration: float) -> dict[str, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = run_cli(f"duration_s={duration:g}", "progress=false", *VARIANTS[name], f"hydra.run.dir={out}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    metrics = json.loads((out / "metrics.json").read_text())
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {
        "rtf": metrics["sim.rtf"],
        "cpu_s_per_s": cpu_s / duration,
        "main_cpu_s_per_s": metrics.get("sim.main_thread_cpu_s", float("nan")) / duration,
        "mib": (out / "recording" / "recording.mcap").stat().st_size / 2**20,
        "ate_cm": 100 * metrics.get("localization.ate_xy_rmse_m", float("nan")),
    }


def summary(results: dict[str, list[dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Medians per variant; ``slower_pct``: the median over the repeats of each run against the
    ideal run of its own repeat (minutes apart at most: the load of a shared machine moves less
    within a repeat than across), ``slower_of_medians_pct``: the ratio of the median RTFs."""
    ideal = results["ideal"]
    base = statistics.median(r["rtf"] for r in ideal)
    out = {}
    for name, rows in results.items():
        rtf = statistics.median(r["rtf"] for r in rows)
        paired = [i["rtf"] / r["rtf"] - 1 for i, r in zip(ideal, rows, strict=False)]
        main_paired = [
            r["main_cpu_s_per_s"] / i["main_cpu_s_per_s"] - 1 for i, r in zip(ideal, rows, strict=False)
        ]
        out[name] = {
            "rtf": round(rtf, 3),
            "slower_pct": round(100 * statistics.median(paired), 1),
            "slower_of_medians_pct": round(100 * (base / rtf - 1), 1),
            "main_cpu_more_pct": round(100 * statistics.median(main_paired), 1),
            "cpu_s_per_s": round(statistics.median(r["cpu_s_per_s"] for r in rows), 3),
            "main_cpu_s_per_s": round(statistics.median(r["main_cpu_s_per_s"] for r in rows), 3),
            "mib": round(statistics.median(r["mib"] for r in rows), 1),
            "ate_cm": round(statistics.median(r["ate_cm"] for r in rows), 3),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    names = args.variants.split(",")
    load_before = os.getloadavg()[0]
    results: dict[str, list[dict[str, float]]] = {n: [] for n in names}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats):
            for name in names:
                r = one(Path(tmp) / f"{name}_{i}", name, args.duration)
                results[name].append(r)
                print(f"  {name} #{i}: RTF {r['rtf']:.2f}, CPU {r['cpu_s_per_s']:.3f} s/s", file=sys.stderr)
    table_ = summary(results)
    print(table(["variant", "RTF", "slower than ideal (paired; of medians)", "CPU s per s",
                 "main thread CPU s per s (more than ideal)", "MiB", "ATE cm"],
                [[n, t["rtf"], f"{t['slower_pct']} %; {t['slower_of_medians_pct']} %", t["cpu_s_per_s"],
                  f"{t['main_cpu_s_per_s']} ({t['main_cpu_more_pct']} %)", t["mib"], t["ate_cm"]]
                 for n, t in table_.items()]))  # fmt: skip
    real = table_.get("realistic")
    figures = []
    if real is not None:
        figures.append({
            "id": "sensors_cost", "figure": f"default run ({args.duration:g} s, 11 cameras 960x540) with sensors=realistic: RTF",
            "value": real["rtf"], "unit": "x", "target": "<= 15 % slower than sensors=ideal",
            "baseline": f"sensors=ideal: RTF {table_['ideal']['rtf']} (same run, alternately)",
            "note": f"{real['slower_pct']} % slower, median of the repeats' pairs ({real['slower_of_medians_pct']} % "
                    f"between the median RTFs); simulation thread's CPU {real['main_cpu_more_pct']} % more; " + ", ".join(
                f"{n} alone {t['slower_pct']} %" for n, t in table_.items() if n not in ("ideal", "realistic")),
        })  # fmt: skip
    date = datetime.datetime.now().isoformat(timespec="minutes")  # (a rerun the same day wins)
    result = {
        "command": f"python benchmarks/sensors_cost.py --repeats {args.repeats} --duration {args.duration:g} --json FILE",
        "machine": machine(),
        "conditions": f"load average {load_before:.1f} at the start, {os.getloadavg()[0]:.1f} at the end",
        "date": date,
        "history": "docs/benchmarks/sensors.md",
        "summary": table_,
        "runs": results,
        "figures": figures,
    }
    path = args.json or REPO / "benchmarks" / "results" / f"sensors_cost_{date[:10]}.json"
    path.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
