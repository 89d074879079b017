"""Benchmark: the fleet coordinator alone over seeded missions, kinematic robots (issue 23).

    python benchmarks/fleet_kinematic.py [--robots 4,8,12] [--seeds 100] [--tasks 3]
                                         [--limit-s 900] [--jobs 2] [--json FILE]

For every fleet size and seed: the missions of ``scenario=fleet`` (simlan_data/config/missions.py,
the same generator and seed as the run), the real layout's occupancy grid, and
``algorithms/coordinator=fleet`` driving a kinematic fleet (simlan_data/evaluation/fleet_kinematic.py:
robots follow the coordinator's routes exactly at their mission speed, no physics, no cameras,
ground-truth poses). Counts goals reached, missions done, deadlocks (the coordinator's, and the recording's definition of
simlan_data/evaluation/fleet_metrics.py on the trace), waits, failures,
the smallest footprint-to-footprint gap, makespan, tasks per hour and the planning time (wall, and
CPU time: on a shared machine the wall time is an upper bound, the CPU time compares runs). This
measures the coordination itself; the closed loop in the simulator is the sweep in docs/fleet.md.
Writes JSON with a ``figures`` list (one per fleet size) for benchmarks/summary.py.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine
from simlan_data.evaluation.fleet_kinematic import mission_fleet

SAFETY_M = 0.6  # navigation.safety_distance_m's default
DWELL_S = 2.0  # at each goal (a pickup, a drop-off, a charge)


def one(robots: int, seed: int, tasks: int, limit_s: float) -> dict:
    """One seeded mission set to the end (or ``limit_s``)."""
    fleet, kinds = mission_fleet(robots, seed, tasks=tasks, dwell_s=DWELL_S, safety_m=SAFETY_M)
    goals = fleet.goals_left()
    t0, c0 = time.perf_counter(), time.process_time()
    fleet.run(limit_s)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    reached = goals - fleet.goals_left()
    state = fleet.coordinator.state
    m = fleet.metrics(kinds)
    tasks_done = m["fleet.tasks_completed"]  # goals 2k, 2k+1 both reached (the recording's definition)
    return {
        "robots": robots, "seed": seed, "goals": goals, "reached": reached,
        "missions_done": fleet.goals_left() == 0, "deadlocks": state.deadlocks,
        # the recording's definitions (fleet_metrics): linked robots with goals, none moving for 20 s
        "fleet_deadlocks": int(m["fleet.deadlocks"]), "deadlock_s": round(m["fleet.deadlock_s"], 1),
        "wait_s_mean": round(m["fleet.wait_s_mean"], 1), "wait_s_max": round(m["fleet.wait_s_max"], 1),
        "failures": dict(state.failures), "min_gap_m": round(fleet.min_gap_m(every=5), 3),
        "makespan_s": round(fleet.t_s, 1), "tasks_per_hour": round(3600 * tasks_done / max(fleet.t_s, 1e-9), 1),
        "replans": state.replans, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
    }  # fmt: skip


def summary(rows: list[dict]) -> dict[int, dict]:
    out: dict[int, dict] = {}
    for n in sorted({r["robots"] for r in rows}):
        rs = [r for r in rows if r["robots"] == n]
        out[n] = {
            "runs": len(rs), "missions_done": sum(r["missions_done"] for r in rs),
            "goals_reached": f"{sum(r['reached'] for r in rs)}/{sum(r['goals'] for r in rs)}",
            "deadlocks": sum(r["deadlocks"] for r in rs), "min_gap_m": min(r["min_gap_m"] for r in rs),
            "fleet_deadlocks": sum(r.get("fleet_deadlocks", 0) for r in rs),
            "runs_with_deadlock": sum(r.get("fleet_deadlocks", 0) > 0 for r in rs),
            "wait_s_mean": round(float(np.mean([r.get("wait_s_mean", np.nan) for r in rs])), 1),
            "wait_s_max": max((r.get("wait_s_max", 0.0) for r in rs), default=0.0),
            "not_done": [r["seed"] for r in rs if not r["missions_done"]],
            "tasks_per_hour_mean": round(float(np.mean([r["tasks_per_hour"] for r in rs])), 1),
            "makespan_s_mean": round(float(np.mean([r["makespan_s"] for r in rs])), 1),
            "wall_s_per_run": round(float(np.mean([r["wall_s"] for r in rs])), 2),
            "cpu_s_per_run": round(float(np.mean([r.get("cpu_s", np.nan) for r in rs])), 2),
        }  # fmt: skip
    return out


def figures(table: dict[int, dict], limit_s: float) -> list[dict]:
    """One BENCHMARKS row per fleet size (benchmarks/summary.py)."""
    return [
        {"id": f"fleet_kinematic_{n}", "figure": f"fleet coordinator alone, {n} robots, seeded missions (kinematic robots): missions done",
         "value": row["missions_done"], "unit": f"of {row['runs']}", "target": "every task done, 0 deadlocks",
         "baseline": "none in this benchmark: gpss and independent robots give no routes to drive; the closed loop compares them",
         "note": f"goals {row['goals_reached']}, deadlocks {row['deadlocks']} (coordinator's count; the recording's "
                 f"definition: {row.get('fleet_deadlocks', '-')} in {row.get('runs_with_deadlock', '-')} runs), "
                 f"wait mean {row.get('wait_s_mean', '-')} s / max {row.get('wait_s_max', '-')} s, "
                 f"smallest gap {row['min_gap_m']} m, "
                 f"{row['tasks_per_hour_mean']} tasks/h, makespan {row['makespan_s_mean']} s (limit {limit_s:g} s), "
                 f"{row['wall_s_per_run']} s wall ({row['cpu_s_per_run']} s CPU) per run; "
                 f"not done: {row.get('not_done', [])}"}
        for n, row in table.items()
    ]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", default="4,8,12")
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--tasks", type=int, default=3)
    ap.add_argument("--limit-s", type=float, default=900.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    cases = [(int(n), s) for n in args.robots.split(",") for s in range(args.seeds)]
    rows = []
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(one, n, s, args.tasks, args.limit_s) for n, s in cases]
        for f in futures:
            r = f.result()
            rows.append(r)
            print(json.dumps(r), flush=True)
    table = summary(rows)
    for n, row in table.items():
        print(n, row, flush=True)
    command = (
        f"python benchmarks/fleet_kinematic.py --robots {args.robots} --seeds {args.seeds}"
        f" --tasks {args.tasks} --limit-s {args.limit_s:g} --json FILE"
    )
    result = {
        "command": command,
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
        "history": "docs/benchmarks/fleet.md",
        "summary": table,
        "figures": figures(table, args.limit_s),
        "rows": rows,
    }
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
