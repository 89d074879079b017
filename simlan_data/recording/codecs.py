"""Image encodings of the recording, compatible with ROS 2 image_transport plugins.

- colour: ``sensor_msgs/CompressedImage`` with format ``"rgb8; jpeg compressed bgr8"`` or
  ``"rgb8; png compressed bgr8"`` (image_transport's compressed plugin), or raw ``rgb8``;
- depth (``recording.depth_encoding``): ``16UC1`` (default: a ``sensor_msgs/Image`` of uint16
  millimetres, 0 = no return, REP 118), ``png`` (``"16UC1; compressedDepth png"``:
  compressed_depth_image_transport's 12-byte config header, then a 16-bit PNG of millimetres;
  0 = no return), or ``raw`` (``32FC1`` metres, NaN = no return, REP 118);
- semantic labels: a PNG with a palette (``"rgb8; png compressed bgr8"``): its pixel values are
  the class ids, its palette the class colours of ``world/labels.py``; or raw ``mono8`` ids.

Why these (docs/recording.md, "Images"): Foxglove's Image panel and Rerun decode neither
compressedDepth (a header before the PNG) nor 16-bit PNGs as numbers (a browser decodes PNGs to
8 bits); Foxglove colour-maps ``16UC1``/``mono16`` images with a value range, and shows ``32FC1``
as grey with 1.0 as white (metres beyond 1 m saturate). A palette PNG is any PNG decoder's colour
image (a viewer shows the classes in their colours; image_transport's compressed subscriber gives
``rgb8``: hence the format) while a reader of the indices gets the ids back losslessly
(:func:`decode_compressed`; OpenCV alone would give the colours).

Decoded depth follows the in-process convention of ``CameraImages.depth_m`` whatever the
encoding: float32 metres, 0 = no return.
"""

from __future__ import annotations

import struct

import cv2
import numpy as np
from isal import isal_zlib
from numpy.typing import NDArray

from simlan_data.errors import RecordingInputError
from simlan_data.world.labels import label_palette

JPEG_FORMAT = "rgb8; jpeg compressed bgr8"
PNG_RGB_FORMAT = "rgb8; png compressed bgr8"
DEPTH_FORMAT = "16UC1; compressedDepth png"
# semantic labels: a palette PNG (indices: class ids); ROS decoders give its colours, as rgb8
LABELS_FORMAT = "rgb8; png compressed bgr8"
MONO_LABELS_FORMAT = "mono8; png compressed mono8"  # labels in recordings before the palette
DEPTH_16UC1 = "16UC1"  # sensor_msgs/Image encodings of the raw depth options
DEPTH_32FC1 = "32FC1"
DEPTH_HEADER = struct.Struct("<iff")  # compressionFormat (INV_DEPTH = 0), depthParam[2]
# PNGs are written here, not by OpenCV: libpng deflates with zlib, whose level 1 spends 8 ms on a
# 960x540 16-bit depth frame; ISA-L's level 1 (python-isal) gave the same size in 1.9 ms (the
# whole encode: depth 3.7x, labels 12x faster; BENCHMARKS.md, benchmarks/spine.py), its level 3
# (PNG_LEVEL below, for determinism) takes 3.5 ms, 3 % larger. The container is
# the PNG standard's minimum (IHDR, one IDAT, IEND), every row with the "up" filter: the fastest
# filter at no cost in size on these images (adaptive filters: 14.4 ms against 11.4 ms in libpng).
# Storing PNGs uncompressed and leaving compression to the bag's zstd chunks is smaller but makes
# every unchanged frame cost compression again: slower overall in a run.
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# ISA-L's level 3, not 1 or 2: their x86 deflate body (igzip_icf_body_h1_gr_bt.asm,
# .write_first_byte) hashes input position 2 of every new stream from a register that still holds
# the address of the compressor's state instead of the data, so the bytes (not the pixels) of about
# 1 run in 50 depended on where malloc or a thread's stack put the compressor (ASLR; issue 21,
# tests/test_determinism.py). Level 3 runs ISA-L's C body (icf_body_hash1_fillgreedy_lazy): 3.5 ms
# instead of 2.1 ms per 960x540 depth frame, 3 % larger (BENCHMARKS.md, "Determinism (issue 21)").
PNG_LEVEL = 3
PNG_FILTER_UP = 2


