"""Background plates: the empty warehouse as each camera sees it, and foreground against it.

Shared by the RGB person detector (``people.detector=rgb``) and usable by any algorithm that
subtracts a background from the colour images. Plates are packaged per camera set under
``assets/backgrounds/<name>/<camera_id>.jpg`` (or .png); a plate made at another resolution is
scaled to the camera's (cv2.INTER_AREA). Pure OpenCV/numpy.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.constants import ASSETS_DIR

BACKGROUNDS_DIR = ASSETS_DIR / "backgrounds"  # <name>/<camera_id>.jpg: the empty warehouse
LENS_MARGIN_LEVEL = 8  # plate pixels at most this bright in every channel: the lens's black margin


def background_dir(name: str) -> Path:
    """The plate folder ``name`` names: a path, or a packaged plate set's name."""
    path = Path(name).expanduser()
    return path if path.is_dir() else BACKGROUNDS_DIR / name


def read_plate(folder: Path, camera_id: str, width: int, height: int) -> NDArray[np.uint8] | None:
    """Camera ``camera_id``'s plate from ``folder`` (BGR) at ``width`` x ``height``, or None if
    there is none."""
    for path in (folder / f"{camera_id}.jpg", folder / f"{camera_id}.png"):
        if path.is_file():
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                return None
            if image.shape[:2] != (height, width):
                image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
            return np.asarray(image, dtype=np.uint8)
    return None


def channel_gains(
    image: NDArray[np.uint8], plate: NDArray[np.uint8], valid: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """Per colour channel, the gain that maps the plate's brightness to the image's: the median
    ratio over the ``valid`` pixels (the median ignores the few pixels people and robots cover),
    so a global change of light intensity or colour is not foreground."""
    img = image[valid].astype(np.float64)
    ref = plate[valid].astype(np.float64)
    keep = ref.min(axis=1) > 20  # dark pixels give noisy ratios
    if keep.sum() < 100:
        return np.ones(3)
    return np.asarray(np.median(img[keep] / ref[keep], axis=0), dtype=np.float64)


def normalized_plate(
    image: NDArray[np.uint8], plate: NDArray[np.uint8], *, sample: int = 12
) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """The plate scaled per channel by :func:`channel_gains` (estimated on every ``sample``-th
    pixel in both directions), and the gains."""
    valid = plate[::sample, ::sample].max(axis=-1) > LENS_MARGIN_LEVEL
    gains = channel_gains(image[::sample, ::sample], plate[::sample, ::sample], valid)
    ref = np.asarray(cv2.transform(plate, np.diag(gains).astype(np.float32)), dtype=np.uint8)  # (saturating)
    return ref, gains


def foreground_mask(
    image: NDArray[np.uint8],
    plate: NDArray[np.uint8],
    threshold: int,
    *,
    normalize: bool = True,
) -> NDArray[np.uint8]:
    """Pixels (1) where any colour channel of ``image`` differs from ``plate`` by more than
    ``threshold`` (0..255), small specks removed (3x3 opening). ``normalize``: the plate is first
    scaled per channel (:func:`normalized_plate`), so global lighting changes are not foreground;
    local ones (a sunlit patch, a recoloured shelf) still are."""
    ref = normalized_plate(image, plate)[0] if normalize else plate
    return _mask(largest_channel_difference(image, ref), threshold)


def _mask(difference: NDArray[np.uint8], threshold: int) -> NDArray[np.uint8]:
    """1 where ``difference`` exceeds ``threshold``, small specks removed (3x3 opening)."""
    mask = _above(difference, threshold)
    return np.asarray(cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)), dtype=np.uint8)


def largest_channel_difference(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Per pixel, the largest absolute difference of the colour channels of ``a`` and ``b``."""
    diff = cv2.absdiff(a, b)
    # (the channels' maximum on strided views: several times faster than cv2.split here)
    return np.asarray(np.maximum(np.maximum(diff[..., 0], diff[..., 1]), diff[..., 2]), dtype=np.uint8)


class AdaptiveBackground:
    """One camera's background: its plate, into which foreground that stays unchanged for
    ``absorb_frames`` frames is absorbed (a recoloured shelf, a sunlit patch, a moved box: what
    the plate does not show but is part of the scene); 0: the plate alone. What matches the plate
    again is background at once (an absorbed object that left, e.g. someone who stood still at
    the start, leaves no ghost). Pixels the caller marks ``protected`` (robots, people being
    tracked) are never absorbed. Deterministic: the same frames in the same order give the same
    masks (the replay's)."""

    def __init__(self, plate: NDArray[np.uint8], threshold: int, absorb_frames: int) -> None:
        self.plate, self.background = plate, plate.copy()
        self.threshold, self.absorb_frames = threshold, absorb_frames
        self.still = np.zeros(plate.shape[:2], np.uint8)  # frames each pixel stayed foreground, unchanged
        self.previous: NDArray[np.uint8] | None = None
        self._ones = np.ones(plate.shape[:2], np.uint8)

    def foreground(self, image: NDArray[np.uint8], protected: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """This frame's foreground mask (1: differs from the background), then absorb what stayed.
        (OpenCV's per-pixel operations throughout: numpy's boolean indexing of whole frames took
        most of the detector's time.)"""
        ref, gains = normalized_plate(image, self.plate)
        off_plate = _above(largest_channel_difference(image, ref), self.threshold)
        if self.absorb_frames <= 0:
            return _mask(off_plate, 0)
        # (the absorbed background is kept in the plate's light: the plate's gains scale it)
        scaled = np.asarray(cv2.transform(self.background, np.diag(gains).astype(np.float32)), dtype=np.uint8)
        differs = np.asarray(
            cv2.bitwise_and(off_plate, _above(largest_channel_difference(image, scaled), self.threshold)),
            dtype=np.uint8,
        )
        mask = _mask(differs, 0)
        cv2.copyTo(self.plate, 1 - off_plate, self.background)  # the plate again: nothing absorbed there
        if self.previous is not None:
            unchanged = 1 - _above(largest_channel_difference(image, self.previous), self.threshold)
            still = cv2.bitwise_and(cv2.bitwise_and(differs, unchanged), 1 - protected)
            grown = cv2.add(self.still, self._ones)  # (saturating at 255)
            self.still = np.asarray(cv2.multiply(grown, still), dtype=np.uint8)
            absorb = _above(self.still, self.absorb_frames - 1)
            if cv2.countNonZero(absorb):
                rows, cols = np.nonzero(absorb)
                self.background[rows, cols] = np.clip(image[rows, cols] / gains, 0, 255).astype(np.uint8)
                self.still[rows, cols] = 0
        self.previous = image
        return mask


def _above(values: NDArray[np.uint8], threshold: int) -> NDArray[np.uint8]:
    """1 where ``values`` exceed ``threshold``, else 0."""
    return np.asarray(cv2.threshold(values, threshold, 1, cv2.THRESH_BINARY)[1], dtype=np.uint8)
