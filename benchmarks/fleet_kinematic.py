"""Benchmark: the fleet coordinator alone over seeded missions, kinematic robots (issue 23).

    python benchmarks/fleet_kinematic.py [--robots 4,8,12] [--seeds 100] [--tasks 3]
                                         [--limit-s 900] [--jobs 2] [--json FILE]
                                         [--cameras gpss_all] [--types jackal]
                                         [--set reverse_ratio=0.5 ...] [--baseline]

For every fleet size and seed: the missions of ``scenario=fleet`` (simlan_data/config/missions.py,
the same generator and seed as the run), the real layout's occupancy grid, and
``algorithms/coordinator=fleet`` driving a kinematic fleet (simlan_data/evaluation/fleet_kinematic.py:
robots follow the coordinator's routes exactly at their mission speed, no physics, no cameras,
ground-truth poses; with ``--cameras`` the missions and the route graph lie on the floor those
cameras see, as in a run whose robots steer on them). Counts goals reached, missions done, deadlocks (the coordinator's, and the recording's definition of
simlan_data/evaluation/fleet_metrics.py on the trace), waits, failures,
the smallest footprint-to-footprint gap, makespan, tasks per hour and the planning time (wall, and
CPU time: on a shared machine the wall time is an upper bound, the CPU time compares runs). This
measures the coordination itself; the closed loop in the simulator is the sweep in docs/fleet.md.
``--set KEY=VALUE`` sets a key of the coordinator's config (``algorithms.coordinator.KEY``, e.g.
``reverse_ratio=0.5``, ``shelters=true``; the figure's id then names them); with ``--baseline``
every case runs a second time with the defaults, in the same run, and the figure names that as its
baseline. Writes JSON with a ``figures`` list (one per fleet size) for benchmarks/summary.py.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine
from simlan_data.algorithms.fleet import FleetConfig
from simlan_data.config.validation import compose_config
from simlan_data.evaluation.fleet_kinematic import mission_fleet
from simlan_data.geometry.calibration import load_calibration

SAFETY_M = 0.6  # navigation.safety_distance_m's default
DWELL_S = 2.0  # at each goal (a pickup, a drop-off, a charge)


def cameras_of(name: str) -> list:
    """The cameras of ``cameras=NAME`` (conf/cameras) at their configured resolution, or none."""
    if not name:
        return []
    cfg = compose_config([f"cameras={name}"])
    return [load_calibration(i).camera.scaled(cfg.cameras.width, cfg.cameras.height) for i in cfg.cameras.ids]


def one(
    robots: int,
    seed: int,
    tasks: int,
    limit_s: float,
    cameras: str = "",
    types: str = "",
    overrides: dict | None = None,
) -> dict:
    """One seeded mission set to the end (or ``limit_s``); ``overrides``: coordinator config keys."""
    config = FleetConfig(**(overrides or {}))
    fleet, kinds = mission_fleet(
        robots, seed, tasks=tasks, dwell_s=DWELL_S, safety_m=SAFETY_M, cameras=cameras_of(cameras),
        types=types.split(",") if types else None, config=config,
    )  # fmt: skip
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
        "overrides": overrides or {},
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


def figures(
    table: dict[int, dict],
    limit_s: float,
    cameras: str = "",
    types: str = "",
    base: dict | None = None,
    overrides: dict | None = None,
) -> list[dict]:
    """One BENCHMARKS row per fleet size (benchmarks/summary.py); ``base``: the same cases with the
    coordinator's defaults, measured in the same run (``overrides``: what the measured run set)."""
    tag = (f"_{cameras}" if cameras else "") + (f"_{types.replace(',', '_')}" if types else "")
    tag += "".join(f"_{k}" for k in sorted(overrides or {}))
    where = f", on the floor the {cameras} cameras see" if cameras else ""
    mix = f", {types} only" if types else ""
    mix += "".join(f", {k}={v}" for k, v in sorted((overrides or {}).items()))
    return [
        {"id": f"fleet_kinematic{tag}_{n}", "figure": f"fleet coordinator alone, {n} robots{mix}, seeded missions (kinematic robots{where}): missions done",
         "value": row["missions_done"], "unit": f"of {row['runs']}", "target": "every task done, 0 deadlocks",
         "baseline": (
             f"the same cases, same run, the coordinator's defaults: {base[n]['missions_done']} of {base[n]['runs']}, "
             f"goals {base[n]['goals_reached']}, {base[n]['runs_with_deadlock']} runs with a deadlock, "
             f"smallest gap {base[n]['min_gap_m']} m"
             if base and n in base else
             "none in this benchmark: gpss and independent robots give no routes to drive; the closed loop compares them"
         ),
         "note": f"goals {row['goals_reached']}, deadlocks {row['deadlocks']} (coordinator's count; the recording's "
                 f"definition: {row.get('fleet_deadlocks', '-')} in {row.get('runs_with_deadlock', '-')} runs), "
                 f"wait mean {row.get('wait_s_mean', '-')} s / max {row.get('wait_s_max', '-')} s, "
                 f"smallest gap {row['min_gap_m']} m, "
                 f"{row['tasks_per_hour_mean']} tasks/h, makespan {row['makespan_s_mean']} s (limit {limit_s:g} s), "
                 f"{row['wall_s_per_run']} s wall ({row['cpu_s_per_run']} s CPU) per run; "
                 f"not done: {row.get('not_done', [])}"}
        for n, row in table.items()
    ]  # fmt: skip


