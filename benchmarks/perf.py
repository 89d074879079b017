"""Benchmark of issue 8: real-time camera networks on 2 CPU cores, sweeps on one machine.

    python benchmarks/perf.py [--quick] [--out-dir DIR] [--json FILE] [--only SECTION]

One run prints, as markdown, then the raw numbers as JSON:

1. renderer   the layered renderer beside the plain full render on the same frames: 12 cameras
              160-171 at 960x540 (distortion on, RGB + depth + segmentation), four robots
              driving through the full warehouse; time per camera frame and how equal the
              outputs are (labels equal, depth within 1 cm, colour equal, worst frame).
2. rtf        ``python -m simlan_data.run -m experiment=rtf`` (basic launcher): the real-time
              factor per camera count {1, 2, 4, 6, 9, 12} x stream set, beside SIMLAN's numbers.
3. launchers  the same sweep through ``hydra/launcher=joblib`` (both cores): wall time of the
              whole command against the basic launcher's, each launcher run twice in the order
              basic, joblib, joblib, basic (a steady drift of the host's speed cancels out);
              then the basic launcher once more with its jobs as joblib runs them (no helper
              threads: ``LP_NUM_THREADS=0``, ``recording.encode_threads=0``), and the ceiling
              of the speedup that this run's CPU seconds allow on 2 cores (see
              :func:`launcher_ceiling`).
4. gpss       the headline configuration with the GPSS loop on (robots steer on the camera
              estimate): 12 cameras, RGB + depth + semantic, 960x540 at 5 Hz, four robots,
              recording on; depth and labels recorded at 1 Hz and at 5 Hz; and, for the cost of
              recording, the same with encoding on the simulation thread and with recording off.
5. replay     ``python -m simlan_data.replay REC --out DIR`` (localization) over the 12-camera
              recording of 4 and over an 80 s one (the scenario's length): replay speed.

``--quick`` shrinks every section (fewer frames, cameras 1 and 12 only, 10 s runs) to check the
command in a few minutes. Timed figures depend on what else runs on the cores: the load average
is printed at the start and at the end.
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
from simlan_data.evaluation.rtf_report import markdown as rtf_markdown
from simlan_data.evaluation.rtf_report import rtf_rows
from simlan_data.evaluation.sweep import collect_sweep
from simlan_data.geometry.calibration import load_calibration
from simlan_data.sim.agents import AGENT_TYPES, spawn_agent
from simlan_data.sim.dynamic_layer import MovedAgents, StaticMeshes
from simlan_data.sim.pybullet_client import connect
from simlan_data.sim.rendering import CameraRenderer, LabelTable
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import build_world
from simlan_data.world.layout import load_layout

CAMERAS = [str(c) for c in range(160, 172)]
KEPT_METRICS = ("sim.", "recording.", "job.", "localization.ate_xy", "localization.availability")
# four robots as conf/agents/four_robots.yaml, in the main aisle, driving (v m/s, w rad/s)
ROBOTS = [
    ("pallet_truck", [-6.0, 1.5, 0.0], (1.0, 0.05)),
    ("pallet_truck", [14.0, -0.7, np.pi], (1.0, -0.05)),
    ("jackal", [2.0, -1.2, 0.7], (0.8, 0.3)),
    ("forklift", [8.0, 1.0, np.pi], (0.8, 0.1)),
]


def load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


# ------------------------------------------------------------------------------------ 1. renderer
def renderer(frames: int) -> tuple[str, dict]:
    """Layered against full render on the same frames, 12 cameras, four moving robots."""
    client = connect("egl")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            world = build_world(
                client.id, load_layout("warehouse_layout.csv", "default"), {}, mesh_dir=Path(tmp)
            )
        labels = LabelTable()
        for body, label in world.labels.items():
            labels.set(body, label)
        cams = [load_calibration(c).camera.scaled(960, 540) for c in CAMERAS]
        layered = [CameraRenderer(client, c, labels, layered=True) for c in cams]
        full = [CameraRenderer(client, c, labels, layered=False) for c in cams]
        t0 = time.perf_counter()
        for r in layered:
            r.render_static()
        static_s = time.perf_counter() - t0
        agents = []
        for n, (kind, pose, cmd) in enumerate(ROBOTS, start=1):
            agent = spawn_agent(client.id, f"robot_agent_{n}", AGENT_TYPES[kind], pose=pose, marker_id=n)
            labels.set(agent.body, agent.label)
            agent.apply_command(*cmd)
            agents.append(agent)
        meshes = StaticMeshes(client.id, world, labels)
        meshes.remove()
        moving = MovedAgents(agents)
        t_layered = t_full = 0.0
        in_view: list[tuple[float, float]] = []  # (layered, full) seconds of camera frames with an agent
        fractions: list[tuple[float, float, float]] = []
        changed = agent_frames = 0
        for _ in range(frames):
            for _ in range(48):  # 0.2 s at 240 Hz: the 5 Hz camera rate
                pb.stepSimulation(physicsClientId=client.id)
            t0 = time.perf_counter()
            moved = moving.boxes()
            t_layered += time.perf_counter() - t0
            outs, lt = [], []
            for r in layered:
                t0 = time.perf_counter()
                outs.append(r.render(moved))
                lt.append(time.perf_counter() - t0)
            refs, ft = [], []
            with meshes.shown():
                for r in full:
                    t0 = time.perf_counter()
                    refs.append(r.render())
                    ft.append(time.perf_counter() - t0)
            t_layered += sum(lt)
            t_full += sum(ft)
            for lr, a, b, tl, tf in zip(layered, outs, refs, lt, ft):
                valid = lr.valid_mask
                fractions.append(
                    (
                        float(np.mean(a.labels == b.labels)),
                        float(np.mean(np.abs(a.depth_m[valid] - b.depth_m[valid]) <= 0.01)),
                        float(np.mean(np.all(a.rgb == b.rgb, axis=-1))),
                    )
                )
                changed += int(a.changed)
                if any((b.labels == ag.label).sum() > 100 for ag in agents):
                    agent_frames += 1
                    in_view.append((tl, tf))
    finally:
        client.disconnect()
    n = frames * len(CAMERAS)
    f = np.array(fractions)
    raw = {
        "camera_frames": n,
        "frames_with_an_agent": agent_frames,
        "frames_changed": changed,
        "layered_ms": t_layered / n * 1e3,
        "full_ms": t_full / n * 1e3,
        "speedup": t_full / t_layered,
        "layered_ms_agent_in_view": float(np.mean([a for a, _ in in_view])) * 1e3 if in_view else None,
        "full_ms_agent_in_view": float(np.mean([b for _, b in in_view])) * 1e3 if in_view else None,
        "static_layers_s": static_s,
        "labels_equal_min": float(f[:, 0].min()),
        "labels_equal_mean": float(f[:, 0].mean()),
        "depth_1cm_min": float(f[:, 1].min()),
        "depth_1cm_mean": float(f[:, 1].mean()),
        "rgb_equal_min": float(f[:, 2].min()),
        "rgb_equal_mean": float(f[:, 2].mean()),
    }
    md = table(
        [
            "render",
            "ms per camera frame",
            "frames/s per camera",
            "labels equal (worst / mean)",
            "depth within 1 cm",
            "colour equal",
        ],
        [
            ["full (baseline)", f"{raw['full_ms']:.1f}", f"{1e3 / raw['full_ms']:.1f}", "-", "-", "-"],
            [
                "layered",
                f"{raw['layered_ms']:.1f}",
                f"{1e3 / raw['layered_ms']:.1f}",
                f"{raw['labels_equal_min'] * 100:.2f} % / {raw['labels_equal_mean'] * 100:.3f} %",
                f"{raw['depth_1cm_min'] * 100:.2f} % / {raw['depth_1cm_mean'] * 100:.3f} %",
                f"{raw['rgb_equal_min'] * 100:.2f} % / {raw['rgb_equal_mean'] * 100:.3f} %",
            ],
        ],
    )
    if in_view:
        md += (
            f"\n\nCamera frames with an agent in view only: layered {raw['layered_ms_agent_in_view']:.1f} ms, "
            f"full {raw['full_ms_agent_in_view']:.1f} ms "
            f"({raw['full_ms_agent_in_view'] / raw['layered_ms_agent_in_view']:.1f}x)."
        )
    md += (
        f"\n\nLayered is **{raw['speedup']:.1f}x** faster on the same {n} camera frames ({frames} frames x 12 "
        f"cameras; an agent in view in {agent_frames}, output changed in {changed}); static layers "
        f"once: {static_s:.1f} s for 12 cameras."
    )
    return md, raw


# ----------------------------------------------------------------------------- 2./3. sweeps
def sweep(
    out: Path, launcher: str, overrides: list[str], env_extra: dict[str, str] | None = None
) -> tuple[float, Any]:
    """Run the rtf experiment through ``launcher``; returns the command's wall time and the table."""
    t0 = time.perf_counter()
    proc = run_cli(
        "-m",
        "experiment=rtf",
        f"hydra/launcher={launcher}",
        *overrides,
        f"hydra.sweep.dir={out}",
        env_extra=env_extra,
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"sweep through {launcher} failed: {proc.stderr.strip()[-2000:]}")
    return wall, collect_sweep(out)


