"""Recovery names every message it could not keep, per damage kind (issue 21).

Each test damages a small recording written by the real writer (a clock at 100 Hz, ground truth at
50 Hz, a camera at 10 Hz; a chunk every 0.25 s), recovers it with the real CLI, and compares the
lost ranges per topic it reports (output, ``INCOMPLETE``, ``replay --info``) with what the undamaged
recording held minus what the recovered one holds, both read with the independent ``mcap`` reader
and ``mcap_ros2`` decoder. The damage kinds:

- bad CRC: a flipped byte in a chunk's records (a finished file);
- bad record length: a message's length inside a chunk whose CRC is valid (recomputed after the
  damage), in a crashed file: the records before it are kept, the rest named exactly;
- truncated chunk: the crashed file ends inside a chunk (its header survives, its index not);
- truncated file: the crashed file ends inside the message index after a chunk, the run's clock
  (its RUNNING marker) having got to the end;
- garbage tail: bytes that are no records (zeros, as a crash leaves, or random) after the last one.
"""

from __future__ import annotations

import socket
import struct
import zlib
from collections import Counter
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import Chunk, DataEnd, MessageIndex
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory
from reliability_cases import run_info_for_tests

from conftest import run_cli
from simlan_data.constants import FORMAT_VERSION, NS_PER_S
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.codecs import encode_rgb
from simlan_data.recording.run_marker import RunMarker, write_running
from simlan_data.recording.writer import RecordingWriter

SECONDS = 3
DEAD_PID = 2**22 + 4321  # above pid_max: no such process (the run crashed)
TOPICS = {t.name: t for t in schema.GLOBAL_TOPICS}
CAM = schema.camera_topics("7", rgb="png", depth=None, semantic=None)["rgb"]
Lost = tuple[str, float, float | None, int | None]  # topic ("*": all), from_s, to_s, messages


