"""Read a recording: time-ordered typed messages by topic, and a ``ros2 bag info``-like summary.

Times here are simulated time (ns from the run's start): the reader subtracts the bag's epoch
(``timebase.py``) from log times, and adds it to the bounds it is asked for. Header stamps inside
decoded messages stay as recorded (bag time: ``epoch_ns`` + simulated time).
"""

from __future__ import annotations

import contextlib
import os
import pickle
from collections.abc import Collection, Iterable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import Reader
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from simlan_data.constants import FORMAT_MAJOR, NS_PER_S, RECORDING_DIRNAME
from simlan_data.errors import RecordingInputError
from simlan_data.recording import losses, schema
from simlan_data.recording.bounded import require_regular
from simlan_data.recording.metadata_checks import MAX_METADATA_BYTES as MAX_METADATA_BYTES
from simlan_data.recording.metadata_checks import bad as _bad
from simlan_data.recording.metadata_checks import check_counts_against_files, first_line, read_metadata
from simlan_data.recording.run_marker import read_running, writer_alive
from simlan_data.recording.timebase import format_epoch, recorded_epoch

METADATA_KEY_FORMAT = "simlan.format_version"
# Every read of a topic decompresses and walks all chunks that hold it, and images share every
# chunk with the small topics: metrics reading ground truth, commands and estimates topic by
# topic made a replay read the whole bag twenty times. The first read of a small topic therefore
# reads all small topics at once and keeps their raw bytes, up to this many messages (about 15
# minutes of the four-robot scenario); images are always streamed.
STREAMED_TYPES = frozenset({"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"})
SMALL_TOPICS_CACHE_MAX_MESSAGES = 500_000


@dataclass(frozen=True)
class Message:
    """One message: topic, log time (simulated clock, ns: the bag's log time less its epoch), type
    name and the decoded object."""

    topic: str
    stamp_ns: int
    msgtype: str
    msg: Any


@dataclass(frozen=True)
class TopicInfo:
    name: str
    msgtype: str
    count: int


@cache
def _types_by_suffix() -> tuple[dict[str, tuple[str, ...]], dict[str, tuple[str, ...]]]:
    """({topic suffix of a camera: types}, {topic suffix of an agent: types}) from :mod:`schema`,
    for every encoding a camera's streams can have."""
    cameras: dict[str, set[str]] = {}
    for rgb, other in (("raw", "raw"), ("jpeg", "png")):
        for t in [
            *schema.camera_topics("X", rgb=rgb, depth=other, semantic=other).values(),
            *schema.instance_topics("X").values(),
        ]:
            cameras.setdefault(t.name.removeprefix("/camera_X"), set()).add(t.msgtype)
    agents = {t.name.removeprefix("/NS"): {t.msgtype} for t in schema.agent_topics("NS").values()}
    return (
        {k: tuple(sorted(v)) for k, v in cameras.items()},
        {k: tuple(sorted(v)) for k, v in agents.items()},
    )


def expected_types(topic: str) -> tuple[str, ...]:
    """The message types :mod:`schema` allows on ``topic``; () for a topic it does not name."""
    for t in schema.GLOBAL_TOPICS:
        if t.name == topic:
            return (t.msgtype,)
    cameras, agents = _types_by_suffix()
    if topic.startswith("/camera_"):
        _, _, rest = topic[len("/camera_") :].partition("/")
        return cameras.get(f"/{rest}", ())
    parts = topic.split("/")
    if len(parts) == 3 and parts[0] == "" and parts[1]:
        return agents.get(f"/{parts[2]}", ())
    return ()


def _unfinished(path: Path) -> RecordingInputError:
    """The error for a bag directory with an MCAP file but no metadata.yaml."""
    marker = read_running(path.parent)
    if marker is not None and writer_alive(marker):
        return RecordingInputError(
            "recording is still being written",
            str(path),
            f"process {marker.pid} is running it (simulated {marker.simulated_s:.1f} of {marker.duration_s:g} s)",
            "wait for the run to finish",
        )
    return RecordingInputError(
        "recording is unfinished",
        str(path),
        "an MCAP file without metadata.yaml (the run crashed or was killed)",
        f"run `python -m simlan_data.recover {path}` to keep everything up to its last flushed chunk",
    )


