"""Hostile inputs to the readers and the replay CLI (issue 21): each answers within 5 s with one
line and exit 2, writes nothing, and never hangs.

The reader-level shapes are cases of ``reliability_cases.RECORDING_CASES`` (run by
test_validation.py and benchmarks/reliability.py); here the same shapes go through the real
command lines, as users meet them: a FIFO named ``recording.mcap`` (opening it blocks until a
writer comes: ``replay --info`` hung), an alias bomb or inflated counts in ``metadata.yaml``, a
topic of the wrong type, a ``--set`` value of the wrong type, and output piped into ``head``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from reliability_cases import ALIAS_BOMB, _inflate, _meta, small_recording, wrong_type

from conftest import REPO, run_cli
from simlan_data.errors import EXIT_BAD_INPUT, RecordingInputError
from simlan_data.recording.reader import RecordingReader

HANG_S = 60  # a CLI that has not answered by then hangs (the answer itself must come within 5 s)


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    return small_recording(tmp_path / "run" / "recording")


def _one_line_exit_2(proc: subprocess.CompletedProcess[str], *needles: str) -> str:
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == EXIT_BAD_INPUT, (proc.returncode, proc.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def _fifo_mcap(bag: Path) -> None:
    (bag / "recording.mcap").unlink()
    os.mkfifo(bag / "recording.mcap")


def _fifo_metadata(bag: Path) -> None:
    (bag / "metadata.yaml").unlink()
    os.mkfifo(bag / "metadata.yaml")


@pytest.mark.parametrize(
    ("make", "what"),
    [(_fifo_mcap, "recording.mcap: it is a FIFO"), (_fifo_metadata, "metadata.yaml: it is a FIFO")],
    ids=["recording.mcap", "metadata.yaml"],
)
def test_a_fifo_in_a_recording_is_refused_at_once(bag: Path, make, what: str, tmp_path: Path) -> None:
    make(bag)
    t0 = time.perf_counter()
    with pytest.raises(RecordingInputError, match="is not a regular file") as info:
        RecordingReader(bag)
    assert time.perf_counter() - t0 < 5.0
    assert info.value.exit_code == EXIT_BAD_INPUT and what in info.value.line()
    out = tmp_path / "out"
    for args in ([str(bag), "--info"], [str(bag.parent), "--out", str(out)]):
        proc = run_cli(*args, module="simlan_data.replay", timeout=HANG_S)
        _one_line_exit_2(proc, what, "replace it by the real file")
    assert not out.exists()


def test_recover_refuses_a_fifo_instead_of_blocking(bag: Path) -> None:
    _fifo_mcap(bag)
    (bag / "metadata.yaml").unlink()
    proc = run_cli(str(bag), module="simlan_data.recover", timeout=HANG_S)
    _one_line_exit_2(proc, "recording.mcap: it is a FIFO")


def test_a_fifo_without_metadata_is_named_not_sent_to_recover(bag: Path) -> None:
    """A FIFO recording.mcap beside no metadata.yaml looked like a crashed run's bag: replay said
    'recording is unfinished ... run recover', and recover then refused the FIFO."""
    _fifo_mcap(bag)
    (bag / "metadata.yaml").unlink()
    proc = run_cli(str(bag), "--info", module="simlan_data.replay", timeout=HANG_S)
    _one_line_exit_2(proc, "recording.mcap: it is a FIFO", "replace it by the real file")


def test_a_device_as_the_recording_is_refused() -> None:
    proc = run_cli("/dev/zero", "--info", module="simlan_data.replay", timeout=HANG_S)
    _one_line_exit_2(proc, "/dev/zero: it is a character device")


def test_a_metadata_alias_bomb_is_refused_at_its_first_alias(bag: Path) -> None:
    (bag / "metadata.yaml").write_text(ALIAS_BOMB + (bag / "metadata.yaml").read_text())
    t0 = time.perf_counter()
    with pytest.raises(RecordingInputError, match=r"YAML alias at line 2"):
        RecordingReader(bag)
    assert time.perf_counter() - t0 < 5.0
    proc = run_cli(str(bag), "--info", module="simlan_data.replay", timeout=HANG_S)
    _one_line_exit_2(proc, "metadata.yaml unreadable: YAML alias")


@pytest.mark.parametrize(
    ("key", "value", "said"),
    [
        (
            "message_count",
            10**23,
            "message_count is 100000000000000000000000, but its MCAP file's summary says 245",
        ),
        ("topics:/ground_truth/poses", 7, "topics_with_message_count /ground_truth/poses is 7, but"),
        ("duration", 10**15, "duration is 1000000000000000, but its MCAP file's summary says 2000000000"),
        ("starting_time", 5, "starting_time is 5, but its MCAP file's summary says 0"),
    ],
)
def test_metadata_counts_that_disagree_with_the_file_are_refused(
    bag: Path, key: str, value: int, said: str
) -> None:
    """--info printed metadata.yaml's counts as is: ``Messages: 100000000000000000000000``."""
    _inflate(bag, key, value)
    proc = run_cli(str(bag), "--info", module="simlan_data.replay", timeout=HANG_S)
    assert "Messages:" not in proc.stdout
    _one_line_exit_2(proc, said, "python -m simlan_data.recover")


