"""Benchmark of reliability (issue 9): crash recovery, bad inputs, fuzzing, determinism, flush cost.

    python benchmarks/reliability.py [--kill-points 0.6,1.8,3.1,4.3,5.6,6.9] [--duration 8]
                                     [--default-kill-points 12,31,47] [--fuzz-examples 500]
                                     [--overhead-duration 20] [--skip SECTION,...] [--json FILE]

1. Kill points: a complete reference run, then the same config killed (SIGSTOP, then SIGKILL) as
   soon as its RUNNING marker reports each simulated time; ``python -m simlan_data.recover``;
   the recovered messages (independent mcap reader, CRCs checked) compared with the reference:
   how many, whether they are exactly its beginning, how far they reach. Small config (3
   cameras, 480x270) at several points, and the default scenario (11 cameras, 960x540) at a few.
2. Bad inputs: every case of ``tests/reliability_cases.py`` per boundary: clear one-line errors
   (the expected message, exit code 2), other exceptions (must be 0).
3. Fuzzing: the hypothesis targets of ``tests/fuzz_targets.py`` with a larger budget: examples
   run per target and outcome, uncaught exceptions (must be 0).
4. Determinism: the small config twice: identical file bytes and payload digest.
5. Hardening (issue 21, ``benchmarks/hardening.py``): hostile input through the CLI, timed, and
   the issue's behaviour tests (signals, run directories, recovery losses, bounded readers,
   full disk, strict metrics.json, repeated-run identity), each with expected and observed.
6. Cost of the flush policy (timed, depends on load): the default scenario with the default flush
   (1 s), with flushes effectively off, and with fsync.

Prints markdown for BENCHMARKS.md and the raw numbers as JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import hardening
from reliability_helpers import (
    SMALL_RUN,
    finish_kill,
    kill_when,
    messages_in_file_order,
    payload_digest,
    read_running,
    start_run,
)

from common import machine, run_cli, table
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS

NS = 1_000_000_000


def recover_cli(path: Path) -> tuple[int, str, str, float]:
    import subprocess

    t0 = time.perf_counter()
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    proc = subprocess.run(
        [sys.executable, "-m", "simlan_data.recover", str(path), "--json"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    return proc.returncode, proc.stdout, proc.stderr, time.perf_counter() - t0


def kill_points(
    name: str,
    overrides: list[str],
    points: list[float],
    root: Path,
    flush_s: float,
    camera_period_s: float = 0.2,
) -> list[dict]:
    ref = root / f"{name}_reference"
    proc = run_cli(*overrides, f"hydra.run.dir={ref}")
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    reference = messages_in_file_order(ref / "recording")
    rows = []
    for kill_s in points:
        run_dir = root / f"{name}_killed_{kill_s}"
        proc = start_run(run_dir, *overrides)

        def reached(run_dir: Path = run_dir, kill_s: float = kill_s) -> bool:
            try:
                return float(read_running(run_dir)["simulated_s"]) >= kill_s
            except (OSError, TypeError, KeyError, ValueError):
                return False

        if not kill_when(proc, reached, timeout_s=1800):
            rows.append({"config": name, "kill_at_s": kill_s, "error": "finished before the kill point"})
            continue
        reached_s = float(read_running(run_dir)["simulated_s"])
        finish_kill(proc)
        code, out, err, wall = recover_cli(run_dir)
        if code != 0:
            rows.append({"config": name, "kill_at_s": kill_s, "error": err.strip()})
            continue
        report = json.loads(out)
        got = messages_in_file_order(run_dir / "recording")
        sim = [m.log_time - DEFAULT_EPOCH_NS for m in reference]  # simulated time (timebase.py)
        last_s = (max(m.log_time for m in got) - DEFAULT_EPOCH_NS) / NS
        before_window = sum(1 for t in sim if t < (reached_s - flush_s) * NS)
        upto_reached = sum(1 for t in sim if t <= reached_s * NS)
        rows.append(
            {
                "config": name,
                "kill_at_s": kill_s,
                "reached_s": reached_s,
                "recovered_until_s": last_s,
                # the marker is updated at camera ticks: the clock was at most one tick past it
                "loss_at_most_s": max(0.0, reached_s + camera_period_s - last_s),
                "messages_recovered": len(got),
                "messages_reference_before_reached_minus_flush": before_window,
                "messages_reference_up_to_reached": upto_reached,
                "messages_reference_total": len(reference),
                "prefix_of_reference": got == reference[: len(got)],
                "unreadable_tail_bytes": report["unreadable_bytes"],
                "recover_wall_s": wall,
                "file_mib": sum(p.stat().st_size for p in (run_dir / "recording").glob("*.mcap.damaged"))
                / 2**20,
            }
        )
        print(f"  {name} kill at {kill_s} s: {rows[-1]}", file=sys.stderr)
    return rows


def bad_inputs() -> dict[str, dict[str, int]]:
    from reliability_cases import BOUNDARIES

    from simlan_data.errors import SimlanError

    out: dict[str, dict[str, int]] = {}
    for name, (cases, runner, wants_tmp) in BOUNDARIES.items():
        counts = Counter()
        for case in cases:
            with tempfile.TemporaryDirectory() as tmp:
                try:
                    runner(case, Path(tmp)) if wants_tmp else runner(case)
                    counts["accepted (wrong)"] += 1
                except SimlanError as err:
                    line = err.line()
                    ok = re.search(case.match, line) and "\n" not in line and err.exit_code == 2
                    counts["clear error" if ok else "other message"] += 1
                except Exception as err:
                    counts["uncaught"] += 1
                    print(f"  UNCAUGHT {name}/{case.id}: {type(err).__name__}: {err}", file=sys.stderr)
        out[name] = {"cases": len(cases), **counts}
    return out


def _run_fuzz(strategy: object, check: object, n: int, outcomes: Counter) -> None:
    """Run ``check`` on ``n`` examples of ``strategy``, counting outcomes; raises on the first failure."""
    from hypothesis import HealthCheck, given, settings

    @settings(max_examples=n, deadline=10_000, database=None, suppress_health_check=list(HealthCheck))
    @given(strategy)
    def run(value: object) -> None:
        outcomes[check(value)] += 1  # type: ignore[operator]

    run()


def fuzz(examples: int) -> dict[str, dict[str, object]]:
    from fuzz_targets import (
        calibration_inputs,
        check_calibration,
        check_config,
        check_hostile,
        check_recording,
        config_overrides,
        hostile_inputs,
        recording_inputs,
    )
    from reliability_cases import small_recording

    with tempfile.TemporaryDirectory() as tmp:
        bag = small_recording(Path(tmp) / "recording")
        files = {p.name: p.read_bytes() for p in bag.iterdir()}
    targets = {
        "calibration loader (mutated and generated FileStorage YAML)": (
            calibration_inputs(),
            check_calibration,
            examples,
        ),
        "config validation (random overrides, compose + checks)": (
            config_overrides(),
            check_config,
            max(1, examples // 4),
        ),
        "recording reader + recovery (mutated bytes of a real bag)": (
            recording_inputs(files),
            check_recording,
            examples,
        ),
        "hostile inputs (FIFOs, alias bombs, inflated counts, wrong types, --set values)": (
            hostile_inputs(),
            check_hostile,
            max(1, examples // 4),
        ),
    }
    out: dict[str, dict[str, object]] = {}
    for name, (strategy, check, n) in targets.items():
        outcomes: Counter = Counter()
        failure = ""

        t0 = time.perf_counter()
        try:
            _run_fuzz(strategy, check, n, outcomes)
        except Exception as err:
            failure = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
        out[name] = {
            "examples": sum(outcomes.values()),
            "outcomes": dict(outcomes),
            "uncaught": failure,
            "wall_s": time.perf_counter() - t0,
        }
        print(f"  fuzz {name}: {out[name]}", file=sys.stderr)
    return out


def determinism(root: Path, duration: float) -> dict[str, object]:
    digests, files = [], []
    for i, env_seed in enumerate(("1", "2")):
        run_dir = root / f"twin_{i}"
        os.environ["PYTHONHASHSEED"] = env_seed
        proc = run_cli(*SMALL_RUN, f"duration_s={duration}", f"hydra.run.dir={run_dir}")
        if proc.returncode != 0:
            raise SystemExit(proc.stderr)
        msgs = messages_in_file_order(run_dir / "recording")
        digests.append(payload_digest(msgs))
        files.append((run_dir / "recording" / "recording.mcap").read_bytes())
    os.environ.pop("PYTHONHASHSEED", None)
    return {
        "messages": len(msgs),
        "payload_digest_equal": digests[0] == digests[1],
        "file_bytes_equal": files[0] == files[1],
        "digest": digests[0][:16],
    }


def overhead(root: Path, duration: float) -> list[dict]:
    rows = []
    for label, extra in (
        ("flush every 1 s (default)", []),
        ("flushes off (baseline: flush_period_s=1e9)", ["recording.flush_period_s=1e9"]),
        ("flush every 1 s + fsync", ["recording.fsync=true"]),
    ):
        run_dir = root / f"overhead_{len(rows)}"
        proc = run_cli(f"duration_s={duration}", "progress=false", f"hydra.run.dir={run_dir}", *extra)
        if proc.returncode != 0:
            raise SystemExit(proc.stderr)
        m = json.loads((run_dir / "metrics.json").read_text())
        rows.append(
            {
                "run": label,
                "rtf": m["sim.rtf"],
                "wall_s": m["sim.wall_s"],
                "mib": m["recording.bytes"] / 2**20,
            }
        )
        print(f"  overhead {rows[-1]}", file=sys.stderr)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kill-points", default="0.6,1.8,3.1,4.3,5.6,6.9")
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--default-kill-points", default="12,31,47")
    ap.add_argument("--fuzz-examples", type=int, default=500)
    ap.add_argument("--overhead-duration", type=float, default=20.0)
    ap.add_argument(
        "--skip",
        default="",
        help="comma-separated: kills,default_kills,bad_inputs,fuzz,determinism,hardening,overhead",
    )
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    raw: dict[str, object] = {"machine": machine(), "load_average_start": os.getloadavg()[0]}
    print(f"Machine: {raw['machine']}; load average at start {raw['load_average_start']:.1f}\n")
    with tempfile.TemporaryDirectory(prefix="reliability_") as tmp:
        root = Path(tmp)
        kills: list[dict] = []
        if "kills" not in skip:
            pts = [float(x) for x in args.kill_points.split(",") if x]
            kills += kill_points("small", [*SMALL_RUN, f"duration_s={args.duration}"], pts, root, 1.0)
        if "default_kills" not in skip:
            pts = [float(x) for x in args.default_kill_points.split(",") if x]
            kills += kill_points("default", ["progress=false"], pts, root, 1.0)
        raw["kills"] = kills
        if kills:
            print("### Kill points (SIGKILL, then python -m simlan_data.recover)\n")
            print(
                table(
                    [
                        "config",
                        "killed at (sim s, RUNNING marker; the clock was < 0.2 s further)",
                        "recovered until (s)",
                        "loss at most (s)",
                        "messages recovered",
                        "reference messages before kill - 1 s",
                        "reference messages up to kill",
                        "exactly the reference's beginning",
                        "recover wall (s)",
                    ],
                    [
                        [
                            r["config"],
                            f"{r.get('reached_s', r['kill_at_s']):.2f}",
                            f"{r['recovered_until_s']:.3f}"
                            if "recovered_until_s" in r
                            else r.get("error", ""),
                            f"{r['loss_at_most_s']:.3f}" if "loss_at_most_s" in r else "",
                            r.get("messages_recovered", ""),
                            r.get("messages_reference_before_reached_minus_flush", ""),
                            r.get("messages_reference_up_to_reached", ""),
                            "yes" if r.get("prefix_of_reference") else "NO",
                            f"{r['recover_wall_s']:.1f}" if "recover_wall_s" in r else "",
                        ]
                        for r in kills
                    ],
                )
            )
            print()
        if "bad_inputs" not in skip:
            bad = bad_inputs()
            raw["bad_inputs"] = bad
            print("### Bad inputs per boundary\n")
            print(
                table(
                    [
                        "boundary",
                        "cases",
                        "one clear line (expected message, exit 2)",
                        "other message",
                        "accepted",
                        "uncaught",
                    ],
                    [
                        [
                            n,
                            c["cases"],
                            c.get("clear error", 0),
                            c.get("other message", 0),
                            c.get("accepted (wrong)", 0),
                            c.get("uncaught", 0),
                        ]
                        for n, c in bad.items()
                    ],
                )
            )
            print()
        if "fuzz" not in skip:
            fz = fuzz(args.fuzz_examples)
            raw["fuzz"] = fz
            print("### Fuzzing (hypothesis)\n")
            print(
                table(
                    ["target", "examples run", "outcomes", "uncaught", "wall (s)"],
                    [
                        [
                            n,
                            f["examples"],
                            ", ".join(f"{k} {v}" for k, v in sorted(f["outcomes"].items())),
                            f["uncaught"] or 0,
                            f"{f['wall_s']:.0f}",
                        ]
                        for n, f in fz.items()
                    ],
                )
            )
            print()
        if "determinism" not in skip:
            det = determinism(root, 4.0)
            raw["determinism"] = det
            print("### Determinism\n")
            print(
                f"Small config, 4 s, run twice (PYTHONHASHSEED 1 and 2): {det['messages']} messages, payload digest equal: "
                f"{det['payload_digest_equal']}, file bytes equal: {det['file_bytes_equal']}\n"
            )
        if "hardening" not in skip:
            hostile = hardening.hostile_inputs(root)
            behaviour = hardening.behaviour_tests(root)
            raw["hardening"] = {"hostile_inputs": hostile, "behaviour_tests": behaviour}
            print(
                "### Hardening (issue 21): hostile input through the CLI (expected: exit 2, one line, < 5 s)\n"
            )
            print(
                table(
                    ["case", "exit", "observed line", "wall (s)", "as expected"],
                    [
                        [r["case"], r["exit"], f"`{r['line']}`", r["wall_s"], "yes" if r["ok"] else "NO"]
                        for r in hostile
                    ],
                )
            )
            print(
                "\n### Hardening (issue 21): behaviour tests (real processes, signals, tmpfs, damaged bags)\n"
            )
            print(
                table(
                    ["test file", "expected (the test's name)", "observed", "wall (s)"],
                    [[r["module"], r["expected"], r["observed"], r["wall_s"]] for r in behaviour],
                )
            )
            print()
        if "overhead" not in skip:
            ov = overhead(root, args.overhead_duration)
            raw["overhead"] = ov
            print(f"### Cost of the flush policy (default scenario, {args.overhead_duration:g} s; timed)\n")
            print(
                table(
                    ["run", "real-time factor", "loop wall (s)", "recording MiB"],
                    [[r["run"], f"{r['rtf']:.2f}", f"{r['wall_s']:.1f}", f"{r['mib']:.0f}"] for r in ov],
                )
            )
            print()
    raw["load_average_end"] = os.getloadavg()[0]
    print(
        f"Load average (1 min) at start {raw['load_average_start']:.1f}, at end {raw['load_average_end']:.1f} on {os.cpu_count()} cores.\n"
    )
    text = json.dumps(raw, indent=2, default=str)
    print("<details><summary>raw JSON</summary>\n\n```json\n" + text + "\n```\n</details>")
    if args.json:
        args.json.write_text(text + "\n")


if __name__ == "__main__":
    main()
