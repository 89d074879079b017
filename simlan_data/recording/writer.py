"""Write a recording: a ROS 2 bag (metadata.yaml + MCAP) through rosbags, crash-tolerant.

- Refuses to write into an existing path (rosbags does too): a failed run never touches an
  existing recording.
- Crash safety: at any moment every message stamped more than ``flush_period_ns`` before the
  newest one submitted sits in complete MCAP chunks handed to the OS (and to the disk with
  ``fsync``), so a crash (SIGKILL, power cut with ``fsync``) loses at most that much simulated
  time; ``python -m simlan_data.recover`` rebuilds the rest of the file (``recording.recover``).
  The simulation thread waits for the file at each flush mark if the I/O falls behind.
- Every chunk carries the CRC32 of its uncompressed records (rosbags writes 0 = none), so a
  reader can tell a corrupted chunk from a valid one.
- Encoding (JPEG/PNG) and serialization can run on worker threads, and the file is written by
  an I/O thread; messages still reach the file in submission order, so the same run gives the
  same bytes.
"""

from __future__ import annotations

import contextlib
import functools
import os
import queue
import sys
import threading
from collections import defaultdict
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from io import BytesIO
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # pragma: no cover - rosbags depends on backports.zstd before 3.14
    from backports import zstd
from isal import isal_zlib
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.storage_mcap import (
    McapWriter,
    PendingChunk,
    write_record,
    write_string,
    write_uint16,
    write_uint32,
    write_uint64,
)

from simlan_data.constants import NS_PER_S
from simlan_data.errors import RecordingError
from simlan_data.recording.schema import LATCHED_TOPICS, ROS_DISTRO, Topic, typestore
from simlan_data.recording.timebase import EPOCH_KEY

# what a listener gets for each message written: its connection, log time (ns) and CDR bytes
WriteListener = Callable[[Connection, int, bytes], None]
MAX_PENDING = 256  # bound the messages (and frames) waiting for the file
CHUNK_OPCODE, MESSAGE_INDEX_OPCODE = 0x06, 0x07


class _Flush:
    """Queue item: close the pending chunk and hand the file to the OS (flush mark ``mark``)."""

    __slots__ = ("mark",)

    def __init__(self, mark: int) -> None:
        self.mark = mark


class _Done:
    """An already-available result with the Future interface the queue uses."""

    __slots__ = ("_value",)

    def __init__(self, value: Any) -> None:
        self._value = value

    def result(self) -> Any:
        return self._value

    def done(self) -> bool:
        return True


