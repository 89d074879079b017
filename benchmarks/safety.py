"""Benchmark of the safety layer (issue 4): the safety scenarios and SIMLAN's collision sweeps.

    python benchmarks/safety.py [--out-dir DIR] [--json FILE] [--skip-sweeps] [--timeouts 5,2,1,0.5]

1. Runs scenario=restricted_zone, blind_spot and humanoid_crossing and reads their safety metrics
   (ground truth): violations, missed, false stops, max latency against the budget (one control
   period + one camera period), stop distance, clearance, collisions.
2. What a shorter observability timeout buys: blind_spot with each timeout; per run the distance
   the truck really drove after the cameras last could see it, the position error of its estimate
   when it stopped; and the counterfactual replay of the SIMLAN-timeout run with each shorter
   timeout beside the real run with it (when would it have stopped?).
3. Runs ``-m experiment=collision_case1`` and ``collision_case2`` (unless --skip-sweeps) and
   includes their collision tables.

Prints markdown for docs/benchmarks/safety.md and the raw numbers as JSON. Accuracy figures do not depend on
the machine's load; the wall times do (the load average is printed).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine, run_cli, table
from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.replay import ReplayContext
from simlan_data.evaluation.safety_inputs import read_safety_recording
from simlan_data.evaluation.safety_metrics import truth_ages
from simlan_data.recording.reader import RecordingReader

SCENARIOS = ("restricted_zone", "blind_spot", "humanoid_crossing")
BASELINES = ("single_truck", "multi_robot")  # issue 3's scenarios, the safety layer on (defaults)
KEYS = (
    "safety.violations",
    "safety.missed",
    "safety.stops",
    "safety.false_stops",
    "safety.max_latency_s",
    "safety.latency_budget_s",
    "safety.max_stop_distance_m",
    "safety.min_clearance_zone_m",
    "safety.min_clearance_agents_m",
    "safety.violations.zone_entries",
    "safety.collisions_moving",
    "safety.collisions_standing",
    "safety.hazards",
    "safety.hazards_unanswered",
    "safety.stops_while_visible",
    "navigation.goals_reached",
    "navigation.goals_total",
    "sim.rtf",
)


def run(out: Path, name: str, *overrides: str) -> dict[str, float]:
    run_dir = out / name
    if not (run_dir / "metrics.json").is_file():
        proc = run_cli(*overrides, f"hydra.run.dir={run_dir}", "progress=false")
        if proc.returncode != 0:
            raise SystemExit(f"{name} failed: {proc.stderr.strip()}")
    return json.loads((run_dir / "metrics.json").read_text())


def replay(recording: Path, out: Path, *sets: str) -> dict[str, float]:
    if not (out / "metrics.json").is_file():
        options = [a for s in sets for a in ("--set", s)]
        args = [str(recording), "--out", str(out), "--algorithms", "safety", *options]
        proc = run_cli(*args, module="simlan_data.replay")
        if proc.returncode != 0:
            raise SystemExit(f"replay of {recording} failed: {proc.stderr.strip()}")
    return json.loads((out / "metrics.json").read_text())


def blind_figures(run_dir: Path) -> dict[str, float]:
    """The truck's last camera fix, its stop, and how far it drove unseen until it stood still."""
    with RecordingReader(run_dir / "recording") as reader:
        ctx = ReplayContext(reader, run_dir)
        rec = read_safety_recording(reader, ctx.config)
        ages = truth_ages(rec, "robot_agent_1", ctx.cameras)
        tr = rec.truth["robot_agent_1"]
        est = rec.estimates["robot_agent_1"]
        stop = next(e for e in rec.events if e.action == "stop" and e.cause == "unobserved")
        i_stop = rec.index(stop.stamp_ns)
        j = i_stop  # standstill
        while j < len(rec.ticks) - 1 and abs(tr.speed_mps[j]) > 0.02:
            j += 1
        last_fix = max(i for i in range(i_stop + 1) if est[i].fix_age_s == 0.0)
        in_view = [i for i in range(j + 1) if ages[i] == 0.0]
        last_view = max(in_view) if in_view else 0

        def path(a: int, b: int) -> float:
            return float(np.hypot(*np.diff(tr.pose[a : b + 1, :2], axis=0).T).sum()) if b > a else 0.0

        e = est[i_stop]
        err = (
            float(np.hypot(e.pose[0] - tr.pose[i_stop, 0], e.pose[1] - tr.pose[i_stop, 1]))
            if e.pose
            else float("nan")
        )
        return {
            "last_fix_s": float(rec.ticks[last_fix] / NS_PER_S),
            "last_in_view_s": float(rec.ticks[last_view] / NS_PER_S),
            "stop_s": float(stop.stamp_ns / NS_PER_S),
            "driven_since_fix_m": path(last_fix, j),
            "driven_out_of_view_m": path(last_view, j),
            "estimate_error_at_stop_m": err,
            "stop_x_m": float(tr.pose[j, 0]),
        }


