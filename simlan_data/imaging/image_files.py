"""Writing image files so that a failure is an error, not a missing file.

``cv2.imwrite`` returns False (and libpng prints to stderr) when the disk is full: the caller
carries on and links a file that is not there. :func:`write_image` encodes in memory and writes
the bytes itself, so a full disk raises ``OSError`` (errno ENOSPC, the file named) and nothing
half-written is left.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

__all__ = ["write_image"]


def write_image(path: Path | str, image: np.ndarray, params: list[int] | None = None) -> Path:
    """Write ``image`` (BGR, as OpenCV's) to ``path``; the format is the suffix's.

    Raises:
        OSError: the file could not be written (``filename`` is the path; ``errno`` says why,
            e.g. ENOSPC for a full disk); a partial file is removed.
        ValueError: OpenCV cannot encode the image in that format.
    """
    path = Path(path)
    ok, data = cv2.imencode(path.suffix or ".png", image, params or [])
    if not ok:
        raise ValueError(f"could not encode a {image.shape} {image.dtype} image as {path.suffix} for {path}")
    try:
        with open(path, "wb") as f:
            f.write(data.tobytes())
    except OSError as err:
        path.unlink(missing_ok=True)
        if err.filename is None:  # a failed write or close does not name the file
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise
    return path
