"""Read what a damaged or unfinished MCAP file still holds, trusting nothing in it.

    recording.mcap --StreamReader (mcap library, front to back, no seeking)-->
        Header, Chunk, MessageIndex, ..., Chunk, <cut>
        every record: its length must fit in the file (no allocation beyond the file size)
        every Chunk: declared size <= 1 GiB -> zstd into at most that size -> CRC32 -> records
            -> each message names a known channel and lies in the chunk's time range
        a chunk failing a check is skipped and reported; reading stops at the first record that
        is cut short or unreadable
    --(only if reading stopped early and the file still has its summary section, e.g. a damaged
       record in a finished file)--> the summary's chunk index and channel table resume reading
       at every later chunk

Used by ``recording.recover`` (which writes what is found into a new bag) and its ``--dry-run``.
"""

from __future__ import annotations

import contextlib
import struct
import sys
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO

import yaml
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # pragma: no cover - rosbags depends on backports.zstd before 3.14
    from backports import zstd

from simlan_data.errors import RecordingInputError
from simlan_data.recording import schema

MAX_CHUNK_BYTES = (
    1 << 30
)  # an uncompressed chunk larger than this is not ours (rosbags: ~1 MiB + one message)
CHUNK_OPCODE = 0x06
PARSE_ERRORS = (McapError, struct.error, ValueError, UnicodeDecodeError, EOFError, OverflowError, MemoryError)


class BadChunkError(Exception):
    """A chunk whose records cannot be trusted (the reason is the message)."""


@dataclass(frozen=True)
class ChunkDamage:
    """A chunk that was skipped: where, why, and the time range its header claims."""

    offset: int
    why: str
    start_ns: int
    end_ns: int


@dataclass
class Salvage:
    """What one pass over a (possibly damaged) MCAP file found readable."""

    mcap: Path
    size: int
    complete: bool = False  # reached the end of the data section (the summary follows)
    readable_bytes: int = 0  # the file up to here consists of whole records
    stop_reason: str = ""  # why reading front to back stopped early, if it did
    tail_chunk: tuple[int, int] | None = None  # time range of an unfinished chunk at the end
    resumed_from_index: int = 0  # chunks read through the summary's chunk index after a stop
    chunks: int = 0
    chunks_with_crc: int = 0
    damaged: list[ChunkDamage] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)  # topic -> messages recovered
    first_ns: int | None = None
    last_ns: int | None = None
    run_info: Any = None
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    @property
    def intact(self) -> bool:
        return self.complete and not self.damaged and not self.stop_reason


def open_chunk(chunk: Chunk) -> list[Any]:
    """The Schema/Channel/Message records of a chunk, after size, decompression and CRC checks.

    Raises:
        BadChunkError: the chunk cannot be trusted.
    """
    size = chunk.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise BadChunkError(f"claims {size} bytes uncompressed (limit {MAX_CHUNK_BYTES})")
    if chunk.compression == "zstd":
        dec = zstd.ZstdDecompressor()
        try:
            raw = dec.decompress(chunk.data, max_length=size)
        except (zstd.ZstdError, ValueError, MemoryError) as err:
            raise BadChunkError(f"zstd: {err}") from None
        if not dec.eof:
            raise BadChunkError("zstd data does not end where the chunk says")
    elif chunk.compression == "":
        raw = chunk.data
    else:
        raise BadChunkError(f"unsupported compression {chunk.compression!r}")
    if len(raw) != size:
        raise BadChunkError(f"{len(raw)} bytes uncompressed, header says {size}")
    if chunk.uncompressed_crc and zlib.crc32(raw) != chunk.uncompressed_crc:
        raise BadChunkError("CRC mismatch")
    plain = Chunk(
        compression="",
        data=raw,
        message_end_time=chunk.message_end_time,
        message_start_time=chunk.message_start_time,
        uncompressed_crc=0,
        uncompressed_size=size,
    )
    try:
        return breakup_chunk(plain)
    except PARSE_ERRORS as err:
        raise BadChunkError(f"records unreadable ({type(err).__name__})") from None


