"""Read a recording without simlan_data: the independent `mcap` + `mcap-ros2-support` readers.

Every message type, the custom `simlan_msgs` ones included, is embedded in the MCAP file, so any
MCAP/ROS 2 reader decodes it (Foxglove and ROS 2 do the same). This prints the message count per
topic and the first ground-truth pose of every agent.

    python examples/read_with_mcap.py RUN_OR_RECORDING

RUN_OR_RECORDING is a run directory, its `recording/` folder or the `.mcap` file itself.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def mcap_file(path: Path) -> Path:
    """The .mcap file of a run directory, a recording folder or the file itself."""
    for candidate in (path, path / "recording.mcap", path / "recording" / "recording.mcap"):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"no recording.mcap in {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("recording", type=Path)
    args = parser.parse_args(argv)
    try:
        path = mcap_file(args.recording)
    except FileNotFoundError as err:
        print(f"error: {err}; give a run directory or its recording/ folder", file=sys.stderr)
        return 2
    counts: Counter[str] = Counter()
    first_pose: dict[str, tuple[float, float, float]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            counts[channel.topic] += 1
            if channel.topic == "/ground_truth/poses":
                for tf in msg.transforms:
                    t = tf.transform.translation
                    first_pose.setdefault(tf.child_frame_id, (t.x, t.y, t.z))
    for topic, n in sorted(counts.items()):
        print(f"{n:6d}  {topic}")
    for frame, (x, y, z) in sorted(first_pose.items()):
        print(f"first ground truth of {frame}: x={x:.2f} y={y:.2f} z={z:.2f} m (map)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
