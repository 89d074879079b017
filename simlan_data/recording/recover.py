"""Recover a recording whose run crashed: keep every complete chunk, rebuild summary and metadata.

A killed run leaves ``recording.mcap`` without its summary section and the bag without
``metadata.yaml``. The file is read front to back with the ``mcap`` library's streaming reader
(no seeking, no trust in the missing summary)::

    recording.mcap --StreamReader--> Header, Chunk, MessageIndex, ..., Chunk, <partial chunk>
        each Chunk: size bounds -> zstd (bounded) -> CRC32 -> Schema/Channel/Message records
        a record cut short or unreadable ends the readable part; a chunk failing its CRC is skipped
    --> RecordingWriter (a new bag beside the old: same topics, message bytes, log times)
    --> verify with RecordingReader --> commit: original kept as recording.mcap.damaged,
        new file renamed over it, metadata.yaml renamed in last (the commit point)

A recording that is complete and intact is left alone. The run directory's ``RUNNING`` marker
(which says how far the simulated clock got) becomes ``INCOMPLETE``, and the recovered
metadata's custom_data says ``simlan.recovered: 'true'``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import struct
import sys
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import yaml
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # pragma: no cover - rosbags depends on backports.zstd before 3.14
    from backports import zstd

from ..constants import DAMAGED_SUFFIX, NS_PER_S, RECORDING_DIRNAME
from ..errors import RecordingError, RecordingInputError
from ..run_marker import RunMarker, mark_incomplete, read_running, writer_alive
from . import schema
from .reader import METADATA_KEY_FORMAT, RecordingReader
from .writer import RecordingWriter

MAX_CHUNK_BYTES = (
    1 << 30
)  # an uncompressed chunk larger than this is not ours (rosbags: ~1 MiB + one message)
WORK_DIRNAME = ".recover"
RECOVERED_KEY = "simlan.recovered"
_PARSE_ERRORS = (
    McapError,
    struct.error,
    ValueError,
    UnicodeDecodeError,
    EOFError,
    OverflowError,
    MemoryError,
)


class _BadChunkError(Exception):
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
    stop_reason: str = ""  # why reading stopped before the end, if it did
    tail_chunk: tuple[int, int] | None = None  # time range of an unfinished chunk at the end
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
        return self.complete and not self.damaged


@dataclass
class RecoveryReport:
    """What a recovery found, wrote and lost."""

    bag: Path
    salvage: Salvage
    had_metadata: bool
    marker: RunMarker | None
    written: bool = False
    damaged_copy: Path | None = None
    incomplete_marker: Path | None = None

    @property
    def intended_s(self) -> float | None:
        if self.salvage.config.get("duration_s") is not None:
            with contextlib.suppress(TypeError, ValueError):
                return float(self.salvage.config["duration_s"])
        return self.marker.duration_s if self.marker is not None and self.marker.duration_s > 0 else None

    @property
    def recovered_until_s(self) -> float:
        return (self.salvage.last_ns or 0) / NS_PER_S

    @property
    def reached_s(self) -> float | None:
        """How far the run's simulated clock got (its RUNNING marker), if known."""
        return self.marker.simulated_s if self.marker is not None and self.marker.pid > 0 else None

    def summary(self) -> dict[str, Any]:
        """Machine-readable summary (the INCOMPLETE marker and --json)."""
        s = self.salvage
        return {
            "recording": str(self.bag),
            "complete_before": s.intact and self.had_metadata,
            "messages_recovered": s.messages,
            "recovered_until_s": round(self.recovered_until_s, 9),
            "reached_s": self.reached_s,
            "intended_duration_s": self.intended_s,
            "lost_before_crash_s": None
            if self.reached_s is None
            else round(max(0.0, self.reached_s - self.recovered_until_s), 9),
            "chunks_recovered": s.chunks,
            "chunks_damaged": len(s.damaged),
            "unreadable_bytes": s.size - s.readable_bytes,
            "topics": dict(sorted(s.counts.items())),
            "damaged_copy": str(self.damaged_copy) if self.damaged_copy else None,
        }

    def lines(self) -> list[str]:
        """The human report the CLI prints."""
        s = self.salvage
        mib = 2**20
        verb = "recovered" if self.written else "recoverable"
        if s.intact and self.had_metadata:
            return [
                f"simlan_data: {self.bag} is complete and intact ({s.messages} messages in {s.chunks} chunks, "
                f"{s.chunks_with_crc} with a CRC, all readable); nothing to recover"
            ] + (
                [
                    f"  run directory  marked {self.incomplete_marker.name}: the run stopped after finishing "
                    "its recording (no metrics.json or report.md; `python -m simlan_data.replay RUN --out DIR` computes metrics)"
                ]
                if self.incomplete_marker is not None
                else []
            )
        out = [
            f"simlan_data: {'recovered' if self.written else 'checked (dry run, nothing written)'} {self.bag}"
        ]
        tail = s.size - s.readable_bytes
        what = f"{s.readable_bytes / mib:.1f} MiB in whole records"
        if tail:
            why = "an unfinished chunk" if s.tail_chunk is not None else s.stop_reason or "unreadable"
            what += f", the last {tail / 1024:.1f} KiB unreadable ({why})"
        out.append(f"  file           {s.mcap.name}: {what}")
        span = f"{(s.first_ns or 0) / NS_PER_S:.3f} .. {self.recovered_until_s:.3f} s" if s.messages else "-"
        out.append(
            f"  {verb:<14} {s.messages} messages on {len(s.counts)} topics, {span} (simulated clock), {s.chunks} chunks"
        )
        lost = []
        if s.tail_chunk is not None:
            lost.append(
                f"an unfinished chunk with stamps {s.tail_chunk[0] / NS_PER_S:.3f} .. {s.tail_chunk[1] / NS_PER_S:.3f} s"
            )
        for d in s.damaged:
            lost.append(
                f"a chunk at byte {d.offset} ({d.why}; stamps {d.start_ns / NS_PER_S:.3f} .. {d.end_ns / NS_PER_S:.3f} s)"
            )
        if self.reached_s is not None:
            gap = max(0.0, self.reached_s - self.recovered_until_s)
            lost.append(
                f"{gap:.3f} s of data before the crash (the run had simulated {self.reached_s:.3f} s)"
            )
        if self.intended_s is not None:
            end = self.reached_s if self.reached_s is not None else self.recovered_until_s
            lost.append(
                f"{max(0.0, self.intended_s - end):.3f} s never simulated (of {self.intended_s:g} s intended)"
            )
        out.append(f"  lost           {'; '.join(lost) if lost else 'nothing the file says it held'}")
        width = max((len(t) for t in s.counts), default=10)
        out.append("  messages per topic:")
        out.extend(f"    {t:<{width}} {n}" for t, n in sorted(s.counts.items()))
        if self.damaged_copy is not None:
            out.append(f"  original       kept as {self.damaged_copy} (delete it once you are satisfied)")
        if self.incomplete_marker is not None:
            out.append(f"  run directory  marked {self.incomplete_marker.name} (the run did not finish)")
        if self.written:
            out.append(f"  next           python -m simlan_data.replay {self.bag} --info")
        return out


