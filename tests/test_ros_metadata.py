"""What ``ros2 bag play`` reads from metadata.yaml (issue 22): the distro whose message
definitions the bag embeds, and the QoS of the topics published once (latched), so that a
subscriber that comes late still gets /tf_static."""

from __future__ import annotations

from pathlib import Path

import yaml
from rosbags.rosbag2 import Reader


def _topics(run_dir: Path) -> dict[str, dict]:
    info = yaml.safe_load((run_dir / "recording" / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"
    ]
    assert info["ros_distro"] == "jazzy"
    return {t["topic_metadata"]["name"]: t["topic_metadata"] for t in info["topics_with_message_count"]}


def test_latched_topics_are_recorded_transient_local_and_streams_volatile(short_run: Path) -> None:
    topics = _topics(short_run)
    for name in ("/tf_static", "/simlan/config", "/simlan/run_info", "/simlan/semantic_labels"):
        (qos,) = topics[name]["offered_qos_profiles"]
        assert (qos["durability"], qos["reliability"], qos["history"], qos["depth"]) == (
            "transient_local",
            "reliable",
            "keep_last",
            1,
        ), name
    assert topics["/clock"]["offered_qos_profiles"] in ([], "")  # the player's default
    # rosbags (the reader ros2 bag's metadata format is checked with) parses the profiles
    with Reader(short_run / "recording") as reader:
        tf_static = next(c for c in reader.connections if c.topic == "/tf_static")
        assert tf_static.ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
        assert reader.ros_distro == "jazzy"
