"""Images and video files as a landmark source: OpenCV decodes the frames, MediaPipe Pose finds the person.

    posemap.source=FILE.mp4            video: frame k at its own rate (or posemap.source_fps)
    posemap.source=FOLDER              images in name order, frame k at k / posemap.source_fps
    posemap.source=FILE.png            one image, held
        |  (frames up to the run's duration; RGB)
        v
    MediaPipe Pose (its own environment) --> landmarks (F, 33, 4), MediaPipe's layout
        +  every frame as JPEG (recorded beside the landmarks on /posemap/source/...)

The drive (:mod:`simlan_data.sim.posemap_drive`) maps these landmarks like any other landmark
stream. Everything about the file is checked by :func:`open_frames` before MediaPipe starts, and a
source where MediaPipe finds nobody is refused by :func:`estimate_source`: each a one-line
ConfigError naming ``posemap.source`` (or ``posemap.source_fps``), the value and the fix.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.posemap.estimators import MediaPipeEstimator
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
MAX_FPS = 240.0  # above this a container's rate is a broken header, not a camera
BATCH = 8  # frames per request to the MediaPipe worker (its answers wait in a pipe meanwhile)
# FFmpeg's own log lines ("moov atom not found") would go to stderr beside the one-line error:
# quiet (AV_LOG_QUIET), unless set; OpenCV reads it once, when it first opens a video in the process
FFMPEG_LOG_ENV = ("OPENCV_FFMPEG_LOGLEVEL", "-8")
FIX = "give an mp4 (or another video OpenCV reads), an image, or a folder of PNG/JPEG images"


def _source_error(path: str, what: str, why: str, fix: str = FIX) -> ConfigError:
    return ConfigError(what, f"posemap.source={path}", why, fix)


@dataclass(frozen=True)
class FrameReader:
    """A checked source: what it is, its frame rate and size, and how to read its frames."""

    path: str
    kind: str  # video | images
    fps: float
    width: int
    height: int
    files: tuple[Path, ...] = ()  # images, in order
    max_frames: int = 1

    def frames(self) -> Iterator[NDArray[np.uint8]]:
        """RGB frames (H, W, 3), at most ``max_frames``."""
        if self.kind == "images":
            for f in self.files[: self.max_frames]:
                yield _read_image(self.path, f)
            return
        cap = cv2.VideoCapture(self.path)
        try:
            for _ in range(self.max_frames):
                ok, bgr = cap.read()
                if not ok:
                    return
                yield np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
        finally:
            cap.release()


def _read_image(source: str, path: Path) -> NDArray[np.uint8]:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise _source_error(source, "source image unreadable", f"OpenCV cannot decode {path}")
    return np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))


def _check_fps(path: str, fps: float, how: str) -> float:
    if not (math.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise ConfigError.invalid(
            "posemap.source_fps",
            fps,
            f"{how}: a frame rate must be within (0, {MAX_FPS:g}] frames per second",
            f"set the source's rate, e.g. posemap.source_fps=30 (source {path})",
        )
    return fps


def open_frames(path: str, *, fps: float, image_fps: float, duration_s: float) -> FrameReader:
    """Check a source and say how to read it: a video, an image, or a folder of images.

    Args:
        fps: ``posemap.source_fps``: frames per second; 0: a video's own rate, ``image_fps`` for images.
        duration_s: frames beyond the run's duration are not read.
    Raises:
        ConfigError: no such path, nothing OpenCV can decode, a folder without images, or no
            usable frame rate (a video whose header gives none, a rate out of range).
    """
    p = Path(path)
    if not p.exists():
        raise _source_error(path, "source not found", "no such file or folder")
    if p.is_dir():
        files = tuple(sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES and f.is_file()))
        if not files:
            raise _source_error(
                path, "no images in the source folder", f"no {'/'.join(IMAGE_SUFFIXES)} files"
            )
        return _images(path, files, fps or image_fps, duration_s)
    if p.suffix.lower() in IMAGE_SUFFIXES:
        return _images(path, (p,), fps or image_fps, duration_s)
    os.environ.setdefault(*FFMPEG_LOG_ENV)
    cap = cv2.VideoCapture(path)
    try:
        ok, bgr = cap.read() if cap.isOpened() else (False, None)
        if not ok or bgr is None:
            raise _source_error(path, "source unreadable", "OpenCV decodes no video frame from this file")
        own = float(cap.get(cv2.CAP_PROP_FPS))
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        cap.release()
    rate = _check_fps(path, fps, "as given") if fps else _check_fps(path, own, "the video's header says so")
    frames = max(1, math.ceil(duration_s * rate))
    if count > 0:
        frames = min(frames, count)
    return FrameReader(path, "video", rate, int(bgr.shape[1]), int(bgr.shape[0]), max_frames=frames)


def _images(path: str, files: tuple[Path, ...], fps: float, duration_s: float) -> FrameReader:
    rate = _check_fps(path, fps, "the rate images are shown at")
    first = _read_image(path, files[0])
    frames = min(len(files), max(1, math.ceil(duration_s * rate)))
    return FrameReader(path, "images", rate, first.shape[1], first.shape[0], files, frames)


@dataclass(frozen=True)
class SourceLandmarks:
    """MediaPipe's landmarks of every frame of a source, the frames as JPEG, and when each is shown."""

    reader: FrameReader
    stamps_ns: NDArray[np.int64]  # frame k at k / fps
    landmarks: NDArray[np.float32]  # (F, 33, 4); all zeros where no person was found
    jpeg: tuple[bytes, ...]
    estimate_s: float

    @property
    def detected(self) -> NDArray[np.bool_]:
        return np.asarray((self.landmarks[..., 3] > 0).any(axis=1))

    def metrics(self) -> dict[str, float]:
        """``posemap.source.*``: frames, fps, detected_fraction, estimate_ms_per_frame."""
        n = max(1, len(self.stamps_ns))
        return {
            "posemap.source.frames": float(len(self.stamps_ns)),
            "posemap.source.fps": self.reader.fps,
            "posemap.source.detected_fraction": float(self.detected.mean()),
            "posemap.source.estimate_ms_per_frame": 1e3 * self.estimate_s / n,
        }