# --------------------------------------------------------------------------------- reading
def _records(f: BinaryIO, size: int) -> Iterator[Any]:
    """Records of the file in order; no record may claim more bytes than the file has."""
    return StreamReader(f, emit_chunks=True, record_size_limit=max(size, 1)).records


def open_chunk(chunk: Chunk) -> list[Any]:
    """The Schema/Channel/Message records of a chunk, after size, decompression and CRC checks.

    Raises:
        _BadChunkError: the chunk cannot be trusted.
    """
    size = chunk.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise _BadChunkError(f"claims {size} bytes uncompressed (limit {MAX_CHUNK_BYTES})")
    if chunk.compression == "zstd":
        dec = zstd.ZstdDecompressor()
        try:
            raw = dec.decompress(chunk.data, max_length=size)
        except (zstd.ZstdError, ValueError, MemoryError) as err:
            raise _BadChunkError(f"zstd: {err}") from None
        if not dec.eof:
            raise _BadChunkError("zstd data does not end where the chunk says")
    elif chunk.compression == "":
        raw = chunk.data
    else:
        raise _BadChunkError(f"unsupported compression {chunk.compression!r}")
    if len(raw) != size:
        raise _BadChunkError(f"{len(raw)} bytes uncompressed, header says {size}")
    if chunk.uncompressed_crc and zlib.crc32(raw) != chunk.uncompressed_crc:
        raise _BadChunkError("CRC mismatch")
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
    except _PARSE_ERRORS as err:
        raise _BadChunkError(f"records unreadable ({type(err).__name__})") from None


def _tail_chunk_times(f: BinaryIO, offset: int, size: int) -> tuple[int, int] | None:
    """The time range in the header of a chunk cut short at ``offset``, if one starts there."""
    if size - offset < 1 + 8 + 16:
        return None
    f.seek(offset)
    head = f.read(25)
    if head[0] != 0x06:
        return None
    start, end = struct.unpack("<QQ", head[9:25])
    return (start, end) if start <= end else None


