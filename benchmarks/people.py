"""The RGB person detector (``people.detector=rgb``) beside the segmentation oracle.

    python benchmarks/people.py [--duration 30] [--dataset-duration 20] [--cases ...] [--json FILE]

Per case, closed-loop runs (the safety layer steers on the detector's people): humanoid_crossing
with the RGB detector and with the oracle (the safety outcome of each), the dataset cases with
the RGB detector; 11 GPSS cameras at 960x540, colour and segmentation recorded at every camera
tick. Each recording is then replayed through *both* detectors (the same images:
``simlan_data/evaluation/people_replay.py``) and scored against the people's ground truth: missed
share (in-view person-ticks without a track within 1 m), position error, latency (coming into
view -> first track), false tracks per camera tick, and the detector's wall time per frame
(decode included). The live runs give the safety outcome (does the truck stop for the person).

Cases: ``humanoid_crossing`` (one person crossing before a pallet truck), ``dataset_plain``
(scenario=dataset, 4 robots on missions, 3 people walking, randomize=off), ``dataset`` (the
same with randomize=on: light, time of day, materials, placement, distractors).

Writes benchmarks/results/people_<date>.json (figures for BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common import REPO, machine, run_cli
from simlan_data.algorithms.people import DETECTORS, ORACLE, RGB
from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.people_replay import diff_to_live, replay_params, run_detector, score
from simlan_data.evaluation.replay import ReplayContext
from simlan_data.evaluation.safety_inputs import read_safety_recording
from simlan_data.recording.reader import RecordingReader

CASES = {
    "humanoid_crossing": ["scenario=humanoid_crossing"],
    "dataset_plain": ["scenario=dataset", "randomize=off"],
    "dataset": ["scenario=dataset"],
}
COMMON = ["cameras.streams=[rgb,semantic]", "recording.semantic_rate_hz=5", "progress=false"]
SAFETY_KEYS = (
    "safety.missed",
    "safety.stops.ttc",
    "safety.collisions_moving",
    "safety.violations.collisions",
    "safety.min_clearance_agents_m",
    "safety.false_stops",
    "navigation.goals_reached",
)


def live_run(case: str, detector: str, duration: float, out: Path) -> dict[str, Any]:
    """One closed-loop run; its safety outcome and wall time."""
    t0 = time.perf_counter()
    proc = run_cli(
        *CASES[case], f"duration_s={duration}", *COMMON, f"people.detector={detector}", f"hydra.run.dir={out}"
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"error: run {case} {detector} failed:\n{proc.stderr[-2000:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    return {"wall_s": wall, **{k: metrics.get(k) for k in SAFETY_KEYS}}


def scored(recording: Path, detector: str) -> dict[str, Any]:
    """One recording through ``detector``: the people metrics, wall per frame, diff to live."""
    with RecordingReader(recording) as reader:
        ctx = ReplayContext(reader, recording.parent)
        params = replay_params(ctx.config, {"detector": detector})
        rec = read_safety_recording(reader, ctx.config)
        t0 = time.perf_counter()
        ticks = run_detector(rec, reader, ctx.believed_cameras, params)
        wall = time.perf_counter() - t0
        metrics = score(rec, ctx.cameras, ticks, params, prefix="")
        # after the first 2 s (randomize=on: what the plates do not show is absorbed by then)
        settled = [tick for tick in ticks if tick[0] >= 2 * NS_PER_S]
        metrics["false_tracks_per_tick_after_2s"] = score(rec, ctx.cameras, settled, params, prefix="")[
            "false_tracks_per_tick"
        ]
        counts, worst = diff_to_live(ticks, rec.people)
        frames = len(ticks) * len(ctx.believed_cameras)
    return {
        **metrics,
        "ms_per_frame": 1000 * wall / frames,
        "count_diff_to_live": counts,
        "max_diff_to_live_m": worst,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=30.0, help="humanoid_crossing's duration (s)")
    ap.add_argument("--dataset-duration", type=float, default=20.0, help="the dataset cases' duration (s)")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="people_"))
    results: dict[str, Any] = {}
    for case in args.cases:
        results[case] = {}
        duration = args.duration if case == "humanoid_crossing" else args.dataset_duration
        for live in DETECTORS if case == "humanoid_crossing" else (RGB,):
            run_dir = tmp / f"{case}_{live}"
            entry = {"live": live_run(case, live, duration, run_dir)}
            for det in DETECTORS:
                entry[det] = scored(run_dir / "recording", det)
            results[case][live] = entry
            print(case, live, json.dumps(entry), flush=True)
    date = datetime.date.today().isoformat()
    history = "docs/benchmarks/safety.md"
    cmd = "python benchmarks/people.py"
    figures = []
    for case, by_live in results.items():
        rgb, oracle = by_live[RGB][RGB], by_live[RGB][ORACLE]  # both detectors on the RGB run's images
        duration = args.duration if case == "humanoid_crossing" else args.dataset_duration
        stops = by_live[RGB]["live"]["safety.stops.ttc"]
        oracle_stops = by_live[ORACLE]["live"]["safety.stops.ttc"] if ORACLE in by_live else "-"
        note = (
            f"{case}, {duration:g} s, 11 cameras 960x540; RGB: error {rgb['position_error_mean_m']:.3f} m mean / "
            f"{rgb['position_error_p95_m']:.3f} m p95, latency max {rgb['latency_max_s']:.2f} s, "
            f"{rgb['false_tracks_per_tick']:.3f} false tracks per tick ({rgb['false_tracks_per_tick_after_2s']:.3f} "
            f"after 2 s), {rgb['ms_per_frame']:.1f} ms per frame (oracle {oracle['ms_per_frame']:.1f}); "
            f"TTC stops live: RGB {stops}, oracle {oracle_stops}; "
            f"replay - live: {rgb['count_diff_to_live']:.0f} ticks differ"
        )
        figures.append(
            {
                "id": f"people_missed_{case}",
                "figure": f"RGB person detector: share of in-view person-ticks missed ({case})",
                "value": round(rgb["missed_share"], 4),
                "unit": "",
                "baseline": (
                    f"segmentation oracle on the same images: {oracle['missed_share']:.4f} missed, error "
                    f"{oracle['position_error_mean_m']:.3f} m, {oracle['false_tracks_per_tick']:.3f} false tracks per tick"
                ),
                "note": note,
                "history": history,
            }
        )
    result = {
        "command": cmd,
        "machine": machine(),
        "date": date,
        "history": history,
        "duration_s": args.duration,
        "dataset_duration_s": args.dataset_duration,
        "results": results,
        "figures": figures,
    }
    out = args.json or REPO / "benchmarks" / "results" / f"people_{date}.json"
    out.write_text(json.dumps(result, indent=1) + "\n")
    for f in figures:
        print(f"{f['figure']}: {f['value']} ({f['baseline']}; {f['note']})")
    print(f"-> {out}")


if __name__ == "__main__":
    main()
