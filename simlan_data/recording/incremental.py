"""Stream encoders that redo only the rows of an image that changed since their last image.

A camera's changed frame differs from its last one only where an agent moved: about a fifth of
the rows (median 0.18 of the height over the 12-camera warehouse run). The whole-image encoders
(``codecs.encode_png``) compress every row again; these keep, per stream, the compressed form of
each band of rows and compress only the bands whose rows changed.

JPEG: every restart interval of the colour images (``codecs.jpeg_restart_interval``: they never
cross an MCU row of 16 pixels) is an entropy-coded segment that depends on its own pixels only
(DC prediction restarts with it). A run of changed MCU rows is encoded as an image of its own
with the same settings, and its segments replace those rows' segments (the restart markers
renumbered; ``gpss.jpeg_regions`` finds the segments): byte for byte the JPEG that encoding the
whole image gives (checked once per process on a test image; if this OpenCV's encoder does not
split so, every frame is encoded whole).

PNG: the IDAT's deflate stream is the concatenation of one independently compressed segment per
band of ``BAND_ROWS`` filtered rows (each ended by a full flush: byte-aligned, no match reaching
back into an earlier band; the last one final), wrapped in the zlib header and the Adler-32 of
all filtered rows, as pigz builds its streams. Any PNG decoder reads it; it is as small as one segment (within
0.3 %). Semantic labels are left to ``codecs.encode_labels``: they compress in 0.2 ms
whole, no faster banded.

The output depends on the image only, never on the images encoded before it: an unchanged band
reuses the bytes that compressing the same filtered rows gives. A recording is thus the same
whatever the order or thread its frames were encoded on.
"""

from __future__ import annotations

import functools
import threading

import cv2
import numpy as np
from isal import isal_zlib
from numpy.typing import NDArray

from simlan_data.imaging.jpeg_regions import EOI, RST_MARKERS, JpegSegments, segments
from simlan_data.recording.codecs import (
    JPEG_FORMAT,
    PNG_LEVEL,
    PNG_RGB_FORMAT,
    compressed_depth,
    depth_to_mm,
    encode_rgb,
    png_file,
    png_filtered,
)

# rows per independently compressed band, measured on the changed depth frames of a 12-camera run
# (each camera's frames in order): 16 and 32 rows take 1.0 ms a frame (2.3 ms whole), 16 rows
# give 0.5 % more bytes; 64 rows 1.16 ms (a change dirties more rows)
BAND_ROWS = 32
_ZLIB_HEADER = b"\x78\x01"  # deflate, 32 KiB window, no preset dictionary (FLEVEL: fastest)


def changed_rows(new: np.ndarray, old: np.ndarray | None) -> NDArray[np.bool_]:
    """Which rows of ``new`` differ from ``old`` (all, if ``old`` is None or another shape)."""
    if old is None or old.shape != new.shape or old.dtype != new.dtype:
        return np.ones(new.shape[0], dtype=bool)
    a = np.ascontiguousarray(new).view(np.uint8).reshape(new.shape[0], -1)
    b = np.ascontiguousarray(old).view(np.uint8).reshape(old.shape[0], -1)
    if a.shape[1] % 8 == 0:  # compare 8 bytes at a time
        a, b = a.view(np.uint64), b.view(np.uint64)
    return np.asarray(np.not_equal(a, b).any(axis=1))


def _keep(image: np.ndarray, buffer: np.ndarray | None) -> np.ndarray:
    """A copy of ``image``, in ``buffer`` if it has the shape (no fresh pages to fault in)."""
    if buffer is None or buffer.shape != image.shape or buffer.dtype != image.dtype:
        return image.copy()
    np.copyto(buffer, image)
    return buffer


class BandedPng:
    """PNG encoder for one image stream: recompresses only the bands of rows that changed.

    Thread-safe: a stream's frames may be encoded on different worker threads, one at a time.
    """

    def __init__(self, *, level: int = PNG_LEVEL, band_rows: int = BAND_ROWS) -> None:
        if band_rows < 1:
            raise ValueError(f"band_rows must be at least 1, got {band_rows}")
        self.level, self.band_rows = level, band_rows
        self._lock = threading.Lock()
        self._image: np.ndarray | None = None
        self._segments: list[bytes] = []
        self.bands_compressed = 0
        self.bands_reused = 0

    def encode(self, image: NDArray[np.uint8] | NDArray[np.uint16]) -> bytes:
        """The PNG of ``image`` (grey uint8/uint16 or RGB uint8), as ``codecs.encode_png`` takes."""
        filtered = png_filtered(image)  # (validates the image)
        height, rows = image.shape[0], self.band_rows
        starts = range(0, height, rows)
        with self._lock:
            changed = changed_rows(image, self._image)
            # a filtered row is the row minus the one above it: it changes with either
            changed[1:] |= changed[:-1]
            fresh = len(self._segments) != len(starts)
            segments = []
            for i, start in enumerate(starts):
                if fresh or changed[start : start + rows].any():
                    last = start + rows >= height
                    c = isal_zlib.compressobj(self.level, isal_zlib.DEFLATED, -15)
                    flush = isal_zlib.Z_FINISH if last else isal_zlib.Z_FULL_FLUSH
                    segments.append(c.compress(filtered[start : start + rows]) + c.flush(flush))
                    self.bands_compressed += 1
                else:
                    segments.append(self._segments[i])
                    self.bands_reused += 1
            self._segments = segments
            self._image = _keep(image, self._image)
        adler = isal_zlib.adler32(filtered).to_bytes(4, "big")
        return png_file(image, b"".join((_ZLIB_HEADER, *segments, adler)))


