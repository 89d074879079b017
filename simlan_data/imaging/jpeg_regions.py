"""Decode only a region of a JPEG image, by its restart markers (no libjpeg crop API needed).

A baseline JPEG written with a restart interval (``cv2.IMWRITE_JPEG_RST_INTERVAL``, in MCUs, the
16x16 pixel blocks of 4:2:0 colour) is a sequence of independently entropy-coded segments: the
decoder's DC predictions restart at every restart marker. When the interval divides the MCUs of
an image row, every segment covers a fixed rectangle of the image, and a rectangle of segments is
itself a valid JPEG: the original headers with the rectangle's size, its segments with their
restart markers renumbered. Decoding that small JPEG costs about its share of the pixels.

The pixels are the full decode's, bit for bit: grey output is the luminance channel, which is
neither subsampled nor upsampled, and each 8x8 block's inverse DCT depends on its coefficients
alone (tests/test_jpeg_regions.py checks it on rendered frames). Images without usable restart
markers (other writers, older recordings) are decoded whole; callers need not know which.

Pure numpy/OpenCV: no file format beyond JPEG itself.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

_SOF_SEQUENTIAL = (0xC0, 0xC1)  # baseline and extended sequential Huffman: the ones we can splice
_SOF_OTHER = frozenset({0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})
RST_MARKERS = [bytes((0xFF, 0xD0 + i)) for i in range(8)]  # segment j is followed by RST_MARKERS[j % 8]
EOI = b"\xff\xd9"


@dataclass(frozen=True)
class JpegSegments:
    """A JPEG split at its restart markers (see :func:`segments`)."""

    head: bytes  # SOI .. the byte before SOF's height field
    sof_tail: bytes  # SOF after its width field .. end of the SOS header
    width: int
    height: int
    mcu_w: int
    mcu_h: int
    interval: int  # restart interval, MCUs
    per_row: int  # segments per MCU row
    data: bytes  # the whole JPEG
    starts: NDArray[np.int64]  # per segment: first byte in data
    ends: NDArray[np.int64]  # per segment: one past its last byte (before the marker)


MAX_PIXELS = 8192 * 8192  # (as recording.codecs: larger images from a recording are refused)


def segments(jpeg: bytes) -> JpegSegments | None:
    """Parse a JPEG's headers and find its restart segments; None if it cannot be cropped
    (progressive or multi-scan, no restart interval, an interval that does not divide an MCU
    row, or anything unexpected: untrusted bytes never raise here)."""
    try:
        return _segments(bytes(jpeg))
    except (struct.error, IndexError, ValueError):
        return None


def _segments(data: bytes) -> JpegSegments | None:
    n = len(data)
    if n < 4 or data[:2] != b"\xff\xd8":
        return None
    pos, sof, interval, sos_end = 2, None, 0, None
    while pos + 4 <= n:
        if data[pos] != 0xFF:
            return None
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        (length,) = struct.unpack_from(">H", data, pos + 2)
        body = pos + 4
        if length < 2 or pos + 2 + length > n:
            return None
        if marker in _SOF_SEQUENTIAL:
            if length < 8 or length != 8 + 3 * data[body + 5]:
                return None
            sof = pos
        elif marker in _SOF_OTHER:
            return None
        elif marker == 0xDD and length == 4:
            (interval,) = struct.unpack_from(">H", data, body)
        elif marker == 0xDA:
            if sof is None or data[body] != data[sof + 9]:  # one scan with every component
                return None
            sos_end = pos + 2 + length
            break
        elif marker == 0xD9:
            return None
        pos += 2 + length
    if sof is None or sos_end is None or interval <= 0:
        return None
    height, width = struct.unpack_from(">HH", data, sof + 5)
    ncomp = data[sof + 9]
    if width == 0 or height == 0 or width * height > MAX_PIXELS or ncomp not in (1, 3):
        return None
    hs = [data[sof + 11 + 3 * i] >> 4 for i in range(ncomp)]
    vs = [data[sof + 11 + 3 * i] & 0x0F for i in range(ncomp)]
    if not all(1 <= f <= 4 for f in (*hs, *vs)):
        return None
    if ncomp == 1:  # a single-component scan is not interleaved: its MCU is one 8x8 block
        mcu_w = mcu_h = 8
    else:
        mcu_w, mcu_h = 8 * max(hs), 8 * max(vs)
    mcus_x, mcus_y = -(-width // mcu_w), -(-height // mcu_h)
    if mcus_x % interval:
        return None
    # restart markers: 0xFF then 0xD0..0xD7 (inside entropy data 0xFF is followed by 0x00)
    scan = np.frombuffer(data, dtype=np.uint8, offset=sos_end)
    ff = np.flatnonzero(scan[:-1] == 0xFF)
    follow = scan[ff + 1]
    eoi = ff[follow == 0xD9]
    if not len(eoi):
        return None
    end = int(eoi[0]) + sos_end
    rst = ff[(follow & 0xF8) == 0xD0] + sos_end
    rst = rst[rst < end]
    per_row = mcus_x // interval
    if len(rst) != mcus_y * per_row - 1:
        return None
    starts = np.concatenate(([sos_end], rst + 2)).astype(np.int64)
    ends = np.concatenate((rst, [end])).astype(np.int64)
    return JpegSegments(
        data[: sof + 5],
        data[sof + 9 : sos_end],
        width,
        height,
        mcu_w,
        mcu_h,
        interval,
        per_row,
        data,
        starts,
        ends,
    )


def crop_bounds(seg: JpegSegments, roi: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    """The segment-aligned rectangle (x0, y0, x1, y1, pixels) that covers ``roi`` (u0, v0, u1, v1)."""
    u0, v0, u1, v1 = roi
    cell_w = seg.mcu_w * seg.interval
    x0 = (max(0, u0) // cell_w) * cell_w
    y0 = (max(0, v0) // seg.mcu_h) * seg.mcu_h
    x1 = min(seg.width, -(-min(u1, seg.width) // cell_w) * cell_w)
    y1 = min(seg.height, -(-min(v1, seg.height) // seg.mcu_h) * seg.mcu_h)
    return x0, y0, x1, y1


def sub_jpeg(seg: JpegSegments, bounds: tuple[int, int, int, int]) -> bytes:
    """A JPEG of the segment-aligned rectangle ``bounds`` (from :func:`crop_bounds`)."""
    x0, y0, x1, y1 = bounds
    cell_w = seg.mcu_w * seg.interval
    k0, k1 = x0 // cell_w, -(-x1 // cell_w)
    r0, r1 = y0 // seg.mcu_h, -(-y1 // seg.mcu_h)
    idx = (np.arange(r0, r1)[:, None] * seg.per_row + np.arange(k0, k1)[None, :]).ravel()
    data, starts, ends = seg.data, seg.starts[idx].tolist(), seg.ends[idx].tolist()
    parts = [seg.head, struct.pack(">HH", y1 - y0, x1 - x0), seg.sof_tail]
    last = len(starts) - 1
    for j, (a, b) in enumerate(zip(starts, ends)):
        parts.append(data[a:b])
        if j != last:
            parts.append(RST_MARKERS[j & 7])
    parts.append(EOI)
    return b"".join(parts)


def decode_gray_regions(
    jpeg: bytes | NDArray[np.uint8], rois: list[tuple[int, int, int, int]]
) -> list[NDArray[np.uint8]] | None:
    """The grey pixels of each of ``rois`` (u0, v0, u1, v1 with u0, v0 >= 0), as
    ``whole_image[v0:v1, u0:u1]`` would give them (clipped at the image's border), decoding only
    the restart segments each covers; None if the JPEG has no usable restart markers (then
    decode it whole) or a region does not decode.

    (No full-size canvas: allocating and zeroing one per image cost more than decoding the
    regions.)"""
    raw = jpeg.tobytes() if isinstance(jpeg, np.ndarray) else jpeg
    seg = segments(raw)
    if seg is None:
        return None
    out: list[NDArray[np.uint8]] = []
    for u0, v0, u1, v1 in rois:
        if u0 < 0 or v0 < 0:
            raise ValueError(f"region {(u0, v0, u1, v1)} starts outside the image")
        x0, y0, x1, y1 = crop_bounds(seg, (u0, v0, u1, v1))
        if x1 <= x0 or y1 <= y0:
            rows, cols = max(0, min(v1, seg.height) - v0), max(0, min(u1, seg.width) - u0)
            out.append(np.zeros((rows, cols), dtype=np.uint8))
            continue
        part = cv2.imdecode(
            np.frombuffer(sub_jpeg(seg, (x0, y0, x1, y1)), dtype=np.uint8), cv2.IMREAD_GRAYSCALE
        )
        if part is None or part.shape != (y1 - y0, x1 - x0):
            return None
        out.append(np.asarray(part[v0 - y0 : v1 - y0, u0 - x0 : u1 - x0], dtype=np.uint8))
    return out
