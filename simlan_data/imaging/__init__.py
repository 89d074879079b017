"""Image-level helpers shared by the algorithms and the recorder (JPEG restart-segment regions)."""

from __future__ import annotations

from simlan_data.imaging.jpeg_regions import (
    JpegSegments,
    crop_bounds,
    decode_gray_regions,
    segments,
    sub_jpeg,
)

__all__ = [
    "JpegSegments",
    "crop_bounds",
    "decode_gray_regions",
    "segments",
    "sub_jpeg",
]
