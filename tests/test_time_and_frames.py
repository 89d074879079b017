"""Bag time and the TF tree (issue 22): viewers see real dates, every frame has one parent.

A run's recording is read back with the independent ``mcap`` + ``mcap_ros2`` decoder (what
Foxglove and Rerun see) and with our own reader (what metrics, replay and evals see).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from simlan_data.constants import NS_PER_S
from simlan_data.evaluation.metrics import ground_truth
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.recover import recover
from simlan_data.recording.timebase import DEFAULT_EPOCH, EPOCH_KEY, format_epoch, parse_epoch
from simlan_data.recording.writer import RecordingWriter

EPOCH_NS = parse_epoch(DEFAULT_EPOCH)
TOPIC = {t.name: t for t in schema.GLOBAL_TOPICS}


def _decoded(bag: Path) -> list[tuple[str, str, int, int, object]]:
    """(topic, type, log time, publish time, message) of every message, by the independent reader."""
    (mcap,) = bag.glob("*.mcap")
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [
            (ch.topic, sch.name, m.log_time, m.publish_time, msg)
            for sch, ch, m, msg in reader.iter_decoded_messages(log_time_order=True)
        ]


@pytest.fixture(scope="module")
def decoded(short_run: Path) -> list[tuple[str, str, int, int, object]]:
    return _decoded(short_run / "recording")


def _ns(stamp: object) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)  # type: ignore[attr-defined]


def test_every_frame_has_one_parent_and_reaches_map(decoded: list) -> None:
    """REP 105: over /tf, /tf_static and /ground_truth/poses, each child frame has exactly one
    parent, and following parents from any frame ends at ``map``."""
    parents: dict[str, set[str]] = defaultdict(set)
    topics = set()
    for topic, msgtype, _, _, msg in decoded:
        if msgtype == schema.TF_TYPE:
            topics.add(topic)
            for tf in msg.transforms:
                parents[tf.child_frame_id].add(tf.header.frame_id)
    assert topics == {schema.TF, schema.TF_STATIC, schema.GROUND_TRUTH_POSES}
    ns = "robot_agent_1"
    # the estimate and the truth of the robot are both there, as two frames
    assert parents[schema.base_link_frame(ns)] == {schema.odom_frame(ns)}
    assert parents[schema.ground_truth_frame(ns)] == {schema.MAP_FRAME}
    several = {child: sorted(p) for child, p in parents.items() if len(p) != 1}
    assert not several, f"frames with several parents: {several}"
    for frame in parents:
        seen, at = [frame], frame
        while at in parents:
            at = next(iter(parents[at]))
            assert at not in seen, f"a cycle: {seen}"
            seen.append(at)
        assert at == schema.MAP_FRAME, f"{frame} does not reach map: {' -> '.join(seen)}"


def test_log_times_and_stamps_are_bag_time(decoded: list) -> None:
    """Log time, publish time, header stamps and /clock carry the epoch (viewers show its date):
    the first messages sit at the epoch, every header stamp equals its message's log time."""
    log_times = [log for _, _, log, _, _ in decoded]
    assert min(log_times) == EPOCH_NS  # the config, /tf_static ... at simulated time 0
    assert max(log_times) - EPOCH_NS == 3 * NS_PER_S
    assert all(pub == log for _, _, log, pub, _ in decoded)
    stamped = defaultdict(int)
    for topic, msgtype, log, _, msg in decoded:
        if msgtype == schema.CLOCK_TYPE:
            assert _ns(msg.clock) == log
        if msgtype == schema.TF_TYPE:
            assert all(_ns(tf.header.stamp) == log for tf in msg.transforms), topic
        header = getattr(msg, "header", None)
        if header is not None:
            assert _ns(header.stamp) == log, (topic, _ns(header.stamp) - log)
            stamped[msgtype] += 1
    # the sensor topics are among them: images (restamped CDR reused), camera info, estimates
    for msgtype in (schema.CAMERA_INFO_TYPE, schema.TWIST_STAMPED_TYPE, schema.POSE_COV_TYPE):
        assert stamped[msgtype] > 0, msgtype
    assert stamped[schema.IMAGE_TYPE] + stamped[schema.COMPRESSED_IMAGE_TYPE] > 100


def test_our_reader_gives_simulated_time(short_run: Path) -> None:
    """RecordingReader subtracts the recorded epoch: metrics, replay and evals see time from 0."""
    with RecordingReader(short_run) as reader:
        assert reader.epoch_ns == EPOCH_NS
        assert reader.custom_data[EPOCH_KEY] == str(EPOCH_NS)
        assert (reader.start_ns, reader.end_ns) == (0, 3 * NS_PER_S + 1)  # (end: exclusive, as rosbags')
        clock = list(reader.messages([schema.CLOCK]))
        assert clock[0].stamp_ns == 0
        assert all(_ns(m.msg.clock) == EPOCH_NS + m.stamp_ns for m in clock)
        window = [
            m.stamp_ns for m in reader.messages([schema.CLOCK], start_ns=NS_PER_S, stop_ns=2 * NS_PER_S)
        ]
        assert window[0] == NS_PER_S and max(window) < 2 * NS_PER_S
        assert reader.first(schema.TF_STATIC).stamp_ns == 0  # type: ignore[union-attr]
        assert "Epoch:             2026-01-01T00:00:00Z" in reader.summary()
        truth = ground_truth(reader)
    assert list(truth) == ["robot_agent_1"] and truth["robot_agent_1"]["stamp_ns"][0] == 0