def scan(
    mcap: Path,
    *,
    on_channel: Callable[[Channel, Schema], None] | None = None,
    on_message: Callable[[Channel, Message], None] | None = None,
) -> Salvage:
    """Read ``mcap`` front to back and report what is readable, calling back for each record.

    Raises:
        RecordingInputError: the file is not an MCAP file at all.
    """
    size = mcap.stat().st_size
    out = Salvage(mcap, size)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    store = schema.typestore()

    def take(rec: Any) -> None:
        if isinstance(rec, Schema):
            schemas.setdefault(rec.id, rec)
        elif isinstance(rec, Channel):
            if rec.id not in channels and rec.schema_id in schemas:
                channels[rec.id] = rec
                if on_channel is not None:
                    on_channel(rec, schemas[rec.schema_id])
        elif isinstance(rec, Message):
            ch = channels.get(rec.channel_id)
            if ch is None:
                return
            out.counts[ch.topic] = out.counts.get(ch.topic, 0) + 1
            out.first_ns = rec.log_time if out.first_ns is None else min(out.first_ns, rec.log_time)
            out.last_ns = rec.log_time if out.last_ns is None else max(out.last_ns, rec.log_time)
            if ch.topic in (schema.RUN_INFO, schema.CONFIG) and out.counts[ch.topic] == 1:
                _provenance(out, ch.topic, schemas[ch.schema_id].name, rec.data, store)
            if on_message is not None:
                on_message(ch, rec)

    with mcap.open("rb") as f:
        records = _records(f, size)
        try:
            for rec in records:
                pos = f.tell()
                if isinstance(rec, Chunk):
                    try:
                        inner = open_chunk(rec)
                        _check_chunk(inner, rec, schemas, channels)
                    except _BadChunkError as err:
                        out.damaged.append(
                            ChunkDamage(
                                out.readable_bytes, str(err), rec.message_start_time, rec.message_end_time
                            )
                        )
                    else:
                        for r in inner:
                            take(r)
                        out.chunks += 1
                        out.chunks_with_crc += int(rec.uncompressed_crc != 0)
                elif isinstance(rec, (DataEnd, Footer)):
                    out.complete = True
                    out.readable_bytes = size
                    break
                else:
                    take(rec)
                out.readable_bytes = pos
        except InvalidMagic:
            raise RecordingInputError(
                "not an MCAP file",
                str(mcap),
                "no MCAP magic at its start",
                "point to a simlan_data recording",
            ) from None
        except EndOfFile:
            out.stop_reason = "the file ends inside a record" if out.readable_bytes else "the file is empty"
            out.tail_chunk = _tail_chunk_times(f, out.readable_bytes, size)
        except _PARSE_ERRORS as err:
            first = str(err).strip().splitlines()[0] if str(err).strip() else ""
            out.stop_reason = f"{type(err).__name__}: {first}" if first else type(err).__name__
            out.tail_chunk = _tail_chunk_times(f, out.readable_bytes, size)
    return out


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
            raise _BadChunkError("a message contradicts the chunk header")


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


# --------------------------------------------------------------------------------- writing
def _find_mcap(bag: Path) -> Path:
    files = sorted(p for p in bag.glob("*.mcap") if p.is_file())
    if not files:
        raise RecordingInputError(
            "nothing to recover",
            str(bag),
            "no .mcap file in it",
            "point to a recording directory (the run directory's recording/)",
        )
    if len(files) > 1:
        raise RecordingInputError(
            "recording has several MCAP files",
            str(bag),
            ", ".join(f.name for f in files),
            "simlan_data writes one; move the others away",
        )
    return files[0]


def resolve_bag(path: Path | str) -> Path:
    """The recording directory of a run directory, recording directory or file in it."""
    p = Path(path)
    if p.is_file():
        p = p.parent
    if not p.exists():
        raise RecordingInputError("no such recording", str(p), "no such file or directory", "check the path")
    if not any(p.glob("*.mcap")) and (p / RECORDING_DIRNAME).is_dir():
        p = p / RECORDING_DIRNAME
    return p


def _custom_data(bag: Path, salvage: Salvage) -> dict[str, str]:
    data: dict[str, str] = {}
    meta = bag / "metadata.yaml"
    if meta.is_file():
        with contextlib.suppress(Exception):
            old = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"].get("custom_data") or {}
            data.update({str(k): str(v) for k, v in old.items()})
    info = salvage.run_info
    if info is not None and METADATA_KEY_FORMAT not in data:
        data.update(
            {
                METADATA_KEY_FORMAT: str(info.format_version),
                "simlan.version": str(info.simlan_data_version),
                "simlan.seed": str(info.seed),
                "simlan.scenario": str(info.scenario),
                "simlan.renderer": str(info.renderer),
            }
        )
    return data


