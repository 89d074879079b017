"""Recording format: writer -> reader round trips, codecs, custom types, safety of the writer."""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image

from simlan_data.constants import NS_PER_S
from simlan_data.errors import RecordingError, RecordingInputError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.codecs import (
    decode_compressed,
    decode_raw,
    depth_to_mm,
    encode_depth,
    encode_labels,
    encode_png,
    encode_rgb,
)
from simlan_data.recording.reader import RecordingReader
from simlan_data.recording.writer import RecordingWriter

TOPICS = {t.name: t for t in schema.GLOBAL_TOPICS}


def _small_bag(path: Path, *, frames: int = 4, encode_threads: int = 0) -> None:
    """2 cameras x ``frames`` frames x 16x16 px, ground truth, a custom message."""
    rng = np.random.default_rng(0)
    cams = {cid: schema.camera_topics(cid, rgb="jpeg", depth="png", semantic="raw") for cid in ("1", "2")}
    with RecordingWriter(path, encode_threads=encode_threads, flush_period_ns=NS_PER_S // 2) as w:
        w.set_metadata("simlan.format_version", "1.0")
        for k in range(frames):
            t = k * NS_PER_S // 4
            w.write(TOPICS["/clock"], t, M.clock(t))
            pose = Transform.from_pose2d(0.1 * k, 0.0, 0.05 * k)
            w.write(
                TOPICS["/ground_truth/poses"],
                t,
                M.tf_message([M.transform_stamped(t, "map", "robot_agent_1/base_link", pose)]),
            )
            for cid, topics in cams.items():
                rgb = rng.integers(0, 255, (16, 16, 3), dtype=np.uint8)
                depth = rng.uniform(1, 30, (16, 16)).astype(np.float32)
                labels = rng.integers(0, 60, (16, 16), dtype=np.uint8)
                w.submit(
                    topics["rgb"],
                    t,
                    lambda a=rgb, t=t, c=cid: M.compressed_image(t, f"camera_{c}", *encode_rgb(a, "png")),
                )
                w.submit(
                    topics["depth"],
                    t,
                    lambda a=depth, t=t, c=cid: M.compressed_image(t, f"camera_{c}", *encode_depth(a)),
                )
                w.submit(topics["semantic"], t, lambda a=labels, t=t, c=cid: M.raw_image(t, f"camera_{c}", a))
            w.write(
                schema.agent_topics("robot_agent_1")["collision"],
                t,
                M.collision_state(
                    t,
                    "robot_agent_1/base_link",
                    in_collision=k == 2,
                    max_force_n=3.0 * k,
                    total_force_n=4.0 * k,
                    others=["shelf_1"] if k == 2 else [],
                ),
            )


@pytest.mark.parametrize("threads", [0, 2])
def test_round_trip_and_time_order(tmp_path: Path, threads: int) -> None:
    _small_bag(tmp_path / "bag", encode_threads=threads)
    with RecordingReader(tmp_path / "bag") as r:
        assert r.format_version == "1.0"
        assert r.topics["/camera_1/image_raw/compressed"].count == 4
        stamps = [m.stamp_ns for m in r.messages()]
        assert stamps == sorted(stamps)
        collisions = [m.msg for m in r.messages(["/robot_agent_1/collision"])]
        assert [c.in_collision for c in collisions] == [False, False, True, False]
        assert collisions[2].other_bodies == ["shelf_1"]
        depth = [
            decode_compressed(m.msg.format, m.msg.data)
            for m in r.messages(["/camera_2/depth/image_raw/compressedDepth"])
        ]
        assert depth[0].shape == (16, 16) and depth[0].min() >= 1.0 and depth[0].max() <= 30.0
        assert "Topic: /camera_2/semantic/image_raw" in r.summary()


def test_same_input_same_bytes_with_threads(tmp_path: Path) -> None:
    _small_bag(tmp_path / "a" / "bag", encode_threads=0)
    _small_bag(tmp_path / "b" / "bag", encode_threads=3)
    assert (tmp_path / "a" / "bag" / "bag.mcap").read_bytes() == (
        tmp_path / "b" / "bag" / "bag.mcap"
    ).read_bytes()


def test_custom_types_decode_with_the_independent_reader(tmp_path: Path) -> None:
    _small_bag(tmp_path / "bag")
    with (tmp_path / "bag" / "bag.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs = [
            (c.topic, m) for _, c, _, m in reader.iter_decoded_messages(topics=["/robot_agent_1/collision"])
        ]
    assert msgs[2][1].in_collision and msgs[2][1].max_normal_force_n == 6.0


def test_flush_policy_puts_data_on_disk_while_writing(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    w = RecordingWriter(path, flush_period_ns=NS_PER_S)
    w.open()
    topic = TOPICS["/clock"]
    sizes = []
    for k in range(40):
        t = k * NS_PER_S // 10
        w.write(topic, t, M.clock(t))
        sizes.append((path / "bag.mcap").stat().st_size)
    assert w.flushes >= 3 and sizes[-1] > sizes[0]
    w.close()


def test_writer_refuses_an_existing_path(tmp_path: Path) -> None:
    (tmp_path / "bag").mkdir()
    with pytest.raises(RecordingError, match=r"recording exists in .*bag: simlan_data never overwrites"):
        RecordingWriter(tmp_path / "bag")


def test_codecs_round_trip() -> None:
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 255, (24, 32, 3), dtype=np.uint8)
    assert np.array_equal(decode_compressed(*encode_rgb(rgb, "png")), rgb)
    jpeg = decode_compressed(
        *encode_rgb(np.full((24, 32, 3), (200, 30, 10), np.uint8), "jpeg", jpeg_quality=95)
    )
    assert np.abs(jpeg.astype(int) - (200, 30, 10)).max() <= 3
    depth = rng.uniform(0.5, 60.0, (24, 32)).astype(np.float32)
    depth[0, 0] = 0.0
    back = decode_compressed(*encode_depth(depth))
    assert np.abs(back - depth).max() <= 0.0005 + 1e-6 and back[0, 0] == 0.0
    labels = rng.integers(0, 255, (24, 32), dtype=np.uint8)
    assert np.array_equal(decode_compressed(*encode_labels(labels)), labels)
    raw = M.raw_image(0, "f", depth)
    assert np.array_equal(decode_raw(raw.encoding, raw.height, raw.width, raw.step, raw.data), depth)


@pytest.mark.parametrize(
    ("shape", "dtype"),
    [
        ((540, 960), np.uint16),
        ((37, 53), np.uint8),
        ((1, 1), np.uint16),
        ((1, 7), np.uint8),
        ((9, 1), np.uint16),
        ((24, 31, 3), np.uint8),
        ((1, 1, 3), np.uint8),
    ],
)
def test_png_decodes_to_the_image_in_two_independent_decoders(shape: tuple[int, ...], dtype: type) -> None:
    """Our PNG writer (ISA-L deflate) against libpng (OpenCV) and Pillow, CRCs checked by Pillow."""
    rng = np.random.default_rng(sum(shape))
    top = np.iinfo(dtype).max
    image = rng.integers(0, top, shape, dtype=dtype, endpoint=True)
    image.flat[0], image.flat[-1] = 0, top  # both extremes, and runs that deflate finds
    if image.shape[0] > 4:
        image[2:4] = image[1]
    data = encode_png(image)
    via_opencv = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image.ndim == 3:
        via_opencv = cv2.cvtColor(via_opencv, cv2.COLOR_BGR2RGB)
    assert via_opencv.dtype == dtype and np.array_equal(via_opencv.reshape(shape), image)
    Image.open(io.BytesIO(data)).verify()  # chunk CRCs and structure
    via_pillow = np.asarray(Image.open(io.BytesIO(data)))
    assert np.array_equal(via_pillow.astype(dtype).reshape(shape), image)


def test_png_writer_takes_views_and_refuses_what_png_cannot_hold() -> None:
    base = np.arange(40 * 30, dtype=np.uint16).reshape(40, 30) * 50
    view = base[::-2, 3:17]  # negative and non-unit strides
    back = cv2.imdecode(np.frombuffer(encode_png(view), np.uint8), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(back, view)
    swapped = view.astype(">u2")  # big-endian input: same pixels
    assert encode_png(swapped) == encode_png(view)
    for bad, match in (
        (np.zeros((4, 4), np.float32), "float32 image"),
        (np.zeros((4, 4, 4), np.uint8), r"shape \(4, 4, 4\)"),
        (np.zeros((0, 4), np.uint8), "empty image"),
    ):
        with pytest.raises(ValueError, match=match):
            encode_png(bad)


def test_depth_to_mm_rounds_saturates_and_zeroes_invalid_depths() -> None:
    depth = np.array(
        [[0.0, 0.0004, 0.0006, 1.2344, 1.2346, 65.535, 70.0, -0.5, np.nan, np.inf, -np.inf]], np.float32
    )
    assert depth_to_mm(depth).tolist() == [[0, 0, 1, 1234, 1235, 65535, 65535, 0, 0, 0, 0]]


def test_camera_info_carries_the_calibration() -> None:
    cam = load_calibration("165").camera.scaled(960, 540)
    info = M.camera_info(5, cam)
    assert info.distortion_model == "plumb_bob" and info.width == 960
    np.testing.assert_allclose(np.asarray(info.k).reshape(3, 3), cam.K)
    np.testing.assert_allclose(info.d, cam.D)


@pytest.mark.parametrize(
    ("fmt", "data", "match"),
    [
        ("16UC1; compressedDepth png", b"\x00" * 5, "truncated"),
        ("rgb8; jpeg compressed bgr8", b"not a jpeg", "undecodable"),
        ("h264", b"\x00", "unknown image format"),
    ],
)
def test_corrupt_images_raise_clear_errors(fmt: str, data: bytes, match: str) -> None:
    with pytest.raises(RecordingInputError, match=match):
        decode_compressed(fmt, data)


def test_reader_refuses_non_recordings(tmp_path: Path) -> None:
    with pytest.raises(RecordingInputError, match="no such file"):
        RecordingReader(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RecordingInputError, match=r"no metadata\.yaml"):
        RecordingReader(tmp_path / "empty")
    _small_bag(tmp_path / "bag")
    meta = tmp_path / "bag" / "metadata.yaml"
    meta.write_text(meta.read_text().replace("simlan.format_version: '1.0'", "simlan.format_version: '7.0'"))
    with pytest.raises(RecordingInputError, match="newer than this simlan_data"):
        RecordingReader(tmp_path / "bag")


def test_restamp_changes_only_the_header_stamp() -> None:
    store = schema.typestore()
    cam = load_calibration("163").camera.scaled(960, 540)
    for msg, msgtype in (
        (M.camera_info(5, cam), schema.CAMERA_INFO_TYPE),
        (
            M.compressed_image(5, "camera_163_optical_frame", "rgb8; png compressed bgr8", b"\x89PNG1234"),
            schema.COMPRESSED_IMAGE_TYPE,
        ),
    ):
        cdr = bytes(store.serialize_cdr(msg, msgtype))
        stamp = 3 * NS_PER_S + 123
        again = store.deserialize_cdr(M.restamp(cdr, stamp), msgtype)
        assert M.stamp_ns_of(again.header.stamp) == stamp
        assert again.header.frame_id == msg.header.frame_id
        assert bytes(store.serialize_cdr(again, msgtype)) == M.restamp(cdr, stamp)


def test_an_image_pass_keeps_the_small_topics_for_later_reads(tmp_path: Path) -> None:
    """Reading images to the end fills the small-topic cache (no second pass over the chunks);
    what it holds is exactly what a pass over the small topics alone reads, in the same order."""
    _small_bag(tmp_path / "bag", frames=6)
    images = ["/camera_1/image_raw/compressed", "/camera_2/depth/image_raw/compressedDepth"]
    with RecordingReader(tmp_path / "bag") as fresh:
        alone = [(m.topic, m.stamp_ns, bytes(m.msg)) for m in fresh.messages(raw=True)]
        small_alone = [x for x in alone if x[0] not in {*images, "/camera_2/image_raw/compressed"}]
        small_alone = [x for x in small_alone if "/camera_" not in x[0]]
    with RecordingReader(tmp_path / "bag") as r:
        seen = [m.topic for m in r.messages(images)]
        assert seen.count(images[0]) == 6 and seen.count(images[1]) == 6
        assert r._small is not None, "the image pass did not fill the cache"
        cached = [(c.topic, s, bytes(d)) for c, s, d in r._small]
        assert cached == small_alone
        truth = [m.stamp_ns for m in r.messages(["/ground_truth/poses"])]
        assert truth == [k * NS_PER_S // 4 for k in range(6)]
    with RecordingReader(tmp_path / "bag") as r:  # a pass left early keeps nothing half-read
        for _ in zip(range(2), r.messages(images)):
            pass
        assert r._small is None
