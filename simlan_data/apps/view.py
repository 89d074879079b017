"""``python -m simlan_data.view RECORDING``: show a recording in Rerun.

    python -m simlan_data.view RECORDING --save run.rrd     write a Rerun file (headless), open it
                                                              with `rerun run.rrd` anywhere
    python -m simlan_data.view RECORDING                   spawn the Rerun viewer (needs a display)

RECORDING is a recording directory, its run directory or its metadata.yaml. What is shown and
where: :mod:`simlan_data.viz.rerun_export` (entity tree) and :mod:`simlan_data.viz.blueprint`.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from simlan_data.apps.cli import run_cli
from simlan_data.apps.outputs import make_dirs, remove_if_empty
from simlan_data.errors import EXIT_BAD_INPUT, ConfigError, RunError, SimlanError


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m simlan_data.view", description="Show a simlan_data recording in Rerun."
    )
    p.add_argument("recording", help="recording directory (or its run directory, or metadata.yaml)")
    p.add_argument(
        "--save", type=Path, metavar="FILE.rrd", help="write a .rrd file instead of spawning a viewer"
    )
    p.add_argument(
        "--image-every",
        type=int,
        default=1,
        metavar="N",
        help="log every N-th image of each camera (default 1)",
    )
    p.add_argument(
        "--foxglove-layout",
        type=Path,
        metavar="FILE.json",
        help="write a Foxglove layout for this recording's cameras and agents instead (docs/foxglove.md)",
    )
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.foxglove_layout is not None:
        return write_foxglove_layout(args.recording, args.foxglove_layout)
    from simlan_data.viz.rerun_export import export  # rerun and the readers: only once the arguments are good

    save: Path | None = args.save
    created: list[Path] = []
    if save is not None:
        if save.suffix != ".rrd":
            raise ConfigError(
                f"invalid --save {save}", "arguments", "a Rerun file ends in .rrd", "e.g. --save run.rrd"
            )
        if save.exists():
            raise ConfigError(
                "output exists", str(save), "inspect never overwrites a file", "choose another --save"
            )
        created = make_dirs(save.parent)
    else:
        if sys.platform.startswith("linux") and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        ):
            raise ConfigError(
                "no display for the Rerun viewer",
                "this session",
                "neither DISPLAY nor WAYLAND_DISPLAY is set",
                "write a file with --save run.rrd and open it with `rerun run.rrd` where there is a display",
            )
        # the viewer executable ships with rerun-sdk next to this interpreter
        os.environ["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])
    t0 = time.perf_counter()
    try:
        logged = export(args.recording, save=save, spawn=save is None, image_every=args.image_every)
    except SimlanError as err:
        if err.exit_code == EXIT_BAD_INPUT:  # a bad recording leaves nothing behind
            remove_if_empty(created)
        raise
    except (RuntimeError, OSError) as err:
        if save is None:
            first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
            raise RunError(
                "cannot start the Rerun viewer",
                "this session",
                f"{type(err).__name__}: {first}",
                "write a file with --save run.rrd and open it with `rerun run.rrd` where there is a display",
            ) from err
        raise
    wall = time.perf_counter() - t0
    where = f"{save} ({save.stat().st_size / 2**20:.1f} MiB)" if save is not None else "the Rerun viewer"
    print(
        f"inspect: {len(logged['cameras'])} cameras, {logged['images']} colour, {logged['depth_images']} depth and "
        f"{logged['semantic_images']} label images, {len(logged['agents'])} agents, "
        f"{logged['layout_parts']} layout parts, {len(logged['markers'])} marker topics, {len(logged['events'])} event topics "
        f"-> {where} in {wall:.1f} s"
    )
    if save is not None:
        print(f"  open it with: rerun {save}")
    return 0


def write_foxglove_layout(recording: str, out: Path) -> int:
    """``--foxglove-layout FILE.json``: the Foxglove layout for a recording's topics."""
    from simlan_data.recording.reader import RecordingReader
    from simlan_data.viz.foxglove_layout import build_layout, write_layout

    if out.suffix != ".json" or out.exists():
        raise ConfigError(
            f"invalid --foxglove-layout {out}",
            "arguments",
            "exists (never overwritten)" if out.exists() else "a Foxglove layout file ends in .json",
            "e.g. --foxglove-layout layout.json, a new file",
        )
    with RecordingReader(recording) as reader:
        layout = build_layout(reader.topics)
        where = reader.path
    make_dirs(out.parent)
    write_layout(out, layout)
    print(f"foxglove layout for {where} -> {out} (Foxglove: Layouts > Import from file)")
    return 0


def cli() -> None:
    """The command line: run :func:`main`, turning errors into one line and an exit code."""
    run_cli(lambda: sys.exit(main()))


if __name__ == "__main__":
    cli()
