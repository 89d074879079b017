"""The stream encoders that encode only changed rows: real OpenCV, real ISA-L, two PNG decoders."""

from __future__ import annotations

import io
import threading
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image

from simlan_data.recording.codecs import (
    DEPTH_HEADER,
    decode_compressed,
    depth_to_mm,
    encode_depth,
    encode_png,
    encode_rgb,
)
from simlan_data.recording.incremental import (
    BAND_ROWS,
    BandedJpeg,
    BandedPng,
    DepthStream,
    RgbStream,
    changed_rows,
    splices_exactly,
)


def _scene(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """A textured image (JPEG segments of noise-free flat images would all look alike)."""
    noise = rng.integers(0, 256, shape, dtype=np.uint8)
    return np.asarray(cv2.GaussianBlur(noise, (7, 7), 2.0), dtype=np.uint8)


def _moved(
    image: np.ndarray, rng: np.random.Generator, rows: tuple[int, int], cols: tuple[int, int]
) -> np.ndarray:
    out = image.copy()
    patch = out[rows[0] : rows[1], cols[0] : cols[1]]
    out[rows[0] : rows[1], cols[0] : cols[1]] = rng.integers(0, 256, patch.shape, dtype=out.dtype)
    return out


# a camera's frame sequence: one robot moving (rows inside one MCU row, across MCU rows, in the
# last, partial MCU row of 540, in the last rows of a PNG band: the next band's first filtered row
# changes with them), two at once, nothing, everything, and a new image size
def _frames(shape: tuple[int, ...], rng: np.random.Generator) -> list[np.ndarray]:
    first = _scene(rng, shape)
    frames = [first]
    for rows, cols in [
        ((100, 110), (200, 300)),
        ((90, 170), (0, 960)),
        ((530, 540), (10, 40)),
        ((0, 3), (0, 5)),
        ((28, 32), (0, 960)),
    ]:
        frames.append(_moved(frames[-1], rng, rows, cols))
    frames.append(_moved(_moved(frames[-1], rng, (40, 60), (5, 50)), rng, (300, 333), (600, 700)))
    frames.append(frames[-1].copy())  # unchanged
    frames.append(_scene(rng, shape))  # every row changed
    frames.append(_scene(rng, (shape[0] - 16, *shape[1:])))  # another size
    frames.append(_moved(frames[-1], rng, (200, 230), (100, 120)))
    return frames


def test_banded_jpeg_is_the_whole_image_encoding_byte_for_byte() -> None:
    assert splices_exactly()  # OpenCV's encoder splits into restart segments as assumed
    rng = np.random.default_rng(1)
    encoder = BandedJpeg(jpeg_quality=85)
    for frame in _frames((540, 960, 3), rng):
        assert encoder.encode(frame) == encode_rgb(frame, "jpeg", jpeg_quality=85)[1]
    # the small changes re-encoded only their MCU rows: most rows came from earlier frames
    assert encoder.rows_reused > 3 * encoder.rows_encoded // 4


@pytest.mark.parametrize("width", [960, 200, 56])  # restart intervals of 4, 2 (13 MCUs: 1) MCUs
def test_banded_jpeg_at_widths_with_other_restart_intervals(width: int) -> None:
    rng = np.random.default_rng(width)
    image = _scene(rng, (100, width, 3))
    encoder = BandedJpeg(jpeg_quality=90)
    encoder.encode(image)
    changed = _moved(image, rng, (35, 45), (0, 8))  # inside MCU row 2 (rows 32-47)
    assert encoder.encode(changed) == encode_rgb(changed, "jpeg", jpeg_quality=90)[1]
    assert encoder.rows_reused == 6  # 7 MCU rows of 16 (100 px), one re-encoded


@pytest.mark.parametrize(
    ("shape", "dtype"), [((540, 960), np.uint16), ((540, 960), np.uint8), ((70, 33, 3), np.uint8)]
)
def test_banded_png_decodes_to_each_image_in_two_independent_decoders(
    shape: tuple[int, ...], dtype: type
) -> None:
    rng = np.random.default_rng(2)
    encoder = BandedPng()
    for frame in _frames(shape, rng) if shape[0] > 100 else [_scene(rng, shape), _scene(rng, shape)]:
        frame = frame.astype(dtype) * (257 if dtype is np.uint16 else 1)
        data = encoder.encode(frame)
        decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(decoded, frame if frame.ndim == 2 else frame[..., ::-1])  # (OpenCV: BGR)
        pil = Image.open(io.BytesIO(data))
        pil.load()  # Pillow checks the chunk CRCs, zlib the stream's Adler-32
        assert np.array_equal(np.asarray(pil).astype(dtype), frame)


def test_banded_png_depends_on_the_image_only_and_is_as_small_as_one_stream() -> None:
    rng = np.random.default_rng(3)
    depth = (rng.random((540, 960)) * 3 + 2).astype(np.float32)
    depth = np.asarray(cv2.GaussianBlur(depth, (0, 0), 8), dtype=np.float32)  # smooth, like a scene
    mm = depth_to_mm(depth)
    encoder = BandedPng()
    encoder.encode(mm)
    changed = mm.copy()
    changed[260:280, 400:500] = 1500  # a box inside one band (rows 256-287)
    after_history = encoder.encode(changed)
    assert encoder.bands_compressed == -(-540 // BAND_ROWS) + 1  # the first image's bands, then one
    assert after_history == BandedPng().encode(changed)  # same bytes as a fresh encoder's
    whole = encode_png(changed)
    assert len(after_history) <= 1.01 * len(whole)
    # one zlib stream with the right Adler-32 (zlib checks it; a wrong one raises)
    idat_start = after_history.index(b"IDAT") + 4
    length = int.from_bytes(after_history[idat_start - 8 : idat_start - 4], "big")
    raw = zlib.decompress(after_history[idat_start : idat_start + length])
    assert len(raw) == 540 * (2 * 960 + 1)


def test_stream_encoders_give_what_the_codecs_give() -> None:
    rng = np.random.default_rng(4)
    depth = (rng.random((60, 80)) * 10).astype(np.float32)
    fmt, data = DepthStream()(depth)
    assert (fmt, data[: DEPTH_HEADER.size]) == (
        encode_depth(depth)[0],
        encode_depth(depth)[1][: DEPTH_HEADER.size],
    )
    assert np.array_equal(decode_compressed(fmt, data), decode_compressed(*encode_depth(depth)))
    rgb = _scene(rng, (64, 96, 3))
    assert RgbStream("jpeg", jpeg_quality=80)(rgb) == encode_rgb(rgb, "jpeg", jpeg_quality=80)
    fmt, data = RgbStream("png", jpeg_quality=80)(rgb)
    assert np.array_equal(decode_compressed(fmt, data), rgb)
    with pytest.raises(ValueError, match="not a compressed colour encoding: 'raw'"):
        RgbStream("raw", jpeg_quality=80)
    with pytest.raises(ValueError, match="band_rows must be at least 1"):
        BandedPng(band_rows=0)


def test_one_stream_encoded_from_two_threads_gives_each_image_its_own_bytes() -> None:
    rng = np.random.default_rng(5)
    frames = [_moved(_scene(rng, (200, 320, 3)), rng, (50, 90), (10, 300)) for _ in range(6)]
    jpeg, png = BandedJpeg(jpeg_quality=85), BandedPng()
    results: dict[tuple[str, int], bytes] = {}

    def work(offset: int) -> None:
        for _ in range(20):
            for i in range(offset, len(frames), 2):
                results[("jpeg", i)] = jpeg.encode(frames[i])
                results[("png", i)] = png.encode(frames[i])

    threads = [threading.Thread(target=work, args=(k,)) for k in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i, frame in enumerate(frames):
        assert results[("jpeg", i)] == encode_rgb(frame, "jpeg", jpeg_quality=85)[1]
        assert results[("png", i)] == BandedPng().encode(frame)


def test_changed_rows_compares_whole_rows_of_any_layout() -> None:
    a = np.zeros((5, 7, 3), np.uint8)  # 21-byte rows: compared byte by byte
    b = a.copy()
    b[3, 6, 2] = 1
    assert changed_rows(b, a).tolist() == [False, False, False, True, False]
    assert changed_rows(b, None).all() and changed_rows(b, a[:4]).all()
    c = np.zeros((4, 8), np.uint16)  # 16-byte rows: compared 8 bytes at a time
    d = c.copy()
    d[0, 7] = 9
    assert changed_rows(d, c).tolist() == [True, False, False, False]
