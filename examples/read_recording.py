"""Read a recording with simlan_data's reader: its summary, the topics, one decoded image.

Shows `RecordingReader` (time-ordered, decoded messages, simulated-clock stamps) and
`decode_compressed` (a CompressedImage to a numpy array: RGB, depth in metres or label ids).

    python examples/read_recording.py RUN_OR_RECORDING [--camera 163]

RUN_OR_RECORDING is a run directory (`recordings/<name>_<date>/`) or its `recording/` folder,
e.g. the committed `recordings/golden/single_truck`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from simlan_data.errors import SimlanError
from simlan_data.recording.codecs import decode_compressed
from simlan_data.recording.reader import RecordingReader


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("recording", type=Path, help="run directory or its recording/ folder")
    parser.add_argument(
        "--camera", default="", help="camera id whose first colour image to decode (default: the first)"
    )
    args = parser.parse_args(argv)
    try:
        with RecordingReader(args.recording) as bag:
            print(
                f"{bag.message_count} messages on {len(bag.topics)} topics, {bag.duration_ns / 1e9:.1f} s simulated"
            )
            images = sorted(t for t in bag.topics if t.endswith("/image_raw/compressed") and "/camera_" in t)
            wanted = (
                [t for t in images if t.startswith(f"/camera_{args.camera}/")] if args.camera else images[:1]
            )
            if not wanted:
                print(
                    f"error: no colour images of camera '{args.camera}' in {args.recording}; cameras: {images}",
                    file=sys.stderr,
                )
                return 2
            for m in bag.messages(wanted):  # time-ordered, decoded
                rgb = decode_compressed(m.msg.format, m.msg.data)
                print(
                    f"{m.topic} at {m.stamp_ns / 1e9:.3f} s: {rgb.shape[1]}x{rgb.shape[0]} {rgb.dtype}, format '{m.msg.format}'"
                )
                break
    except SimlanError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