def _check_chunk(
    inner: list[Any], chunk: Chunk, schemas: dict[int, Schema], channels: dict[int, Channel]
) -> None:
    """Refuse a chunk (without a CRC) whose records contradict themselves or its header."""
    known_schemas = set(schemas) | {r.id for r in inner if isinstance(r, Schema)}
    known_channels = set(channels) | {
        r.id for r in inner if isinstance(r, Channel) and r.schema_id in known_schemas
    }
    for r in inner:
        if isinstance(r, Message) and (
            r.channel_id not in known_channels
            or not chunk.message_start_time <= r.log_time <= chunk.message_end_time
        ):
            raise BadChunkError("a message contradicts the chunk header")


def _tail_chunk_times(f: BinaryIO, offset: int, size: int) -> tuple[int, int] | None:
    """The time range in the header of a chunk cut short at ``offset``, if one starts there."""
    if size - offset < 1 + 8 + 16:
        return None
    f.seek(offset)
    head = f.read(25)
    if head[0] != CHUNK_OPCODE:
        return None
    start, end = struct.unpack("<QQ", head[9:25])
    return (start, end) if start <= end else None


def _chunk_at(f: BinaryIO, offset: int, length: int, size: int) -> Chunk:
    """The Chunk record a chunk index entry points to (``length`` includes opcode and length).

    The index's length is used, not the record's own (which may be the damaged part); the
    chunk's CRC (and the consistency checks) decide whether its contents are good.
    """
    if not (offset >= 8 and length >= 9 + 40 and offset + length <= size):
        raise BadChunkError("the chunk index points outside the file")
    f.seek(offset)
    body = f.read(length)[9:]
    try:
        return Chunk.read(ReadDataStream(BytesIO(body)))
    except PARSE_ERRORS as err:
        raise BadChunkError(
            f"no readable chunk where the chunk index points ({type(err).__name__})"
        ) from None


class _Collector:
    """Schemas, channels and messages in file order, with the callbacks of ``scan``."""

    def __init__(
        self,
        out: Salvage,
        on_channel: Callable[[Channel, Schema], None] | None,
        on_message: Callable[[Channel, Message], None] | None,
    ) -> None:
        self.out, self.on_channel, self.on_message = out, on_channel, on_message
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.store = schema.typestore()

    def take(self, rec: Any) -> None:
        out = self.out
        if isinstance(rec, Schema):
            self.schemas.setdefault(rec.id, rec)
        elif isinstance(rec, Channel):
            if rec.id not in self.channels and rec.schema_id in self.schemas:
                self.channels[rec.id] = rec
                if self.on_channel is not None:
                    self.on_channel(rec, self.schemas[rec.schema_id])
        elif isinstance(rec, Message):
            ch = self.channels.get(rec.channel_id)
            if ch is None:
                return
            out.counts[ch.topic] = out.counts.get(ch.topic, 0) + 1
            out.first_ns = rec.log_time if out.first_ns is None else min(out.first_ns, rec.log_time)
            out.last_ns = rec.log_time if out.last_ns is None else max(out.last_ns, rec.log_time)
            if ch.topic in (schema.RUN_INFO, schema.CONFIG) and out.counts[ch.topic] == 1:
                _provenance(out, ch.topic, self.schemas[ch.schema_id].name, rec.data, self.store)
            if self.on_message is not None:
                self.on_message(ch, rec)

    def chunk(self, rec: Chunk, offset: int) -> None:
        try:
            inner = open_chunk(rec)
            _check_chunk(inner, rec, self.schemas, self.channels)
        except BadChunkError as err:
            self.out.damaged.append(
                ChunkDamage(offset, str(err), rec.message_start_time, rec.message_end_time)
            )
            return
        for r in inner:
            self.take(r)
        self.out.chunks += 1
        self.out.chunks_with_crc += int(rec.uncompressed_crc != 0)