class RecordingWriter:
    """Context manager writing typed messages to a new ROS 2 bag directory."""

    def __init__(
        self,
        path: Path | str,
        *,
        compression: str = "zstd",
        compression_level: int = 2,
        flush_period_ns: int = NS_PER_S,
        encode_threads: int = 0,
        fsync: bool = False,
        epoch_ns: int = 0,
    ) -> None:
        """Prepare a new bag at ``path`` (created by :meth:`open`).

        Args:
            compression: MCAP chunk compression, ``zstd`` or ``none``.
            flush_period_ns: at most this much simulated time is lost on a crash (> 0).
            encode_threads: worker threads for encoding; 0 writes on the caller's thread.
            fsync: also force each flushed chunk to the disk (survives a power cut, not just a
                killed process).
            epoch_ns: added to every stamp given to the ``write`` methods (simulated time) to
                make the log time; recorded in the metadata (``timebase.EPOCH_KEY``). Header
                stamps are the caller's: build them with :meth:`stamp_ns`.
        """
        self.path = Path(path)
        if self.path.exists():
            raise RecordingError(
                "recording exists",
                str(self.path),
                "simlan_data never overwrites a recording",
                "choose another hydra.run.dir or remove it yourself",
            )
        self.flush_period_ns = int(flush_period_ns)
        if self.flush_period_ns <= 0:
            raise ValueError(f"flush_period_ns must be > 0, got {flush_period_ns}")
        # flush marks every half period, and the submitter waits for the previous mark: the
        # newest submitted stamp is never more than two half periods ahead of the file
        self._mark_period_ns = max(1, self.flush_period_ns // 2)
        self._mark_issued = 0
        self._mark_done = 0
        self._newest_ns = 0
        self._marks = threading.Condition()
        self.fsync = fsync
        self.epoch_ns = int(epoch_ns)
        if self.epoch_ns < 0:
            raise ValueError(f"epoch_ns must be >= 0, got {epoch_ns}")
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.set_custom_data(EPOCH_KEY, str(self.epoch_ns))
        self.compression_level = int(compression_level)
        if compression == "zstd":
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._store = typestore()
        self._connections: dict[str, Any] = {}
        self._pool = (
            ThreadPoolExecutor(max_workers=encode_threads, thread_name_prefix="encode")
            if encode_threads > 0
            else None
        )
        # FIFO of (topic, stamp, future bytes) and flush marks drained in order by the I/O
        # thread (None ends it)
        self._queue: queue.Queue[tuple[Topic, int, Future[bytes] | _Done] | _Flush | None] = queue.Queue(
            maxsize=MAX_PENDING
        )
        self._io: threading.Thread | None = None
        self._io_error: BaseException | None = None
        self.message_counts: dict[str, int] = {}
        self.byte_counts: dict[str, int] = {}
        self.flushes = 0
        self._listeners: list[WriteListener] = []

    # ------------------------------------------------------------------------------ lifecycle
    def __enter__(self) -> RecordingWriter:
        self.open()
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def open(self) -> None:
        try:
            self._writer.open()
        except (WriterError, OSError) as err:
            raise RecordingError(
                "cannot create recording",
                str(self.path),
                str(err),
                "check the directory is writable and does not exist",
            ) from err
        storage = self._writer.storage
        assert isinstance(storage, McapWriter)
        if storage.compression == "zstd":
            # rosbags compresses chunks at zstd's default level 3. Level 2 is as small and about
            # twice as fast on our chunks; it finds the repeated bytes of cameras whose image did
            # not change (the default run: 0.83 of raw at 600 MB/s; levels 1 and -1 miss them:
            # 0.95). benchmarks/spine.py --only chunks measures both kinds of recording.
            storage.compressor = functools.partial(zstd.compress, level=self.compression_level)
        # rosbags leaves the chunk CRC at 0 (none); ours lets readers detect a corrupt chunk
        storage.close_chunk = functools.partial(_close_chunk_with_crc, storage)  # type: ignore[method-assign]
        if self._pool is not None:
            self._io = threading.Thread(target=self._io_loop, name="bag-writer", daemon=True)
            self._io.start()

    def _io_loop(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if isinstance(item, _Flush):
                if self._io_error is None:
                    try:
                        self._flush_chunk()
                    except BaseException as err:
                        self._io_error = err
                self._mark_reached(item.mark)
                continue
            if self._io_error is not None:
                continue  # keep draining so producers never block; the error is raised to them
            topic, stamp_ns, fut = item
            try:
                self._write_serialized(topic, stamp_ns, fut.result())
            except BaseException as err:
                self._io_error = err

    def _mark_reached(self, mark: int) -> None:
        with self._marks:
            self._mark_done = max(self._mark_done, mark)
            self._marks.notify_all()

    def _flush_mark(self, stamp_ns: int) -> None:
        """At every half flush period of submitted time: queue a flush, wait for the previous one."""
        self._newest_ns = max(self._newest_ns, stamp_ns)
        mark = self._newest_ns // self._mark_period_ns
        if mark <= self._mark_issued:
            return
        previous, self._mark_issued = self._mark_issued, mark
        if self._io is None:
            self._flush_chunk()
            self._mark_reached(mark)
            return
        self._queue.put(_Flush(mark))
        with self._marks:
            while self._mark_done < previous and self._io_error is None:
                self._marks.wait(timeout=1.0)

    def _put(self, item: tuple[Topic, int, Future[bytes] | _Done]) -> None:
        if self._io_error is not None:
            raise RecordingError(
                "recording failed",
                str(self.path),
                f"{type(self._io_error).__name__}: {self._io_error}",
                "check free disk space",
            ) from self._io_error
        self._flush_mark(item[1])
        if self._io is None:
            topic, stamp_ns, fut = item
            self._write_serialized(topic, stamp_ns, fut.result())
        else:
            self._queue.put(item)

    def _stop_io(self) -> None:
        if self._io is not None:
            self._queue.put(None)
            self._io.join()
            self._io = None

    def set_metadata(self, key: str, value: str) -> None:
        """Store a string in metadata.yaml's custom_data (written at close)."""
        self._writer.set_custom_data(key, value)

    def add_listener(self, listener: WriteListener) -> None:
        """Call ``listener(connection, log_time_ns, data)`` with every message as it goes into the
        file: its rosbags ``Connection`` (topic, type, the message definition the bag embeds), log
        time and CDR bytes, in file order, on the thread that writes the file (a live view)."""
        self._listeners.append(listener)

    def add_connection(self, topic: str, msgtype: str, *, msgdef: str, rihs01: str) -> None:
        """Declare a topic with its message definition as found in another bag (for recovery)."""
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(
                topic, msgtype, msgdef=msgdef, rihs01=rihs01, offered_qos_profiles=offered_qos(topic)
            )

    def close(self) -> None:
        """Write everything queued, the MCAP summary and metadata.yaml."""
        self._stop_io()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
        if self._io_error is not None:
            self._writer.abort()
            raise RecordingError(
                "recording failed",
                str(self.path),
                f"{type(self._io_error).__name__}: {self._io_error}",
                "check free disk space",
            ) from self._io_error
        self._writer.close()
        name_the_distro(self.path / "metadata.yaml")

    def abort(self) -> None:
        """Stop without finishing the file (recover() can rebuild its index later)."""
        self._stop_io()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        # best effort: the error that brought us here (a full disk...) is the one to report
        with contextlib.suppress(Exception):
            if self._io_error is None:
                self._flush_chunk()
        with contextlib.suppress(Exception):
            self._writer.abort()

    # -------------------------------------------------------------------------------- writing
    def stamp_ns(self, t_ns: int) -> int:
        """The header stamp of simulated time ``t_ns``: bag time, as the log time it is written at."""
        return self.epoch_ns + int(t_ns)

    def write(self, topic: Topic, stamp_ns: int, msg: Any) -> None:
        """Queue a message object (serialized now)."""
        data = self._store.serialize_cdr(msg, topic.msgtype)
        self._put((topic, int(stamp_ns), _Done(bytes(data))))

    def write_serialized(self, topic: Topic, stamp_ns: int, data: bytes) -> None:
        """Queue an already serialized (CDR) message."""
        self._put((topic, int(stamp_ns), _Done(data)))

    def write_pending(self, topic: Topic, stamp_ns: int, pending: Any) -> None:
        """Queue a message whose CDR bytes ``pending.result()`` yields once ``pending.done()``."""
        self._put((topic, int(stamp_ns), pending))

    def run_async(self, fn: Callable[..., Any], *args: Any) -> Future[Any] | _Done:
        """Run ``fn(*args)`` on a worker thread (inline without workers); returns its future."""
        if self._pool is None:
            return _Done(fn(*args))
        return self._pool.submit(fn, *args)

    def submit(self, topic: Topic, stamp_ns: int, build: Callable[[], Any]) -> Future[bytes] | _Done:
        """Queue a message built by ``build()`` on a worker thread (encoding happens there).

        Returns the future of its CDR bytes (to reuse them for an identical later message).
        """
        msgtype = topic.msgtype

        def job() -> bytes:
            return bytes(self._store.serialize_cdr(build(), msgtype))

        fut: Future[bytes] | _Done = self._pool.submit(job) if self._pool is not None else _Done(job())
        self._put((topic, int(stamp_ns), fut))
        return fut

    def serialize(self, topic: Topic, msg: Any) -> bytes:
        return bytes(self._store.serialize_cdr(msg, topic.msgtype))

    def _write_serialized(self, topic: Topic, stamp_ns: int, data: bytes) -> None:
        conn = self._connections.get(topic.name)
        if conn is None:
            conn = self._writer.add_connection(
                topic.name, topic.msgtype, typestore=self._store, offered_qos_profiles=offered_qos(topic.name)
            )
            self._connections[topic.name] = conn
        log_ns = self.epoch_ns + stamp_ns  # bag time (recording/timebase.py)
        self._writer.write(conn, log_ns, data)
        for listener in self._listeners:
            listener(conn, log_ns, data)
        self.message_counts[topic.name] = self.message_counts.get(topic.name, 0) + 1
        self.byte_counts[topic.name] = self.byte_counts.get(topic.name, 0) + len(data)

    def _flush_chunk(self) -> None:
        """Close the pending MCAP chunk and hand it to the OS (rosbags' storage internals)."""
        storage = getattr(self._writer, "storage", None)
        if storage is None:
            return
        if storage.chunk.bio.tell():
            storage.close_chunk()
        storage.bio.flush()
        if self.fsync:
            os.fsync(storage.bio.fileno())
        self.flushes += 1


class NullWriter(RecordingWriter):
    """Accepts everything and writes nothing (``recording.enabled=false``: benchmarks, dry runs)."""

    def __init__(self) -> None:
        self.message_counts, self.byte_counts, self.flushes = {}, {}, 0
        self.epoch_ns = 0
        self._listeners = []  # (never called: nothing is written)

    def __enter__(self) -> NullWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def set_metadata(self, key: str, value: str) -> None:
        return None

    def write(self, topic: Topic, stamp_ns: int, msg: Any) -> None:
        return None

    def write_serialized(self, topic: Topic, stamp_ns: int, data: bytes) -> None:
        return None

    def write_pending(self, topic: Topic, stamp_ns: int, pending: Any) -> None:
        return None

    def serialize(self, topic: Topic, msg: Any) -> bytes:
        return b"\x00\x01\x00\x00" + bytes(8)  # an empty little-endian CDR header

    def run_async(self, fn: Callable[..., Any], *args: Any) -> _Done:
        return _Done(None)

    def submit(self, topic: Topic, stamp_ns: int, build: Callable[[], Any]) -> _Done:
        return _Done(b"")


def _close_chunk_with_crc(storage: McapWriter) -> None:
    """rosbags' ``McapWriter.close_chunk`` (0.11.9), plus the CRC32 of the uncompressed records.

    Writes the Chunk record, its MessageIndex records, and keeps the ChunkIndex for the summary.
    """
    pending = storage.chunk
    raw = pending.bio.getvalue()
    rec = BytesIO()
    write_uint64(rec, pending.message_start_time)
    write_uint64(rec, pending.message_end_time)
    write_uint64(rec, len(raw))
    write_uint32(rec, isal_zlib.crc32(raw))  # zlib's CRC32, 6x faster (spine.py --only chunks)
    compressed = storage.compressor(raw)
    write_string(rec, storage.compression)
    write_uint64(rec, len(compressed))
    rec.write(compressed)
    chunk_start = storage.bio.tell()
    write_record(storage.bio, CHUNK_OPCODE, rec)
    chunk_end = storage.bio.tell()
    offsets: list[tuple[int, int]] = []
    for cid, msgs in pending.msgs.items():
        offsets.append((cid, storage.bio.tell()))
        rec = BytesIO()
        write_uint16(rec, cid)
        write_uint32(rec, len(msgs) * 16)
        for ts, offset in msgs:
            write_uint64(rec, ts)
            write_uint64(rec, offset)
        write_record(storage.bio, MESSAGE_INDEX_OPCODE, rec)
    rec = BytesIO()
    write_uint64(rec, pending.message_start_time)
    write_uint64(rec, pending.message_end_time)
    write_uint64(rec, chunk_start)
    write_uint64(rec, chunk_end - chunk_start)
    write_uint32(rec, len(offsets) * 10)
    for cid, offset in offsets:
        write_uint16(rec, cid)
        write_uint64(rec, offset)
    write_uint64(rec, storage.bio.tell() - chunk_end)
    write_string(rec, storage.compression)
    write_uint64(rec, len(compressed))
    write_uint64(rec, len(raw))
    storage.chunks.append(rec)
    storage.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))