def launcher_ceiling(pairs: list[tuple[float, Any, float, Any]], cores: int = 2) -> dict[str, float]:
    """What the basic sweeps' wall and the parallel sweeps' CPU allow the parallel launcher.

    ``pairs``: (basic command's wall, its table, parallel command's wall, its table) per pair
    of sweeps. A basic sweep is its jobs' loops (wall: ``sim.wall_s`` summed; they may spread
    over more than one core) plus the rest (start-up, evaluation, reports: the command's wall
    minus the loops'). A parallel launcher can at best keep all ``cores`` busy with its own
    loops' CPU (``sim.cpu_s`` summed) and the same rest: ``basic_s / ((loops CPU + rest) /
    cores)``, over the pairs' sums. Figures per sweep are means over the pairs."""
    n = len(pairs)
    basic_s = sum(p[0] for p in pairs)
    loops_wall = sum(float(p[1]["sim.wall_s"].sum()) for p in pairs)
    rest = basic_s - loops_wall
    parallel_cpu = sum(float(p[3]["sim.cpu_s"].sum()) for p in pairs)
    return {
        "basic_loops_wall_s": loops_wall / n,
        "basic_loops_cpu_s": sum(float(p[1]["sim.cpu_s"].sum()) for p in pairs) / n,
        "basic_rest_s": rest / n,
        "parallel_loops_cpu_s": parallel_cpu / n,
        "ceiling": basic_s / ((parallel_cpu + rest) / cores),
    }


