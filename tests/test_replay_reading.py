"""The localization replay's reading process (--set reader=process): the same results as the
reading thread, its errors raised in the replay, stopped when the replay stops
early; the rows the metrics need, collected while reading. Real runs, real forks."""

from __future__ import annotations

import json
from pathlib import Path

import polars as pl
import pytest

from conftest import run_cli
from simlan_data.errors import RecordingInputError
from simlan_data.evaluation import localization_replay as lr
from simlan_data.evaluation.metrics import RecordedRows, estimates_from_recording, ground_truth
from simlan_data.evaluation.replay import ReplayContext
from simlan_data.recording.reader import RecordingReader

TIMING = ("replay.cpu_s", "replay.children_cpu_s", "replay.main_thread_cpu_s", "replay.wall_s")


def _replay(recording: Path, out: Path, *extra: str) -> dict[str, float]:
    proc = run_cli(str(recording), "--out", str(out), *extra, module="simlan_data.replay")
    assert proc.returncode == 0, proc.stderr
    return json.loads((out / "metrics.json").read_text())


def test_reading_process_and_reading_thread_give_the_same_replay(short_run: Path, tmp_path: Path) -> None:
    recording = short_run / "recording"
    by_process = _replay(recording, tmp_path / "process", "--set", "reader=process")
    by_thread = _replay(recording, tmp_path / "thread", "--set", "reader=thread")
    assert by_process["replay.children_cpu_s"] > 0  # the reading process's CPU is counted
    assert by_thread["replay.children_cpu_s"] == 0
    assert (
        by_process["replay.localization.reading_process"],
        by_thread["replay.localization.reading_process"],
    ) == (1, 0)
    timed = ("replay.speed_x_realtime", "replay.localization.wall_s", "replay.localization.frame_ms")
    for key in set(by_process) | set(by_thread):
        if key in TIMING or key.startswith(timed) or key == "replay.localization.reading_process":
            continue
        assert by_process.get(key) == by_thread.get(key), key
    assert by_process["replay.localization.max_diff_to_live_m"] == 0.0
    for name in ("estimates.parquet", "frame_timings.parquet"):
        a, b = pl.read_parquet(tmp_path / "process" / name), pl.read_parquet(tmp_path / "thread" / name)
        keep = [c for c in a.columns if c != "seconds"]
        assert a.select(keep).equals(b.select(keep)), name


@pytest.mark.parametrize(
    ("requested", "cores", "load", "chosen"),
    [
        ("auto", 2, 0.3, "process"),  # a quiet machine: the bag is read on the free core
        ("auto", 2, 1.4, "process"),  # (the lagging average just after other work)
        ("auto", 2, 1.6, "thread"),  # no core free: the pipe's hand-over would only cost
        ("auto", 1, 0.0, "thread"),
        ("auto", 8, 7.0, "process"),
        ("thread", 8, 0.0, "thread"),  # an explicit choice stands
        ("process", 2, 4.0, "process"),
    ],
)
def test_auto_reader_takes_the_process_only_when_a_core_is_free(
    requested: str, cores: int, load: float, chosen: str
) -> None:
    assert lr.choose_reader(requested, cpu_count=cores, load_1min=load) == chosen


def test_rows_collected_while_reading_make_the_same_tables(short_run: Path) -> None:
    """What the reading process collects for the metrics equals reading the topics afterwards."""
    with RecordingReader(short_run / "recording") as reader:
        config = ReplayContext(reader, short_run).config
        mounts, _ = lr.marker_mounts(config)
        namespaces = [m.namespace for m in mounts]
        recorded = RecordedRows(estimates_of=namespaces, navigation_of=namespaces)
        with lr.ReadingProcess(reader, lr.image_camera_ids(reader, config), namespaces, recorded) as reading:
            sets = list(reading)
        assert len(sets) >= 10 and all(len(jpegs) >= 1 for _, jpegs, _, _ in sets)
        truth, live = ground_truth(reader), estimates_from_recording(reader, namespaces)
    assert recorded.truth_tables().keys() == truth.keys()
    for ns, table in truth.items():
        assert recorded.truth_tables()[ns].equals(table)
    for ns, table in live.items():
        assert recorded.estimate_tables()[ns].equals(table)
    assert all(last is not None for last, _, _ in recorded.navigation.values())


def test_reading_process_errors_are_raised_in_the_replay_and_early_stops_end_it(
    short_run: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(*_args, **_kwargs):
        yield 0, {}, [], {}
        raise RecordingInputError("message undecodable", "bag", "corrupt chunk", "recover it")

    with RecordingReader(short_run / "recording") as reader:
        # (the forked process runs the patched function)
        monkeypatch.setattr(lr, "frame_sets", broken)
        reading = lr.ReadingProcess(reader, [], [], RecordedRows())
        items = iter(reading)
        assert next(items) == (0, {}, [], {})
        with pytest.raises(RecordingInputError, match="message undecodable in bag: corrupt chunk"):
            next(items)
        monkeypatch.undo()
        reading = lr.ReadingProcess(reader, lr.image_camera_ids(reader, {}), [], RecordedRows())
        next(iter(reading))
        reading.close()  # stopped after one frame set: the process is ended, not left blocked
        assert reading._proc.exitcode is not None
        # the parent's reader still reads correctly (the child read through its own file offset)
        assert reader.first("/tf_static") is not None
        assert sum(1 for _ in reader.messages(["/clock"])) > 10


def test_unknown_reader_is_one_error_line(short_run: Path, tmp_path: Path) -> None:
    proc = run_cli(
        str(short_run / "recording"),
        "--out",
        str(tmp_path / "x"),
        "--set",
        "reader=disk",
        module="simlan_data.replay",
    )
    assert proc.returncode == 2
    assert "error: unknown reader 'disk' in replay --set reader: known: auto, thread, process" in proc.stderr