_INFINITE = QosTime(9223372036, 854775807)  # how ROS 2 writes an infinite duration in metadata.yaml
LATCHED_QOS = Qos(
    QosHistory.KEEP_LAST,
    1,
    QosReliability.RELIABLE,
    QosDurability.TRANSIENT_LOCAL,
    _INFINITE,
    _INFINITE,
    QosLiveliness.AUTOMATIC,
    _INFINITE,
    False,
)


def offered_qos(topic: str) -> list[Qos]:
    """The QoS recorded for ``topic``: a latched publisher's for the topics published once
    (``schema.LATCHED_TOPICS``); none (the player's default: reliable, volatile) for the streams."""
    return [LATCHED_QOS] if topic in LATCHED_TOPICS else []


def name_the_distro(metadata: Path) -> None:
    """rosbags writes ``ros_distro: rosbags``; the bag's message definitions are a ROS 2 distro's
    (``schema.ROS_DISTRO``): say which. Rewritten in place, never larger than before (a copy
    beside it would need free space the run may not have left: a full disk must not fail here)."""
    if not metadata.is_file():
        return
    text = metadata.read_text()
    named = text.replace("  ros_distro: rosbags\n", f"  ros_distro: {ROS_DISTRO}\n", 1)
    if named != text and len(named.encode()) <= len(text.encode()):
        with metadata.open("r+") as f:
            f.write(named)
            f.truncate()