class DepthStream:
    """``codecs.encode_depth`` for one camera's depth stream, banded (see :class:`BandedPng`)."""

    def __init__(self) -> None:
        self.png = BandedPng()

    def __call__(self, depth_m: NDArray[np.float32]) -> tuple[str, bytes]:
        return compressed_depth(self.png.encode(depth_to_mm(depth_m)))


def _split(data: bytes) -> tuple[JpegSegments, list[bytes]]:
    """A JPEG of ``encode_rgb``'s parsed at its restart markers, and its entropy-coded segments."""
    seg = segments(data)
    if seg is None:  # pragma: no cover - encode_rgb always writes an interval dividing an MCU row
        raise ValueError("a JPEG without usable restart markers")
    return seg, [data[a:b] for a, b in zip(seg.starts.tolist(), seg.ends.tolist())]


class BandedJpeg:
    """JPEG encoder for one colour stream: re-encodes only the MCU rows that changed.

    Thread-safe like :class:`BandedPng`. ``encode`` returns what ``codecs.encode_rgb`` returns
    for ``"jpeg"``, byte for byte.
    """

    def __init__(self, *, jpeg_quality: int) -> None:
        self.quality = jpeg_quality
        self._lock = threading.Lock()
        self._image: np.ndarray | None = None
        self._header = b""
        self._mcu_px = self._per_row = 0  # MCU height (pixels) and segments per MCU row
        self._rows: list[bytes] = []  # per MCU row: its segments, each with the marker after it
        self.rows_encoded = 0
        self.rows_reused = 0

    def _encode(self, rgb: NDArray[np.uint8]) -> bytes:
        return encode_rgb(rgb, "jpeg", jpeg_quality=self.quality)[1]

    @staticmethod
    def _row_bytes(segments: list[bytes], first: int, total: int) -> bytes:
        """Segments ``first``.. of the image's ``total``, each followed by its restart marker
        (numbered by its index in the image; none after the last)."""
        parts: list[bytes] = []
        for i, segment in enumerate(segments, start=first):
            parts += (segment, RST_MARKERS[i % 8] if i < total - 1 else b"")
        return b"".join(parts)

    def encode(self, rgb: NDArray[np.uint8]) -> bytes:
        height = rgb.shape[0]
        with self._lock:
            changed = changed_rows(rgb, self._image)  # all rows for a first image or a new size
            if not splices_exactly() or changed.all():
                data = self._encode(rgb)
                seg, segs = _split(data)
                self._header = data[: int(seg.starts[0])]
                self._mcu_px, self._per_row = seg.mcu_h, seg.per_row
                self._rows = [
                    self._row_bytes(segs[i : i + seg.per_row], i, len(segs))
                    for i in range(0, len(segs), seg.per_row)
                ]
                self._image = _keep(rgb, self._image)
                self.rows_encoded += len(self._rows)
                return data
            mcu_px, per_row, rows = self._mcu_px, self._per_row, len(self._rows)
            mcu = np.zeros(rows * mcu_px, dtype=bool)
            mcu[:height] = changed
            dirty = mcu.reshape(rows, mcu_px).any(axis=1)
            # runs of changed MCU rows: [start, end)
            edges = np.flatnonzero(np.diff(np.concatenate(([0], dirty.astype(np.int8), [0]))))
            for start, end in zip(edges[::2].tolist(), edges[1::2].tolist()):
                band = rgb[start * mcu_px : min(end * mcu_px, height)]
                _, new = _split(self._encode(np.ascontiguousarray(band)))
                if len(new) != (end - start) * per_row:  # pragma: no cover - guarded by splices_exactly
                    raise RuntimeError(f"JPEG band of {end - start} MCU rows gave {len(new)} segments")
                for r in range(start, end):
                    first = (r - start) * per_row
                    self._rows[r] = self._row_bytes(new[first : first + per_row], r * per_row, rows * per_row)
            self.rows_encoded += int(dirty.sum())
            self.rows_reused += rows - int(dirty.sum())
            self._image = _keep(rgb, self._image)
            return b"".join((self._header, *self._rows, EOI))


@functools.cache
def splices_exactly() -> bool:
    """Whether this OpenCV's JPEG encoder gives, for a band of MCU rows encoded alone, the same
    restart segments as for those rows in the whole image (checked on a textured test image)."""
    rng = np.random.default_rng(0)
    image = np.asarray(
        cv2.GaussianBlur(rng.integers(0, 256, (72, 200, 3), dtype=np.uint8), (5, 5), 1.5), np.uint8
    )
    seg, whole = _split(encode_rgb(image, "jpeg", jpeg_quality=85)[1])
    mcu_px, per_row = seg.mcu_h, seg.per_row
    band = np.ascontiguousarray(image[mcu_px : 3 * mcu_px])
    _, band_segments = _split(encode_rgb(band, "jpeg", jpeg_quality=85)[1])
    return band_segments == whole[per_row : 3 * per_row]


class RgbStream:
    """``codecs.encode_rgb`` for one camera's colour stream (``"jpeg"`` or ``"png"``), banded."""

    def __init__(self, encoding: str, *, jpeg_quality: int) -> None:
        if encoding not in ("jpeg", "png"):
            raise ValueError(f"not a compressed colour encoding: {encoding!r}")
        self.encoding = encoding
        self.jpeg = BandedJpeg(jpeg_quality=jpeg_quality) if encoding == "jpeg" else None
        self.png = BandedPng() if encoding == "png" else None

    def __call__(self, rgb: NDArray[np.uint8]) -> tuple[str, bytes]:
        if self.jpeg is not None:
            return JPEG_FORMAT, self.jpeg.encode(rgb)
        assert self.png is not None
        return PNG_RGB_FORMAT, self.png.encode(rgb)
