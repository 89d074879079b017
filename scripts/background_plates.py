"""Write the marker-free localizer's background plates from a recording of the empty warehouse.

    python -m simlan_data.run scenario=default '~agents.robot_agent_1' cameras=gpss_all \
        streams=rgb duration_s=0.2 hydra.run.dir=DIR          # no agents: the empty warehouse
    python scripts/background_plates.py DIR/recording OUT      # OUT/<camera_id>.jpg

Each camera's first image, as recorded (the JPEG bytes, not re-encoded). Select the plates with
``algorithms.localizer.background=OUT``; the packaged ``gpss_960x540`` were made so.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from simlan_data.recording.messages import compressed_image_data
from simlan_data.recording.reader import RecordingReader

SUFFIX = "/image_raw/compressed"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", type=Path)
    ap.add_argument("out", type=Path)
    args = ap.parse_args()
    if args.out.exists():
        print(f"error: {args.out} exists in background_plates: it would be overwritten; choose a new folder",
              file=sys.stderr)  # fmt: skip
        return 2
    with RecordingReader(args.recording) as reader:
        topics = [t for t in reader.topics if t.startswith("/camera_") and t.endswith(SUFFIX)]
        plates: dict[str, bytes] = {}
        for m in reader.messages(topics, raw=True):
            cid = m.topic.removeprefix("/camera_").removesuffix(SUFFIX)
            if cid not in plates:
                data = compressed_image_data(m.msg)
                plates[cid] = bytes(data if data is not None else reader.deserialize(m).msg.data)
            if len(plates) == len(topics):
                break
    args.out.mkdir(parents=True)
    for cid, data in sorted(plates.items()):
        (args.out / f"{cid}.jpg").write_bytes(data)
    print(f"{len(plates)} plates -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
