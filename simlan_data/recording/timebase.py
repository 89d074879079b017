"""Bag time: the simulated clock plus the recording's epoch, a fixed date from the config.

Viewers (Foxglove, Rerun, ``ros2 bag``) read log times and header stamps as nanoseconds since
1970; a clock starting at 0 shows runs on 1 January 1970. So a recording is stamped at::

    bag time = epoch (recording.epoch, ISO 8601, a fixed date: same config, same bytes)
             + simulated time (ns since the run started)

in every log time, publish time, header stamp and ``/clock``. The epoch is stored in the bag's
metadata (``EPOCH_KEY``, in metadata.yaml's custom_data and the MCAP file's ``rosbag2`` metadata
record); :class:`~simlan_data.recording.reader.RecordingReader` subtracts it again, so everything
that reads through it sees simulated time from 0. Recordings made before the epoch existed have
no key: their epoch is 0.

Only the standard library here: the config checks the epoch before anything heavy is imported.
"""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

EPOCH_KEY = "simlan.epoch_ns"  # metadata.yaml custom_data: the epoch in ns since 1970 (UTC)
DEFAULT_EPOCH = "2026-01-01T00:00:00Z"  # conf/config.yaml recording.epoch; docs/recording.md
_UNIX = datetime(1970, 1, 1, tzinfo=timezone.utc)
# ROS 2 header stamps keep whole seconds in an int32, which runs out on 2038-01-19: an epoch
# before 2037 leaves a year of simulated time
LATEST_EPOCH = datetime(2037, 1, 1, tzinfo=timezone.utc)


def _ns(when: datetime) -> int:
    return (when - _UNIX) // timedelta(microseconds=1) * 1000


def parse_epoch(text: str) -> int:
    """The epoch ``text`` names, in ns since 1970-01-01T00:00:00Z.

    ``text`` is an ISO 8601 date or date and time (``2026-01-01``, ``2026-01-01T08:30:00Z``,
    ``2026-01-01T09:30:00+01:00``); without an offset it is UTC.

    Raises:
        ValueError: not such a date, or outside 1970-01-01 .. 2037-01-01 (the reason is the message).
    """
    text = str(text).strip()
    iso = text[:-1] + "+00:00" if text[-1:] in ("Z", "z") else text
    try:
        when = datetime.fromisoformat(iso)
    except ValueError:
        raise ValueError("not an ISO 8601 date and time") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=timezone.utc)
    if not _UNIX <= when < LATEST_EPOCH:
        raise ValueError("must lie within 1970-01-01 .. 2037-01-01 (ROS 2 stamps end in 2038)")
    return _ns(when)


DEFAULT_EPOCH_NS = parse_epoch(DEFAULT_EPOCH)


def format_epoch(epoch_ns: int) -> str:
    """``epoch_ns`` as ISO 8601 UTC (``2026-01-01T00:00:00Z``), for summaries."""
    when = _UNIX + timedelta(microseconds=epoch_ns // 1000)
    return when.strftime("%Y-%m-%dT%H:%M:%S") + (f".{when.microsecond:06d}" if when.microsecond else "") + "Z"


def recorded_epoch(custom_data: dict[str, str]) -> int:
    """The epoch a bag's metadata custom_data records; 0 for a bag made before epochs existed.

    Raises:
        ValueError: the key holds no whole number of ns in the range :func:`parse_epoch` allows.
    """
    text = custom_data.get(EPOCH_KEY)
    if text is None:
        return 0
    if not (text.isascii() and text.isdigit()) or int(text) >= _ns(LATEST_EPOCH):
        raise ValueError(f"{EPOCH_KEY} is {text!r}, not a whole number of ns before 2037")
    return int(text)
