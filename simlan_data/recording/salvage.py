"""Read what a damaged or unfinished MCAP file still holds, trusting nothing in it.

    recording.mcap --StreamReader (mcap library, front to back, no seeking)-->
        Header, Chunk, MessageIndex, ..., Chunk, <cut>
        every record: its length must fit in the file (no allocation beyond the file size)
        every Chunk: declared size <= 1 GiB -> zstd into at most that size -> CRC32 -> records,
            each of whose lengths must fit -> each message names a known channel and lies in the
            chunk's time range
        a chunk failing a check is skipped (records before a bad record length inside it are
        kept) and what it lost is named per topic from its MessageIndex records (which follow
        it), or as "all topics" in its header's time range; reading stops at the first record
        that is cut short or unreadable, or at bytes that are no record (garbage)
    --(only if reading stopped early and the file still has its summary section, e.g. a damaged
       record in a finished file)--> the summary's chunk index and channel table resume reading
       at every later chunk, and its chunk index finds the message indexes of damaged chunks

Used by ``recording.recover`` (which writes what is found into a new bag) and its ``--dry-run``.
One chunk's checks and strict record parsing live in ``chunks.py``.
Callbacks get the file's records as they are; :class:`Salvage` times are simulated time (the
file's bag time less the recorded config's ``recording.epoch``, 0 if none: ``timebase.py``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO

import yaml
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, InvalidMagic
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Message, MessageIndex, Schema
from mcap.stream_reader import read_magic

from simlan_data.errors import RecordingInputError
from simlan_data.recording import schema
from simlan_data.recording.bounded import load_yaml_without_aliases, require_regular
from simlan_data.recording.chunks import (
    CHUNK_OPCODE,
    PARSE_ERRORS,
    BadChunkError,
    ChunkRecords,
    check_chunk,
    chunk_data,
    chunk_records,
)
from simlan_data.recording.losses import ALL_TOPICS, Loss
from simlan_data.recording.timebase import parse_epoch


class NotRecordsError(Exception):
    """Bytes where a record should start that are no MCAP record (garbage, or zeros after a crash)."""


@dataclass(frozen=True)
class ChunkDamage:
    """A chunk that was skipped (or kept only up to a damaged record): where, why, its header's times."""

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
    losses: list[Loss] = field(default_factory=list)  # messages the file held that are not kept
    counts: dict[str, int] = field(default_factory=dict)  # topic -> messages recovered
    first_ns: int | None = None
    last_ns: int | None = None
    run_info: Any = None
    config: dict[str, Any] = field(default_factory=dict)
    epoch_ns: int = 0  # of the recorded config: the file's log times less this are the times above

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    @property
    def intact(self) -> bool:
        return self.complete and not self.damaged and not self.stop_reason

    @property
    def covered_ns(self) -> int | None:
        """The latest time the file's readable part speaks of (recovered, or named as lost)."""
        ends = [t for t in (self.last_ns, *(d.end_ns for d in self.damaged)) if t is not None]
        if self.tail_chunk is not None:
            ends.append(self.tail_chunk[1])
        return max(ends, default=None)


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


def _indexes_at(f: BinaryIO, ci: ChunkIndex, size: int) -> list[MessageIndex] | None:
    """The MessageIndex records a chunk index entry points to, or None if any is unreadable."""
    out = []
    for offset in ci.message_index_offsets.values():
        if not 8 <= offset <= size - 9:
            return None
        f.seek(offset)
        opcode, length = struct.unpack("<BQ", f.read(9))
        if opcode != Opcode.MESSAGE_INDEX or length > min(size - offset - 9, ci.message_index_length):
            return None
        try:
            out.append(MessageIndex.read(ReadDataStream(BytesIO(f.read(length)))))
        except PARSE_ERRORS:
            return None
    return out


