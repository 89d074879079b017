"""``python -m simlan_data.export RUN --format trajectory --out DIR [--rate-hz 1]``: a recording's
ground truth in SIMLAN's tracker replay format (issue 25 item 6), so any run can drive
``experiment=trajectory`` and a replayed run exports back to what drove it.

    DIR/trajectory.json   [{"time_stamp": <ms>, "object_list": [[id, x, y, z, yaw], ...]}, ...]

Every ``1 / rate_hz`` seconds of simulated time (from the recording's start) the first
``/ground_truth/poses`` message at or after that time gives one entry: ``time_stamp`` is its
header stamp in ms (the bag's epoch + simulated time; ``experiment=trajectory`` sets the epoch to
the tracker file's first stamp, so stamps round-trip), ids are the N of ``robot_agent_N`` (a
trajectory run's agents are the tracker's ids), yaw about the vertical in radians. An agent
hidden by a trajectory run (below ``HIDDEN_BELOW_M``: the tracker did not see it) is left out.
Streamed: one entry is written as it is read; the same recording gives the same bytes.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import IO

from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError, RecordingInputError
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import schema
from simlan_data.recording.messages import stamp_ns_of
from simlan_data.recording.reader import RecordingReader
from simlan_data.sim.trajectory_drive import HIDDEN_BELOW_M

__all__ = ["FILE_NAME", "export_trajectory"]

FILE_NAME = "trajectory.json"
_NUMBER = re.compile(r"(\d+)/base_link$")
_NS_PER_MS = 1_000_000


def _object(frame: str, t: object) -> list[float | int] | None:
    """``[id, x, y, z, yaw]`` of one ground-truth transform, None for a hidden agent."""
    m = _NUMBER.search(frame)
    if m is None:
        return None
    tr = t.translation  # type: ignore[attr-defined]
    r = t.rotation  # type: ignore[attr-defined]
    pose = Transform.from_quat([tr.x, tr.y, tr.z], [r.x, r.y, r.z, r.w])
    if pose.translation[2] < HIDDEN_BELOW_M:
        return None
    x, y, z = (round(float(v), 6) for v in pose.translation)
    return [int(m.group(1)), x, y, z, round(pose.yaw(), 6)]


def _write_entry(f: IO[str], first: bool, stamp_ms: int, objects: list[list[float | int]]) -> None:
    f.write("[\n" if first else ",\n")
    f.write(json.dumps({"time_stamp": stamp_ms, "object_list": objects}))


def export_trajectory(run: str | Path, out: Path, *, rate_hz: float = 1.0) -> int:
    """Write ``out/trajectory.json``; returns the number of entries (stamps)."""
    if not 0 < rate_hz <= 1000:
        raise ConfigError.invalid("--rate-hz", rate_hz, "must be within (0, 1000] Hz", "use e.g. --rate-hz 1")
    period_ns = round(NS_PER_S / rate_hz)
    entries, due = 0, 0
    with RecordingReader(run) as reader:
        if schema.GROUND_TRUTH_POSES not in reader.topics:
            raise RecordingInputError(
                "no ground truth",
                str(reader.path),
                f"{schema.GROUND_TRUTH_POSES} is missing",
                "export a run recorded by simlan_data.run",
            )
        out.mkdir(parents=True, exist_ok=True)
        with (out / FILE_NAME).open("w") as f:
            for message in reader.messages([schema.GROUND_TRUTH_POSES]):
                if message.stamp_ns < due:
                    continue
                due = (message.stamp_ns // period_ns + 1) * period_ns
                transforms = list(message.msg.transforms)
                stamp = stamp_ns_of(transforms[0].header.stamp) if transforms else message.stamp_ns
                objects = [o for t in transforms if (o := _object(t.child_frame_id, t.transform)) is not None]
                _write_entry(f, entries == 0, stamp // _NS_PER_MS, objects)
                entries += 1
            f.write("[]\n" if entries == 0 else "\n]\n")
    return entries
