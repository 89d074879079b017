"""Benchmark of "the spine" (issue 2): renderer speed, encodings, the default run, recording cost.

    python benchmarks/spine.py [--quick] [--only SECTION]

Prints markdown for docs/benchmarks/spine.md. Every figure comes from this one run, baselines beside them.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import zlib
from pathlib import Path
from typing import Any

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import best_of, machine, run_cli, table
from simlan_data.geometry.calibration import load_calibration
from simlan_data.recording.codecs import encode_depth, encode_labels, encode_png, encode_rgb
from simlan_data.sim.agents import AGENT_TYPES, DiffDriveAgent
from simlan_data.sim.dynamic_layer import MovedAgents
from simlan_data.sim.pybullet_client import connect
from simlan_data.sim.rendering import CameraRenderer, LabelTable
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import build_world
from simlan_data.world.layout import load_layout

CAMERAS = [str(c) for c in range(160, 171)]


def _world(backend: str):
    client = connect(backend)
    with tempfile.TemporaryDirectory() as tmp:
        world = build_world(client.id, load_layout("warehouse_layout.csv", "default"), {}, mesh_dir=Path(tmp))
    labels = LabelTable()
    for body, label in world.labels.items():
        labels.set(body, label)
    return client, labels


def renderer_speed(frames: int) -> tuple[str, dict]:
    """Frames per second per camera, RGB + depth + segmentation, 960x540 distorted, full warehouse."""
    rows, raw = [], {}
    for backend in ("egl", "tiny"):
        client, labels = _world(backend)
        cams = [load_calibration(c).camera.scaled(960, 540) for c in ("161", "163", "165")]
        full = [CameraRenderer(client, c, labels, layered=False) for c in cams]
        t_full = best_of(lambda full=full: [r.render() for r in full for _ in range(frames)], 1) / (
            frames * len(full)
        )
        entry = {"full_ms": t_full * 1e3}
        if backend == "egl":
            layered = [CameraRenderer(client, c, labels, layered=True) for c in cams]
            for r in layered:
                r.render_static()
            agent = DiffDriveAgent(
                client.id, "robot_agent_1", AGENT_TYPES["pallet_truck"], pose=[-2.0, 0.4, 0.0], marker_id=1
            )
            labels.set(agent.body, agent.label)
            agent.apply_command(1.0, 0.1)
            moving = MovedAgents([agent])
            t0 = time.perf_counter()
            n = 0
            for _ in range(frames):
                for _ in range(48):
                    pb.stepSimulation(physicsClientId=client.id)
                moved = moving.boxes()
                for r in layered:
                    r.render(moved)
                    n += 1
            entry["layered_ms"] = (time.perf_counter() - t0) / n * 1e3
        client.disconnect()
        raw[backend] = entry
        rows.append(
            [
                backend.upper() if backend == "egl" else "TinyRenderer",
                f"{1e3 / entry['full_ms']:.1f}",
                f"{entry['full_ms']:.0f}",
                f"{1e3 / entry['layered_ms']:.0f} ({entry['layered_ms']:.1f} ms)"
                if "layered_ms" in entry
                else "n/a",
            ]
        )
    md = table(
        [
            "renderer",
            "full render, frames/s per camera",
            "ms/frame",
            "layered, moving truck in view: frames/s (ms)",
        ],
        rows,
    )
    return md, raw


def _libpng(image: np.ndarray) -> bytes:
    """The recorder's PNGs before ISA-L: OpenCV's encoder (libpng, zlib level 1, "up" filter)."""
    params = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP]
    return cv2.imencode(".png", image, params)[1].tobytes()


def encodings(frames: int) -> tuple[str, dict]:
    """Bytes per camera-minute (5 Hz) and encode time per stream and encoding, on rendered frames."""
    client, labels = _world("egl")
    images = []
    for cid in CAMERAS:
        r = CameraRenderer(client, load_calibration(cid).camera.scaled(960, 540), labels, layered=False)
        images.append(r.render())
    client.disconnect()
    cases = {
        ("rgb", "jpeg q85 (default)"): lambda im: encode_rgb(im.rgb, "jpeg", jpeg_quality=85)[1],
        ("rgb", "jpeg q95"): lambda im: encode_rgb(im.rgb, "jpeg", jpeg_quality=95)[1],
        ("rgb", "png"): lambda im: encode_rgb(im.rgb, "png")[1],
        ("rgb", "png via OpenCV (libpng + zlib 1, the baseline)"): lambda im: _libpng(
            cv2.cvtColor(im.rgb, cv2.COLOR_RGB2BGR)
        ),
        ("rgb", "raw rgb8"): lambda im: im.rgb.tobytes(),
        ("depth", "png 16UC1 mm (default)"): lambda im: encode_depth(im.depth_m)[1],
        ("depth", "png via OpenCV (libpng + zlib 1, the baseline)"): lambda im: _libpng(
            np.rint(np.clip(im.depth_m, 0.0, 65.535) * 1000.0).astype(np.uint16)
        ),
        ("depth", "raw 32FC1"): lambda im: im.depth_m.tobytes(),
        ("semantic", "png mono8 (default)"): lambda im: encode_labels(im.labels)[1],
        ("semantic", "png via OpenCV (libpng + zlib 1, the baseline)"): lambda im: _libpng(im.labels),
        ("semantic", "raw mono8"): lambda im: im.labels.tobytes(),
    }
    rows, raw = [], {}
    for (stream, name), fn in cases.items():
        fn(images[0])  # warm-up
        t0 = time.perf_counter()
        sizes = [len(fn(im)) for im in images for _ in range(frames)]
        ms = (time.perf_counter() - t0) / len(sizes) * 1e3
        kib = float(np.mean(sizes)) / 1024
        raw[f"{stream}/{name}"] = {"kib_per_frame": kib, "ms_per_frame": ms}
        rows.append([stream, name, f"{kib:.1f}", f"{kib * 300 / 1024:.1f}", f"{ms:.2f}"])
    return table(
        ["stream", "encoding", "KiB/frame", "MiB per camera-minute at 5 Hz", "encode ms/frame"], rows
    ), raw


CHUNK_RUNS = {
    "default scenario, 20 s (most cameras unchanged)": ["duration_s=20", "progress=false"],
    "12 cameras, 4 robots, all streams at 5 Hz, 4 s": [
        "experiment=rtf",
        "cameras.count=12",
        "streams=rgbds_full",
        "duration_s=4",
    ],
}


def chunks(out_dir: Path, repeats: int) -> tuple[str, dict]:
    """The recording's chunk compression and checksum on the chunks of two real recordings:
    zstd's levels, rosbags' level 3 the baseline."""
    mds, raws = [], {}
    for name, overrides in CHUNK_RUNS.items():
        md, raws[name] = _chunks(out_dir / str(len(raws)), overrides, repeats)
        mds.append(f"{name}:\n\n{md}")
    return "\n\n".join(mds), raws


def _chunks(run_dir: Path, overrides: list[str], repeats: int) -> tuple[str, dict]:
    from isal import isal_zlib
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    from simlan_data.recording.writer import zstd

    proc = run_cli(*overrides, "recording.compression=none", f"hydra.run.dir={run_dir}")
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    with (run_dir / "recording" / "recording.mcap").open("rb") as f:
        raws = [r.data for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    total = sum(map(len, raws))
    cases: dict[str, Any] = {
        "zstd level 3 (rosbags' default, the baseline)": lambda b: zstd.compress(b, level=3),
        "zstd level 2 (default)": lambda b: zstd.compress(b, level=2),
        "zstd level 1": lambda b: zstd.compress(b, level=1),
        "zstd level -1": lambda b: zstd.compress(b, level=-1),
        "CRC32, zlib (the baseline)": zlib.crc32,
        "CRC32, ISA-L (default)": isal_zlib.crc32,
    }
    rows, raw = [], {"chunks": len(raws), "mib": total / 2**20}
    for name, fn in cases.items():
        out = [fn(b) for b in raws]
        seconds = best_of(lambda fn=fn: [fn(b) for b in raws], repeats)
        ratio = sum(len(o) for o in out) / total if isinstance(out[0], bytes) else None
        raw[name] = {"mb_per_s": total / seconds / 1e6, "ratio": ratio}
        rows.append([name, "-" if ratio is None else f"{ratio:.3f}", f"{total / seconds / 1e6:.0f}"])
    md = table(["chunk step", "compressed / raw", "MB/s"], rows)
    return md + f"\n\nOver {len(raws)} chunks, {total / 2**20:.0f} MiB uncompressed.", raw


def changed_frames(out_dir: Path, seconds: float) -> tuple[str, dict]:
    """The stream encoders (only changed rows again) against encoding every changed frame whole,
    on the changed frames of a real 12-camera recording, in recording order per camera."""
    from simlan_data.recording.codecs import decode_compressed, depth_to_mm
    from simlan_data.recording.incremental import BandedJpeg, BandedPng
    from simlan_data.recording.reader import RecordingReader

    run_dir = out_dir / "changed"
    overrides = ["experiment=rtf", "cameras.count=12", "streams=rgbds_full", f"duration_s={seconds:g}"]
    proc = run_cli(*overrides, f"hydra.run.dir={run_dir}")
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    streams: dict[str, dict[str, list[np.ndarray]]] = {"rgb": {}, "depth": {}}
    for m in RecordingReader(run_dir / "recording").messages():
        fmt = getattr(m.msg, "format", "")
        stream = "rgb" if "jpeg" in fmt else "depth" if "compressedDepth" in fmt else None
        if stream is None:
            continue
        image = decode_compressed(fmt, m.msg.data)
        frames = streams[stream].setdefault(m.topic, [])
        if stream == "depth":
            image = depth_to_mm(image)
        if not frames or not np.array_equal(frames[-1], image):  # (unchanged frames reuse bytes)
            frames.append(image)
    cases: dict[str, tuple[str, Any, Any]] = {
        "rgb: jpeg q85, every changed frame whole (the baseline)": (
            "rgb",
            lambda: lambda im: encode_rgb(im, "jpeg", jpeg_quality=85)[1],
            None,
        ),
        "rgb: jpeg q85, changed MCU rows only (default)": (
            "rgb",
            lambda: BandedJpeg(jpeg_quality=85).encode,
            "rgb: jpeg q85, every changed frame whole (the baseline)",
        ),
        "depth: png, every changed frame whole (the baseline)": ("depth", lambda: encode_png, None),
        "depth: png, changed bands of 32 rows only (default)": (
            "depth",
            lambda: BandedPng().encode,
            "depth: png, every changed frame whole (the baseline)",
        ),
    }
    rows, raw, outputs = [], {}, {}
    for name, (stream, make, baseline) in cases.items():
        topics = streams[stream]
        n = sum(len(f) for f in topics.values())

        def run(make: Any = make, topics: Any = topics) -> list[bytes]:
            out = []
            for frames in topics.values():
                encode = make()  # a new encoder per camera, as the recorder has
                out += [encode(im) for im in frames]
            return out

        outputs[name] = run()
        seconds_all = best_of(run, 3)
        size = sum(map(len, outputs[name]))
        if baseline is None:
            same = "-"
        elif outputs[name] == outputs[baseline]:
            same = "same bytes"
        else:  # PNG: another deflate stream of the same rows
            frames = [im for f in topics.values() for im in f]
            decoded = [cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_UNCHANGED) for b in outputs[name]]
            same = "same pixels" if all(map(np.array_equal, decoded, frames)) else "DIFFERENT"
        raw[name] = {"frames": n, "ms_per_frame": seconds_all / n * 1e3, "bytes": size, "same_bytes": same}
        rows.append([name, str(n), f"{seconds_all / n * 1e3:.2f}", f"{size / n / 1024:.0f}", same])
    md = table(
        ["stream: encoder", "changed frames", "ms/frame", "KiB/frame", "output against the baseline's"], rows
    )
    return md, raw


def default_run(out_dir: Path, repeat: int) -> tuple[str, dict]:
    """The default scenario end to end, with recording and without (the baseline), interleaved,
    ``repeat`` times each; medians reported."""
    runs: dict[str, list[dict]] = {"recording on (default)": [], "recording off (baseline)": []}
    for i in range(repeat):
        for label, extra in (
            ("recording on (default)", []),
            ("recording off (baseline)", ["recording.enabled=false"]),
        ):
            run_dir = out_dir / f"{label.split()[1]}_{i}"
            t0 = time.perf_counter()
            proc = run_cli(f"hydra.run.dir={run_dir}", "progress=false", *extra)
            total = time.perf_counter() - t0
            if proc.returncode != 0:
                raise SystemExit(proc.stderr)
            m = json.loads((run_dir / "metrics.json").read_text())
            m["process_s"] = total
            runs[label].append(m)
    med = {label: {k: float(np.median([r[k] for r in rs])) for k in rs[0]} for label, rs in runs.items()}
    on, off = med["recording on (default)"], med["recording off (baseline)"]
    overhead = (on["sim.wall_s"] - off["sim.wall_s"]) / on["sim.wall_s"]
    rows = [
        [
            k,
            f"{v['sim.duration_s']:.0f}",
            f"{v['sim.wall_s']:.1f} ({', '.join(format(r['sim.wall_s'], '.1f') for r in runs[k])})",
            f"{v['sim.rtf']:.2f}",
            f"{v['process_s']:.1f}",
            f"{v['recording.bytes'] / 2**20:.0f}" if v["recording.bytes"] else "-",
            f"{int(v['sim.camera_frames'])}",
        ]
        for k, v in med.items()
    ]
    md = table(
        [
            f"run (median of {repeat})",
            "simulated s",
            "loop wall s (each run)",
            "real-time factor",
            "whole command s",
            "recording MiB",
            "camera frames",
        ],
        rows,
    )
    md += f"\n\nRecording overhead: {overhead * 100:.0f} % of the recorded run's loop time ((on - off) / on, medians)."
    return md, {"runs": runs, "median": med, "overhead": overhead}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer frames, no default run")
    parser.add_argument("--json", type=Path, help="also write raw numbers here")
    parser.add_argument("--repeat", type=int, default=3, help="default-run repetitions (medians)")
    parser.add_argument(
        "--only",
        choices=["renderers", "encodings", "changed", "chunks", "default_run"],
        help="one section",
    )
    args = parser.parse_args()
    frames = 3 if args.quick else 10
    print(f"Machine: {machine()}\n")
    sections = {}
    if args.only in (None, "renderers"):
        md, sections["renderers"] = renderer_speed(frames)
        print(
            "### Renderer speed (3 cameras, RGB + depth + segmentation, 960x540, distortion on, full warehouse)\n"
        )
        print(md + "\n")
    if args.only in (None, "encodings"):
        md, sections["encodings"] = encodings(2 if args.quick else 5)
        print(
            "### Bytes and encode time per stream (11 cameras 160-170, frames of the full warehouse, no agent)\n"
        )
        print(md + "\n")
    if args.only in (None, "changed"):
        with tempfile.TemporaryDirectory() as tmp:
            md, sections["changed"] = changed_frames(Path(tmp), 4.0 if args.quick else 20.0)
        print(
            "### Encoding changed frames (12 cameras, 4 robots, every frame recorded; per camera in order)\n"
        )
        print(md + "\n")
    if args.only in (None, "chunks"):
        with tempfile.TemporaryDirectory() as tmp:
            md, sections["chunks"] = chunks(Path(tmp), 3)
        print("### MCAP chunk compression and checksum (the chunks of two recordings)\n")
        print(md + "\n")
    if not args.quick and args.only in (None, "default_run"):
        with tempfile.TemporaryDirectory() as tmp:
            md, sections["default_run"] = default_run(Path(tmp), args.repeat)
        print("### Default scenario (python -m simlan_data.run)\n")
        print(md + "\n")
    if args.json:
        args.json.write_text(json.dumps(sections, indent=2))


if __name__ == "__main__":
    main()
