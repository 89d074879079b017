"""``python -m simlan_data.view``: a recording to a Rerun file, read back with the Rerun SDK."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rerun.chunk import RrdReader
from rosbags.typesys import Stores, get_typestore

from conftest import REPO, run_cli
from simlan_data.apps.view import main as inspect_main
from simlan_data.errors import ConfigError
from simlan_data.recording.messages import compressed_image
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.schema import BIRDSEYE_IMAGE, COMPRESSED_IMAGE_TYPE, Topic
from simlan_data.recording.writer import RecordingWriter
from simlan_data.viz.rerun_export import export

GOLDEN = REPO / "recordings" / "golden" / "single_truck"


def read_rrd(path: Path) -> tuple[dict[str, int], dict[str, dict[str, list[Any]]]]:
    """Rows per entity path and, per entity, the values of every component column."""
    rows: dict[str, int] = defaultdict(int)
    values: dict[str, dict[str, list[Any]]] = defaultdict(lambda: defaultdict(list))
    for chunk in RrdReader(path).stream().to_chunks():
        rows[chunk.entity_path] += chunk.num_rows
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if ":" in name:
                values[chunk.entity_path][name] += batch.column(name).to_pylist()
    return dict(rows), values


def test_inspect_writes_an_rrd_with_the_warehouse_cameras_images_and_errors(tmp_path: Path) -> None:
    rrd = tmp_path / "golden.rrd"
    proc = run_cli(str(GOLDEN), "--save", str(rrd), module="simlan_data.view")
    assert proc.returncode == 0, proc.stderr
    # (the golden recording has labels, no depth)
    assert "inspect: 2 cameras, 142 colour, 0 depth and 28 label images, 1 agents" in proc.stdout
    rows, values = read_rrd(rrd)
    expected = {
        "/world",
        "/world/layout/shelf",
        "/world/layout/floor",
        "/world/layout/wall",
        "/world/cameras/162",
        "/world/cameras/163",
        "/world/cameras/162/image",
        "/world/cameras/163/image",
        "/world/cameras/162/detections",
        "/world/agents/robot_agent_1/truth",
        "/world/agents/robot_agent_1/truth_path",
        "/world/agents/robot_agent_1/estimate",
        "/world/agents/robot_agent_1/estimate_path",
        "/world/agents/robot_agent_1/goal",
        "/world/agents/robot_agent_1/plan",
        "/metrics/robot_agent_1/xy_error_cm",
        "/metrics/robot_agent_1/yaw_error_deg",
        "/metrics/robot_agent_1/fix_age_s",
    }
    assert expected <= set(rows), sorted(expected - set(rows))
    with RecordingReader(GOLDEN) as bag:
        images = bag.topics["/camera_163/image_raw/compressed"].count
        detections = bag.topics["/camera_162/marker_detections"].count
        gt_ticks = bag.topics["/ground_truth/poses"].count
        first = next(bag.messages(["/camera_163/image_raw/compressed"]))
    # every image kept compressed, byte for byte, as JPEG
    assert rows["/world/cameras/163/image"] == images
    assert all(v == ["image/jpeg"] for v in values["/world/cameras/163/image"]["EncodedImage:media_type"])
    assert bytes(values["/world/cameras/163/image"]["EncodedImage:blob"][0][0]) == bytes(first.msg.data)
    assert rows["/world/cameras/162/detections"] == detections
    assert "id 1" in values["/world/cameras/162/detections"]["LineStrips2D:labels"][0]
    # a frustum per camera: the pinhole of the recorded camera info, the transform of /tf_static
    assert values["/world/cameras/162"]["Pinhole:resolution"][0] == [[480.0, 270.0]]
    assert rows["/world/agents/robot_agent_1/truth"] >= gt_ticks
    errors = [v[0] for v in values["/metrics/robot_agent_1/xy_error_cm"]["Scalars:scalars"]]
    assert len(errors) > 200 and 0 < max(errors) < 10  # centimetres
    blueprints = RrdReader(rrd).blueprints()
    assert len(blueprints) == 1 and blueprints[0].application_id == "simlan_data"


def copy_with_extra_topics(src: Path, dst: Path) -> None:
    """The golden recording plus zones (MarkerArray) and events of a type this exporter does not know."""
    store = get_typestore(Stores.ROS2_JAZZY)
    zones_t = Topic("/safety/zones", "visualization_msgs/msg/MarkerArray", "zones")
    events_t = Topic("/safety/events", "diagnostic_msgs/msg/DiagnosticStatus", "events")
    M = store.types
    header = M["std_msgs/msg/Header"](
        stamp=M["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="map"
    )
    point = M["geometry_msgs/msg/Point"]
    pose = M["geometry_msgs/msg/Pose"](
        position=point(x=0.0, y=0.0, z=0.0),
        orientation=M["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    marker = M["visualization_msgs/msg/Marker"](
        header=header,
        ns="zones",
        id=0,
        type=4,
        action=0,
        pose=pose,
        scale=M["geometry_msgs/msg/Vector3"](x=0.05, y=0.0, z=0.0),
        color=M["std_msgs/msg/ColorRGBA"](r=1.0, g=0.0, b=0.0, a=1.0),
        lifetime=M["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
        frame_locked=False,
        points=[
            point(x=2.0, y=-1.0, z=0.0),
            point(x=4.0, y=-1.0, z=0.0),
            point(x=4.0, y=1.0, z=0.0),
            point(x=2.0, y=-1.0, z=0.0),
        ],
        colors=[],
        texture_resource="",
        texture=M["sensor_msgs/msg/CompressedImage"](header=header, format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[],
        text="",
        mesh_resource="",
        mesh_file=M["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False,
    )
    event = M["diagnostic_msgs/msg/DiagnosticStatus"](
        level=1, name="robot_agent_1", message="stop: restricted zone ahead", hardware_id="", values=[]
    )
    with RecordingReader(src) as bag, RecordingWriter(dst) as out:
        for key, value in bag.custom_data.items():
            out.set_metadata(key, value)
        topics = {t.name: Topic(t.name, t.msgtype, "") for t in bag.topics.values()}
        for m in bag.messages(raw=True):
            out.write_serialized(topics[m.topic], m.stamp_ns, m.msg)
        out.write_serialized(
            zones_t,
            1_000_000_000,
            bytes(
                store.serialize_cdr(
                    M["visualization_msgs/msg/MarkerArray"](markers=[marker]), zones_t.msgtype
                )
            ),
        )
        out.write_serialized(events_t, 2_000_000_000, bytes(store.serialize_cdr(event, events_t.msgtype)))
        # a bird's-eye canvas as the live topic records it (any JPEG will do)
        jpeg = next(bag.messages(["/camera_162/image_raw/compressed"])).msg.data
        canvas = compressed_image(3_000_000_000, "map", "rgb8; jpeg compressed bgr8", bytes(jpeg))
        out.write(Topic(BIRDSEYE_IMAGE, COMPRESSED_IMAGE_TYPE, ""), 3_000_000_000, canvas)


def test_zones_and_events_show_up_without_knowing_their_topics(tmp_path: Path) -> None:
    bag = tmp_path / "with_zones"
    copy_with_extra_topics(GOLDEN / "recording", bag)
    rrd = tmp_path / "zones.rrd"
    logged = export(bag, save=rrd, image_every=10)
    assert logged["markers"] == ["/safety/zones"]
    assert "/safety/events" in logged["events"]
    rows, values = read_rrd(rrd)
    strips = values["/world/markers/safety/zones"]["LineStrips3D:strips"][0][0]
    assert [p[:2] for p in strips] == [[2.0, -1.0], [4.0, -1.0], [4.0, 1.0], [2.0, -1.0]]
    text = values["/events/safety/events"]["TextLog:text"][0][0]
    assert "stop: restricted zone ahead" in text and "robot_agent_1" in text
    assert rows["/world/cameras/163/image"] == 8  # every 10th of 71
    assert logged["birdseye"] and rows["/birdseye/image"] == 1
    assert values["/birdseye/image"]["EncodedImage:media_type"][0] == ["image/jpeg"]


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--save", "{tmp}/out.txt"], r"invalid --save .*out.txt in arguments: a Rerun file ends in .rrd"),
        (["--save", "{tmp}/exists.rrd"], r"output exists in .*exists.rrd: inspect never overwrites a file"),
        (
            ["--image-every", "0", "--save", "{tmp}/x.rrd"],
            r"invalid --image-every 0 in arguments: must be >= 1",
        ),
    ],
)
def test_bad_inspect_arguments_are_refused(tmp_path: Path, args: list[str], match: str) -> None:
    (tmp_path / "exists.rrd").write_bytes(b"keep me")
    with pytest.raises(ConfigError, match=match) as err:
        inspect_main([str(GOLDEN), *[a.format(tmp=tmp_path) for a in args]])
    assert err.value.exit_code == 2
    assert (tmp_path / "exists.rrd").read_bytes() == b"keep me"
    assert not (tmp_path / "x.rrd").exists()


def test_inspect_refuses_what_is_not_a_recording(tmp_path: Path) -> None:
    proc = run_cli(str(tmp_path), "--save", str(tmp_path / "x.rrd"), module="simlan_data.view")
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: not a readable recording in ")
    assert not (tmp_path / "x.rrd").exists()


def test_without_save_and_without_a_display_it_says_what_to_do() -> None:
    proc = run_cli(str(GOLDEN), module="simlan_data.view", env={"DISPLAY": "", "WAYLAND_DISPLAY": ""})
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: no display for the Rerun viewer in this session: neither DISPLAY nor WAYLAND_DISPLAY is set; "
        "write a file with --save run.rrd and open it with `rerun run.rrd` where there is a display"
    ]