# -------------------------------------------------------------------------------- 4. gpss runs
def cpu_bound(m: dict[str, float], cores: int = 2) -> float:
    """The real-time factor the loop's CPU time allows on ``cores`` free cores: simulated time
    over max(simulation-thread CPU, process CPU / cores). An upper bound (it ignores waits for
    Mesa's rasterizer thread and for the GIL), for reading results taken on shared cores."""
    return m["sim.duration_s"] / max(m["sim.main_thread_cpu_s"], m["sim.cpu_s"] / cores)


def gpss_runs(out: Path, duration: float) -> tuple[str, dict]:
    common = ["experiment=rtf", "localization.source=camera", f"duration_s={duration}", "cameras.count=12"]
    cases = {
        "depth + labels recorded at 1 Hz (default)": ["streams=rgbds"],
        "depth + labels recorded at 5 Hz": ["streams=rgbds_full"],
        "1 Hz, encoding on the simulation thread": ["streams=rgbds", "recording.encode_threads=0"],
        "recording off": ["streams=rgbds", "recording.enabled=false"],
    }
    raw: dict[str, Any] = {}
    rows = []
    for i, (name, extra) in enumerate(cases.items()):
        run_dir = out / f"gpss_{i}"
        proc = run_cli(*common, *extra, f"hydra.run.dir={run_dir}")
        if proc.returncode != 0:
            raise SystemExit(f"run {name!r} failed: {proc.stderr.strip()[-2000:]}")
        m = json.loads((run_dir / "metrics.json").read_text())
        m = {k: v for k, v in m.items() if k.startswith(KEPT_METRICS)}
        m["run_dir"] = str(run_dir)
        raw[name] = m
        rows.append(
            [
                name,
                f"{m['sim.rtf']:.2f}",
                f"{m['sim.wall_s']:.1f}",
                f"{m['sim.main_thread_cpu_s']:.1f}",
                f"{m['sim.cpu_s']:.1f}",
                f"{cpu_bound(m):.2f}",
                f"{m['recording.bytes'] / 2**20:.0f}" if m.get("recording.bytes") else "-",
                f"{m.get('localization.ate_xy_rmse_m', float('nan')) * 100:.1f}",
            ]
        )
    md = table(
        [
            f"12 cameras, RGB + depth + semantic, 960x540 at 5 Hz, four robots on the camera estimate, {duration:g} s",
            "real-time factor",
            "loop wall s",
            "simulation thread CPU s",
            "process CPU s",
            "CPU-time bound on 2 free cores",
            "recording MiB",
            "ATE cm",
        ],
        rows,
    )
    return md, raw


