"""``python -m simlan_data.export RUN --format coco|yolo|mot|aicity --out DIR``: a recording's
instance ground truth as a dataset (issue 25).

    python -m simlan_data.export RUN --format coco --out DIR   DIR/images/*.jpg + DIR/annotations/instances.json
    python -m simlan_data.export RUN --format yolo --out DIR   DIR/images/*.jpg + DIR/labels/*.txt + DIR/data.yaml
    python -m simlan_data.export RUN --format mot --out DIR    DIR/SIMLAN-train/camera_<id>/{img1,gt,seqinfo.ini} + DIR/seqmaps
    python -m simlan_data.export RUN --format aicity --out DIR DIR/ground_truth.txt + DIR/instances.csv
    python -m simlan_data.export RUN --format trajectory --out DIR [--rate-hz 1]
                                                               DIR/trajectory.json (SIMLAN's tracker
                                                               format, any run: apps/trajectory_export.py)

RUN is a run directory, its recording, or the recording's metadata.yaml; the run must have been
recorded with ``cameras.streams=[...,instance]`` and JPEG or PNG colour images. Data flow::

    bag --reader, time order--> per camera and log time: colour image + instance image + boxes
                                (+ the latest /ground_truth/boxes: world positions)
        --complete frame--> writer.add (files written at once) --end--> writer.finish (index files)

Exit 0 only when every promised file exists; 2 for bad arguments (an unknown format, a DIR that
is not empty, a recording without instance ground truth); 1 for a failed export.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from simlan_data.apps.cli import run_cli
from simlan_data.apps.dataset_formats import AnnotatedFrame, CocoWriter, InstanceInfo, YoloWriter
from simlan_data.apps.tracking_formats import BOXES, AiCityWriter, MotWriter
from simlan_data.apps.trajectory_export import FILE_NAME as TRAJECTORY_FILE
from simlan_data.apps.trajectory_export import export_trajectory
from simlan_data.errors import ConfigError, RecordingInputError, RunError
from simlan_data.recording import schema
from simlan_data.recording.messages import stamp_ns_of
from simlan_data.recording.reader import RecordingReader

_STREAMS = ("rgb", "instance", "boxes_2d")
WRITERS: dict[str, type[CocoWriter | YoloWriter | MotWriter | AiCityWriter]] = {
    "coco": CocoWriter,
    "yolo": YoloWriter,
    "mot": MotWriter,
    "aicity": AiCityWriter,
}
BOXED = ("mot", "aicity")  # the formats that take --box
POSE_FORMATS = ("trajectory",)  # ground-truth poses (any run), not instance images


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simlan_data.export",
        description="Export a recording's instance ground truth (stream instance) as a COCO, YOLO, "
        "MOTChallenge or AI City dataset.",
    )
    parser.add_argument("run", help="run directory, recording directory, or its metadata.yaml")
    parser.add_argument(
        "--format", required=True, help=f"dataset format: {' | '.join([*WRITERS, *POSE_FORMATS])}"
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
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def _check_out(out: Path) -> None:
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ConfigError(
            "invalid --out",
            str(out),
            "it exists and is not an empty directory (export never overwrites)",
            "choose a new --out or remove it",
        )


def _camera_topics(reader: RecordingReader) -> dict[str, tuple[str, str]]:
    """topic -> (camera id, stream) for every camera with instance ground truth."""
    out: dict[str, tuple[str, str]] = {}
    for name in reader.topics:
        if name.startswith("/camera_") and name.endswith("/instances/boxes"):
            cid = name[len("/camera_") :].split("/")[0]
            for rgb in ("jpeg", "raw"):
                topics = {
                    **schema.camera_topics(cid, rgb=rgb, depth=None, semantic=None),
                    **schema.instance_topics(cid),
                }
                for stream in _STREAMS:
                    if topics[stream].name in reader.topics:
                        out[topics[stream].name] = (cid, stream)
    if not out:
        raise RecordingInputError(
            "no instance ground truth",
            str(reader.path),
            "the run was recorded without stream instance",
            "record it with cameras.streams=[rgb,semantic,instance]",
        )
    return out


def _jpeg(msg: Any) -> bytes:
    """The JPEG bytes of a colour image message (re-encoded only if the recording holds PNG)."""
    fmt = str(getattr(msg, "format", ""))
    data = np.asarray(msg.data, dtype=np.uint8)
    if "jpeg" in fmt:
        return data.tobytes()
    if not fmt:
        raise RecordingInputError(
            "raw colour images",
            "the recording",
            "export reads compressed colour images",
            "record with recording.rgb_encoding=jpeg or png",
        )
    image = cv2.imdecode(data, cv2.IMREAD_COLOR)
    ok, out = (False, None) if image is None else cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
    if not ok or out is None:
        raise RunError("JPEG encoding failed", "export")
    return out.tobytes()


def frames(reader: RecordingReader, topics: dict[str, tuple[str, str]]) -> Iterator[AnnotatedFrame]:
    """Complete annotated frames in log-time order; a frame's three messages share its log time,
    and its world positions are the 3D boxes of the latest camera tick at or before it."""
    pending: dict[tuple[str, int], dict[str, Any]] = {}
    counts: dict[str, int] = {}
    world: tuple[np.ndarray, np.ndarray] = (np.zeros(0, dtype=np.uint16), np.zeros((0, 3)))
    for m in reader.messages([*topics, schema.INSTANCE_BOXES_3D]):
        if m.topic == schema.INSTANCE_BOXES_3D:
            world = (np.asarray(m.msg.ids), np.asarray(m.msg.centers, dtype=np.float64).reshape(-1, 3))
            continue
        cid, stream = topics[m.topic]
        parts = pending.setdefault((cid, m.stamp_ns), {})
        parts[stream] = m.msg
        if len(parts) < len(_STREAMS):
            continue
        del pending[(cid, m.stamp_ns)]
        for key in [k for k in pending if k[0] == cid and k[1] < m.stamp_ns]:  # (incomplete: left out)
            del pending[key]
        boxes = parts["boxes_2d"]
        instances = cv2.imdecode(np.asarray(parts["instance"].data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        index = counts.get(cid, 0)
        counts[cid] = index + 1
        yield AnnotatedFrame(
            camera_id=cid,
            index=index,
            stamp_ns=stamp_ns_of(boxes.header.stamp),
            jpeg=_jpeg(parts["rgb"]),
            width=int(boxes.width),
            height=int(boxes.height),
            instances=np.asarray(instances, dtype=np.uint16),
            ids=np.asarray(boxes.ids),
            pixels=np.asarray(boxes.pixels),
            visible=np.asarray(boxes.visible, dtype=np.int32).reshape(-1, 4),
            amodal=np.asarray(boxes.amodal, dtype=np.float32).reshape(-1, 4),
            visible_fraction=np.asarray(boxes.visible_fraction),
            truncation=np.asarray(boxes.truncation),
            world_ids=world[0],
            world_centers=world[1],
        )


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.format in POSE_FORMATS:
        _check_out(args.out)
        entries = export_trajectory(args.run, args.out, rate_hz=args.rate_hz)
        print(f"exported {entries} stamps ({args.format}) -> {args.out / TRAJECTORY_FILE}")
        return 0
    if args.format not in WRITERS:
        known = [*WRITERS, *POSE_FORMATS]
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
    _check_out(out)
    with RecordingReader(args.run) as reader:
        topics = _camera_topics(reader)
        table = reader.first(schema.INSTANCES)
        labels = reader.first(schema.SEMANTIC_LABELS)
        if table is None or labels is None:
            raise RecordingInputError(
                "no instance table",
                str(reader.path),
                f"{schema.INSTANCES} is missing",
                "record with stream instance",
            )
        objects = {
            int(i): InstanceInfo(int(i), ns, name, int(c))
            for i, ns, name, c in zip(
                table.msg.ids, table.msg.namespaces, table.msg.names, table.msg.class_ids, strict=True
            )
        }
        class_names = {int(i): str(n) for i, n in zip(labels.msg.ids, labels.msg.names, strict=True)}
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