def recover(path: Path | str, *, dry_run: bool = False, force: bool = False) -> RecoveryReport:
    """Rebuild a crashed recording in place (see the module docstring); returns the report.

    Raises:
        RecordingInputError: not a recording, still being written, nothing readable.
        RecordingError: writing the repaired recording failed (the original is untouched).
    """
    bag = resolve_bag(path)
    run_dir = bag.parent
    marker = read_running(run_dir)
    if marker is not None and writer_alive(marker) and not force:
        raise RecordingInputError(
            "recording is still being written",
            str(bag),
            f"process {marker.pid} on {marker.host} is running it (simulated {marker.simulated_s:.1f} s)",
            "wait for it to finish, or stop it first (--force recovers anyway)",
        )
    mcap = _find_mcap(bag)
    had_metadata = (bag / "metadata.yaml").is_file()
    probe = scan(mcap)
    report = RecoveryReport(bag, probe, had_metadata, marker)
    if probe.intact and had_metadata and marker is not None and not dry_run:
        # the recording was finished; the run died while writing metrics.json or report.md
        report.incomplete_marker = mark_incomplete(run_dir, report.summary())
    if (probe.intact and had_metadata) or dry_run:
        return report
    if probe.messages == 0:
        raise RecordingInputError(
            "nothing to recover",
            str(mcap),
            f"no complete chunk in the file ({probe.stop_reason or 'empty'})",
            "the run stopped before its first flush; record it again",
        )
    damaged = mcap.with_name(mcap.name + DAMAGED_SUFFIX)
    if damaged.exists():
        raise RecordingInputError(
            "a previous recovery left its original behind",
            str(damaged),
            "recovering again would replace the only copy of the damaged file",
            "move it away, then rerun",
        )
    report.salvage = _rewrite(bag, mcap)
    # commit: keep the original under another name (a hard link: no copy, no window without a
    # file), put the new MCAP in place, then metadata.yaml (readers need it: the commit point)
    work = bag / WORK_DIRNAME / bag.name
    new_mcap = work / f"{bag.name}.mcap"
    try:
        os.link(mcap, damaged)
    except OSError:
        shutil.copy2(mcap, damaged)
    if had_metadata:
        os.replace(bag / "metadata.yaml", bag / f"metadata.yaml{DAMAGED_SUFFIX}")
    os.replace(new_mcap, bag / new_mcap.name)
    if mcap.name != new_mcap.name:
        mcap.unlink()
    os.replace(work / "metadata.yaml", bag / "metadata.yaml")
    shutil.rmtree(bag / WORK_DIRNAME, ignore_errors=True)
    _fsync(bag)
    report.written, report.damaged_copy = True, damaged
    if marker is not None:
        report.incomplete_marker = mark_incomplete(run_dir, report.summary())
    return report


def _rewrite(bag: Path, mcap: Path) -> Salvage:
    """Write the readable part of ``mcap`` as a new bag under ``bag/.recover/``; verify it."""
    shutil.rmtree(bag / WORK_DIRNAME, ignore_errors=True)
    (bag / WORK_DIRNAME).mkdir()
    work = bag / WORK_DIRNAME / bag.name
    store = schema.typestore()
    writer = RecordingWriter(work, compression="zstd", flush_period_ns=2**62, fsync=True)
    topics: dict[int, schema.Topic] = {}

    def on_channel(ch: Channel, sch: Schema) -> None:
        msgtype = sch.name
        try:
            rihs01 = store.hash_rihs01(msgtype)
        except Exception:  # a type this version does not know: keep its definition, no hash
            rihs01 = "RIHS01_" + "0" * 64
        writer.add_connection(ch.topic, msgtype, msgdef=sch.data.decode("utf-8", "replace"), rihs01=rihs01)
        topics[ch.id] = schema.Topic(ch.topic, msgtype, "")

    def on_message(ch: Channel, msg: Message) -> None:
        writer.write_serialized(topics[ch.id], msg.log_time, bytes(msg.data))

    try:
        writer.open()
        salvage = scan(mcap, on_channel=on_channel, on_message=on_message)
        for key, value in sorted(_custom_data(bag, salvage).items()):
            writer.set_metadata(key, value)
        writer.set_metadata(RECOVERED_KEY, "true")
        writer.set_metadata("simlan.recovered_until_ns", str(salvage.last_ns or 0))
        writer.set_metadata("simlan.recovered_damaged_chunks", str(len(salvage.damaged)))
        writer.close()
        for written in (work / f"{bag.name}.mcap", work / "metadata.yaml"):
            _fsync(written)
        with RecordingReader(work, check_format=False) as check:
            if check.message_count != salvage.messages:
                raise RecordingError(
                    "recovery failed",
                    str(bag),
                    f"wrote {check.message_count} messages, read {salvage.messages}",
                    "report this; the original file is untouched",
                )
    except BaseException:
        with contextlib.suppress(Exception):
            writer.abort()
        shutil.rmtree(bag / WORK_DIRNAME, ignore_errors=True)
        raise
    return salvage


def _fsync(path: Path) -> None:
    """Force a file (or a directory's entries) to the disk, where the platform allows."""
    flags = os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if path.is_dir() else 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        return
    try:
        with contextlib.suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)