@pytest.mark.parametrize(
    ("value", "said"),
    [
        (10**23, "files[0] (recording.mcap) message_count is 100000000000000000000000, but its MCAP file's"),
        (1e23, "files[0] message_count is not a non-negative integer"),
    ],
)
def test_a_file_entry_s_count_that_disagrees_with_its_file_is_refused(
    bag: Path, value: object, said: str
) -> None:
    """metadata.yaml's files[].message_count was never checked: 1e23 there opened as if intact."""
    _meta(bag, lambda info: info["files"][0].__setitem__("message_count", value))
    proc = run_cli(str(bag), "--info", module="simlan_data.replay", timeout=HANG_S)
    assert "Messages:" not in proc.stdout
    _one_line_exit_2(proc, said, "python -m simlan_data.recover")


def test_the_unchanged_recording_opens_and_counts_agree(bag: Path) -> None:
    proc = run_cli(str(bag), "--info", module="simlan_data.replay", timeout=HANG_S)
    assert proc.returncode == 0, proc.stderr
    assert "Messages:          245" in proc.stdout


def test_a_topic_of_the_wrong_type_is_named_with_both_types(bag: Path, tmp_path: Path) -> None:
    """A String /ground_truth/poses failed deep in the replay (KeyError, AttributeError), exit 1."""
    wrong_type(bag)
    out = tmp_path / "out"
    proc = run_cli(
        str(bag), "--out", str(out), "--algorithms", "safety", module="simlan_data.replay", timeout=HANG_S
    )
    _one_line_exit_2(
        proc,
        "recording topic /ground_truth/poses has the wrong message type",
        "found std_msgs/msg/String, expected tf2_msgs/msg/TFMessage",
    )
    assert not out.exists()


def test_replay_checks_every_topic_schema_names_before_it_starts(tmp_path: Path) -> None:
    """Not only the required topics: a replay interprets every topic by its name. The reader
    itself still reads it."""
    bag = tmp_path / "golden" / "recording"
    shutil.copytree(REPO / "recordings" / "golden" / "single_truck" / "recording", bag)
    wrong_type(bag, "/robot_agent_1/cmd_vel")
    out = tmp_path / "out"
    proc = run_cli(str(bag), "--out", str(out), module="simlan_data.replay", timeout=HANG_S)
    _one_line_exit_2(
        proc,
        "recording topic /robot_agent_1/cmd_vel has the wrong message type",
        "found std_msgs/msg/String, expected geometry_msgs/msg/TwistStamped",
    )
    assert not out.exists()
    with RecordingReader(bag) as reader:
        reader.require_topics(["/clock"])  # (not a required topic)
        assert len(list(reader.messages(["/robot_agent_1/cmd_vel"]))) == 281


