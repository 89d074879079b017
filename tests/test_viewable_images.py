"""Depth and semantic labels that viewers can show (issue 22): what the recording holds, read back
with the independent mcap + mcap_ros2 decoders (and PIL, OpenCV: what a viewer's PNG decoder
gives), and what the Rerun export holds, read back with the Rerun SDK.

- depth: the default ``16UC1`` (sensor_msgs/Image, millimetres, 0 = no return) is what Foxglove's
  Image panel colour-maps; ``png`` (compressedDepth) and ``raw`` (32FC1 metres, NaN = no return,
  REP 118) stay options. Each decodes to the in-process depth within half a millimetre.
- labels: a palette PNG: its indices are the class ids byte for byte, its palette the class
  colours of ``world/labels.py`` (a PNG decoder shows them), the names those of
  ``/simlan/semantic_labels``.
- the .rrd: depth and segmentation images of every camera, the class names and colours, and a
  pinhole whose projection lands on the image content of the undistorted image it shows in 3D.
"""

from __future__ import annotations

import io
import tempfile
from collections import defaultdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image
from rerun.chunk import RrdReader

from conftest import run_cli
from simlan_data.config.schema import RecordingConfig
from simlan_data.errors import RecordingInputError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.geometry.transforms import Transform
from simlan_data.recording.codecs import (
    LABELS_FORMAT,
    MONO_LABELS_FORMAT,
    decode_compressed,
    decode_raw,
    depth_to_32fc1,
    encode_labels,
    encode_png,
    png_palette,
)
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.camera_recording import CameraRecorder
from simlan_data.sim.pybullet_client import connect
from simlan_data.sim.rendering import CameraImages, CameraRenderer, LabelTable
from simlan_data.viz.rerun_export import rectification
from simlan_data.world.agent_types import agent_type
from simlan_data.world.builder import build_world
from simlan_data.world.labels import LABEL_COLOURS, LABEL_NAMES, SEMANTIC_CLASSES, label_palette
from simlan_data.world.layout import load_layout

CAMERAS = [str(c) for c in range(160, 171)]


