"""Crash safety: bounded loss under SIGKILL, chunk CRCs, recovery of truncated and corrupted bags.

The bags are written by the real RecordingWriter (worker threads, I/O thread) and read back with
the independent mcap reader; SIGKILL is real (a child process frozen with SIGSTOP at an arbitrary
point, then killed).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import time
from io import BytesIO
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from mcap.records import Chunk
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from reliability_helpers import REPO, LineWatcher, Msg, finish_kill, messages_in_file_order, payload_digest

from conftest import run_cli
from simlan_data.constants import NS_PER_S
from simlan_data.errors import RecordingInputError
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.codecs import encode_rgb
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.recover import recover
from simlan_data.recording.run_marker import RunMarker, write_running
from simlan_data.recording.salvage import scan
from simlan_data.recording.writer import RecordingWriter

CLOCK = next(t for t in schema.GLOBAL_TOPICS if t.name == schema.CLOCK)
CAM = schema.camera_topics("1", rgb="png", depth=None, semantic=None)

# A writer whose encoders are slower than its producer (50 ms per image on 2 threads, an image
# every 10 simulated steps): without back-pressure at the flush marks, the I/O would fall seconds
# of simulated time behind and a kill would lose far more than the flush period.
WRITER_SCRIPT = r"""
import sys, time
import numpy as np
from simlan_data.constants import NS_PER_S
from simlan_data.recording import messages as M, schema
from simlan_data.recording.codecs import encode_rgb
from simlan_data.recording.writer import RecordingWriter

clock = next(t for t in schema.GLOBAL_TOPICS if t.name == schema.CLOCK)
cam = schema.camera_topics("1", rgb="png", depth=None, semantic=None)["rgb"]
rng = np.random.default_rng(0)

def slow_image(img, t):
    time.sleep(0.05)
    return M.compressed_image(t, "camera_1", *encode_rgb(img, "png"))

period_ns = int(float(sys.argv[2]) * NS_PER_S)
with RecordingWriter(sys.argv[1], encode_threads=2, flush_period_ns=period_ns) as w:
    w.set_metadata("simlan.format_version", "1.0")
    for k in range(10**6):
        t = k * NS_PER_S // 100
        w.write(clock, t, M.clock(t))
        if k % 10 == 0:
            w.submit(cam, t, lambda a=rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), t=t: slow_image(a, t))
        print(t, flush=True)
        time.sleep(0.0005)