def estimate_source(
    reader: FrameReader, estimator: MediaPipeEstimator, encode: Callable[[NDArray[np.uint8]], bytes]
) -> SourceLandmarks:
    """Run MediaPipe Pose on every frame; keep each frame as ``encode`` gives it (the recorder's JPEG).

    Raises:
        ConfigError: MediaPipe found a person in none of the frames.
    """
    landmarks: list[NDArray[np.float32]] = []
    jpeg: list[bytes] = []
    batch: list[NDArray[np.uint8]] = []
    estimate_s = 0.0

    def flush() -> float:
        t0 = time.perf_counter()
        landmarks.extend(estimator.estimate_images(batch))
        batch.clear()
        return time.perf_counter() - t0

    for rgb in reader.frames():
        jpeg.append(encode(rgb))
        batch.append(rgb)
        if len(batch) == BATCH:
            estimate_s += flush()
    if batch:
        estimate_s += flush()
    stamps = np.round(np.arange(len(jpeg)) * (NS_PER_S / reader.fps)).astype(np.int64)
    out = SourceLandmarks(reader, stamps, np.stack(landmarks), tuple(jpeg), estimate_s)
    if not out.detected.any():
        raise _source_error(
            reader.path,
            "no person in the source",
            f"MediaPipe Pose found no person in any of its {len(jpeg)} frames",
            "give images or a video that show a person, whole body in view",
        )
    return out


def hold_undetected(predicted: NDArray[np.float64], detected: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Joint targets of every frame from those of the frames with a person (``predicted``, one row
    per True in ``detected``): a frame without one takes the last such frame's (before the first:
    the first one's), so the humanoid holds its pose through missed detections."""
    index = np.cumsum(detected) - 1
    return predicted[np.maximum(index, 0)]