def _overrides(items: list[str]) -> dict:
    """``KEY=VALUE`` strings as coordinator config values (typed as FleetConfig's fields)."""
    fields = {f.name: f.type for f in dataclasses.fields(FleetConfig)}
    out: dict = {}
    for item in items:
        key, _, value = item.partition("=")
        if key not in fields:
            sys.exit(f"error: --set {item}: FleetConfig has no key '{key}' (known: {', '.join(fields)})")
        kind = str(fields[key])
        out[key] = value.lower() in ("1", "true", "yes") if kind == "bool" else float(value)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", default="4,8,12")
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--tasks", type=int, default=3)
    ap.add_argument("--limit-s", type=float, default=900.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--cameras", default="", help="e.g. gpss_all: missions and routes on the floor they see")
    ap.add_argument("--types", default="", help="robot types of the mix, e.g. jackal (default: the fleet's)")
    ap.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="a coordinator config key"
    )
    ap.add_argument(
        "--baseline", action="store_true", help="also run every case with the coordinator's defaults"
    )
    args = ap.parse_args()
    overrides = _overrides(args.set)
    cases = [(int(n), s) for n in args.robots.split(",") for s in range(args.seeds)]
    variants = [overrides] + ([{}] if args.baseline else [])
    rows, base_rows = [], []
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [
            (k, pool.submit(one, n, s, args.tasks, args.limit_s, args.cameras, args.types, v))
            for n, s in cases
            for k, v in enumerate(variants)
        ]
        for k, f in futures:
            r = f.result()
            (rows if k == 0 else base_rows).append(r)
            print(json.dumps(r), flush=True)
    table = summary(rows)
    base = summary(base_rows) if base_rows else None
    for n, row in table.items():
        print(n, row, flush=True)
    command = (
        f"python benchmarks/fleet_kinematic.py --robots {args.robots} --seeds {args.seeds}"
        f" --tasks {args.tasks} --limit-s {args.limit_s:g}"
        + (f" --cameras {args.cameras}" if args.cameras else "")
        + (f" --types {args.types}" if args.types else "")
        + "".join(f" --set {kv}" for kv in args.set)
        + (" --baseline" if base else "")
        + " --json FILE"
    )
    result = {
        "command": command,
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
        "history": "docs/benchmarks/fleet.md",
        "summary": table,
        "baseline_summary": base,
        "figures": figures(table, args.limit_s, args.cameras, args.types, base, overrides),
        "rows": rows,
        "baseline_rows": base_rows,
    }
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