"""


def _small_bag(path: Path, *, seconds: float = 6.0, flush_period_s: float = 0.5, threads: int = 2) -> None:
    """A clock at 100 Hz and a 48x64 PNG camera at 10 Hz, many chunks (one per half flush period)."""
    rng = np.random.default_rng(1)
    with RecordingWriter(path, encode_threads=threads, flush_period_ns=round(flush_period_s * NS_PER_S)) as w:
        w.set_metadata("simlan.format_version", "1.0")
        for k in range(round(seconds * 100) + 1):
            t = k * NS_PER_S // 100
            w.write(CLOCK, t, M.clock(t))
            if k % 10 == 0:
                img = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
                w.submit(
                    CAM["rgb"], t, lambda a=img, t=t: M.compressed_image(t, "camera_1", *encode_rgb(a, "png"))
                )


def _chunk_ends(mcap: Path) -> list[tuple[int, int]]:
    """(end offset, messages) of every chunk record, parsed with the mcap library only."""
    out = []
    with mcap.open("rb") as f:
        for rec in StreamReader(f, emit_chunks=True).records:
            if isinstance(rec, Chunk):
                n = sum(1 for r in breakup_chunk(rec, validate_crc=True) if type(r).__name__ == "Message")
                out.append((f.tell(), n))
    return out


def _check_stream_is_whole(msgs: list[Msg]) -> float:
    """The clock ticks every 10 ms from 0 without a gap, images every 100 ms decode; last stamp (s)."""
    clock = [m.log_time for m in msgs if m.topic == schema.CLOCK]
    assert clock == [k * NS_PER_S // 100 for k in range(len(clock))]
    images = [m for m in msgs if m.topic == CAM["rgb"].name]
    assert [m.log_time for m in images] == [k * NS_PER_S // 10 for k in range(len(images))]
    store = schema.typestore()
    for m in images[-3:]:
        msg = store.deserialize_cdr(m.data, schema.COMPRESSED_IMAGE_TYPE)
        assert cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_COLOR).shape == (48, 64, 3)
    return max(m.log_time for m in msgs) / NS_PER_S


def test_chunks_carry_crcs_that_the_mcap_library_checks(tmp_path: Path) -> None:
    _small_bag(tmp_path / "bag", seconds=2)
    mcap = tmp_path / "bag" / "bag.mcap"
    with mcap.open("rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    assert len(chunks) >= 4 and all(c.uncompressed_crc != 0 for c in chunks)
    assert len(messages_in_file_order(tmp_path / "bag")) == 201 + 21
    # a flipped byte inside the first chunk's records (stored uncompressed here) fails its CRC
    bag = tmp_path / "plain"
    with RecordingWriter(bag, compression="none") as w:
        w.set_metadata("simlan.format_version", "1.0")
        for k in range(50):
            w.write(CLOCK, k * 10**7, M.clock(k * 10**7))
    data = bytearray((bag / "plain.mcap").read_bytes())
    at = data.index(b"\x06", 8)  # the first chunk record (after magic and header)
    data[at + 9 + 40 + 200] ^= 0x01  # 9: opcode+length, 40: chunk header with empty compression
    (bag / "plain.mcap").write_bytes(bytes(data))
    with pytest.raises(CRCValidationError):
        messages_in_file_order(bag)


def test_flush_marks_keep_the_file_within_one_period_of_the_newest_message(tmp_path: Path) -> None:
    """While writing with lagging encoders, the file always holds everything older than one period."""
    path = tmp_path / "bag"
    period_ns = NS_PER_S // 2
    w = RecordingWriter(path, encode_threads=2, flush_period_ns=period_ns)
    w.open()
    rng = np.random.default_rng(2)

    def slow(img: np.ndarray, t: int) -> object:
        time.sleep(0.03)
        return M.compressed_image(t, "camera_1", *encode_rgb(img, "png"))

    worst_lag_s = 0.0
    for k in range(400):  # 4 s at 100 Hz, an image every 5th step
        t = k * NS_PER_S // 100
        w.write(CLOCK, t, M.clock(t))
        if k % 5 == 0:
            img = rng.integers(0, 255, (32, 32, 3), dtype=np.uint8)
            w.submit(CAM["rgb"], t, lambda a=img, t=t: slow(a, t))
        if k % 25 == 24:
            on_disk = scan(path / "bag.mcap")
            assert on_disk.last_ns is not None or t < period_ns
            lag = (t - (on_disk.last_ns or 0)) / NS_PER_S
            worst_lag_s = max(worst_lag_s, lag)
            assert lag <= period_ns / NS_PER_S + 0.01, (t, on_disk.last_ns)
    w.close()
    assert worst_lag_s > 0.1  # the encoders did lag: the bound was exercised, not free


@pytest.mark.parametrize("kill_at_s", [0.8, 2.6, 4.4])
def test_sigkill_loses_at_most_the_flush_period(tmp_path: Path, kill_at_s: float) -> None:
    bag = tmp_path / "bag"
    period_s = 0.5
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER_SCRIPT, str(bag), str(period_s)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )
    watch = LineWatcher(proc)
    deadline = time.monotonic() + 120
    while (not watch.last() or int(watch.last()) < kill_at_s * NS_PER_S) and time.monotonic() < deadline:
        assert proc.poll() is None
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGSTOP)
    time.sleep(0.2)  # let the pump read what the frozen process had printed
    newest_s = int(watch.last()) / NS_PER_S
    finish_kill(proc)
    with pytest.raises(RecordingInputError, match=r"recording is unfinished.*python -m simlan_data.recover"):
        RecordingReader(bag)
    report = recover(bag)
    assert report.written and (bag / "bag.mcap.damaged").is_file()
    last_s = _check_stream_is_whole(messages_in_file_order(bag))
    assert last_s >= newest_s - period_s - 0.01, (newest_s, last_s)
    with RecordingReader(bag, check_format=False) as r:  # (no /simlan/run_info in this bag)
        assert r.recovered and r.message_count == report.salvage.messages


def test_recovery_after_a_cut_at_any_byte_keeps_every_complete_chunk(tmp_path: Path) -> None:
    _small_bag(tmp_path / "full")
    full = tmp_path / "full" / "full.mcap"
    reference = messages_in_file_order(tmp_path / "full")
    ends = _chunk_ends(full)
    assert len(ends) >= 10
    rng = np.random.default_rng(3)
    cuts = sorted(
        {e + d for e, _ in ends[::3] for d in (-1, 0, 1)}
        | {int(x) for x in rng.integers(8, full.stat().st_size, 12)}
    )
    data = full.read_bytes()
    for i, cut in enumerate(cuts):
        bag = tmp_path / f"cut{i}" / "recording"
        bag.mkdir(parents=True)
        (bag / "recording.mcap").write_bytes(data[:cut])
        expected = sum(n for end, n in ends if end <= cut)
        if expected == 0:
            with pytest.raises(RecordingInputError, match="nothing to recover"):
                recover(bag)
            continue
        report = recover(bag)
        got = messages_in_file_order(bag)
        assert got == reference[:expected], (cut, len(got), expected)
        assert report.salvage.messages == expected
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert meta["message_count"] == expected and meta["version"] == 9
        assert meta["custom_data"]["simlan.recovered"] == "true"


def test_a_corrupted_chunk_is_named_by_the_reader_and_skipped_by_recovery(tmp_path: Path) -> None:
    _small_bag(tmp_path / "bag", seconds=4)
    bag = tmp_path / "bag"
    reference = messages_in_file_order(bag)
    mcap = bag / "bag.mcap"
    ends = _chunk_ends(mcap)
    data = bytearray(mcap.read_bytes())
    # flip a byte in the middle of the 4th chunk's compressed data
    start = ends[2][0]
    while data[start] != 0x06:  # skip the message indexes after chunk 3
        start += 9 + struct.unpack_from("<Q", data, start + 1)[0]
    data[(start + ends[3][0]) // 2] ^= 0x40
    mcap.write_bytes(bytes(data))
    with (
        RecordingReader(bag) as r,
        pytest.raises(RecordingInputError, match=r"not a readable recording.*recover"),
    ):
        for _ in r.messages():
            pass
    report = recover(bag)
    assert len(report.salvage.damaged) == 1 and report.salvage.damaged[0].offset == start
    skipped = ends[3][1]
    kept = reference[: sum(n for _, n in ends[:3])] + reference[sum(n for _, n in ends[:4]) :]
    assert messages_in_file_order(bag) == kept and len(kept) == len(reference) - skipped
    assert "a chunk at byte" in "\n".join(report.lines())


def test_recover_refuses_what_it_cannot_or_must_not_repair(tmp_path: Path) -> None:
    not_mcap = tmp_path / "junk" / "recording"
    not_mcap.mkdir(parents=True)
    (not_mcap / "recording.mcap").write_bytes(b"this is not a bag at all" * 10)
    with pytest.raises(RecordingInputError, match=r"not an MCAP file in .*recording.mcap: no MCAP magic"):
        recover(not_mcap)
    empty = tmp_path / "empty" / "recording"
    empty.mkdir(parents=True)
    (empty / "recording.mcap").write_bytes(b"")
    with pytest.raises(RecordingInputError, match=r"nothing to recover.*the file is empty"):
        recover(empty)
    (tmp_path / "nobag").mkdir()
    with pytest.raises(RecordingInputError, match=r"nothing to recover in .*nobag: no \.mcap file"):
        recover(tmp_path / "nobag")
    # a run whose writer still runs is left alone
    run = tmp_path / "live"
    _small_bag(run / "recording", seconds=1)
    (run / "recording" / "metadata.yaml").unlink()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)  # simlan_data.apps.run"])
    cmdline = Path(f"/proc/{sleeper.pid}/cmdline")
    for _ in range(200):  # until the child has exec'd (before, /proc shows the parent's command)
        if not cmdline.exists() or b"time.sleep" in cmdline.read_bytes():
            break
        time.sleep(0.01)
    try:
        write_running(run, RunMarker(sleeper.pid, socket.gethostname(), 10.0, 1.0))
        with pytest.raises(RecordingInputError, match=rf"still being written.*process {sleeper.pid}"):
            recover(run)
        with pytest.raises(RecordingInputError, match=rf"still being written.*process {sleeper.pid}"):
            RecordingReader(run)
    finally:
        sleeper.kill()
        sleeper.wait()
    report = recover(run)  # the writer is gone now: a crash
    assert report.written and (run / "INCOMPLETE").is_file() and not (run / "RUNNING").exists()
    # a second recovery finds the recording intact
    assert "nothing to recover" in recover(run).lines()[0]


def test_an_intact_recording_is_left_alone(tmp_path: Path) -> None:
    _small_bag(tmp_path / "bag", seconds=1)
    before = {p.name: p.read_bytes() for p in (tmp_path / "bag").iterdir()}
    report = recover(tmp_path / "bag")
    assert not report.written and "complete and intact" in report.lines()[0]
    assert {p.name: p.read_bytes() for p in (tmp_path / "bag").iterdir()} == before
    # a run that died after finishing its recording (while writing its report): only marked
    run = tmp_path / "run"
    _small_bag(run / "recording", seconds=1)
    before = {p.name: p.read_bytes() for p in (run / "recording").iterdir()}
    write_running(run, RunMarker(2**22 + 12345, socket.gethostname(), 1.0, 1.0))  # no such process
    report = recover(run)
    assert not report.written and "marked INCOMPLETE" in "\n".join(report.lines())
    assert (run / "INCOMPLETE").is_file() and not (run / "RUNNING").exists()
    assert {p.name: p.read_bytes() for p in (run / "recording").iterdir()} == before


def test_recover_cli_and_replay_recover(tmp_path: Path) -> None:
    for name in ("a", "b"):
        _small_bag(tmp_path / name / "recording", seconds=2)
        (tmp_path / name / "recording" / "metadata.yaml").unlink()
    digest_before = payload_digest(messages_in_file_order_unfinished(tmp_path / "a" / "recording"))
    proc = run_cli(str(tmp_path / "a"), "--dry-run", module="simlan_data.recover")
    assert proc.returncode == 0, proc.stderr
    assert (
        "dry run, nothing written" in proc.stdout
        and not (tmp_path / "a" / "recording" / "metadata.yaml").exists()
    )
    proc = run_cli(str(tmp_path / "a"), module="simlan_data.recover")
    assert proc.returncode == 0, proc.stderr
    assert "recovered      222 messages on 2 topics" in proc.stdout
    assert payload_digest(messages_in_file_order(tmp_path / "a" / "recording")) == digest_before
    proc = run_cli(str(tmp_path / "b" / "recording"), "--recover", module="simlan_data.replay")
    assert proc.returncode == 0 and "recovered /" in proc.stdout, proc.stderr
    proc = run_cli(str(tmp_path / "nowhere"), module="simlan_data.recover")
    assert proc.returncode == 2 and proc.stderr.startswith("error: no such recording in ")
    assert len(proc.stderr.strip().splitlines()) == 1


def messages_in_file_order_unfinished(bag: Path) -> list[Msg]:
    """Messages of a bag without summary, via the mcap library's streaming reader."""
    out = []
    channels = {}
    with (bag / "recording.mcap").open("rb") as f:
        for rec in StreamReader(f).records:
            kind = type(rec).__name__
            if kind == "Channel":
                channels[rec.id] = rec.topic
            elif kind == "Message":
                out.append(Msg(channels[rec.channel_id], rec.log_time, bytes(rec.data)))
    return out