# Restart markers every few MCUs (16x16 pixel blocks at OpenCV's 4:2:0 chroma) let a reader
# decode only the image regions it needs (simlan_data/gpss/jpeg_regions.py: the localizer
# searches small regions around predicted markers). Same pixels; measured on rendered 960x540
# frames at quality 85: +2.5 % bytes with 4 MCUs (64 px), +5 % with 2, +10 % with 1.
JPEG_MCU_PX = 16
JPEG_RESTART_MCUS = 4


def jpeg_restart_interval(width: int) -> int:
    """Restart interval (MCUs) for an image ``width`` pixels wide: one that divides its MCU row
    (the regions a reader can cut are then rectangles), at most JPEG_RESTART_MCUS."""
    mcus = -(-width // JPEG_MCU_PX)
    return next(n for n in (JPEG_RESTART_MCUS, 2, 1) if mcus % n == 0)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    # ISA-L's CRC32 is zlib's, 6x faster (benchmarks/spine.py --only chunks)
    crc = isal_zlib.crc32(data, isal_zlib.crc32(kind))
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def png_filtered(image: NDArray[np.uint8] | NDArray[np.uint16]) -> NDArray[np.uint8]:
    """The rows a PNG compresses: each row big-endian, "up"-filtered, after its filter byte.

    Raises:
        ValueError: another shape or dtype than a PNG of :func:`encode_png` takes, or an empty image.
    """
    unsigned = image.dtype.kind == "u"  # either byte order: rows are written big-endian
    grey = image.ndim == 2 and unsigned and image.itemsize in (1, 2)
    rgb = image.ndim == 3 and image.shape[2] == 3 and unsigned and image.itemsize == 1
    if not (grey or rgb):
        raise ValueError(
            f"no PNG for a {image.dtype} image of shape {image.shape}: HxW grey or HxWx3 uint8 RGB"
        )
    height, width = image.shape[:2]
    if height == 0 or width == 0:
        raise ValueError(f"no PNG for an empty image ({width}x{height})")
    big_endian = image.astype(">u2", copy=False) if image.itemsize == 2 else image
    rows = np.ascontiguousarray(big_endian).view(np.uint8).reshape(height, -1)
    filtered = np.empty((height, rows.shape[1] + 1), np.uint8)
    filtered[:, 0] = PNG_FILTER_UP  # each byte minus the one above it (the first row: minus 0)
    filtered[0, 1:] = rows[0]
    np.subtract(rows[1:], rows[:-1], out=filtered[1:, 1:])
    return filtered


PNG_GREY, PNG_RGB, PNG_PALETTE = 0, 2, 3  # IHDR colour types


def png_file(image: np.ndarray, idat: bytes, *, palette: NDArray[np.uint8] | None = None) -> bytes:
    """The PNG file of ``image`` (checked by :func:`png_filtered`) around its zlib stream ``idat``;
    with ``palette`` (N x 3 uint8 RGB, N <= 256) an indexed-colour PNG whose indices are the
    pixels of ``image`` (HxW uint8)."""
    height, width = image.shape[:2]
    chunks = []
    if palette is not None:
        if (
            image.ndim != 2
            or image.dtype != np.uint8
            or palette.shape[1:] != (3,)
            or not 0 < len(palette) <= 256
        ):
            raise ValueError(
                f"no palette PNG of a {image.dtype} {image.shape} image with a {palette.shape} palette"
            )
        if image.size and int(image.max()) >= len(palette):
            raise ValueError(f"index {int(image.max())} beyond a palette of {len(palette)} colours")
        colour_type = PNG_PALETTE
        chunks.append(_png_chunk(b"PLTE", np.ascontiguousarray(palette, dtype=np.uint8).tobytes()))
    else:
        colour_type = PNG_RGB if image.ndim == 3 else PNG_GREY
    header = struct.pack(">IIBBBBB", width, height, 8 * image.itemsize, colour_type, 0, 0, 0)
    return b"".join(
        (
            PNG_SIGNATURE,
            _png_chunk(b"IHDR", header),
            *chunks,
            _png_chunk(b"IDAT", idat),
            _png_chunk(b"IEND", b""),
        )
    )


def encode_png(
    image: NDArray[np.uint8] | NDArray[np.uint16],
    *,
    level: int = PNG_LEVEL,
    palette: NDArray[np.uint8] | None = None,
) -> bytes:
    """A PNG of a grey (HxW, uint8 or uint16) or RGB (HxWx3, uint8) image; decodes to ``image``.
    With ``palette``, the indexed-colour PNG of a HxW uint8 image of indices (see :func:`png_file`).

    Raises:
        ValueError: another shape or dtype, or an empty image (PNG has no 0-pixel images), or
            an index beyond the palette.
    """
    return png_file(image, isal_zlib.compress(png_filtered(image), level), palette=palette)


MAX_DECODED_PIXELS = 8192 * 8192  # refuse decoding absurd images from untrusted recordings


def encode_rgb(rgb: NDArray[np.uint8], encoding: str, *, jpeg_quality: int = 90) -> tuple[str, bytes]:
    """Encode an RGB image: returns (CompressedImage.format, data)."""
    if encoding == "png":
        return PNG_RGB_FORMAT, encode_png(rgb)
    if encoding == "jpeg":
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
        params += [cv2.IMWRITE_JPEG_RST_INTERVAL, jpeg_restart_interval(bgr.shape[1])]
        ok, buf = cv2.imencode(".jpg", bgr, params)
        fmt = JPEG_FORMAT
    else:
        raise ValueError(f"not a compressed colour encoding: {encoding!r}")
    if not ok:  # pragma: no cover - OpenCV fails only on invalid input
        raise ValueError("OpenCV could not encode the image")
    return fmt, buf.tobytes()


def depth_to_mm(depth_m: NDArray[np.float32]) -> NDArray[np.uint16]:
    """Metres -> uint16 millimetres, rounded to nearest; beyond 65.535 m saturates; 0, negative,
    NaN and infinite depths give 0 (no return). One OpenCV pass (0.3 ms at 960x540, against 2 ms
    for numpy's clip, scale, round and cast)."""
    scaled = cv2.multiply(depth_m, 1000.0, dtype=cv2.CV_16U)  # type: ignore[call-overload]
    return np.asarray(scaled, dtype=np.uint16)


def compressed_depth(png: bytes) -> tuple[str, bytes]:
    """The (format, data) of compressed_depth_image_transport's 16UC1 PNG: its config header
    (no inverse-depth parameters: the PNG holds millimetres), then the PNG of ``depth_to_mm``."""
    return DEPTH_FORMAT, DEPTH_HEADER.pack(0, 0.0, 0.0) + png


def encode_depth(depth_m: NDArray[np.float32], *, level: int = PNG_LEVEL) -> tuple[str, bytes]:
    """Encode metric depth as compressed_depth_image_transport's 16UC1 PNG."""
    return compressed_depth(encode_png(depth_to_mm(depth_m), level=level))


def depth_to_32fc1(depth_m: NDArray[np.float32]) -> NDArray[np.float32]:
    """Metres as a 32FC1 depth image holds them (REP 118): no return (0, negative, NaN,
    infinite) is NaN. A new array; the in-process image (0 = no return) is left as it is."""
    depth = np.asarray(depth_m, dtype=np.float32)
    return np.where(np.isfinite(depth) & (depth > 0), depth, np.float32(np.nan)).astype(
        np.float32, copy=False
    )


def raw_depth(depth_m: NDArray[np.float32], encoding: str) -> NDArray[np.float32] | NDArray[np.uint16]:
    """The pixels of a raw depth image (``sensor_msgs/Image``) in ``encoding``: ``"16UC1"``
    millimetres (0 = no return) or ``"32FC1"`` metres (NaN = no return)."""
    if encoding == DEPTH_16UC1:
        return depth_to_mm(depth_m)
    if encoding == DEPTH_32FC1:
        return depth_to_32fc1(depth_m)
    raise ValueError(f"not a raw depth encoding: {encoding!r}")


def encode_labels(
    labels: NDArray[np.uint8], *, level: int = PNG_LEVEL, palette: NDArray[np.uint8] | None = None
) -> tuple[str, bytes]:
    """Encode class ids as a palette PNG: the indices are the ids, the palette the class colours
    (``palette``, default :func:`~simlan_data.world.labels.label_palette`, extended with its
    unknown-class colour when an id lies beyond it)."""
    table = label_palette() if palette is None else palette
    if labels.size and int(labels.max()) >= len(table):
        table = np.concatenate([table, label_palette(int(labels.max()) + 1)[len(table) :]])
    return LABELS_FORMAT, encode_png(labels, level=level, palette=table)


def png_chunks(data: bytes) -> list[tuple[bytes, bytes]] | None:
    """The (type, data) of every chunk of a PNG file; None if ``data`` is no well-formed PNG
    (CRCs are left to the decoder)."""
    if data[: len(PNG_SIGNATURE)] != PNG_SIGNATURE:
        return None
    out, pos = [], len(PNG_SIGNATURE)
    while pos + 12 <= len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        if pos + 12 + n > len(data):
            return None
        out.append((kind, data[pos + 8 : pos + 8 + n]))
        pos += 12 + n
        if kind == b"IEND":
            return out
    return None


def png_palette(data: bytes) -> NDArray[np.uint8] | None:
    """The palette (N x 3 uint8 RGB) of an indexed-colour PNG, None for any other image."""
    chunks = png_chunks(data)
    if not chunks or chunks[0][0] != b"IHDR" or len(chunks[0][1]) != 13 or chunks[0][1][9] != PNG_PALETTE:
        return None
    plte = next((d for k, d in chunks if k == b"PLTE"), b"")
    return np.frombuffer(plte[: len(plte) // 3 * 3], dtype=np.uint8).reshape(-1, 3).copy()


def palette_indices_png(data: bytes) -> bytes | None:
    """An indexed-colour PNG as a grey PNG of its indices (the same IDAT: a palette image's
    samples are its indices), so that OpenCV decodes the indices instead of the colours; None
    if ``data`` is no indexed-colour PNG."""
    if data[25:26] != bytes([PNG_PALETTE]):  # IHDR's colour type (checked again below)
        return None
    chunks = png_chunks(data)
    if not chunks or chunks[0][0] != b"IHDR" or len(chunks[0][1]) != 13 or chunks[0][1][9] != PNG_PALETTE:
        return None
    header = chunks[0][1]
    parts = [PNG_SIGNATURE, _png_chunk(b"IHDR", header[:9] + bytes([PNG_GREY]) + header[10:])]
    parts += [_png_chunk(k, d) for k, d in chunks[1:] if k not in (b"PLTE", b"tRNS")]
    return b"".join(parts)


def _imdecode(data: bytes | NDArray[np.uint8], flags: int, what: str) -> np.ndarray:
    buf = np.frombuffer(bytes(data) if not isinstance(data, np.ndarray) else data.tobytes(), dtype=np.uint8)
    # check the declared size before OpenCV allocates it (untrusted input)
    if buf[: len(PNG_SIGNATURE)].tobytes() == PNG_SIGNATURE and len(buf) >= 24:
        width, height = struct.unpack(">II", buf[16:24].tobytes())
        if width * height > MAX_DECODED_PIXELS:
            raise RecordingInputError(
                f"{what} too large", "recording", f"{width}x{height} pixels", "the recording is corrupt"
            )
    image = cv2.imdecode(buf, flags)
    if image is None:
        raise RecordingInputError(
            f"{what} undecodable", "recording", "not a valid image", "the recording is corrupt"
        )
    return image


def decode_compressed(fmt: str, data: bytes | NDArray[np.uint8]) -> np.ndarray:
    """Decode a CompressedImage by its format string: RGB uint8, depth float32 metres (0 = no
    return), or labels (HxW uint8 class ids: the indices of a palette PNG, whatever its format
    string says, or a mono8 PNG's values)."""
    if "png" in fmt and not fmt.startswith(("16UC1", "32FC1")):
        indices = palette_indices_png(bytes(data) if not isinstance(data, np.ndarray) else data.tobytes())
        if indices is not None:
            return _imdecode(indices, cv2.IMREAD_UNCHANGED, "label image")
    if fmt.startswith(("16UC1; compressedDepth", "32FC1; compressedDepth")):
        raw = bytes(data) if not isinstance(data, np.ndarray) else data.tobytes()
        if len(raw) < DEPTH_HEADER.size:
            raise RecordingInputError(
                "depth image truncated",
                "recording",
                "shorter than its 12-byte header",
                "the recording is corrupt",
            )
        image = _imdecode(raw[DEPTH_HEADER.size :], cv2.IMREAD_UNCHANGED, "depth image")
        if fmt.startswith("32FC1"):
            _, a, b = DEPTH_HEADER.unpack(raw[: DEPTH_HEADER.size])
            q = image.astype(np.float32)
            with np.errstate(divide="ignore"):
                return np.where(q > 0, a / (q - b), 0.0).astype(np.float32)
        return image.astype(np.float32) / 1000.0
    if fmt.startswith("mono8"):
        return _imdecode(data, cv2.IMREAD_UNCHANGED, "label image")
    if fmt.startswith(("rgb8", "bgr8")) or fmt in ("jpeg", "png"):
        bgr = _imdecode(data, cv2.IMREAD_COLOR, "colour image")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    raise RecordingInputError(
        f"unknown image format {fmt!r}",
        "recording",
        "not one of simlan_data's encodings",
        "re-record with a supported recording.*_encoding",
    )


def decode_raw(encoding: str, height: int, width: int, step: int, data: NDArray[np.uint8]) -> np.ndarray:
    """Decode a sensor_msgs/Image (rgb8, mono8, 32FC1, 16UC1). Depth (32FC1 metres, 16UC1
    millimetres) comes back as float32 metres with 0 = no return: a 32FC1 image's NaN, infinite
    or non-positive pixels (REP 118's "no return") are 0."""
    channels, dtype = {
        "rgb8": (3, np.uint8),
        "bgr8": (3, np.uint8),
        "mono8": (1, np.uint8),
        "32FC1": (1, np.float32),
        "16UC1": (1, np.uint16),
    }.get(encoding, (0, None))
    if dtype is None:
        raise RecordingInputError(
            f"unknown raw image encoding {encoding!r}",
            "recording",
            "expected rgb8, mono8, 32FC1 or 16UC1",
            "re-record it",
        )
    itemsize = np.dtype(dtype).itemsize
    if height * width > MAX_DECODED_PIXELS or step < width * channels * itemsize or len(data) < step * height:
        raise RecordingInputError(
            "raw image inconsistent",
            "recording",
            f"{width}x{height} step {step} with {len(data)} bytes",
            "the recording is corrupt",
        )
    rows = np.frombuffer(np.asarray(data, dtype=np.uint8).tobytes()[: step * height], dtype=np.uint8).reshape(
        height, step
    )
    pixels = rows[:, : width * channels * itemsize].copy().view(dtype)
    image = pixels.reshape(height, width, channels) if channels > 1 else pixels.reshape(height, width)
    if encoding == "bgr8":
        image = image[..., ::-1].copy()
    if encoding == "16UC1":
        return image.astype(np.float32) / 1000.0
    if encoding == "32FC1":
        return np.where(np.isfinite(image) & (image > 0), image, np.float32(0.0)).astype(np.float32)
    return image
