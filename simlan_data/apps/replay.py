"""``python -m simlan_data.replay RECORDING``: inspect and replay a recording without the simulator.

    python -m simlan_data.replay RECORDING --info
    python -m simlan_data.replay RECORDING --recover     (same as python -m simlan_data.recover)
    python -m simlan_data.replay RECORDING --out DIR [--algorithms localization,...] [--set KEY=VALUE ...]

RECORDING is a recording directory (the bag), its run directory, or its metadata.yaml. Replay
writes ``DIR/metrics.json`` (dotted metric names) and each algorithm's artifacts into DIR.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from simlan_data.apps.cli import run_cli
from simlan_data.constants import METRICS_FILENAME, NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.evaluation import replay_algorithms  # noqa: F401 - registers the algorithms
from simlan_data.evaluation.metrics_io import write_metrics
from simlan_data.evaluation.replay import REPLAY_ALGORITHMS, ReplayContext
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.recover import recover


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simlan_data.replay",
        description="Inspect a simlan_data recording, or replay it through algorithms (no simulator).",
    )
    parser.add_argument("recording", help="recording directory (or its run directory, or metadata.yaml)")
    parser.add_argument("--info", action="store_true", help="print a summary like `ros2 bag info` and exit")
    parser.add_argument(
        "--recover",
        action="store_true",
        help="repair the recording of a crashed run (see python -m simlan_data.recover --help) and exit",
    )
    parser.add_argument("--out", type=Path, help="directory for the replay's metrics.json and artifacts")
    parser.add_argument(
        "--algorithms",
        default="localization",
        help=f"comma-separated, from: {', '.join(sorted(REPLAY_ALGORITHMS)) or '(none)'} (default: localization)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="algorithm option, e.g. method=pnp (repeatable)",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def parse_options(items: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(
                f"invalid --set {item!r}", "replay arguments", "expected KEY=VALUE", "e.g. --set method=pnp"
            )
        key, value = item.split("=", 1)
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def _children_cpu_s() -> float:
    t = os.times()
    return t.children_user + t.children_system


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.recover:
        print("\n".join(recover(args.recording).lines()))
        return 0
    if not args.info and args.out is None:
        parser.error("give --info, --recover or --out DIR")
    names = [n.strip() for n in args.algorithms.split(",") if n.strip()]
    unknown = [n for n in names if n not in REPLAY_ALGORITHMS]
    if unknown and not args.info:
        raise ConfigError(
            f"unknown replay algorithm {unknown[0]!r}",
            "--algorithms",
            f"known: {', '.join(sorted(REPLAY_ALGORITHMS))}",
            "pick from the list",
        )
    options = parse_options(args.set)
    with RecordingReader(args.recording) as reader:
        if args.info:
            print(reader.summary())
            return 0
        reader.require_topics(schema.REQUIRED_TOPICS)
        out: Path = args.out
        if out.resolve() == reader.path.resolve() or reader.path.resolve() in out.resolve().parents:
            raise ConfigError(
                "invalid --out", str(out), "it is inside the recording", "write replay outputs elsewhere"
            )
        if (out / METRICS_FILENAME).exists():
            raise ConfigError(
                "replay output exists",
                str(out / METRICS_FILENAME),
                "replay never overwrites results",
                "choose another --out",
            )
        out.mkdir(parents=True, exist_ok=True)
        ctx = ReplayContext(reader, out, options)
        metrics: dict[str, float] = {}
        wall0, cpu0, main0 = time.perf_counter(), time.process_time(), time.thread_time()
        children0 = _children_cpu_s()
        for name in names:
            metrics.update(REPLAY_ALGORITHMS[name](ctx))
        wall = time.perf_counter() - wall0
        # every thread and every (finished) child process, such as the localization's reader:
        # wall figures depend on the load
        metrics["replay.children_cpu_s"] = _children_cpu_s() - children0
        metrics["replay.cpu_s"] = time.process_time() - cpu0 + metrics["replay.children_cpu_s"]
        metrics["replay.main_thread_cpu_s"] = time.thread_time() - main0  # the serial part
        duration_s = reader.duration_ns / NS_PER_S
        metrics["replay.wall_s"] = wall
        metrics["replay.speed_x_realtime"] = duration_s / wall if wall > 0 else 0.0
        write_metrics(out / METRICS_FILENAME, metrics)  # strict JSON: null for NaN and inf
        print(
            f"replayed {reader.path} ({duration_s:.1f} s) through {', '.join(names)} in {wall:.1f} s ({metrics['replay.speed_x_realtime']:.1f}x real time)"
        )
        for key in sorted(metrics):
            print(f"  {key:<40} {metrics[key]:.6g}")
        print(f"  -> {out / METRICS_FILENAME}")
    return 0


def cli() -> None:
    """The command line: run :func:`main`, turning errors into one line and an exit code."""
    run_cli(lambda: sys.exit(main()))


if __name__ == "__main__":
    cli()
