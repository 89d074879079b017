"""Benchmark of the depth and label encodings that viewers can show (issue 22).

    python benchmarks/image_encodings.py [--repeats 3] [--duration 10] [--frames 20] [--json FILE]

Two measurements:

1. Real runs of the default scenario (``--duration`` simulated seconds, its 11 cameras at
   960x540, depth and labels at 1 Hz), ``--repeats`` times per depth encoding, the encodings
   interleaved (``recording.depth_encoding`` = png (compressedDepth, the baseline), 16UC1, raw
   (32FC1)): recording MiB, MiB per simulated second, the real-time factor and the CPU time
   of the run's process per simulated second (user + system: the real-time factor moves with
   whatever else the machine runs, the CPU time much less); medians.
2. Per frame, on the depth and label frames of the baseline's recording (decoded back:
   millimetres, the in-process depth to 0.5 mm): what each encoding costs where the recorder
   pays it: the encode (a PNG, or the conversion of the raw option), the CDR serialization and
   the bag's zstd chunk compression at the default level of that message, and what the message
   adds to the bag (its zstd-compressed size); per stage, each frame's fastest of the repeats
   (the least disturbed by other work on the machine), averaged over the frames. The labels: the mono8 PNG of before
   against the palette PNG.

Prints markdown; writes the numbers as JSON (default
``benchmarks/results/image_encodings_<date>.json``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine, run_cli, table

ENCODINGS = {
    "png": "compressedDepth PNG, 16UC1 mm (the baseline)",
    "16UC1": "sensor_msgs/Image 16UC1 mm",
    "raw": "sensor_msgs/Image 32FC1 m, NaN = no return",
}


def runs(out: Path, repeats: int, duration: float) -> dict[str, list[dict[str, float]]]:
    results: dict[str, list[dict[str, float]]] = {e: [] for e in ENCODINGS}
    for i in range(repeats):
        for enc in ENCODINGS:
            run_dir = out / f"{enc}_{i}"
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            proc = run_cli(
                f"duration_s={duration:g}",
                f"recording.depth_encoding={enc}",
                "progress=false",
                f"hydra.run.dir={run_dir}",
            )
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            if proc.returncode != 0:
                raise SystemExit(proc.stderr)
            metrics = json.loads((run_dir / "metrics.json").read_text())
            mib = (run_dir / "recording" / "recording.mcap").stat().st_size / 2**20
            results[enc].append(
                {
                    "mib": mib,
                    "mib_per_s": mib / duration,
                    "rtf": metrics["sim.rtf"],
                    "cpu_s_per_s": cpu_s / duration,
                }
            )
            print(
                f"  {enc} #{i}: {mib:.1f} MiB, RTF {metrics['sim.rtf']:.2f}, CPU {cpu_s:.1f} s",
                file=sys.stderr,
            )
    return results


def frames(recording: Path, count: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Up to ``count`` depth frames (metres, float32) and label frames (ids) of a recording."""
    from simlan_data.recording.codecs import decode_compressed, decode_raw
    from simlan_data.recording.reader import RecordingReader

    depth, labels = [], []
    with RecordingReader(recording) as reader:
        topics = [t for t in reader.topics if "/depth/" in t or "/semantic/" in t]
        for m in reader.messages(topics):
            if m.msgtype.endswith("CompressedImage"):
                image = decode_compressed(m.msg.format, m.msg.data)
            else:
                image = decode_raw(m.msg.encoding, m.msg.height, m.msg.width, m.msg.step, m.msg.data)
            (depth if "/depth/" in m.topic else labels).append(image)
    step_d, step_l = max(1, len(depth) // count), max(1, len(labels) // count)
    return depth[::step_d][:count], labels[::step_l][:count]


def per_frame(depth: list[np.ndarray], labels: list[np.ndarray], repeats: int) -> dict[str, dict[str, float]]:
    from simlan_data.recording import messages as M
    from simlan_data.recording import schema
    from simlan_data.recording.codecs import (
        MONO_LABELS_FORMAT,
        encode_depth,
        encode_labels,
        encode_png,
        raw_depth,
    )
    from simlan_data.recording.writer import RecordingWriter, zstd

    level = 2  # recording.compression_level's default
    with tempfile.TemporaryDirectory() as tmp, RecordingWriter(Path(tmp) / "bag") as writer:
        image_t = schema.Topic("/d", schema.IMAGE_TYPE, "")
        compressed_t = schema.Topic("/c", schema.COMPRESSED_IMAGE_TYPE, "")
        cases = {
            "depth/png": (
                lambda d: M.compressed_image(0, "f", *encode_depth(d)),
                compressed_t,
                depth,
            ),
            "depth/16UC1": (lambda d: M.raw_image(0, "f", raw_depth(d, "16UC1")), image_t, depth),
            "depth/raw": (lambda d: M.raw_image(0, "f", raw_depth(d, "32FC1")), image_t, depth),
            "labels/mono8 png (before)": (
                lambda a: M.compressed_image(0, "f", MONO_LABELS_FORMAT, encode_png(a)),
                compressed_t,
                labels,
            ),
            "labels/palette png": (
                lambda a: M.compressed_image(0, "f", *encode_labels(a)),
                compressed_t,
                labels,
            ),
        }
        out: dict[str, dict[str, float]] = {}
        for name, (build, topic, images) in cases.items():
            writer.serialize(topic, build(images[0]))  # warm-up
            times = np.full((repeats, len(images), 3), np.inf)  # (repeat, frame, stage)
            for r in range(repeats):
                sizes, bag = [], []
                for f, image in enumerate(images):
                    t0 = time.perf_counter()
                    msg = build(image)
                    t1 = time.perf_counter()
                    cdr = writer.serialize(topic, msg)
                    t2 = time.perf_counter()
                    packed = zstd.compress(cdr, level=level)
                    t3 = time.perf_counter()
                    times[r, f] = (t1 - t0, t2 - t1, t3 - t2)
                    sizes.append(len(cdr))
                    bag.append(len(packed))
            best = times.min(axis=0).mean(axis=0) * 1e3  # each frame's fastest, averaged
            out[name] = {
                "encode_ms": float(best[0]),
                "serialize_ms": float(best[1]),
                "zstd_ms": float(best[2]),
                "total_ms": float(best.sum()),
                "message_kib": float(np.mean(sizes)) / 1024,
                "in_bag_kib": float(np.mean(bag)) / 1024,
            }
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--frames", type=int, default=20)
    today = datetime.date.today().isoformat()
    p.add_argument(
        "--json", type=Path, default=REPO / "benchmarks" / "results" / f"image_encodings_{today}.json"
    )
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        run_results = runs(Path(tmp), args.repeats, args.duration)
        depth, labels = frames(Path(tmp) / "png_0" / "recording", args.frames)
    costs = per_frame(depth, labels, max(5, args.repeats))
    rows = []
    for enc, label in ENCODINGS.items():
        r = run_results[enc]
        c = costs[f"depth/{enc}"]
        rows.append(
            [
                f"`{enc}`: {label}",
                f"{statistics.median(x['mib_per_s'] for x in r):.2f}",
                f"{statistics.median(x['rtf'] for x in r):.2f}",
                f"{statistics.median(x['cpu_s_per_s'] for x in r):.2f}",
                f"{c['encode_ms']:.2f} + {c['serialize_ms']:.2f} + {c['zstd_ms']:.2f} = {c['total_ms']:.2f}",
                f"{c['in_bag_kib']:.0f}",
            ]
        )
    print(f"Machine: {machine()}\n")
    print(
        f"Default scenario, {args.duration:g} s, 11 cameras 960x540, depth and labels at 1 Hz; "
        f"median of {args.repeats} runs per encoding, interleaved:\n"
    )
    print(
        table(
            [
                "depth encoding",
                "bag MiB per simulated s",
                "real-time factor",
                "CPU s per simulated s",
                "ms per depth frame: encode + CDR + zstd",
                "KiB per depth frame in the bag",
            ],
            rows,
        )
    )
    print()
    print(
        table(
            ["labels", "ms per frame: encode + CDR + zstd", "KiB per frame in the bag"],
            [
                [
                    name.split("/", 1)[1],
                    f"{c['encode_ms']:.2f} + {c['serialize_ms']:.2f} + {c['zstd_ms']:.2f} = {c['total_ms']:.2f}",
                    f"{c['in_bag_kib']:.1f}",
                ]
                for name, c in costs.items()
                if name.startswith("labels/")
            ],
        )
    )
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(
        json.dumps(
            {
                "machine": machine(),
                "date": datetime.date.today().isoformat(),
                "command": "python benchmarks/image_encodings.py "
                f"--repeats {args.repeats} --duration {args.duration:g} --frames {args.frames}",
                "runs": run_results,
                "per_frame": costs,
            },
            indent=2,
        )
        + "\n"
    )
    print(f"\n-> {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