@dataclass
class _Damaged:
    """A damaged chunk waiting for its MessageIndex records (which follow it in the file)."""

    offset: int
    start_ns: int
    end_ns: int
    size: int  # of its uncompressed data
    why: str
    parsed: ChunkRecords  # what was readable before the damage (nothing for a bad CRC)
    index: list[MessageIndex] = field(default_factory=list)


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
        self.orphans: dict[int, list[int]] = {}  # channel id -> [count, first, last] without a channel

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
            if ch is None:  # its Channel record was lost (with a damaged chunk): reported
                o = self.orphans.setdefault(rec.channel_id, [0, rec.log_time, rec.log_time])
                o[0], o[1], o[2] = o[0] + 1, min(o[1], rec.log_time), max(o[2], rec.log_time)
                return
            out.counts[ch.topic] = out.counts.get(ch.topic, 0) + 1
            out.first_ns = rec.log_time if out.first_ns is None else min(out.first_ns, rec.log_time)
            out.last_ns = rec.log_time if out.last_ns is None else max(out.last_ns, rec.log_time)
            if ch.topic in (schema.RUN_INFO, schema.CONFIG) and out.counts[ch.topic] == 1:
                _provenance(out, ch.topic, self.schemas[ch.schema_id].name, rec.data, self.store)
            if self.on_message is not None:
                self.on_message(ch, rec)

    def chunk(self, rec: Chunk, offset: int) -> _Damaged | None:
        """Take an intact chunk's records; a damaged one is returned to wait for its index."""
        damaged = _Damaged(
            offset,
            rec.message_start_time,
            rec.message_end_time,
            rec.uncompressed_size,
            "",
            ChunkRecords([], 0),
        )
        try:
            parsed = chunk_records(chunk_data(rec))
            check_chunk([r for _, r in parsed.records], rec, self.schemas, self.channels)
        except BadChunkError as err:
            damaged.why = str(err)
            return damaged
        if parsed.damage_at is not None:
            damaged.why, damaged.parsed = parsed.why, parsed
            return damaged
        for _, r in parsed.records:
            self.take(r)
        self.out.chunks += 1
        self.out.chunks_with_crc += int(rec.uncompressed_crc != 0)
        return None

    def finish(self, d: _Damaged, index: list[MessageIndex] | None, index_whole: bool) -> None:
        """Keep what a damaged chunk still holds; name what it lost (exactly, where its index tells)."""
        entries = self._entries(d, index)
        parsed = d.parsed
        at = parsed.damage_at or 0
        kept = list(parsed.records)
        starts = {off for es in (entries or {}).values() for _, off in es}
        if at and parsed.suspect_last and at not in starts:
            # no record starts where the damage does: the last record's own length may be wrong
            last = max((i for i, (_, r) in enumerate(kept) if isinstance(r, Message)), default=None)
            if last is not None:
                at = kept[last][0]
                kept = [x for i, x in enumerate(kept) if i < last or not isinstance(x[1], Message)]
        for _, r in kept:
            self.take(r)
        cause = f"{d.why} in the chunk at byte {d.offset}"
        self.out.damaged.append(ChunkDamage(d.offset, d.why, d.start_ns, d.end_ns))
        if entries is None:
            self.out.losses.append(Loss(ALL_TOPICS, d.start_ns, d.end_ns, None, cause))
            return
        for cid, es in sorted(entries.items()):
            lost = [t for t, off in es if off >= at]
            if lost:
                ch = self.channels.get(cid)
                topic = ch.topic if ch is not None else f"<channel {cid}>"
                self.out.losses.append(Loss(topic, min(lost), max(lost), len(lost), cause))
        if not index_whole:
            self.out.losses.append(
                Loss(ALL_TOPICS, d.start_ns, d.end_ns, None, f"{cause}; its message index is cut short")
            )

    def _entries(
        self, d: _Damaged, index: list[MessageIndex] | None
    ) -> dict[int, list[tuple[int, int]]] | None:
        """channel id -> (log time, offset) of the chunk's messages, if its index is plausible."""
        if not index:
            return None
        out: dict[int, list[tuple[int, int]]] = {}
        for mi in index:
            if not all(d.start_ns <= t <= d.end_ns and 0 <= off < d.size for t, off in mi.records):
                return None
            out.setdefault(mi.channel_id, []).extend(mi.records)
        return out

    def orphan_losses(self) -> None:
        for cid, (n, first, last) in sorted(self.orphans.items()):
            self.out.losses.append(
                Loss(f"<channel {cid}>", first, last, n, f"channel {cid} is defined in a lost chunk")
            )


_PARSED: dict[int, Any] = {
    Opcode.CHUNK: Chunk,
    Opcode.MESSAGE_INDEX: MessageIndex,
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.DATA_END: DataEnd,
    Opcode.FOOTER: Footer,
}
RECORD_OPCODES = frozenset(int(op) for op in Opcode)  # 0x01 (Header) .. 0x0F (DataEnd)


