"""``python -m simlan_data.replay RECORDING``: inspect and replay a recording without the simulator.

    python -m simlan_data.replay RECORDING --info
    python -m simlan_data.replay RECORDING --recover     (same as python -m simlan_data.recover)
    python -m simlan_data.replay RECORDING --out DIR [--algorithms localization,...] [--set KEY=VALUE ...]

RECORDING is a recording directory (the bag), its run directory, or its metadata.yaml. Replay
writes ``DIR/metrics.json`` (dotted metric names) and each algorithm's artifacts into DIR.
"""

from __future__ import annotations

import argparse
import collections.abc
import dataclasses
import json
import os
import sys
import time
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

from simlan_data.algorithms import registry
from simlan_data.apps.cli import run_cli
from simlan_data.apps.outputs import make_dirs, remove_if_empty
from simlan_data.config.legacy import with_algorithms
from simlan_data.constants import METRICS_FILENAME, NS_PER_S
from simlan_data.errors import EXIT_BAD_INPUT, ConfigError, SimlanError
from simlan_data.evaluation import replay_algorithms  # noqa: F401 - registers the algorithms
from simlan_data.evaluation.birdseye_replay import birdseye_settings
from simlan_data.evaluation.localization_replay import selected_localizer
from simlan_data.evaluation.posemap_replay import selected_mapper
from simlan_data.evaluation.replay import REPLAY_ALGORITHMS, ReplayContext
from simlan_data.evaluation.safety_inputs import selected_safety
from simlan_data.metrics_io import write_metrics
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
        if not key.strip():
            raise ConfigError(
                f"invalid --set {item!r}", "replay arguments", "the key is empty", "e.g. --set method=pnp"
            )
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


# what each replay algorithm builds from the --set options: the typed config of the algorithm in
# this role (the recording's, or the one the option of the role's name selects), and its check
OPTION_ROLES = {"localization": "localizer", "safety": "safety", "birdseye": "stitcher", "posemap": "posemap"}
OPTION_CHECKS: dict[str, Callable[[ReplayContext], object]] = {
    "localization": lambda ctx: selected_localizer(ctx.config, ctx.options),
    "safety": lambda ctx: selected_safety(ctx.config, dict(ctx.options), where="replay --set"),
    "birdseye": birdseye_settings,
    "posemap": lambda ctx: selected_mapper(ctx.config, ctx.options),
}


def check_options(ctx: ReplayContext, names: list[str]) -> None:
    """Every ``--set KEY=VALUE`` of the chosen algorithms checked before anything is written: its
    type against the typed config field it sets (``hold_s=abc``: a float field), then the
    algorithm's own checks (unknown keys, ranges).

    Raises:
        ConfigError: the first option that does not fit, naming the key, the value and the type.
    """
    for name in names:
        role = OPTION_ROLES.get(name)
        if role is not None:
            chosen = ctx.options.get(role)
            recorded = registry.selection(with_algorithms(ctx.config), role)[0]
            spec = registry.resolve(role, recorded if chosen is None else str(chosen), where="replay --set")
            for key, value in ctx.options.items():
                hint = _field_type(spec.config_class, key)
                if hint is not None and not _fits(value, hint):
                    example = _default(spec.config_class, key)
                    raise ConfigError.invalid(
                        key,
                        value,
                        f"expected {_type_name(hint)} ({spec.config_class.__name__}.{key}), got {type(value).__name__}",
                        f"e.g. --set {key}={example}"
                        if example is not None
                        else f"give {key} a {_type_name(hint)}",
                        where="replay --set",
                    )
        check = OPTION_CHECKS.get(name)
        if check is not None:
            check(ctx)


def _field_type(cls: type, key: str) -> Any:
    """The type hint of the (dotted) field ``key`` of dataclass ``cls``; None if it has none."""
    for i, part in enumerate(key.split(".")):
        if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
            return None
        try:
            hints = typing.get_type_hints(cls)
        except Exception:  # an annotation that does not resolve: the config checks it
            return None
        if part not in hints:
            return None
        if i == key.count("."):
            return hints[part]
        cls = hints[part]
    return None


def _default(cls: type, key: str) -> Any:
    """The default of the (dotted) field ``key``, as JSON, for the hint; None if it has none."""
    *path, last = key.split(".")
    for part in path:
        fields = {f.name: f for f in dataclasses.fields(cls)}
        cls = typing.get_type_hints(cls)[part] if part in fields else cls
    field = {f.name: f for f in dataclasses.fields(cls)}.get(last)
    if field is None or field.default is dataclasses.MISSING or isinstance(field.default, (list, dict)):
        return None
    return json.dumps(field.default)


def _fits(value: Any, hint: Any) -> bool:
    """Whether a ``--set`` value (parsed as JSON) has the type of the field; unknown types fit
    (the config checks them)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_fits(value, a) for a in args)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is str:
        return not isinstance(value, (list, dict, bool)) and value is not None
    if origin is typing.Literal:
        return value in args
    if origin in (list, tuple, collections.abc.Sequence) or hint in (list, tuple):
        if not isinstance(value, list):
            return False
        if origin is tuple and args and args[-1] is not Ellipsis:
            return len(value) == len(args) and all(_fits(v, a) for v, a in zip(value, args))
        return not args or all(_fits(v, args[0]) for v in value)
    if origin is dict or hint is dict or (isinstance(hint, type) and dataclasses.is_dataclass(hint)):
        return isinstance(value, dict)
    return True


def _type_name(hint: Any) -> str:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " or ".join("null" if a is type(None) else _type_name(a) for a in typing.get_args(hint))
    return (
        hint.__name__
        if isinstance(hint, type) and not typing.get_args(hint)
        else str(hint).replace("typing.", "")
    )


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
        reader.check_types()  # every topic the schema names (a replay reads most of them)
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
        if out.exists() and not out.is_dir():
            raise ConfigError(
                "invalid --out", str(out), "it exists and is not a directory", "choose a directory"
            )
        ctx = ReplayContext(reader, out, options)
        check_options(ctx, names)  # all of them, before --out exists
        created = make_dirs(out)
        try:
            return _replay(ctx, names)
        except SimlanError as err:
            if err.exit_code == EXIT_BAD_INPUT:  # rejected input leaves nothing behind
                remove_if_empty(created)
            raise


def _replay(ctx: ReplayContext, names: list[str]) -> int:
    """Run the algorithms, write metrics.json and print them."""
    reader, out = ctx.reader, ctx.out_dir
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
