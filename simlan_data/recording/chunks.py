"""Reading one MCAP chunk strictly: size, decompression, CRC, then every record's length and body.

    Chunk --chunk_data (size <= MAX_CHUNK_BYTES, zstd into at most that size, CRC32)--> bytes
          --chunk_records (every length must fit, every body must parse)--> records up to the
            first unreadable one, and where and why it stopped
    check_chunk: a chunk without a CRC whose messages name unknown channels or lie outside its
    header's time range is refused

Used by ``salvage.scan`` (which keeps what a damaged chunk held before its damage and names the
rest as lost); any failure is a :class:`BadChunkError` whose message says why.
"""

from __future__ import annotations

import struct
import sys
import zlib
from dataclasses import dataclass
from io import BytesIO
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # pragma: no cover - rosbags depends on backports.zstd before 3.14
    from backports import zstd

MAX_CHUNK_BYTES = (
    1 << 30
)  # an uncompressed chunk larger than this is not ours (rosbags: ~1 MiB + one message)
CHUNK_OPCODE = 0x06
PARSE_ERRORS = (McapError, struct.error, ValueError, UnicodeDecodeError, EOFError, OverflowError, MemoryError)


class BadChunkError(Exception):
    """A chunk whose records cannot be trusted (the reason is the message)."""


def chunk_data(chunk: Chunk) -> bytes:
    """A chunk's records as bytes, after size, decompression and CRC checks.

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
    return raw


@dataclass
class ChunkRecords:
    """The records of a chunk's data up to the first that cannot be read."""

    records: list[tuple[int, Any]]  # (offset in the chunk's data, Schema | Channel | Message)
    damage_at: int | None = None  # where the first unreadable record starts (None: all read)
    why: str = ""
    suspect_last: bool = False  # no record starts at damage_at: the previous one's length may be wrong


def chunk_records(raw: bytes) -> ChunkRecords:
    """Parse a chunk's records strictly: every length must fit, every body must parse.

    (The mcap library's ``breakup_chunk`` stops silently where a length runs past the data, and
    skips what it does not know: a damaged length there lost the rest of the chunk unreported.)
    """
    out = ChunkRecords([])
    pos, n, view = 0, len(raw), memoryview(raw)
    while pos < n:
        if n - pos < 9:
            out.damage_at, out.why, out.suspect_last = pos, f"a record cut short at byte {pos}", True
            return out
        opcode, length = struct.unpack_from("<BQ", raw, pos)
        if opcode not in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
            out.damage_at, out.why, out.suspect_last = (
                pos,
                f"no record at byte {pos} (opcode {opcode:#04x})",
                True,
            )
            return out
        if length > n - pos - 9:
            out.damage_at, out.why = (
                pos,
                f"bad record length at byte {pos} ({length} bytes, {n - pos - 9} left)",
            )
            return out
        body = view[pos + 9 : pos + 9 + length]
        try:
            if opcode == Opcode.MESSAGE:
                if length < 22:
                    raise ValueError("message record too short")
                cid, seq, log_time, pub_time = struct.unpack_from("<HIQQ", body)
                rec: Any = Message(cid, log_time, bytes(body[22:]), pub_time, seq)
            else:
                rec = (Schema if opcode == Opcode.SCHEMA else Channel).read(ReadDataStream(BytesIO(body)))
        except PARSE_ERRORS:
            out.damage_at, out.why, out.suspect_last = pos, f"an unreadable record at byte {pos}", True
            return out
        out.records.append((pos, rec))
        pos += 9 + length
    return out


def open_chunk(chunk: Chunk) -> list[Any]:
    """The Schema/Channel/Message records of a chunk, after size, decompression and CRC checks.

    Raises:
        BadChunkError: the chunk cannot be trusted (in whole or in part).
    """
    parsed = chunk_records(chunk_data(chunk))
    if parsed.damage_at is not None:
        raise BadChunkError(parsed.why)
    return [r for _, r in parsed.records]


def check_chunk(
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
