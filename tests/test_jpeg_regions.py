"""Decoding only the searched regions of a recorded JPEG (restart markers) gives the whole
decode's pixels bit for bit, and so the same markers and corners; JPEGs without usable restart
markers fall back to a whole decode. Real recorded frames of a real run (the short_run fixture)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from simlan_data.algorithms.localization import Localizer
from simlan_data.algorithms.markers import MarkerMount
from simlan_data.imaging.jpeg_regions import decode_gray_regions, segments
from simlan_data.recording import schema
from simlan_data.recording.cameras import cameras_in_recording
from simlan_data.recording.codecs import encode_rgb, jpeg_restart_interval
from simlan_data.recording.messages import compressed_image_data
from simlan_data.recording.reader import RecordingReader
from simlan_data.world.agent_types import MARKER_SIZE_M


@pytest.fixture(scope="module")
def recorded(short_run: Path):
    """(camera id, JPEG bytes) of every third colour image of the short run, and its cameras."""
    with RecordingReader(short_run / "recording") as reader:
        cameras = cameras_in_recording(reader)
        topics = [f"/camera_{c}/image_raw/compressed" for c in cameras]
        images = [
            (m.topic.split("/")[1].removeprefix("camera_"), bytes(m.msg.data))
            for m in reader.messages(topics)
        ]
    return cameras, images[::3]


def _full(jpeg: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_GRAYSCALE)


def _random_rois(
    rng: np.random.Generator, width: int, height: int, n: int
) -> list[tuple[int, int, int, int]]:
    rois = [(0, 0, width, height), (width - 9, height - 9, width, height), (0, height - 8, 40, height)]
    rois.append((width - 30, height - 20, width + 50, height + 40))  # past the border: clipped as a slice
    for _ in range(n):
        u0, v0 = int(rng.integers(0, width - 8)), int(rng.integers(0, height - 8))
        rois.append(
            (u0, v0, min(width, u0 + int(rng.integers(8, 200))), min(height, v0 + int(rng.integers(8, 200))))
        )
    return rois


def test_recorded_regions_decode_to_the_whole_decodes_pixels(recorded) -> None:
    _, images = recorded
    rng = np.random.default_rng(0)
    assert len(images) >= 20
    for _, jpeg in images:
        seg = segments(jpeg)
        assert seg is not None, "the recorder writes restart markers"
        assert seg.interval == jpeg_restart_interval(seg.width)
        full = _full(jpeg)
        rois = _random_rois(rng, seg.width, seg.height, 6)
        crops = decode_gray_regions(jpeg, rois)
        assert crops is not None and len(crops) == len(rois)
        for (u0, v0, u1, v1), crop in zip(rois, crops):
            np.testing.assert_array_equal(crop, full[v0:v1, u0:u1])


def test_region_search_finds_the_same_markers_and_corners_as_a_whole_decode(recorded) -> None:
    """Localizer.detect on the JPEG (regions decoded) against the whole decoded grey image."""
    cameras, images = recorded
    mounts = [MarkerMount(f"robot_agent_{i}", i, MARKER_SIZE_M, 0.3, (0.0, 0.0)) for i in range(1, 5)]
    localizer = Localizer(cameras, mounts)
    compared = 0
    for cid, jpeg in images:
        full = _full(jpeg)
        whole = localizer.detect(cid, "full", gray=full)
        if not whole.detections:
            continue
        plan = []
        for d in whole.detections:
            lo = np.floor(d.corners_px.min(axis=0) - 24).astype(int).clip(0)
            hi = np.ceil(d.corners_px.max(axis=0) + 24).astype(int)
            plan.append((int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])))
        by_regions = localizer.detect(cid, plan, jpeg=jpeg)
        reference = localizer.detect(cid, plan, gray=full)
        assert [d.marker_id for d in by_regions.detections] == [d.marker_id for d in reference.detections]
        for a, b in zip(by_regions.detections, reference.detections):
            np.testing.assert_array_equal(a.corners_px, b.corners_px)
        assert by_regions.observations == reference.observations
        compared += len(plan)
    assert compared >= 5


@pytest.mark.parametrize(
    ("params", "why"),
    [
        ([cv2.IMWRITE_JPEG_QUALITY, 85], "no restart markers (other writers, older recordings)"),
        ([cv2.IMWRITE_JPEG_PROGRESSIVE, 1, cv2.IMWRITE_JPEG_RST_INTERVAL, 4], "progressive"),
        ([cv2.IMWRITE_JPEG_RST_INTERVAL, 7], "an interval that does not divide an MCU row (60)"),
    ],
)
def test_jpegs_that_cannot_be_cut_are_decoded_whole(recorded, params, why) -> None:
    cameras, images = recorded
    cid, jpeg = images[len(images) // 2]
    full = _full(jpeg)
    other = cv2.imencode(".jpg", cv2.cvtColor(full, cv2.COLOR_GRAY2BGR), params)[1].tobytes()
    assert decode_gray_regions(other, [(10, 10, 90, 90)]) is None, why
    localizer = Localizer(cameras, [MarkerMount("robot_agent_1", 1, MARKER_SIZE_M, 0.3, (0.0, 0.0))])
    assert localizer.detect(cid, [(0, 0, 400, 300)], jpeg=other).detections == (
        localizer.detect(cid, [(0, 0, 400, 300)], gray=_full(other)).detections
    )
    assert segments(b"not a jpeg") is None
    assert segments(jpeg[: len(jpeg) // 2]) is None  # truncated: no end of image


@pytest.mark.parametrize(("width", "height"), [(100, 70), (960, 540), (136, 33)])
def test_odd_sizes_still_cut_exactly(width: int, height: int) -> None:
    rng = np.random.default_rng(width)
    rgb = cv2.GaussianBlur(rng.integers(0, 256, (height, width, 3), dtype=np.uint8), (5, 5), 0)
    _, data = encode_rgb(rgb, "jpeg", jpeg_quality=85)
    full = _full(data)
    rois = _random_rois(rng, width, height, 8)
    crops = decode_gray_regions(data, rois)
    assert crops is not None
    for (u0, v0, u1, v1), crop in zip(rois, crops):
        np.testing.assert_array_equal(crop, full[v0:v1, u0:u1])


def test_compressed_image_bytes_are_read_without_deserializing(short_run: Path) -> None:
    store = schema.typestore()
    with RecordingReader(short_run / "recording") as reader:
        topics = [t for t in reader.topics if reader.topics[t].msgtype == schema.COMPRESSED_IMAGE_TYPE]
        n = 0
        for m in reader.messages(topics[:6], raw=True):
            view = compressed_image_data(m.msg)
            assert view is not None
            assert bytes(view) == bytes(store.deserialize_cdr(m.msg, m.msgtype).data)
            n += 1
        assert n >= 20
    assert compressed_image_data(b"\x01\x00\x00\x00" + bytes(40)) is None  # big-endian CDR
    assert compressed_image_data(m.msg[:-5]) is None  # truncated
    assert compressed_image_data(bytes(m.msg) + bytes(8)) is None  # not this layout


def test_damaged_jpegs_never_raise(recorded) -> None:
    """Untrusted bytes (a corrupt recording): a region decode gives the whole decode's pixels
    where the regions hold, or None (then the localizer decodes the image whole), never an
    exception from the parser."""
    _, images = recorded
    rng = np.random.default_rng(3)
    jpeg = images[0][1]
    for _ in range(300):
        data = bytearray(jpeg)
        for _ in range(int(rng.integers(1, 6))):
            at = int(rng.integers(0, 700)) if rng.random() < 0.7 else int(rng.integers(0, len(data)))
            data[at] = int(rng.integers(0, 256))
        if rng.random() < 0.2:
            data = data[: int(rng.integers(0, len(data)))]
        crops = decode_gray_regions(bytes(data), [(0, 0, 100, 100), (500, 300, 600, 400)])
        assert crops is None or all(c.dtype == np.uint8 for c in crops)