def _records(f: BinaryIO, size: int) -> Iterator[Any]:
    """Records of the file in order; no record may claim more bytes than the file has."""
    return StreamReader(f, emit_chunks=True, record_size_limit=max(size, 1)).records


def scan(
    mcap: Path,
    *,
    on_channel: Callable[[Channel, Schema], None] | None = None,
    on_message: Callable[[Channel, Message], None] | None = None,
) -> Salvage:
    """Read ``mcap`` and report what is readable, calling back for each channel and message.

    Raises:
        RecordingInputError: the file is not an MCAP file at all.
    """
    size = mcap.stat().st_size
    out = Salvage(mcap, size)
    take = _Collector(out, on_channel, on_message)
    with mcap.open("rb") as f:
        try:
            for rec in _records(f, size):
                pos = f.tell()
                if isinstance(rec, Chunk):
                    take.chunk(rec, out.readable_bytes)
                elif isinstance(rec, (DataEnd, Footer)):
                    out.complete = True
                    break
                else:
                    take.take(rec)
                out.readable_bytes = pos
        except InvalidMagic:
            raise RecordingInputError(
                "not an MCAP file",
                str(mcap),
                "no MCAP magic at its start",
                "point to a simlan_data recording",
            ) from None
        except EndOfFile:
            out.stop_reason = (
                "the file is empty"
                if size <= 8
                else "a record runs past the end of the file (cut short, or a damaged length)"
            )
        except PARSE_ERRORS as err:
            first = str(err).strip().splitlines()[0] if str(err).strip() else ""
            out.stop_reason = f"{type(err).__name__}: {first}" if first else type(err).__name__
        if out.stop_reason:
            out.tail_chunk = _tail_chunk_times(f, out.readable_bytes, size)
        # chunks the summary indexes beyond where reading stopped (none in a healthy file)
        if _resume_from_summary(f, size, out, take) and out.complete:
            out.stop_reason = "a damaged record read as the end of the data"
        if out.complete:
            out.readable_bytes = size
    return out


def _resume_from_summary(f: BinaryIO, size: int, out: Salvage, take: _Collector) -> int:
    """Read the chunks the summary section indexes beyond where reading stopped; how many."""
    try:
        f.seek(0)  # the reader checks the magic where the stream stands
        summary = SeekingReader(f, record_size_limit=max(size, 1)).get_summary()
    except Exception:  # no (readable) summary: an unfinished file, the usual case
        return 0
    if summary is None:
        return 0
    later = sorted(
        (ci for ci in summary.chunk_indexes if ci.chunk_start_offset >= out.readable_bytes),
        key=lambda ci: ci.chunk_start_offset,
    )
    if not later:
        return 0
    out.tail_chunk = None  # not an unfinished chunk: a damaged record in a finished file
    for sid, sch in sorted(summary.schemas.items()):
        take.schemas.setdefault(sid, sch)
    for _, ch in sorted(summary.channels.items()):
        take.take(ch)
    for ci in later:
        try:
            rec = _chunk_at(f, ci.chunk_start_offset, ci.chunk_length, size)
        except BadChunkError as err:
            out.damaged.append(
                ChunkDamage(ci.chunk_start_offset, str(err), ci.message_start_time, ci.message_end_time)
            )
            continue
        take.chunk(rec, ci.chunk_start_offset)
        out.resumed_from_index += 1
    return len(later)


def _provenance(out: Salvage, topic: str, msgtype: str, data: bytes, store: Any) -> None:
    try:
        msg = store.deserialize_cdr(data, msgtype)
    except Exception:  # a damaged provenance message only costs the custom_data
        return
    if topic == schema.RUN_INFO:
        out.run_info = msg
    else:
        with contextlib.suppress(yaml.YAMLError, AttributeError):
            cfg = yaml.safe_load(msg.data)
            out.config = cfg if isinstance(cfg, dict) else {}