def people_accuracy(run_dir: Path, ns: str = "robot_agent_2") -> dict[str, float]:
    """Error of /people/detections against the person's ground truth, per camera tick."""
    from simlan_data.evaluation.metrics import ground_truth
    from simlan_data.recording import schema

    with RecordingReader(run_dir / "recording") as reader:
        gt = ground_truth(reader)[ns]
        t, x, y = (gt[c].to_numpy() for c in ("stamp_ns", "x", "y"))
        errors, frames, ghosts = [], 0, 0
        for m in reader.messages([schema.PEOPLE_DETECTIONS]):
            frames += 1
            i = min(int(np.searchsorted(t, m.stamp_ns)), len(t) - 1)
            d = [float(np.hypot(p.position.x - x[i], p.position.y - y[i])) for p in m.msg.poses]
            if d:
                errors.append(min(d))
                ghosts += sum(1 for v in d if v > 0.5)
    e = np.array(errors)
    return {
        "frames": float(frames),
        "found": float(len(e)),
        "median_m": float(np.median(e)) if len(e) else float("nan"),
        "p90_m": float(np.quantile(e, 0.9)) if len(e) else float("nan"),
        "max_m": float(e.max()) if len(e) else float("nan"),
        "ghosts": float(ghosts),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out-dir", type=Path, default=None, help="keep the runs here (default: a temp dir)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--skip-sweeps", action="store_true")
    ap.add_argument("--timeouts", default="5,2,1,0.5")
    args = ap.parse_args()
    out = args.out_dir or Path(tempfile.mkdtemp(prefix="simlan_safety_bench_"))
    out.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()
    raw: dict[str, Any] = {"machine": machine(), "load_average_start": load0}
    t0 = time.perf_counter()

    # 1. scenarios (and issue 3's, to show the layer leaves normal operation alone)
    scen = {s: run(out, s, f"scenario={s}") for s in SCENARIOS + BASELINES}
    raw["scenarios"] = {s: {k: m.get(k) for k in KEYS} for s, m in scen.items()}
    rows = []
    for s, m in scen.items():
        rows.append(
            [
                s,
                int(m["safety.violations"]),
                int(m["safety.missed"]),
                int(m["safety.stops"]),
                int(m["safety.false_stops"]),
                f"{m['safety.max_latency_s']:.2f} / {m['safety.latency_budget_s']:.2f}",
                f"{m['safety.max_stop_distance_m']:.2f}",
                f"{m['safety.min_clearance_zone_m']:.2f}"
                if np.isfinite(m["safety.min_clearance_zone_m"])
                else "-",
                f"{m['safety.min_clearance_agents_m']:.2f}"
                if np.isfinite(m["safety.min_clearance_agents_m"])
                else "-",
                f"{int(m['safety.collisions_moving'])} / {int(m['safety.collisions_standing'])}",
                f"{int(m['navigation.goals_reached'])}/{int(m['navigation.goals_total'])}",
            ]
        )
    md = [
        "### Safety scenarios (and issue 3's GPSS scenarios with the safety layer on)",
        "",
        table(
            [
                "scenario",
                "violations",
                "missed",
                "stops",
                "false stops",
                "max latency / budget (s)",
                "max stop distance (m)",
                "min clearance to zones (m)",
                "min clearance to agents (m)",
                "collisions driving / standing",
                "goals",
            ],
            rows,
        ),
        "",
    ]

    scen = {s: scen[s] for s in SCENARIOS}  # the figures below are over the safety scenarios
    people = people_accuracy(out / "humanoid_crossing")
    raw["people"] = people
    md += [
        f"People from the segmentation images (humanoid_crossing, {int(people['frames'])} camera ticks): "
        f"person found in {int(people['found'])}, error median {people['median_m'] * 100:.1f} cm, "
        f"90th percentile {people['p90_m'] * 100:.1f} cm, max {people['max_m'] * 100:.1f} cm, "
        f"{int(people['ghosts'])} detections farther than 0.5 m from the person.",
        "",
    ]

    # 2. observability timeouts, live and counterfactual
    timeouts = [float(t) for t in args.timeouts.split(",")]
    base = out / "blind_spot"
    trows = []
    raw["timeouts"] = {}
    for t in timeouts:
        live_dir = base if t == 5.0 else out / f"blind_spot_timeout_{t:g}"
        metrics = (
            scen["blind_spot"]
            if t == 5.0
            else run(
                out, live_dir.name, "scenario=blind_spot", f"algorithms.safety.observability.timeout_s={t}"
            )
        )
        live = blind_figures(live_dir)
        cf: dict[str, Any] = {}
        if t != 5.0:
            cf_out = out / f"replay_blind_spot_timeout_{t:g}"
            cf_metrics = replay(base / "recording", cf_out, f"observability.timeout_s={t}")
            import polars as pl

            ev = pl.read_parquet(cf_out / "safety_events.parquet").filter(
                (pl.col("action") == "stop") & (pl.col("cause") == "unobserved")
            )
            cf = {
                "stop_s": float(ev["stamp_ns"][0] / NS_PER_S) if ev.height else float("nan"),
                **{k: cf_metrics[k] for k in ("replay.safety.events_diff_to_live",)},
            }
        raw["timeouts"][f"{t:g}"] = {
            "live": live,
            "counterfactual": cf,
            "max_latency_s": metrics["safety.max_latency_s"],
        }
        trows.append(
            [
                f"{t:g}",
                f"{live['last_fix_s']:.2f}",
                f"{live['stop_s']:.2f}",
                f"{cf['stop_s']:.2f}" if cf else "(recorded)",
                f"{live['driven_since_fix_m']:.2f}",
                f"{live['driven_out_of_view_m']:.2f}",
                f"{live['estimate_error_at_stop_m'] * 100:.1f}",
                f"{live['stop_x_m']:.2f}",
            ]
        )
    md += [
        "### What a shorter observability timeout buys (scenario=blind_spot)",
        "",
        table(
            [
                "timeout (s)",
                "last camera fix (s)",
                "stop (s), real run",
                "stop (s), counterfactual replay of the 5 s run",
                "driven since the last fix until standstill (m)",
                "of it out of every camera's view (m)",
                "estimate error at the stop (cm)",
                "stands at x (m)",
            ],
            trows,
        ),
        "",
    ]

    # 3. sweeps
    if not args.skip_sweeps:
        raw["sweeps"] = {}
        for exp in ("collision_case1", "collision_case2"):
            sweep_dir = out / exp
            wall0 = time.perf_counter()
            if not (sweep_dir / "collision_sweep.md").is_file():
                proc = run_cli("-m", f"experiment={exp}", f"hydra.sweep.dir={sweep_dir}", timeout=4 * 3600)
                if proc.returncode != 0:
                    raise SystemExit(f"{exp} failed: {proc.stderr.strip()[-2000:]}")
            wall = time.perf_counter() - wall0
            text = (sweep_dir / "collision_sweep.md").read_text()
            raw["sweeps"][exp] = {"wall_s": wall, "report": str(sweep_dir / "collision_sweep.md")}
            body = text.split("\n", 2)[2].replace(
                "](collision_sweep.png)", f"]({sweep_dir / 'collision_sweep.png'})"
            )
            md += [
                f"### `python -m simlan_data.run -m experiment={exp}` ({wall / 60:.1f} min wall)",
                "",
                body,
                "",
            ]

    raw["load_average_end"] = os.getloadavg()
    raw["wall_s"] = time.perf_counter() - t0
    print(f"Machine: {raw['machine']}")
    print(f"Load average at start {load0[0]:.1f}, at end {raw['load_average_end'][0]:.1f} (shared cores)")
    print(f"Runs in {out}\n")
    print("\n".join(md))
    print("Raw:\n\n```")
    print(json.dumps(raw, default=float))
    print("```")
    if args.json:
        args.json.write_text(json.dumps(raw, indent=2, default=float))


if __name__ == "__main__":
    main()