def _records(f: BinaryIO, size: int) -> Iterator[tuple[int, Any]]:
    """(offset, record) of the file's records in order (None for those recovery skips).

    No record may claim more bytes than the file has, and each must parse within its length.

    Raises:
        InvalidMagic: not an MCAP file.
        EndOfFile: the file ends inside a record (cut short, or a length is damaged).
        NotRecordsError: where a record should start, bytes that are no record.
        ValueError: a record's contents are unreadable.
    """
    read_magic(ReadDataStream(f))
    pos = 8
    while True:
        head = f.read(9)
        if head and head[0] not in RECORD_OPCODES:
            raise NotRecordsError(pos)
        if len(head) < 9:
            raise EndOfFile()
        opcode, length = struct.unpack("<BQ", head)
        if length > size - pos - 9:
            raise EndOfFile()
        body = f.read(length)
        if len(body) < length:
            raise EndOfFile()
        kind = _PARSED.get(opcode)
        if opcode == Opcode.MESSAGE:
            kind = Message
        rec = None
        if kind is not None:
            try:
                stream = ReadDataStream(BytesIO(body))
                rec = kind.read(stream, length) if kind is Message else kind.read(stream)
            except PARSE_ERRORS:
                raise ValueError(f"an unreadable {kind.__name__} record at byte {pos}") from None
        yield pos, rec
        pos += 9 + length


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
    require_regular(mcap, "recording file")  # (a FIFO: opening it would block)
    size = mcap.stat().st_size
    out = Salvage(mcap, size)
    take = _Collector(out, on_channel, on_message)
    pending: _Damaged | None = None  # a damaged chunk whose MessageIndex records may follow
    with mcap.open("rb") as f:
        try:
            for offset, rec in _records(f, size):
                pos = f.tell()
                if pending is not None and isinstance(rec, MessageIndex):
                    pending.index.append(rec)
                elif pending is not None:
                    take.finish(pending, pending.index, index_whole=True)
                    pending = None
                if isinstance(rec, Chunk):
                    pending = take.chunk(rec, offset)
                elif isinstance(rec, (DataEnd, Footer)):
                    out.complete = True
                    break
                elif rec is not None and not isinstance(rec, MessageIndex):
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
        except NotRecordsError:
            out.stop_reason = (
                f"the {size - out.readable_bytes} bytes from byte {out.readable_bytes} are not MCAP records"
            )
        except PARSE_ERRORS as err:
            first = str(err).strip().splitlines()[0] if str(err).strip() else ""
            out.stop_reason = f"{type(err).__name__}: {first}" if first else type(err).__name__
        if out.stop_reason:
            out.tail_chunk = _tail_chunk_times(f, out.readable_bytes, size)
        summary = _summary(f, size)
        if pending is not None:  # reading stopped among its message indexes: the summary may know them
            ci = (
                next((c for c in summary.chunk_indexes if c.chunk_start_offset == pending.offset), None)
                if summary
                else None
            )
            index = _indexes_at(f, ci, size) if ci is not None else None
            if index is not None:
                take.finish(pending, index, index_whole=True)
            else:
                take.finish(pending, pending.index, index_whole=out.complete)
        # chunks the summary indexes beyond where reading stopped (none in a healthy file)
        if _resume_from_summary(f, size, out, take, summary) and out.complete:
            out.stop_reason = "a damaged record read as the end of the data"
        if out.complete:
            out.readable_bytes = size
        if out.tail_chunk is not None:
            start, end = out.tail_chunk
            out.losses.append(
                Loss(
                    ALL_TOPICS,
                    start,
                    end,
                    None,
                    f"the file ends inside the chunk at byte {out.readable_bytes}",
                )
            )
        take.orphan_losses()
    _to_simulated_time(out)
    return out


def _to_simulated_time(out: Salvage) -> None:
    """Turn the file's times (bag time) into simulated time, by the recorded config's epoch."""
    epoch = (out.config.get("recording") or {}).get("epoch") if isinstance(out.config, dict) else None
    with contextlib.suppress(ValueError, AttributeError):
        out.epoch_ns = parse_epoch(str(epoch)) if epoch is not None else 0
    e = out.epoch_ns
    out.first_ns, out.last_ns = (None if t is None else t - e for t in (out.first_ns, out.last_ns))
    out.tail_chunk = None if out.tail_chunk is None else (out.tail_chunk[0] - e, out.tail_chunk[1] - e)
    out.damaged = [dataclasses.replace(d, start_ns=d.start_ns - e, end_ns=d.end_ns - e) for d in out.damaged]
    out.losses = [
        dataclasses.replace(x, from_ns=x.from_ns - e, to_ns=None if x.to_ns is None else x.to_ns - e)
        for x in out.losses
    ]


def _summary(f: BinaryIO, size: int) -> Any:
    """The file's summary section, if it has a readable one."""
    try:
        f.seek(0)  # the reader checks the magic where the stream stands
        return SeekingReader(f, record_size_limit=max(size, 1)).get_summary()
    except Exception:  # no (readable) summary: an unfinished file, the usual case
        return None


def _resume_from_summary(f: BinaryIO, size: int, out: Salvage, take: _Collector, summary: Any) -> int:
    """Read the chunks the summary section indexes beyond where reading stopped; how many."""
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
            damaged: _Damaged | None = _Damaged(
                ci.chunk_start_offset,
                ci.message_start_time,
                ci.message_end_time,
                ci.uncompressed_size,
                str(err),
                ChunkRecords([], 0),
            )
        else:
            damaged = take.chunk(rec, ci.chunk_start_offset)
            out.resumed_from_index += damaged is None
        if damaged is not None:
            take.finish(damaged, _indexes_at(f, ci, size), index_whole=True)
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
            cfg = load_yaml_without_aliases(msg.data)  # (an alias bomb must not hang recover)
            out.config = cfg if isinstance(cfg, dict) else {}