class RecordingReader:
    """Open a recording directory (or its metadata.yaml) for reading; use as a context manager."""

    def __init__(self, path: Path | str, *, check_format: bool = True) -> None:
        p = Path(path)
        if p.exists() and not p.is_dir():  # (a FIFO or device given as the recording: never opened)
            require_regular(p, "recording path")
        if p.is_file() and p.name == "metadata.yaml":
            p = p.parent
        if p.is_dir() and not (p / "metadata.yaml").exists() and (p / RECORDING_DIRNAME).is_dir():
            p = p / RECORDING_DIRNAME  # a run directory
        if not p.exists():
            raise _bad(p, "no such file or directory", "check the path")
        require_regular(p / "metadata.yaml", "recording metadata")
        if not (p / "metadata.yaml").is_file():
            if p.is_dir() and any(p.glob("*.mcap")):
                for f in p.glob("*.mcap"):  # a FIFO named recording.mcap is no crashed run's bag
                    require_regular(f, "recording file")
                raise _unfinished(p)
            raise _bad(p, "no metadata.yaml (not a ROS 2 bag)", "point to a recording directory")
        self.path = p
        self._store: Typestore = schema.typestore()
        self._metadata = read_metadata(p)  # size and fields checked before rosbags trusts them
        files = [p / str(f) for f in self._metadata.get("relative_file_paths") or []]
        for f in files:  # rosbags opens them: a FIFO would block it
            require_regular(f, "recording file", missing_ok=True)
        try:
            self._reader = Reader(p)
            self._reader.open()
            # rosbags parses metadata.yaml itself (YAML 1.2, where PyYAML reads 1.1) and trusts it
            counts = [c.msgcount for c in self._reader.connections] + [
                self._reader.message_count,
                self._reader.start_time,
                self._reader.end_time,
            ]
        except Exception as err:  # rosbags raises assorted errors on corrupt input
            raise _bad(p, f"{type(err).__name__}: {first_line(err)}") from err
        if not all(isinstance(n, int) and not isinstance(n, bool) for n in counts):
            raise _bad(p, "metadata.yaml holds a message count or time that is not an integer")
        check_counts_against_files(p, self._metadata, files)
        self._small: list[tuple[Any, int, bytes]] | None = None  # see STREAMED_TYPES
        self._small_pickled: bytes | None = None  # see adopt_small_topics
        self._register_bag_types()
        try:
            self.epoch_ns = recorded_epoch(self.custom_data)  # 0 for bags made before epochs
        except ValueError as err:
            raise _bad(p, f"metadata.yaml custom_data: {err}") from None
        self.format_version = self.custom_data.get(METADATA_KEY_FORMAT, "")
        if check_format:
            self._check_format()

    # ---------------------------------------------------------------------------- metadata
    @property
    def custom_data(self) -> dict[str, str]:
        """metadata.yaml's custom_data (format version, seed, scenario, renderer)."""
        return dict(self._metadata.get("custom_data") or {})

    @property
    def recovered(self) -> bool:
        """True for a recording rebuilt by ``python -m simlan_data.recover`` (its run crashed)."""
        return self.custom_data.get("simlan.recovered") == "true"

    @property
    def topics(self) -> dict[str, TopicInfo]:
        out: dict[str, TopicInfo] = {}
        for c in self._reader.connections:
            prev = out.get(c.topic)
            out[c.topic] = TopicInfo(c.topic, c.msgtype, c.msgcount + (prev.count if prev else 0))
        return out

    @property
    def start_ns(self) -> int:
        """The first log time, simulated clock (0 for a recording made by a run)."""
        return int(self._reader.start_time) - self.epoch_ns

    @property
    def end_ns(self) -> int:
        """The last log time, simulated clock."""
        return int(self._reader.end_time) - self.epoch_ns

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    @property
    def message_count(self) -> int:
        return int(self._reader.message_count)

    def _check_format(self) -> None:
        version = self.format_version
        if not version:
            raise RecordingInputError(
                "recording has no simlan_data format version",
                str(self.path),
                f"metadata.yaml custom_data lacks {METADATA_KEY_FORMAT}",
                "only recordings written by simlan_data can be replayed",
            )
        try:
            major = int(version.split(".")[0])
        except ValueError:
            raise RecordingInputError(
                "recording format version unreadable",
                str(self.path),
                f"{version!r}",
                "the metadata is corrupt",
            ) from None
        if major > FORMAT_MAJOR:
            raise RecordingInputError(
                f"recording format {version} is newer than this simlan_data ({FORMAT_MAJOR}.x)",
                str(self.path),
                "it may hold data this version cannot interpret",
                "upgrade simlan_data",
            )
        if major < FORMAT_MAJOR:
            raise RecordingInputError(
                f"recording format {version} is older than this simlan_data ({FORMAT_MAJOR}.x)",
                str(self.path),
                "no converter exists yet for that major version",
                "replay it with the simlan_data version that wrote it",
            )

    def require_topics(self, names: Iterable[str]) -> None:
        missing = [n for n in names if n not in self.topics]
        if missing:
            raise RecordingInputError(
                "recording lacks required topics",
                str(self.path),
                ", ".join(missing),
                "record with a config that publishes them",
            )
        self.check_types(names)

    def check_types(self, topics: Iterable[str] | None = None) -> None:
        """Refuse any of ``topics`` (all if None) whose type is not the one :mod:`schema` gives its
        name: for readers that interpret topics by name (a String /ground_truth/poses made replays
        fail with a KeyError or AttributeError deep inside; the Rerun export too). This reader
        itself reads any type."""
        wanted = None if topics is None else set(topics)
        for c in self._reader.connections:
            if wanted is not None and c.topic not in wanted:
                continue
            expected = expected_types(c.topic)
            if expected and c.msgtype not in expected:
                raise RecordingInputError(
                    f"recording topic {c.topic} has the wrong message type",
                    str(self.path),
                    f"found {c.msgtype}, expected {' or '.join(expected)} (simlan_data.recording.schema)",
                    "record it with simlan_data, or make the tool that wrote it publish that type",
                )

    def check_types_of(self, types: Collection[str]) -> None:
        """:meth:`check_types` for the topics whose schema type is one of ``types``: those a reader
        takes by their names (the Rerun export shows the others, such as events, by their type)."""
        self.check_types([t for t in self.topics if set(expected_types(t)) & set(types)])

    def _register_bag_types(self) -> None:
        """Register message types that the bag defines and our typestore lacks."""
        extra: dict[str, Any] = {}
        for c in self._reader.connections:
            if c.msgtype in self._store.types or c.msgtype in extra:
                continue
            try:
                if c.msgdef.data:
                    extra.update(get_types_from_msg(c.msgdef.data, c.msgtype))
            except Exception:
                continue
        if extra:
            with contextlib.suppress(Exception):
                self._store.register(extra)

    # ---------------------------------------------------------------------------- messages
    def messages(
        self,
        topics: Iterable[str] | None = None,
        *,
        start_ns: int | None = None,
        stop_ns: int | None = None,
        raw: bool = False,
    ) -> Iterator[Message]:
        """Yield messages in log-time order, decoded unless ``raw`` (then ``msg`` is bytes);
        ``start_ns`` <= simulated time < ``stop_ns`` where given."""
        wanted = set(topics) if topics is not None else None
        conns = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if not conns:
            return
        epoch = self.epoch_ns
        start = None if start_ns is None else start_ns + epoch
        stop = None if stop_ns is None else stop_ns + epoch
        try:
            for conn, stamp, data in self._raw_messages(conns, start, stop):
                message = Message(conn.topic, int(stamp) - epoch, conn.msgtype, data)
                yield message if raw else self.deserialize(message)
        except RecordingInputError:
            raise
        except Exception as err:
            raise _bad(
                self.path,
                f"{type(err).__name__} while reading messages: {first_line(err)}",
            ) from err

    def deserialize(self, raw: Message) -> Message:
        """A message read with ``raw=True``, decoded (for readers that decode only some)."""
        try:
            msg = self._store.deserialize_cdr(raw.msg, raw.msgtype)
        except Exception as err:
            raise RecordingInputError(
                "message undecodable",
                f"{self.path} topic {raw.topic} at {raw.stamp_ns} ns",
                f"{type(err).__name__}: {first_line(err)}",
                f"the recording is corrupt; `python -m simlan_data.recover {self.path}` keeps its intact chunks",
            ) from err
        return Message(raw.topic, raw.stamp_ns, raw.msgtype, msg)

    def _raw_messages(
        self, conns: list[Any], start_ns: int | None, stop_ns: int | None, *, cache: bool = True
    ) -> Iterator[tuple[Any, int, bytes]]:
        """(connection, log time, CDR bytes) in log-time order; small topics from the cache.
        Bag time (with the epoch), as rosbags reads it."""
        if self._small_pickled is not None:
            self._unpickle_small()
        small = [c for c in self._reader.connections if c.msgtype not in STREAMED_TYPES]
        fits = sum(c.msgcount for c in small) <= SMALL_TOPICS_CACHE_MAX_MESSAGES
        cacheable = fits and all(c.msgtype not in STREAMED_TYPES for c in conns)
        if not cacheable and fits and cache and self._small is None and start_ns is stop_ns is None:
            # a whole pass over images decompresses every chunk anyway: keep the small topics
            # that pass by, so that reading them afterwards costs no second pass
            yield from self._stream_filling_cache(conns, small)
            return
        if not cacheable or (self._small is None and not cache):
            yield from self._reader.messages(connections=conns, start=start_ns, stop=stop_ns)
            return
        if self._small is None:
            # one pass for every small topic; a subset of this time order is what reading that
            # subset alone gives (the same merge of the same chunks)
            self._small = list(self._reader.messages(connections=small))
        ids = {c.id for c in conns}
        lo = -(2**63) if start_ns is None else start_ns
        hi = 2**63 if stop_ns is None else stop_ns
        for conn, stamp, data in self._small:
            if conn.id in ids and lo <= stamp < hi:
                yield conn, stamp, data

    def detach_after_fork(self) -> None:
        """In a forked child process: give the bag files their own file offsets, so that
        reading here cannot move the parent's (a fork shares open file descriptions)."""
        storages = getattr(self._reader.storage, "storages", None)
        if not storages:
            raise RuntimeError("unknown rosbags reader layout")
        for storage in storages:
            bio, path = getattr(storage, "bio", None), getattr(storage, "path", None)
            if bio is None or path is None:
                raise RuntimeError("unknown rosbags reader layout")
            fd = bio.fileno()
            offset = os.lseek(fd, 0, os.SEEK_CUR)
            own = os.open(path, os.O_RDONLY)
            os.dup2(own, fd)
            os.close(own)
            os.lseek(fd, offset, os.SEEK_SET)

    def small_topics(self) -> bytes | None:
        """The small topics' raw messages a whole pass over images kept (see STREAMED_TYPES),
        pickled, or None if no such pass has run: for :meth:`adopt_small_topics` in another
        process."""
        if self._small is None:
            return None
        return pickle.dumps([(conn.id, int(stamp), bytes(data)) for conn, stamp, data in self._small])

    def adopt_small_topics(self, pickled: bytes) -> None:
        """Take the small topics another reader of the same recording kept (its
        :meth:`small_topics`), so that reading them here costs no pass over the bag; unpickled
        only when first read."""
        self._small_pickled = pickled

    def _unpickle_small(self) -> None:
        pickled, self._small_pickled = self._small_pickled, None
        if self._small is not None or pickled is None:
            return
        rows = pickle.loads(pickled)  # (our own reading process's, see small_topics)
        by_id = {c.id: c for c in self._reader.connections}
        if any(conn_id not in by_id for conn_id, _, _ in rows):
            raise ValueError("small topics of another recording")
        self._small = [(by_id[conn_id], stamp, data) for conn_id, stamp, data in rows]

    def _stream_filling_cache(self, conns: list[Any], small: list[Any]) -> Iterator[tuple[Any, int, bytes]]:
        """``conns``' messages from a pass that reads the small topics too and caches them."""
        wanted = {c.id for c in conns}
        every = {c.id: c for c in [*conns, *small]}
        kept: list[tuple[Any, int, bytes]] = []
        for conn, stamp, data in self._reader.messages(connections=list(every.values())):
            if conn.msgtype not in STREAMED_TYPES:
                kept.append((conn, stamp, data))
            if conn.id in wanted:
                yield conn, stamp, data
        self._small = kept  # (only a pass read to its end fills the cache)

    def first(self, topic: str) -> Message | None:
        """The first message of ``topic`` (reads only what it needs unless small topics are cached)."""
        conns = [c for c in self._reader.connections if c.topic == topic]
        if not conns:
            return None
        for conn, stamp, data in self._raw_messages(conns, None, None, cache=False):
            try:
                msg = self._store.deserialize_cdr(data, conn.msgtype)
            except Exception as err:
                raise RecordingInputError(
                    "message undecodable",
                    f"{self.path} topic {conn.topic} at {int(stamp) - self.epoch_ns} ns",
                    f"{type(err).__name__}: {err}",
                    "the recording is corrupt; try --recover",
                ) from err
            return Message(conn.topic, int(stamp) - self.epoch_ns, conn.msgtype, msg)
        return None

    def firsts(self, topics: Iterable[str]) -> dict[str, Message]:
        """The first message of each of ``topics`` that has one, from one pass that stops when
        it has them all (:meth:`first` of each would read the start of the bag again each time)."""
        wanted = set(topics)
        conns = [c for c in self._reader.connections if c.topic in wanted]
        present = {c.topic for c in conns}
        out: dict[str, Message] = {}
        if not conns:
            return out
        for conn, stamp, data in self._raw_messages(conns, None, None, cache=False):
            if conn.topic not in out:
                out[conn.topic] = self.deserialize(
                    Message(conn.topic, int(stamp) - self.epoch_ns, conn.msgtype, data)
                )
                if len(out) == len(present):
                    break
        return out

    # ----------------------------------------------------------------------------- summary
    def summary(self) -> str:
        """A ``ros2 bag info``-style text summary."""
        files = sorted(self.path.glob("*.mcap"))
        size = sum(f.stat().st_size for f in files)
        lines = [
            f"Files:             {', '.join(f.name for f in files)}",
            f"Bag size:          {_human_bytes(size)}",
            "Storage id:        mcap",
            f"Format version:    {self.format_version or '?'}",
            f"Duration:          {self.duration_ns / NS_PER_S:.3f}s",
            f"Start:             {self.start_ns / NS_PER_S:.3f} (simulated clock, s)",
            f"End:               {self.end_ns / NS_PER_S:.3f}",
            f"Epoch:             {format_epoch(self.epoch_ns)} (log times and stamps: epoch + simulated clock)",
            f"Messages:          {self.message_count}",
        ]
        if self.recovered:
            until = int(self.custom_data.get("simlan.recovered_until_ns", "0") or 0) / NS_PER_S
            lines.append(
                f"Recovered:         yes: the run crashed; data until {until:.3f} s, "
                f"{self.custom_data.get('simlan.recovered_damaged_chunks', '0')} damaged chunks skipped"
            )
            text = self.custom_data.get(losses.LOSSES_KEY)
            lost = losses.decode(text) if text is not None else losses.from_incomplete(self.path.parent)
            shown = lost[:20] + ([f"... and {len(lost) - 20} more"] if len(lost) > 20 else [])
            shown = shown or (["no message (nothing the file held or the run reached)"] if text else [])
            lines.extend(f"{'Lost:' if i == 0 else '':<19}{x}" for i, x in enumerate(shown))
        lines.append("Topic information:")
        topics = sorted(self.topics.values(), key=lambda t: t.name)
        width = max((len(t.name) for t in topics), default=10)
        for t in topics:
            lines.append(f"  Topic: {t.name:<{width}} | Type: {t.msgtype} | Count: {t.count}")
        return "\n".join(lines)

    def close(self) -> None:
        self._reader.close()

    def __enter__(self) -> RecordingReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} GiB"