def test_golden_recordings_pass_the_new_checks() -> None:
    for meta in sorted((REPO / "recordings" / "golden").glob("*/recording/metadata.yaml")):
        with RecordingReader(meta.parent) as reader:
            reader.require_topics(["/clock"])
            reader.check_types()


@pytest.mark.parametrize(
    ("setting", "said"),
    [
        (
            "hold_s=abc",
            "invalid hold_s='abc' in replay --set: expected float (TreesConfig.hold_s), got str; e.g. --set hold_s=1.0",
        ),
        ("hold_s=[1]", "invalid hold_s=[1] in replay --set: expected float"),
        (
            "ttc.enabled=3",
            "invalid ttc.enabled=3 in replay --set: expected bool (TreesConfig.ttc.enabled), got int",
        ),
        ("=3", "invalid --set '=3' in replay arguments: the key is empty"),
    ],
)
def test_set_of_the_wrong_type_names_key_value_and_type_and_writes_nothing(
    bag: Path, tmp_path: Path, setting: str, said: str
) -> None:
    """``--set hold_s=abc``: ValueError, exit 1 and an empty --out left behind."""
    out = tmp_path / "new" / "out"
    proc = run_cli(
        str(bag), "--out", str(out), "--algorithms", "safety", "--set", setting,
        module="simlan_data.replay", timeout=HANG_S,
    )  # fmt: skip
    _one_line_exit_2(proc, said)
    assert not (tmp_path / "new").exists()


def test_bad_input_found_after_out_was_created_removes_it(bag: Path, tmp_path: Path) -> None:
    """The small recording has no robots: the safety replay says so after --out exists."""
    out = tmp_path / "new" / "out"
    proc = run_cli(
        str(bag), "--out", str(out), "--algorithms", "safety", module="simlan_data.replay", timeout=HANG_S
    )
    _one_line_exit_2(proc, "no robots")
    assert not (tmp_path / "new").exists()


def test_output_into_a_closed_pipe_exits_141_quietly(bag: Path) -> None:
    """``replay --info | head -1``: a BrokenPipeError (traceback or 'run failed'); now the status a
    process killed by SIGPIPE has (128 + 13), nothing on stderr."""
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader has gone before anything is written
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "simlan_data.replay", str(bag), "--info"],
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            cwd=REPO,
            timeout=HANG_S,
            check=False,
        )
    finally:
        os.close(write_end)
    assert proc.returncode == 141, (proc.returncode, proc.stderr)
    assert proc.stderr == ""


def test_output_into_an_open_pipe_is_unchanged(bag: Path) -> None:
    proc = run_cli(str(bag), "--info", module="simlan_data.replay", timeout=HANG_S)
    assert proc.returncode == 0 and proc.stdout.startswith("Files:") and proc.stderr == ""


def test_view_refuses_a_bad_recording_and_leaves_no_directory(bag: Path, tmp_path: Path) -> None:
    """view created --save's directory before it opened the recording."""
    _inflate(bag, "message_count", 10**23)
    save = tmp_path / "new" / "run.rrd"
    proc = run_cli(str(bag), "--save", str(save), module="simlan_data.view", timeout=HANG_S)
    _one_line_exit_2(proc, "message_count is 100000000000000000000000")
    assert not (tmp_path / "new").exists()


def test_view_refuses_a_topic_of_the_wrong_type_and_writes_no_file(bag: Path, tmp_path: Path) -> None:
    """The Rerun export reads ground truth, estimates and camera topics by name: a String
    /ground_truth/poses failed with 'run failed: AttributeError ... transforms' (exit 1) and left
    a partial .rrd behind."""
    wrong_type(bag)
    save = tmp_path / "new" / "run.rrd"
    proc = run_cli(str(bag), "--save", str(save), module="simlan_data.view", timeout=HANG_S)
    _one_line_exit_2(
        proc,
        "recording topic /ground_truth/poses has the wrong message type",
        "found std_msgs/msg/String, expected tf2_msgs/msg/TFMessage",
    )
    assert not (tmp_path / "new").exists()