def test_recovered_copy_in_a_fresh_directory_is_independent(tmp_path: Path) -> None:
    """Recovery writes beside the original and commits by rename: a copy of the original recovers the same."""
    _small_bag(tmp_path / "a" / "recording", seconds=2)
    (tmp_path / "a" / "recording" / "metadata.yaml").unlink()
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    recover(tmp_path / "a")
    recover(tmp_path / "b")
    assert (tmp_path / "a" / "recording" / "recording.mcap").read_bytes() == (
        tmp_path / "b" / "recording" / "recording.mcap"
    ).read_bytes()
    assert BytesIO((tmp_path / "a" / "recording" / "recording.mcap").read_bytes()).read(8) == b"\x89MCAP0\r\n"


def _chunk_start(data: bytes, after: int) -> int:
    """Offset of the first chunk record at or after ``after`` (skipping message indexes)."""
    at = after
    while data[at] != 0x06:
        at += 9 + struct.unpack_from("<Q", data, at + 1)[0]
    return at


def test_a_damaged_record_length_in_a_finished_file_costs_only_that_chunk(tmp_path: Path) -> None:
    """Reading front to back stops at a damaged length; the summary's chunk index resumes it."""
    _small_bag(tmp_path / "bag", seconds=4)
    bag = tmp_path / "bag"
    reference = messages_in_file_order(bag)
    ends = _chunk_ends(bag / "bag.mcap")
    data = bytearray((bag / "bag.mcap").read_bytes())
    third = _chunk_start(data, ends[1][0])
    struct.pack_into("<Q", data, third + 1, 2**40)  # the 3rd chunk claims a terabyte
    (bag / "bag.mcap").write_bytes(bytes(data))
    report = recover(bag)
    # the index knows the chunk's true length, and its CRC shows the contents are good: all kept
    assert report.salvage.resumed_from_index == len(ends) - 2 and report.salvage.damaged == []
    assert messages_in_file_order(bag) == reference
    assert "later chunks read through the summary's chunk index" in "\n".join(report.lines())
    # damage inside the same chunk as well: only that chunk is lost
    _small_bag(tmp_path / "bag2", seconds=4)
    bag = tmp_path / "bag2"
    data = bytearray((bag / "bag2.mcap").read_bytes())
    struct.pack_into("<Q", data, third + 1, 2**40)
    data[third + 200] ^= 0xFF
    (bag / "bag2.mcap").write_bytes(bytes(data))
    report = recover(bag)
    assert [d.offset for d in report.salvage.damaged] == [third]
    n = [k for _, k in ends]
    assert messages_in_file_order(bag) == reference[: n[0] + n[1]] + reference[n[0] + n[1] + n[2] :]


def test_a_damaged_metadata_yaml_is_rebuilt_from_the_file(tmp_path: Path) -> None:
    _small_bag(tmp_path / "bag", seconds=2)
    bag = tmp_path / "bag"
    reference = messages_in_file_order(bag)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9, message_count: 3}\n")
    with pytest.raises(RecordingInputError, match="not a readable recording"):
        RecordingReader(bag, check_format=False)
    report = recover(bag)
    assert report.written and (bag / "metadata.yaml.damaged").is_file()
    assert messages_in_file_order(bag) == reference
    with RecordingReader(bag, check_format=False) as r:
        assert r.message_count == len(reference) and r.recovered