def _truth_bag(path: Path, *, epoch_ns: int, child: str) -> Path:
    """Two seconds of ground truth of one robot at 60 Hz, its frame named ``child``."""
    with RecordingWriter(path, epoch_ns=epoch_ns) as w:
        w.write(
            TOPIC[schema.CONFIG],
            0,
            M.string(yaml.safe_dump({"recording": {"epoch": format_epoch(epoch_ns)}})),
        )
        for k in range(121):
            t = k * NS_PER_S // 60
            pose = Transform.from_pose2d(0.01 * k, -0.02 * k, 0.003 * k)
            w.write(TOPIC[schema.CLOCK], t, M.clock(w.stamp_ns(t)))
            tf = M.transform_stamped(w.stamp_ns(t), schema.MAP_FRAME, child, pose)
            w.write(TOPIC[schema.GROUND_TRUTH_POSES], t, M.tf_message([tf]))
    return path


def test_old_bags_read_as_before(tmp_path: Path) -> None:
    """A bag from before the epoch and the ground-truth frames (log times from 0, ground truth
    on ``<ns>/base_link``, no epoch in its metadata) reads like a new one."""
    ns = "robot_agent_1"
    old = _truth_bag(tmp_path / "old", epoch_ns=0, child=schema.base_link_frame(ns))
    meta = old / "metadata.yaml"  # as written before: no epoch key at all
    meta.write_text(meta.read_text().replace(f"    {EPOCH_KEY}: '0'\n", ""))
    new = _truth_bag(tmp_path / "new", epoch_ns=EPOCH_NS, child=schema.ground_truth_frame(ns))
    with RecordingReader(old, check_format=False) as a, RecordingReader(new, check_format=False) as b:
        assert EPOCH_KEY not in a.custom_data and a.epoch_ns == 0 and b.epoch_ns == EPOCH_NS
        assert (a.start_ns, a.end_ns) == (b.start_ns, b.end_ns) == (0, 2 * NS_PER_S + 1)
        assert [m.stamp_ns for m in a.messages()] == [m.stamp_ns for m in b.messages()]
        truth_old, truth_new = ground_truth(a), ground_truth(b)
    assert list(truth_old) == list(truth_new) == [ns]
    assert truth_old[ns].equals(truth_new[ns]) and len(truth_new[ns]) == 121


def test_recovery_keeps_the_epoch(tmp_path: Path) -> None:
    """A crashed bag (no metadata.yaml, the file cut short) is recovered with its epoch (from the
    recorded config): reported and read in simulated time, log times kept as they were."""
    bag = _truth_bag(
        tmp_path / "crashed", epoch_ns=EPOCH_NS, child=schema.ground_truth_frame("robot_agent_1")
    )
    (bag / "metadata.yaml").unlink()
    mcap = bag / "crashed.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) * 3 // 4])  # the summary and some data gone
    report = recover(bag)
    assert report.written and report.salvage.epoch_ns == EPOCH_NS
    assert 0 < report.recovered_until_s <= 2.0
    assert all(0 <= x.from_ns <= 2 * NS_PER_S for x in report.losses)
    with RecordingReader(bag, check_format=False) as reader:
        assert reader.epoch_ns == EPOCH_NS and reader.start_ns == 0
        assert reader.end_ns == round(report.recovered_until_s * NS_PER_S) + 1
    assert min(log for _, _, log, _, _ in _decoded(bag)) == EPOCH_NS


def test_the_golden_recording_reads_as_before() -> None:
    """The committed golden recording (made before epochs and ground-truth frames) keeps reading:
    epoch 0, time from 0, its ground truth on ``<ns>/base_link`` found by namespace."""
    golden = Path(__file__).resolve().parents[1] / "recordings" / "golden" / "single_truck"
    with RecordingReader(golden) as reader:
        assert EPOCH_KEY not in reader.custom_data and reader.epoch_ns == 0
        assert (reader.start_ns, reader.end_ns) == (0, 14 * NS_PER_S + 1)
        first = reader.first(schema.GROUND_TRUTH_POSES)
        truth = ground_truth(reader)
    assert first is not None and first.msg.transforms[0].child_frame_id == "robot_agent_1/base_link"
    assert list(truth) == ["robot_agent_1"] and len(truth["robot_agent_1"]) == 841