def _record(run_dir: Path, compression: str = "zstd") -> Path:
    """A 3 s recording in ``run_dir/recording``; returns its MCAP file."""
    rng = np.random.default_rng(0)
    with RecordingWriter(run_dir / "recording", compression=compression, flush_period_ns=NS_PER_S // 2) as w:
        w.set_metadata("simlan.format_version", FORMAT_VERSION)
        w.write(TOPICS[schema.CONFIG], 0, M.string(yaml.safe_dump({"duration_s": float(SECONDS)})))
        w.write(TOPICS[schema.RUN_INFO], 0, run_info_for_tests("losses", FORMAT_VERSION))
        for k in range(SECONDS * 100 + 1):
            t = k * NS_PER_S // 100
            w.write(TOPICS[schema.CLOCK], t, M.clock(t))
            if k % 2 == 0:
                pose = Transform.from_pose2d(0.01 * k, 0.0, 0.0)
                tf = M.tf_message([M.transform_stamped(t, "map", "robot_agent_1/base_link", pose)])
                w.write(TOPICS[schema.GROUND_TRUTH_POSES], t, tf)
            if k % 10 == 0:
                img = rng.integers(0, 255, (8, 8, 3), dtype=np.uint8)
                w.write(CAM, t, M.compressed_image(t, "camera_7", *encode_rgb(img, "png")))
    return run_dir / "recording" / "recording.mcap"


def _crashed(run_dir: Path, mcap: Path, reached_s: float, data: bytes | None = None) -> None:
    """Make the run look crashed: no metadata.yaml, the clock at ``reached_s``; ``data``: the file."""
    (mcap.parent / "metadata.yaml").unlink()
    if data is not None:
        mcap.write_bytes(data)
    write_running(run_dir, RunMarker(DEAD_PID, socket.gethostname(), float(SECONDS), reached_s))


def _records(mcap: Path) -> list[tuple[int, int, Any]]:
    """(start, end, record) of the file's records up to DataEnd (mcap's stream reader)."""
    out = []
    with mcap.open("rb") as f:
        start = 8
        for rec in StreamReader(f, emit_chunks=True).records:
            out.append((start, f.tell(), rec))
            start = f.tell()
            if isinstance(rec, DataEnd):
                break
    return out


def _chunks(mcap: Path) -> list[tuple[int, int, Chunk]]:
    return [(a, b, r) for a, b, r in _records(mcap) if isinstance(r, Chunk)]


def _messages(mcap: Path) -> list[tuple[str, int]]:
    """(topic, log time) of every message of a finished file, each decoded (mcap + mcap_ros2)."""
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [
            (ch.topic, msg.log_time) for _, ch, msg, _ in reader.iter_decoded_messages(log_time_order=False)
        ]


def _expected(reference: list[tuple[str, int]], recovered: list[tuple[str, int]]) -> list[Lost]:
    """Per topic: (first, last, count) of the messages the reference holds and the recovery not."""
    assert not Counter(recovered) - Counter(reference), "recovery invented messages"
    lost = Counter(reference) - Counter(recovered)
    out = []
    for topic in sorted({t for t, _ in lost}):
        times = [ns for (t, ns), n in lost.items() if t == topic for _ in range(n)]
        out.append((topic, min(times) / NS_PER_S, max(times) / NS_PER_S, len(times)))
    return out


def _line(x: Lost) -> str:
    topic, a, b, n = x
    name = "all topics" if topic == "*" else topic
    span = f"after {a:.3f} s" if b is None else f"{a:.3f}-{b:.3f} s"
    return f"{name} {span} ({'messages unknown' if n is None else f'{n} message' + 's' * (n != 1)})"


def _recover(run_dir: Path) -> tuple[str, dict[str, Any], str]:
    """The CLI's output, the INCOMPLETE marker and `replay --info` of the recovered run."""
    proc = run_cli(str(run_dir), module="simlan_data.recover")
    assert proc.returncode == 0, proc.stderr
    marker = yaml.safe_load((run_dir / "INCOMPLETE").read_text())
    info = run_cli(str(run_dir), "--info", module="simlan_data.replay")
    assert info.returncode == 0, info.stderr
    return proc.stdout, marker, info.stdout


def _assert_reported(reported: tuple[str, dict[str, Any], str], expected: list[Lost]) -> None:
    """Every expected range, and no other, in the output, INCOMPLETE and --info."""
    out, marker, info = reported
    got = sorted((d["topic"], d["from_s"], d["to_s"], d["messages"]) for d in marker["losses"])
    expected = sorted(expected)
    assert len(got) == len(expected), (got, expected)
    for g, e in zip(got, expected, strict=True):
        assert g[0] == e[0] and g[3] == e[3], (g, e)
        assert g[1] == pytest.approx(e[1], abs=1e-9), (g, e)
        assert (g[2] is None) == (e[2] is None) and (e[2] is None or g[2] == pytest.approx(e[2], abs=1e-9))
    assert marker["messages_lost"] == sum(e[3] or 0 for e in expected)
    assert marker["messages_lost_unknown"] == any(e[3] is None for e in expected)
    assert marker["lost_s"] > 0
    block = out[out.index("  lost messages") :].split("\n  messages per topic")[0]
    ranges = sorted(x.strip() for x in block.splitlines() if x.startswith("      "))
    assert ranges == sorted(map(_line, expected)), out
    lost = info[info.index("Lost:") :].split("Topic information:")[0]
    assert sorted(x[19:] for x in lost.splitlines()) == sorted(map(_line, expected)), info


def _recorded(tmp_path: Path, compression: str = "zstd") -> tuple[Path, Path, list[tuple[str, int]]]:
    """A run directory with a fresh recording: (run, its MCAP file, the messages it holds)."""
    run = tmp_path / "run"
    mcap = _record(run, compression=compression)
    return run, mcap, _messages(mcap)


def _assert_tail_lost(
    run: Path, mcap: Path, reference: list[tuple[str, int]]
) -> tuple[str, dict[str, Any], str]:
    """A file that lost its end: recover, then the loss is one range for all topics, from the last
    message kept to where the clock got (SECONDS); returns what was reported."""
    reported = _recover(run)
    recovered = _messages(mcap)
    lost = _expected(reference, recovered)
    kept_until = max(t for _, t in recovered) / NS_PER_S
    assert kept_until < min(e[1] for e in lost) and max(e[2] or 0 for e in lost) == SECONDS
    _assert_reported(reported, [("*", kept_until, float(SECONDS), None)])
    return reported


def test_bad_crc_names_the_chunk_s_messages_per_topic(tmp_path: Path) -> None:
    run, mcap, reference = _recorded(tmp_path, compression="none")
    start, end, chunk = _chunks(mcap)[5]
    data = bytearray(mcap.read_bytes())
    data[(start + end) // 2] ^= 0x40  # inside the chunk's (uncompressed) records
    mcap.write_bytes(bytes(data))
    write_running(run, RunMarker(DEAD_PID, socket.gethostname(), float(SECONDS), float(SECONDS)))
    reported = _recover(run)
    expected = _expected(reference, _messages(mcap))
    # exactly the chunk's messages are lost, on all three topics
    in_chunk = [r for r in breakup_chunk(chunk) if type(r).__name__ == "Message"]
    assert len(expected) == 3 and sum(e[3] or 0 for e in expected) == len(in_chunk)
    assert min(e[1] for e in expected) == chunk.message_start_time / NS_PER_S
    _assert_reported(reported, expected)
    out, marker, info = reported
    assert "CRC mismatch in the chunk at byte" in out and marker["chunks_damaged"] == 1
    assert "1 damaged chunks skipped" in info


def test_bad_record_length_in_a_chunk_with_a_valid_crc(tmp_path: Path) -> None:
    """The finding: the rest of the chunk was dropped, '0 damaged chunks', 'lost 0.000 s'."""
    run, mcap, reference = _recorded(tmp_path, compression="none")
    start, _, chunk = _chunks(mcap)[4]
    data = bytearray(mcap.read_bytes())
    records_at = start + 9 + 8 + 8 + 8 + 4 + 4 + 8  # opcode, length; times, size, crc, "", records length
    pos, in_chunk = 0, []
    while pos < len(chunk.data):  # the records of the chunk: damage the 10th message's length
        opcode, length = struct.unpack_from("<BQ", chunk.data, pos)
        if opcode == 0x05:
            in_chunk.append(pos)
        pos += 9 + length
    damaged_at = in_chunk[9]
    struct.pack_into("<Q", data, records_at + damaged_at + 1, 10**6)
    records = bytes(data[records_at : records_at + len(chunk.data)])
    struct.pack_into("<I", data, start + 9 + 24, zlib.crc32(records))  # the CRC is valid again
    # the mcap library finds the CRC valid and silently reads 10 messages (the 10th swallowing the rest)
    chunks = [r for r in StreamReader(BytesIO(data), emit_chunks=True).records if isinstance(r, Chunk)]
    damaged = next(r for r in chunks if r.message_start_time == chunk.message_start_time)
    assert sum(type(r).__name__ == "Message" for r in breakup_chunk(damaged, validate_crc=True)) == 10
    crashed = bytes(data[: _records(mcap)[-1][0]])  # cut at DataEnd: no summary, as after a crash
    _crashed(run, mcap, float(SECONDS), crashed)
    reported = _recover(run)
    expected = _expected(reference, _messages(mcap))
    # the 9 messages before the damaged one are kept, the others of the chunk are named
    assert sum(e[3] or 0 for e in expected) == len(in_chunk) - 9
    _assert_reported(reported, expected)
    out, marker, info = reported
    assert f"bad record length at byte {damaged_at}" in out
    assert marker["chunks_damaged"] == 1 and "1 damaged chunks skipped" in info


def test_truncated_chunk_names_its_time_range_for_all_topics(tmp_path: Path) -> None:
    run, mcap, reference = _recorded(tmp_path)
    start, end, chunk = _chunks(mcap)[6]
    reached_s = chunk.message_end_time / NS_PER_S  # the clock got to the end of that chunk
    _crashed(run, mcap, reached_s, mcap.read_bytes()[: (start + end) // 2])
    reported = _recover(run)
    held = [m for m in reference if m[1] <= chunk.message_end_time]  # what the file had had
    lost = _expected(held, _messages(mcap))
    assert len(lost) == 3
    first, last = min(e[1] for e in lost), max(e[2] or 0 for e in lost)
    assert (first, last) == (chunk.message_start_time / NS_PER_S, reached_s)
    _assert_reported(reported, [("*", first, last, None)])
    assert f"the file ends inside the chunk at byte {start}" in reported[0]


def test_truncated_file_names_what_the_clock_reached_beyond_it(tmp_path: Path) -> None:
    run, mcap, reference = _recorded(tmp_path)
    _, end, _ = _chunks(mcap)[7]
    _crashed(run, mcap, float(SECONDS), mcap.read_bytes()[: end + 20])  # inside the message index
    reported = _assert_tail_lost(run, mcap, reference)
    assert f"20 bytes from byte {end} are unreadable" in reported[0]


@pytest.mark.parametrize("garbage", ["zeros", "random"])
def test_garbage_tail_is_named_with_the_time_it_may_have_held(tmp_path: Path, garbage: str) -> None:
    run, mcap, reference = _recorded(tmp_path)
    records = _records(mcap)
    cut = next(a for a, _, r in records if isinstance(r, Chunk) and a > _chunks(mcap)[7][0])
    assert isinstance(records[[a for a, _, _ in records].index(cut) - 1][2], MessageIndex)
    tail = bytes(4096) if garbage == "zeros" else np.random.default_rng(5).bytes(4096)
    _crashed(run, mcap, float(SECONDS), mcap.read_bytes()[:cut] + tail)
    out, marker, _ = _assert_tail_lost(run, mcap, reference)
    assert f"4096 bytes from byte {cut} are unreadable" in out and marker["unreadable_bytes"] == 4096
