"""``python -m simlan_data.export RUN --format coco|yolo|mot|aicity --out DIR``: a recording's
instance ground truth as a dataset (issue 25).

    python -m simlan_data.export RUN --format coco --out DIR   DIR/images/*.jpg + DIR/annotations/instances.json
    python -m simlan_data.export RUN --format yolo --out DIR   DIR/images/*.jpg + DIR/labels/*.txt + DIR/data.yaml
    python -m simlan_data.export RUN --format mot --out DIR    DIR/SIMLAN-train/camera_<id>/{img1,gt,seqinfo.ini} + DIR/seqmaps
    python -m simlan_data.export RUN --format aicity --out DIR DIR/ground_truth.txt + DIR/instances.csv
    python -m simlan_data.export RUN --format trajectory --out DIR [--rate-hz 1]
                                                               DIR/trajectory.json (SIMLAN's tracker
                                                               format, any run: apps/trajectory_export.py)
    python -m simlan_data.export RUN --format lerobot --out DIR [--agent NS] [--task TEXT]
                                                               a LeRobot v3.0 dataset of one agent, cameras
                                                               as videos (any run: apps/lerobot_export.py)

RUN is a run directory, its recording, or the recording's metadata.yaml; the run must have been
recorded with ``cameras.streams=[...,instance]`` and JPEG or PNG colour images. Data flow::

    bag --instance_truth.frames (the reader the tracking metrics share)--> complete annotated frames
        --> writer.add (files written at once) --end--> writer.finish (index files)

Exit 0 only when every promised file exists; 2 for bad arguments (an unknown format, a DIR that
is not empty, a recording without instance ground truth); 1 for a failed export.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from simlan_data.apps.cli import run_cli
from simlan_data.apps.dataset_formats import CocoWriter, YoloWriter
from simlan_data.apps.export_shards import check_out, export_shards, sweep_runs
from simlan_data.apps.lerobot_export import export_lerobot
from simlan_data.apps.tracking_formats import BOXES, AiCityWriter, MotWriter
from simlan_data.apps.trajectory_export import FILE_NAME as TRAJECTORY_FILE
from simlan_data.apps.trajectory_export import export_trajectory
from simlan_data.errors import ConfigError, RunError
from simlan_data.evaluation.instance_truth import camera_topics, frames, instance_table
from simlan_data.recording.reader import RecordingReader

WRITERS: dict[str, type[CocoWriter | YoloWriter | MotWriter | AiCityWriter]] = {
    "coco": CocoWriter,
    "yolo": YoloWriter,
    "mot": MotWriter,
    "aicity": AiCityWriter,
}
BOXED = ("mot", "aicity")  # the formats that take --box
POSE_FORMATS = ("trajectory",)  # ground-truth poses (any run), not instance images
ROBOT_FORMATS = ("lerobot",)  # an agent's images, states and commands (any run)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simlan_data.export",
        description="Export a recording's instance ground truth (stream instance) as a COCO, YOLO, "
        "MOTChallenge or AI City dataset, its ground-truth poses as a tracker trajectory, or an agent's "
        "cameras, states and commands as a LeRobot dataset.",
    )
    parser.add_argument("run", help="run directory, recording directory, or its metadata.yaml")
    parser.add_argument(
        "--format",
        required=True,
        help=f"dataset format: {' | '.join([*WRITERS, *POSE_FORMATS, *ROBOT_FORMATS])}",
    )
    parser.add_argument("--out", type=Path, required=True, help="new or empty output directory")
    parser.add_argument(
        "--box",
        default="visible",
        help="mot and aicity: the 2D box written, visible (the mask's bounds, default) or amodal "
        "(the 3D box projected, clipped to the image)",
    )
    parser.add_argument(
        "--rate-hz", type=float, default=1.0, help="trajectory: entries per simulated second (default 1)"
    )
    parser.add_argument(
        "--agent", help="lerobot: the agent whose state and commands are written (default: the first)"
    )
    parser.add_argument(
        "--task", help="lerobot: the episode's task string (default: drive AGENT to its goals)"
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def _without(argv: list[str], *flags: str) -> list[str]:
    """``argv`` without ``flags`` and their values (``--flag VALUE`` or ``--flag=VALUE``)."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a in flags:
            skip = True
        elif not any(a.startswith(f + "=") for f in flags):
            out.append(a)
    return out


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    runs = sweep_runs(Path(args.run))
    if runs is not None:  # a sweep: one shard per run (apps/export_shards.py)
        given = [a for a in (sys.argv[1:] if argv is None else argv) if a not in (args.run,)]
        return export_shards(runs, args.out, args.format, _without(given, "--format", "--out"), main)
    if args.format in POSE_FORMATS:
        check_out(args.out)
        entries = export_trajectory(args.run, args.out, rate_hz=args.rate_hz)
        print(f"exported {entries} stamps ({args.format}) -> {args.out / TRAJECTORY_FILE}")
        return 0
    if args.format in ROBOT_FORMATS:
        check_out(args.out)
        done = export_lerobot(args.run, args.out, agent=args.agent, task=args.task)
        left = (
            f", {done.incomplete_ticks} ticks without every camera left out" if done.incomplete_ticks else ""
        )
        print(
            f"exported {done.frames} frames at {done.fps} fps of {done.agent} ({args.format}{left}) -> {args.out}"
        )
        return 0
    if args.format not in WRITERS:
        known = [*WRITERS, *POSE_FORMATS, *ROBOT_FORMATS]
        raise ConfigError(
            f"invalid --format {args.format!r}",
            "export arguments",
            f"known: {', '.join(known)}",
            f"use --format {' or --format '.join(known)}",
        )
    if args.box not in BOXES or (args.box != "visible" and args.format not in BOXED):
        raise ConfigError(
            f"invalid --box {args.box!r}",
            "export arguments",
            f"known: {', '.join(BOXES)}; amodal only with --format {' or '.join(BOXED)}",
            "leave --box out or use --box visible",
        )
    out: Path = args.out
    check_out(out)
    with RecordingReader(args.run) as reader:
        topics = camera_topics(reader)
        objects, class_names = instance_table(reader)
        out.mkdir(parents=True, exist_ok=True)
        options = {"box": args.box} if args.format in BOXED else {}
        writer = WRITERS[args.format](out, objects, class_names, **options)
        try:
            for frame in frames(reader, topics):
                writer.add(frame)
            writer.finish({"description": "simlan_data instance ground truth", "recording": reader.path.name})
        except OSError as err:
            raise RunError(
                "export failed", str(out), str(err), "check the disk and retry into a new --out"
            ) from err
    missing = [p for p in writer.files if not p.is_file()]
    if missing:
        raise RunError(
            "export incomplete",
            str(out),
            f"{len(missing)} promised files are missing, e.g. {missing[0]}",
            "retry into a new --out",
        )
    print(
        f"exported {writer.image_count} images, {writer.annotation_count} annotations ({args.format}) -> {out}"
    )
    return 0


def cli() -> None:
    """The command line: run :func:`main`, turning errors into one line and an exit code."""
    run_cli(lambda: sys.exit(main()))


if __name__ == "__main__":
    cli()
