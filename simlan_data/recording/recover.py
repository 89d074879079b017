"""Recover a recording whose run crashed: keep every complete chunk, rebuild summary and metadata.

A killed run leaves ``recording.mcap`` without its summary section and the bag without
``metadata.yaml``::

    recording.mcap --salvage.scan (streaming, checked)--> schemas, channels, messages
        --> RecordingWriter: a new bag under recording/.recover/ (same topics, message bytes,
            log times; chunks with CRCs, summary, metadata.yaml v9 with custom_data, the epoch
            of the recorded config among it: timebase.py)
        --> read back with RecordingReader (message count must match)
        --> commit by renames: the original kept as recording.mcap.damaged (a hard link), the
            new file over it, metadata.yaml last (the commit point: readers need it)

A recording that is complete and intact is left alone. The run directory's ``RUNNING`` marker
(which says how far the simulated clock got) becomes ``INCOMPLETE``, and the recovered
metadata's custom_data says ``simlan.recovered: 'true'``.

Every message the file held (or the run's clock reached) that is not kept is named as a time
range per topic (``recording.losses``): in the printed report, in ``INCOMPLETE`` (``losses``,
``messages_lost``, ``lost_s``) and in the recovered bag's custom_data (``replay --info``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Schema

from simlan_data.constants import DAMAGED_SUFFIX, NS_PER_S, RECORDING_DIRNAME
from simlan_data.errors import RecordingError, RecordingInputError
from simlan_data.recording import losses as L
from simlan_data.recording import schema
from simlan_data.recording.bounded import load_yaml_without_aliases, require_regular
from simlan_data.recording.reader import MAX_METADATA_BYTES, METADATA_KEY_FORMAT, RecordingReader
from simlan_data.recording.run_marker import RunMarker, mark_incomplete, read_running, writer_alive
from simlan_data.recording.salvage import Salvage, scan
from simlan_data.recording.timebase import EPOCH_KEY
from simlan_data.recording.writer import RecordingWriter

WORK_DIRNAME = ".recover"
RECOVERED_KEY = "simlan.recovered"


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

    @property
    def losses(self) -> list[L.Loss]:
        """Every range of messages not kept, per topic where known (see ``all_losses``)."""
        return all_losses(self.salvage, self.reached_s)

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
            "chunks_resumed_from_index": s.resumed_from_index,
            "topics": dict(sorted(s.counts.items())),
            **({} if s.intact and self.had_metadata else L.totals(self.losses)),
            "damaged_copy": str(self.damaged_copy) if self.damaged_copy else None,
        }

    def _loss_lines(self) -> list[str]:
        losses = self.losses
        if not losses:
            return ["  lost messages  none"]
        known = sum(x.messages or 0 for x in losses)
        unknown = " and an unknown number" if any(x.messages is None for x in losses) else ""
        topics = {x.topic for x in losses}
        on = "" if L.ALL_TOPICS in topics else f" on {len(topics)} topic{'s' * (len(topics) != 1)}"
        out = [f"  lost messages  {known}{unknown}{on}, {L.lost_s(losses):.3f} s of simulated time:"]
        cause = None
        for x in losses[: L.MAX_LISTED]:  # grouped by where and why (one damaged chunk: one group)
            if x.cause != cause:
                cause = x.cause
                out.append(f"    {cause}:")
            d = x.as_dict()
            out.append(f"      {L.describe(x.topic, d['from_s'], d['to_s'], x.messages)}")
        if len(losses) > L.MAX_LISTED:
            out.append(f"    ... and {len(losses) - L.MAX_LISTED} more ranges")
        return out

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
        if s.resumed_from_index:
            what += (
                f", then a damaged record ({s.stop_reason}); {s.resumed_from_index} later chunks read "
                "through the summary's chunk index"
            )
        elif tail:
            why = "an unfinished chunk" if s.tail_chunk is not None else s.stop_reason or "unreadable"
            what += f", the last {tail / 1024:.1f} KiB unreadable ({why})"
        elif s.complete and not self.had_metadata:
            what += " (complete; metadata.yaml missing, unreadable or disagreeing)"
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
                f"{gap:.3f} s of data before {self.reached_s:.3f} s, the last camera tick the run "
                "reported (it crashed before the next)"
            )
        if self.intended_s is not None:
            end = self.reached_s if self.reached_s is not None else self.recovered_until_s
            lost.append(
                f"{max(0.0, self.intended_s - end):.3f} s never simulated (of {self.intended_s:g} s intended)"
            )
        out.append(f"  lost           {'; '.join(lost) if lost else 'nothing the file says it held'}")
        out.extend(self._loss_lines())
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


def all_losses(salvage: Salvage, reached_s: float | None) -> list[L.Loss]:
    """What the file lost (``salvage.losses``), then what lies beyond its readable part.

    Bytes at the end that are no whole record (garbage, or a record cut short) are named with
    the time range they may have held: from the last time the file speaks of to how far the run's
    clock got (its RUNNING marker), or open-ended if that is unknown. Without such bytes, the same
    range is what the run never wrote (it stopped before its next flush).
    """
    s = salvage
    out = list(s.losses)
    covered = s.covered_ns or 0
    reached = None if reached_s is None else round(reached_s * NS_PER_S)
    further = reached is not None and reached > covered
    tail = s.size - s.readable_bytes
    if tail and s.tail_chunk is None and not s.complete and not s.resumed_from_index:
        why = f"{tail} bytes from byte {s.readable_bytes} are unreadable ({s.stop_reason or 'not whole records'})"
        if further or reached is None:
            out.append(L.Loss(L.ALL_TOPICS, covered, reached, None, why))
    elif further:
        out.append(
            L.Loss(L.ALL_TOPICS, covered, reached, None, "not in the file: the run stopped before writing it")
        )
    return out


# --------------------------------------------------------------------------------- writing
def _find_mcap(bag: Path) -> Path:
    for p in bag.glob("*.mcap"):
        require_regular(p, "recording file")  # (a FIFO: opening it would block)
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
    if meta.is_file() and meta.stat().st_size <= MAX_METADATA_BYTES:
        with contextlib.suppress(Exception):
            text = meta.read_text()
            old = load_yaml_without_aliases(text)["rosbag2_bagfile_information"].get("custom_data") or {}
            data.update({str(k): str(v) for k, v in old.items()})
    data.setdefault(EPOCH_KEY, str(salvage.epoch_ns))  # (the writer copies log times as they are)
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
    had_metadata = had_metadata and _metadata_agrees(bag, probe)  # else it is rebuilt too
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
    report.salvage = _rewrite(bag, mcap, report.reached_s)
    # commit: keep the original under another name (a hard link: no copy, no window without a
    # file), put the new MCAP in place, then metadata.yaml (readers need it: the commit point)
    work = bag / WORK_DIRNAME / bag.name
    new_mcap = work / f"{bag.name}.mcap"
    try:
        os.link(mcap, damaged)
    except OSError:
        shutil.copy2(mcap, damaged)
    if (bag / "metadata.yaml").exists():  # damaged or disagreeing: kept beside the new one
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


def _metadata_agrees(bag: Path, probe: Salvage) -> bool:
    """True if the bag opens with its metadata.yaml and that agrees with the file's messages."""
    try:
        with RecordingReader(bag, check_format=False) as reader:
            return (
                reader.message_count == probe.messages
                and {t.name: t.count for t in reader.topics.values()} == probe.counts
            )
    except RecordingError:
        return False


def _rewrite(bag: Path, mcap: Path, reached_s: float | None) -> Salvage:
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
        writer.set_metadata(L.LOSSES_KEY, L.encode(all_losses(salvage, reached_s)))
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