# ------------------------------------------------------------------------------------ 5. replay
def replay(recordings: dict[str, Path], out: Path) -> tuple[str, dict]:
    """Replay the localization over each recording; speed against real time."""
    raw, rows = {}, []
    # the default reader (auto: a forked process when a core is free, else a thread) and, for the
    # first recording, each reader forced: a thread, and a process (off the replay's GIL, but
    # every image goes through a pipe)
    first = next(iter(recordings), None)
    cases = [(name, rec, []) for name, rec in recordings.items()]
    if first is not None:
        cases[1:1] = [
            (f"{first}, bag read by a thread", recordings[first], ["--set", "reader=thread"]),
            (f"{first}, bag read by a process", recordings[first], ["--set", "reader=process"]),
        ]
    for i, (name, recording, extra) in enumerate(cases):
        dest = out / f"replay_{i}"
        proc = run_cli(str(recording), "--out", str(dest), *extra, module="simlan_data.replay")
        if proc.returncode != 0:
            raise SystemExit(f"replay of {recording} failed: {proc.stderr.strip()[-2000:]}")
        m = json.loads((dest / "metrics.json").read_text())
        m = {
            k: v
            for k, v in m.items()
            if k.startswith(("replay.", "localization.ate_xy", "localization.availability"))
        }
        raw[name] = m
        rows.append(
            [
                name,
                "process" if m.get("replay.localization.reading_process") else "thread",
                f"{m['replay.wall_s'] * m['replay.speed_x_realtime']:.1f}",
                f"{m['replay.wall_s']:.2f}",
                f"{m['replay.cpu_s']:.2f}",
                f"{m['replay.main_thread_cpu_s']:.2f}",
                f"{m.get('replay.children_cpu_s', 0.0):.2f}",
                f"**{m['replay.speed_x_realtime']:.1f}**",
                f"{int(m['replay.localization.frames_processed'])} ({int(m['replay.localization.frames_full'])} full)",
                f"{m.get('replay.localization.max_diff_to_live_m', float('nan')):.3g} m",
            ]
        )
    md = table(
        [
            "replay (localization) of",
            "reader",
            "recorded s",
            "wall s",
            "CPU s",
            "of it main thread",
            "of it reading process",
            "x real time",
            "images searched",
            "max diff to live",
        ],
        rows,
    )
    return md, raw


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="small version of every section (a few minutes)")
    parser.add_argument(
        "--out-dir", type=Path, help="keep sweeps, runs and replays here (default: a temporary dir)"
    )
    parser.add_argument("--json", type=Path, help="also write the raw numbers here")
    parser.add_argument(
        "--only", choices=["renderer", "rtf", "launchers", "gpss", "replay"], help="one section"
    )
    args = parser.parse_args()
    quick = args.quick
    tmp = tempfile.TemporaryDirectory(prefix="simlan_perf_")
    out = args.out_dir or Path(tmp.name)
    out.mkdir(parents=True, exist_ok=True)
    want = (
        (lambda s: args.only in (None, s)) if args.only != "replay" else (lambda s: s in ("gpss", "replay"))
    )
    raw: dict[str, Any] = {
        "machine": machine(),
        "cpu_count": os.cpu_count(),
        "quick": quick,
        "load_start": load(),
    }
    print(f"Machine: {raw['machine']}")
    print(f"Load average at the start: {raw['load_start']} (1, 5, 15 min) on {os.cpu_count()} cores\n")
    sweep_args = (
        ["cameras.count=1,12", "streams=rgb,rgbds", "duration_s=10"] if quick else []
    )  # the full experiment: cameras {1,2,4,6,9,12} x {rgb, rgbds, rgbds_full}, 20 s each
    if want("renderer"):
        md, raw["renderer"] = renderer(3 if quick else 10)
        print("### Layered renderer beside the full render, same frames\n")
        print(md + "\n", flush=True)
    if want("rtf") or want("launchers"):
        basic_s, basic = sweep(out / "sweep_basic", "basic", sweep_args)
        rows = rtf_rows(basic)
        raw["rtf"] = {"command_s": basic_s, "rows": rows.to_dicts(), "overrides": sweep_args}
        print(
            "### Real-time factor (python -m simlan_data.run -m experiment=rtf "
            + " ".join(sweep_args)
            + ")\n"
        )
        print(rtf_markdown(rows), flush=True)
        if want("launchers"):
            # basic, joblib, joblib, basic: each launcher twice, in an order that cancels a host
            # that speeds up or slows down steadily during the run (it does: docs/benchmarks/realtime.md,
            # "Real-time camera networks", section 3)
            joblib_s, par = sweep(out / "sweep_joblib", "joblib", sweep_args)
            joblib2_s, par2 = sweep(out / "sweep_joblib_2", "joblib", sweep_args)
            basic2_s, basic2 = sweep(out / "sweep_basic_2", "basic", sweep_args)
            # the basic launcher with its jobs as joblib runs them (one thread each): what the
            # speedup would be against jobs that do not spread over the second core themselves
            serial_s, serial = sweep(
                out / "sweep_basic_serial",
                "basic",
                [*sweep_args, "recording.encode_threads=0"],
                env_extra={"LP_NUM_THREADS": "0"},
            )
            jobs = basic.height
            pairs = [(basic_s, basic, joblib_s, par), (basic2_s, basic2, joblib2_s, par2)]
            ceiling = launcher_ceiling(pairs)
            basic_mean, joblib_mean = (basic_s + basic2_s) / 2, (joblib_s + joblib2_s) / 2
            raw["launchers"] = {
                "jobs": jobs,
                "basic_s": basic_mean,
                "joblib_s": joblib_mean,
                "speedup": basic_mean / joblib_mean,
                "order": ["basic", "joblib", "joblib", "basic", "basic (jobs single-threaded)"],
                "basic_each_s": [basic_s, basic2_s],
                "joblib_each_s": [joblib_s, joblib2_s],
                "speedup_each": [basic_s / joblib_s, basic2_s / joblib2_s],
                "basic_serial_s": serial_s,
                "speedup_over_serial_jobs": serial_s / joblib_mean,
                **ceiling,
                "joblib_rtf": rtf_rows(par).to_dicts(),
                "basic_serial_rtf": rtf_rows(serial).to_dicts(),
            }
            print("### The same sweep through the basic and the joblib launcher\n")

            def loops(*ts: Any) -> str:
                return " + ".join(f"{t['sim.wall_s'].sum():.0f} / {t['sim.cpu_s'].sum():.0f}" for t in ts)

            print(
                table(
                    [
                        "launcher",
                        "each job's helper threads",
                        f"whole command, {jobs} jobs (s)",
                        "the jobs' loops: wall / CPU (s)",
                        "joblib's speedup over it",
                    ],
                    [
                        [
                            "basic (one job at a time), runs 1 and 4",
                            "Mesa 1 + encoders 2 (a single run's default)",
                            f"{basic_s:.0f} + {basic2_s:.0f}",
                            loops(basic, basic2),
                            f"**{basic_mean / joblib_mean:.2f}** (each pair: "
                            f"{basic_s / joblib_s:.2f}, {basic2_s / joblib2_s:.2f})",
                        ],
                        [
                            "joblib (n_jobs=-1: one job per core), runs 2 and 3",
                            "none",
                            f"{joblib_s:.0f} + {joblib2_s:.0f}",
                            loops(par, par2),
                            "1.00",
                        ],
                        [
                            "basic, jobs as joblib runs them, run 5",
                            "none",
                            f"{serial_s:.0f}",
                            loops(serial),
                            f"{serial_s / joblib_mean:.2f}",
                        ],
                    ],
                )
                + f"\n\nCeiling of joblib's speedup over the basic launcher from this run's CPU seconds "
                f"(basic_s / ((joblib loops' CPU + the basic sweep's rest) / 2)): {ceiling['ceiling']:.2f}x "
                f"(rest {ceiling['basic_rest_s']:.0f} s per basic sweep).\n",
                flush=True,
            )
    if want("gpss"):
        md, raw["gpss"] = gpss_runs(out, 10.0 if quick else 20.0)
        print("### The headline configuration with the GPSS loop on\n")
        print(md + "\n", flush=True)
        if want("replay"):
            # the scenario's whole 80 s too: the twelve full-frame searches of the first frame
            # (no robot tracked yet) weigh less in a longer recording
            full_s = 20.0 if quick else 80.0
            long_dir = out / "gpss_long"
            proc = run_cli(
                "experiment=rtf",
                "localization.source=camera",
                "cameras.count=12",
                "streams=rgbds",
                f"duration_s={full_s}",
                f"hydra.run.dir={long_dir}",
            )
            if proc.returncode != 0:
                raise SystemExit(f"the {full_s:g} s run failed: {proc.stderr.strip()[-2000:]}")
            gpss_s = 10 if quick else 20
            recordings = {
                f"the {gpss_s} s 12-camera recording of 4 (depth + labels at 1 Hz)": Path(
                    raw["gpss"]["depth + labels recorded at 1 Hz (default)"]["run_dir"]
                )
                / "recording",
                f"the same configuration, {full_s:g} s{'' if quick else ' (the scenario length)'}": long_dir
                / "recording",
            }
            md, raw["replay"] = replay(recordings, out)
            print("### Replay of the localization over the 12-camera recording\n")
            print(md + "\n", flush=True)
    raw["load_end"] = load()
    print(f"Load average at the end: {raw['load_end']}\n")
    text = json.dumps(raw, indent=None, default=str)
    print("Raw:\n\n```\n" + text + "\n```")
    if args.json:
        args.json.write_text(json.dumps(raw, indent=2, default=str))
    tmp.cleanup()


if __name__ == "__main__":
    main()