def read_bag(recording: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every message of a recording's MCAP file decoded by mcap_ros2: {topic: [(log_time, msg)]}."""
    (path,) = recording.glob("*.mcap")
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            out[channel.topic].append((message.log_time, decoded))
    return out


def depth_metres_from_message(msg: Any) -> np.ndarray:
    """Depth in metres as a ROS consumer reads it, with no simlan_data code: NaN = no return."""
    if hasattr(msg, "format"):  # compressedDepth: 12-byte header, then a 16-bit PNG of mm
        assert msg.format == "16UC1; compressedDepth png"
        mm = cv2.imdecode(np.frombuffer(bytes(msg.data)[12:], np.uint8), cv2.IMREAD_UNCHANGED)
        return np.where(mm > 0, mm / 1000.0, np.nan)
    assert msg.is_bigendian == 0
    if msg.encoding == "16UC1":
        mm = np.frombuffer(bytes(msg.data), "<u2").reshape(msg.height, msg.step // 2)[:, : msg.width]
        return np.where(mm > 0, mm / 1000.0, np.nan)
    assert msg.encoding == "32FC1"
    return (
        np.frombuffer(bytes(msg.data), "<f4").reshape(msg.height, msg.step // 4)[:, : msg.width].astype(float)
    )


# ------------------------------------------------------------------------- the recorder, in process
@pytest.fixture(scope="module")
def rendered() -> list[CameraImages]:
    """Two cameras' frames of the full warehouse, rendered as a run renders them (960x540)."""
    client = connect("auto")
    with tempfile.TemporaryDirectory() as tmp:
        world = build_world(client.id, load_layout("warehouse_layout.csv", "default"), {}, mesh_dir=Path(tmp))
    labels = LabelTable()
    for body, label in world.labels.items():
        labels.set(body, label)
    frames = []
    for cid in ("161", "163"):
        cam = load_calibration(cid).camera.scaled(960, 540)
        frames.append(CameraRenderer(client, cam, labels, layered=False).render())
    client.disconnect()
    return frames


@pytest.mark.parametrize("encoding", ["16UC1", "png", "raw"])
def test_recorded_depth_is_the_in_process_depth(tmp_path: Path, rendered: list, encoding: str) -> None:
    """Each depth encoding, recorded by the recorder and decoded without simlan_data, is the
    in-process depth within 0.5 mm where there is a return; no return is NaN (32FC1) or 0 (the
    integer encodings); simlan_data's own decoders give 0 there, as the in-process image holds."""
    rec = RecordingConfig(depth_encoding=encoding)
    with RecordingWriter(tmp_path / "bag", encode_threads=2) as writer:
        recorder = CameraRecorder(writer, rec, ["rgb", "depth", "semantic"], depth_every=1, semantic_every=1)
        for cid, images in zip(("161", "163"), rendered):
            recorder.record(0, 0, load_calibration(cid).camera.scaled(960, 540), images)
    bag = read_bag(tmp_path / "bag")
    for cid, images in zip(("161", "163"), rendered):
        topic = f"/camera_{cid}/depth/image_raw" + ("/compressedDepth" if encoding == "png" else "")
        ((_, msg),) = bag[topic]
        if encoding == "png":
            raw_16 = cv2.imdecode(np.frombuffer(bytes(msg.data)[12:], np.uint8), cv2.IMREAD_UNCHANGED)
            assert raw_16.dtype == np.uint16
        else:
            assert msg.encoding == {"16UC1": "16UC1", "raw": "32FC1"}[encoding]
        depth = images.depth_m
        hit = depth > 0
        assert 0.05 < (~hit).mean() < 0.4 and hit.any()  # the vignette, and the warehouse
        got = depth_metres_from_message(msg)
        assert np.abs(got[hit] - depth[hit]).max() <= 0.0005 + 1e-6
        assert np.isnan(got[~hit]).all()  # NaN where none (REP 118; the integer 0s read as NaN)
        if encoding == "raw":
            assert np.array_equal(got[hit], depth[hit].astype(float))  # metres, as rendered
            zero = np.frombuffer(bytes(msg.data), "<f4").reshape(540, 960)
            assert not (zero == 0).any()  # no 0 left for "no return"
        mine = (
            decode_compressed(msg.format, msg.data)
            if encoding == "png"
            else decode_raw(
                msg.encoding, msg.height, msg.width, msg.step, np.frombuffer(bytes(msg.data), np.uint8)
            )
        )
        assert mine.dtype == np.float32 and (mine[~hit] == 0).all()
        assert np.abs(mine[hit] - depth[hit]).max() <= 0.0005 + 1e-6
        # the labels of the same frame: palette PNG, ids byte for byte
        ((_, sem),) = bag[f"/camera_{cid}/semantic/image_raw/compressed"]
        assert sem.format == LABELS_FORMAT
        png = Image.open(io.BytesIO(bytes(sem.data)))
        assert png.mode == "P" and np.array_equal(np.asarray(png), images.labels)
        assert np.array_equal(decode_compressed(sem.format, sem.data), images.labels)


def test_the_in_process_depth_is_left_as_it_is(rendered: list) -> None:
    """The recording's boundary converts a copy: the algorithms keep 0 = no return."""
    depth = rendered[0].depth_m
    before = depth.copy()
    nan_marked = depth_to_32fc1(depth)
    assert np.array_equal(depth, before) and (depth == 0).any()
    assert np.isnan(nan_marked[depth == 0]).all() and np.array_equal(nan_marked[depth > 0], depth[depth > 0])


def test_label_png_is_lossless_and_shows_the_class_colours(rendered: list) -> None:
    """What each reader of a label PNG gets: PIL the ids (mode P) and the palette; OpenCV (and
    so image_transport's compressed subscriber, and a browser) the class colours; simlan_data
    the ids. Nearly the size of the mono8 PNG it replaces."""
    labels = rendered[1].labels
    assert {SEMANTIC_CLASSES["floor"], SEMANTIC_CLASSES["shelf"]} <= set(np.unique(labels).tolist())
    fmt, data = encode_labels(labels)
    png = Image.open(io.BytesIO(data))
    assert png.mode == "P" and np.array_equal(np.asarray(png), labels)
    palette = np.asarray(png.getpalette(), dtype=np.uint8).reshape(-1, 3)
    assert np.array_equal(palette[: len(label_palette())], label_palette())
    assert np.array_equal(png_palette(data), label_palette())
    for i, colour in LABEL_COLOURS.items():
        assert tuple(palette[i]) == colour
    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(bgr[..., ::-1], label_palette()[labels])
    assert np.array_equal(decode_compressed(fmt, data), labels)
    mono = encode_png(labels)
    assert np.array_equal(decode_compressed(MONO_LABELS_FORMAT, mono), labels)  # recordings before
    assert len(data) <= 1.03 * len(mono) + 200
    # an id beyond the classes still round-trips (its colour: the unknown-class colour)
    odd = labels.copy()
    odd[0, :3] = (200, 255, 54)
    assert np.array_equal(decode_compressed(*encode_labels(odd)), odd)


def test_class_colours_are_distinct_so_a_colour_gives_its_class() -> None:
    assert set(LABEL_COLOURS) == set(LABEL_NAMES)
    assert len(set(LABEL_COLOURS.values())) == len(LABEL_COLOURS)


# ---------------------------------------------------------------------- a real run and its .rrd
@pytest.fixture(scope="module")
def bag(short_run: Path) -> dict[str, list[tuple[int, Any]]]:
    return read_bag(short_run / "recording")


def test_a_default_run_records_16uc1_depth_and_palette_labels(bag: dict[str, list]) -> None:
    """A default run (every camera, depth and labels every frame): depth as 16UC1 images of
    millimetres, labels as palette PNGs whose palette is the class colours of the classes that
    /simlan/semantic_labels names."""
    ((_, table),) = bag["/simlan/semantic_labels"]
    names = dict(zip(table.ids, table.names))
    assert names == dict(LABEL_NAMES)
    for cid in CAMERAS:
        depth = bag[f"/camera_{cid}/depth/image_raw"]
        assert len(depth) == 16  # 5 Hz over [0, 3] s
        msg = depth[0][1]
        assert (msg.encoding, msg.width, msg.height, msg.step) == ("16UC1", 960, 540, 1920)
        metres = depth_metres_from_message(msg)
        assert 0.05 < np.isnan(metres).mean() < 0.4 and 1.0 < np.nanmedian(metres) < 40.0
        for _, sem in bag[f"/camera_{cid}/semantic/image_raw/compressed"][:3]:
            png = Image.open(io.BytesIO(bytes(sem.data)))
            assert png.mode == "P"
            ids = np.asarray(png)
            assert np.array_equal(ids, decode_compressed(sem.format, sem.data))
            assert set(np.unique(ids).tolist()) <= set(names)
            palette = np.asarray(png.getpalette(), dtype=np.uint8).reshape(-1, 3)
            for i in names:
                assert tuple(palette[i]) == LABEL_COLOURS[i], names[i]


@pytest.fixture(scope="module")
def rrd(short_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rrd") / "run.rrd"
    proc = run_cli(str(short_run), "--save", str(out), module="simlan_data.view")
    assert proc.returncode == 0, proc.stderr
    return out


def _rrd_columns(path: Path) -> dict[str, dict[str, list[Any]]]:
    """Per entity, every column (components and the sim_time index) as Python lists."""
    out: dict[str, dict[str, list[Any]]] = defaultdict(lambda: defaultdict(list))
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        n = chunk.num_rows
        for name in batch.schema.names:
            if ":" in name or name == "sim_time":
                out[chunk.entity_path][name] += batch.column(name).to_pylist()
        if "sim_time" not in batch.schema.names:
            out[chunk.entity_path]["sim_time"] += [None] * n
    return out


def test_rrd_has_depth_and_segmentation_of_every_camera(rrd: Path, bag: dict[str, list]) -> None:
    columns = _rrd_columns(rrd)
    (context,) = columns["/world/cameras"]["AnnotationContext:context"][0]
    classes = {c["class_id"]: c["class_description"]["info"] for c in context}
    assert {i: info["label"] for i, info in classes.items()} == dict(LABEL_NAMES)
    for i, info in classes.items():
        rgba = info["color"]
        assert ((rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255) == LABEL_COLOURS[i]
    for cid in CAMERAS:
        depth = columns[f"/world/cameras/{cid}/depth"]
        assert depth["DepthImage:buffer"], cid
        assert depth["DepthImage:meter"][0] == [1000.0]
        semantic = columns[f"/world/cameras/{cid}/semantic"]
        assert semantic["SegmentationImage:buffer"], cid
        assert columns[f"/world/cameras/{cid}/undistorted"]["EncodedImage:blob"], cid
        assert columns[f"/world/cameras/{cid}/image"]["EncodedImage:blob"], cid
    # the first depth image of a camera, millimetre for millimetre as recorded
    (mm,) = columns["/world/cameras/163/depth"]["DepthImage:buffer"][0]
    recorded = bag["/camera_163/depth/image_raw"][0][1]
    assert bytes(mm) == bytes(recorded.data)
    (ids,) = columns["/world/cameras/163/semantic"]["SegmentationImage:buffer"][0]
    first = bag["/camera_163/semantic/image_raw/compressed"][0][1]
    assert bytes(ids) == np.asarray(Image.open(io.BytesIO(bytes(first.data)))).tobytes()
    blueprints = RrdReader(rrd).blueprints()
    assert len(blueprints) == 1


def test_rectification_maps_an_undistorted_pixel_to_where_the_camera_sees_its_ray() -> None:
    """The undistorted image's pixel of a ray (its pinhole K) holds the distorted image's pixel of
    that ray (the camera model), to the remap's 1/32 pixel."""
    cam = load_calibration("163").camera.scaled(960, 540)
    rect = rectification(cam)
    u, v = np.meshgrid(np.arange(960, dtype=np.float32), np.arange(540, dtype=np.float32))
    where = [rect.apply(c) for c in (u, v)]  # each undistorted pixel: the distorted pixel it shows
    rng = np.random.default_rng(3)
    xy = rng.uniform(-0.9, 0.9, (400, 2)) * [1.0, 0.5]
    uv_rect = xy * [rect.K[0, 0], rect.K[1, 1]] + [rect.K[0, 2], rect.K[1, 2]]
    inside = (uv_rect >= 0).all(axis=1) & (uv_rect <= [959, 539]).all(axis=1)
    inside &= np.hypot(*xy.T) < cam.valid_radius
    col, row = np.rint(uv_rect[inside]).astype(int).T
    xy_at = (np.stack([col, row], 1) - [rect.K[0, 2], rect.K[1, 2]]) / [rect.K[0, 0], rect.K[1, 1]]
    expected = cam.distort_normalized(xy_at)
    got = np.stack([where[0][row, col], where[1][row, col]], axis=1)
    visible = (expected >= 0).all(axis=1) & (expected <= [958, 538]).all(axis=1)
    assert visible.sum() > 100
    assert np.abs(got[visible] - expected[visible]).max() < 0.1
    # the undistorted image keeps the recorded field of view along its axes
    assert rect.K[0, 0] < cam.K[0, 0] and (rect.K[:2, 2] == cam.K[:2, 2]).all()


def test_pinhole_projection_lands_on_the_marker_in_the_undistorted_image(
    rrd: Path, bag: dict[str, list]
) -> None:
    """The robot's marker, its ground-truth position projected through the Transform3D and
    Pinhole the .rrd holds, is where OpenCV finds the marker in the undistorted image of the
    .rrd (the 3D view's image): within 1.5 px of the detected centre (about 0.3 px measured).
    The recorded, distorted camera's K there would miss by tens of pixels."""
    columns = _rrd_columns(rrd)
    marker_xyz = np.asarray(agent_type("pallet_truck").marker_xyz)
    truth = {}
    for stamp, msg in bag["/ground_truth/poses"]:
        (tf,) = msg.transforms
        t, q = tf.transform.translation, tf.transform.rotation
        truth[stamp] = Transform.from_quat([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
    start = min(truth)
    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_1000), cv2.aruco.DetectorParameters()
    )
    errors, recorded_K_errors = [], []
    for cid in CAMERAS:
        pose = columns[f"/world/cameras/{cid}"]
        world_from_camera = Transform(
            np.asarray(pose["Transform3D:mat3x3"][0][0]).reshape(3, 3).T,  # (column-major)
            np.asarray(pose["Transform3D:translation"][0][0]),
        )
        K = np.asarray(pose["Pinhole:image_from_camera"][-1][0]).reshape(3, 3).T
        recorded_K = load_calibration(cid).camera.scaled(960, 540).K
        images = columns[f"/world/cameras/{cid}/undistorted"]
        for when, (blob,) in zip(images["sim_time"], images["EncodedImage:blob"]):
            image = cv2.imdecode(np.frombuffer(bytes(blob), np.uint8), cv2.IMREAD_GRAYSCALE)
            corners, ids, _ = detector.detectMarkers(image)
            if ids is None or 1 not in ids.ravel():
                continue
            detected = corners[list(ids.ravel()).index(1)].reshape(4, 2).mean(axis=0)
            stamp = start + round(when.total_seconds() * 1e9)  # (sim_time: a duration)
            marker_world = truth[min(truth, key=lambda s: abs(s - stamp))].apply(marker_xyz[None])[0]
            p = world_from_camera.inverse().apply(marker_world[None])[0]
            projected = (K @ (p / p[2]))[:2]
            errors.append(float(np.hypot(*(projected - detected))))
            recorded_K_errors.append(float(np.hypot(*((recorded_K @ (p / p[2]))[:2] - detected))))
    assert len(errors) >= 3, "the marker was never found in an undistorted image"
    assert max(errors) < 1.5, errors
    assert min(recorded_K_errors) > 10, recorded_K_errors


@pytest.mark.parametrize("cut", [30, 60, -20])
def test_a_damaged_label_png_is_refused_in_one_line(cut: int) -> None:
    """A truncated palette PNG (a damaged recording) is a RecordingInputError, not a crash."""
    labels = np.zeros((40, 60), np.uint8)
    labels[10:20, 5:50] = SEMANTIC_CLASSES["pallet_truck"]
    fmt, data = encode_labels(labels)
    with pytest.raises(RecordingInputError, match="undecodable"):
        decode_compressed(fmt, data[:cut])
