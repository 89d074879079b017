"""metadata.yaml of a recording, read without trusting it: bounded in size, no YAML aliases, every
count and time an integer, and the counts, start and duration equal to what the MCAP files' own
summaries say (rosbags takes metadata.yaml on trust: ``message_count: 10**23`` was printed as is).

Used by ``reader.RecordingReader`` before rosbags opens the bag; every failure is a
:class:`RecordingInputError` (exit 2) saying which field is wrong and how to rebuild it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from mcap.reader import make_reader

from simlan_data.errors import RecordingInputError
from simlan_data.recording.bounded import load_yaml_without_aliases, require_regular


def bad(path: Path, why: str, fix: str = "") -> RecordingInputError:
    fix = fix or f"run `python -m simlan_data.recover {path}` to rebuild what is readable, or record it again"
    return RecordingInputError("not a readable recording", str(path), why, fix)


def first_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__


# simlan_data writes a few KiB (about 300 bytes a topic); PyYAML and then rosbags' ruamel parse
# 256 KiB in about 1.5 s together (a MiB took 7 s)
MAX_METADATA_BYTES = 256 << 10


def read_metadata(path: Path) -> dict[str, Any]:
    """The rosbag2_bagfile_information of metadata.yaml (already validated by rosbags)."""
    meta = path / "metadata.yaml"
    st = require_regular(meta, "recording metadata", missing_ok=False)
    if st is not None and st.st_size > MAX_METADATA_BYTES:
        raise bad(
            path,
            f"metadata.yaml is {st.st_size} bytes, more than the {MAX_METADATA_BYTES} a recording's has room for",
        )
    try:
        data = load_yaml_without_aliases(meta.read_bytes()[: MAX_METADATA_BYTES + 1])
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise bad(path, f"metadata.yaml unreadable: {first_line(err)}") from err
    except RecursionError:
        raise bad(path, "metadata.yaml is nested too deeply") from None
    info = data.get("rosbag2_bagfile_information") if isinstance(data, dict) else None
    if not isinstance(info, dict):
        raise bad(path, "metadata.yaml lacks rosbag2_bagfile_information")
    custom = info.get("custom_data")
    if custom is not None and not (
        isinstance(custom, dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in custom.items())
    ):
        raise bad(path, "metadata.yaml custom_data is not a mapping of strings")
    _check_metadata_fields(path, info)
    return info


def _is_count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _check_metadata_fields(path: Path, info: dict[str, Any]) -> None:
    """The fields rosbags takes on trust: counts and times are integers, topics have names and types."""
    for key, sub in (
        ("message_count", None),
        ("duration", "nanoseconds"),
        ("starting_time", "nanoseconds_since_epoch"),
    ):
        value = info.get(key)
        if sub is not None:
            value = value.get(sub) if isinstance(value, dict) else None
        if not _is_count(value):
            raise bad(path, f"metadata.yaml {key}{'.' + sub if sub else ''} is not a non-negative integer")
    topics = info.get("topics_with_message_count")
    if not isinstance(topics, list):
        raise bad(path, "metadata.yaml topics_with_message_count is not a list")
    for i, entry in enumerate(topics):
        meta = entry.get("topic_metadata") if isinstance(entry, dict) else None
        if not (
            isinstance(meta, dict)
            and isinstance(meta.get("name"), str)
            and isinstance(meta.get("type"), str)
            and _is_count(entry.get("message_count"))
        ):
            raise bad(
                path, f"metadata.yaml topics_with_message_count[{i}] lacks a name, type or integer count"
            )
    entries = info.get("files") or []  # (rosbag2 metadata of version 5 and later: one per file)
    for i, entry in enumerate(entries if isinstance(entries, list) else [None]):
        if not (isinstance(entry, dict) and _is_count(entry.get("message_count", 0))):
            raise bad(path, f"metadata.yaml files[{i}] message_count is not a non-negative integer")


def check_counts_against_files(path: Path, info: dict[str, Any], files: list[Path]) -> None:
    """metadata.yaml's message counts, start and duration against the MCAP files' own summary
    statistics (rosbags takes metadata.yaml's on trust: ``message_count: 10**23`` was printed as
    is). Files without a summary are not checked (rosbags refuses those anyway)."""
    total, per_topic, per_file, first, last = 0, dict[str, int](), dict[str, int](), None, None
    for f in files:
        try:
            with f.open("rb") as fh:
                summary = make_reader(fh).get_summary()
        except Exception:  # rosbags read it: only its summary is unusable here
            return
        if summary is None or summary.statistics is None:
            return
        stats = summary.statistics
        total += stats.message_count
        per_file[f.name] = stats.message_count
        for cid, n in stats.channel_message_counts.items():
            topic = summary.channels[cid].topic if cid in summary.channels else f"channel {cid}"
            per_topic[topic] = per_topic.get(topic, 0) + n
        if stats.message_count:
            first = min(first if first is not None else stats.message_start_time, stats.message_start_time)
            last = max(last if last is not None else stats.message_end_time, stats.message_end_time)
    claimed: dict[str, int] = {}
    for entry in info.get("topics_with_message_count") or []:
        name = entry["topic_metadata"]["name"]
        claimed[name] = claimed.get(name, 0) + entry["message_count"]
    wrong = [("message_count", info["message_count"], total)]
    wrong += [
        (f"topics_with_message_count {t}", claimed.get(t, 0), per_topic.get(t, 0))
        for t in sorted(set(claimed) | set(per_topic))
    ]
    wrong += [
        (f"files[{i}] ({e.get('path')}) message_count", e["message_count"], per_file[str(e.get("path"))])
        for i, e in enumerate(info.get("files") or [])
        if "message_count" in e and str(e.get("path")) in per_file
    ]
    if first is not None and last is not None:
        wrong.append(("starting_time", info["starting_time"]["nanoseconds_since_epoch"], first))
        wrong.append(("duration", info["duration"]["nanoseconds"], last - first))
    for key, said, found in wrong:
        if said != found:
            raise bad(
                path,
                f"metadata.yaml {key} is {said}, but its MCAP file's summary says {found}",
                f"run `python -m simlan_data.recover {path}` to rebuild metadata.yaml from the file",
            )
