"""Queue camera frames into the recording, reusing work for frames that did not change.

Most cameras see no motion most of the time: their images are identical frame after frame. The
first time an image version is recorded it is encoded and serialized on a worker thread; while it
stays unchanged, later frames reuse those CDR bytes with a new header stamp (as do camera infos).
A changed image differs from the last one mostly in a few rows: each camera's colour and depth
streams have their own encoder (``recording/incremental.py``) that encodes only those again.

Depth is recorded as ``recording.depth_encoding`` says (``codecs``): a raw ``16UC1`` image of
millimetres (the default), compressedDepth PNG (``png``) or raw ``32FC1`` metres (``raw``); the
in-process ``depth_m`` (0 = no return) is converted here, at the recording's boundary (32FC1
marks no return with NaN, REP 118). Semantic labels are a palette PNG (``png``) or raw mono8.

With ``decode_gray`` the worker that JPEG-encodes a colour image also decodes it to grey, which
is what the localizer searches (it sees what the bag holds): the simulation thread only waits
for the result instead of decoding every searched image itself (about 1.5 ms each).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.config.schema import RecordingConfig
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.codecs import DEPTH_16UC1, DEPTH_32FC1, encode_labels, raw_depth
from simlan_data.recording.incremental import DepthStream, RgbStream
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.rendering import CameraImages


class EncodedRgb(NamedTuple):
    """A compressed colour image, and its grey decoding if it was asked for."""

    format: str
    data: bytes
    gray: NDArray[np.uint8] | None = None


# recording.depth_encoding -> the sensor_msgs/Image encoding of a raw depth option
RAW_DEPTH = {"16UC1": DEPTH_16UC1, "raw": DEPTH_32FC1}


def depth_topic(camera_id: str, encoding: str) -> schema.Topic:
    """The depth topic of a camera for ``recording.depth_encoding``: ``16UC1`` and ``raw``
    (32FC1) are sensor_msgs/Image on ``depth/image_raw``, ``png`` compressedDepth."""
    return schema.camera_topics(camera_id, rgb="jpeg", depth=encoding, semantic=None)["depth"]


def _raw_depth(stamp_ns: int, frame_id: str, encoding: str, depth_m: np.ndarray) -> Any:
    """The sensor_msgs/Image of in-process depth (metres, 0 = no return) in ``encoding``."""
    return M.raw_image(stamp_ns, frame_id, raw_depth(depth_m, encoding))


def _compressed(stamp_ns: int, frame_id: str, encoded: Future[Any] | Any) -> Any:
    """The CompressedImage message of an encoding job's (format, data)."""
    return M.compressed_image(stamp_ns, frame_id, *encoded.result()[:2])


class _Restamped:
    """Pending CDR bytes of an earlier message, stamped anew when they are written."""

    __slots__ = ("_pending", "_stamp_ns")

    def __init__(self, pending: Any, stamp_ns: int) -> None:
        self._pending, self._stamp_ns = pending, stamp_ns

    def done(self) -> bool:
        return bool(self._pending.done())

    def result(self) -> bytes:
        return M.restamp(self._pending.result(), self._stamp_ns)


class CameraRecorder:
    """Turn rendered camera frames into image, depth, semantic and camera-info messages."""

    def __init__(
        self,
        writer: RecordingWriter,
        rec: RecordingConfig,
        streams: list[str],
        *,
        depth_every: int,
        semantic_every: int,
        decode_gray: bool = False,
    ) -> None:
        self.writer, self.rec = writer, rec
        self.decode_gray = decode_gray
        self.depth_every, self.semantic_every = depth_every, semantic_every
        self._streams = streams
        self._topics: dict[str, dict[str, schema.Topic]] = {}
        self._info: dict[str, bytes] = {}
        self._version: dict[str, int] = {}
        self._last_index: dict[str, int] = {}  # the frame index each camera recorded last
        self._cache: dict[tuple[str, str, int], tuple[int, Any, Any]] = {}
        self._encoders: dict[tuple[str, str, int], Callable[[Any], tuple[Any, ...]] | None] = {}
        self.encoded = 0

    def topics(self, camera_id: str) -> dict[str, schema.Topic]:
        if camera_id not in self._topics:
            rec = self.rec
            topics = schema.camera_topics(
                camera_id,
                rgb=rec.rgb_encoding,
                depth=rec.depth_encoding if "depth" in self._streams else None,
                semantic=rec.semantic_encoding if "semantic" in self._streams else None,
            )
            if "depth" in topics:
                topics["depth"] = depth_topic(camera_id, rec.depth_encoding)
            self._topics[camera_id] = topics
        return self._topics[camera_id]

    def _encoder(self, stream: str, phase: int = -1) -> Callable[[Any], tuple[Any, ...]] | None:
        """A new encoder for one camera's ``stream`` (None: recorded raw); ``phase`` >= 0: colour
        images with sensor noise, which are not decoded to grey at once (most of them are never
        searched whole; a region search decodes only its regions from the JPEG)."""
        rec = self.rec
        if stream == "rgb":
            if rec.rgb_encoding == "raw":
                return None
            decode = self.decode_gray and phase < 0
            encode = RgbStream(rec.rgb_encoding, jpeg_quality=rec.jpeg_quality)

            def rgb(a: Any) -> EncodedRgb:
                fmt, data = encode(a)
                gray = None
                if decode:
                    gray = np.asarray(
                        cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE),
                        dtype=np.uint8,
                    )
                return EncodedRgb(fmt, data, gray)

            return rgb
        if stream == "depth":
            return None if rec.depth_encoding in RAW_DEPTH else DepthStream()
        return None if rec.semantic_encoding == "raw" else encode_labels

    def record(
        self,
        t: int,
        frame_index: int,
        camera: CameraModel,
        images: CameraImages,
        *,
        stamp_ns: int | None = None,
        phase: int = -1,
    ) -> Any:
        """Queue one camera frame; returns the future of the colour image's EncodedRgb, or None.

        ``stamp_ns``: the simulated time the camera writes in the headers (its own clock, default
        ``t``); ``phase``: the sensor noise field the colour image carries (``sim/sensors.py``):
        each phase has its own colour encoder, so an unchanged scene re-encodes only the rows that
        changed since that phase's last frame. ``images.changed`` is against the camera's previous
        frame: after a skipped ``frame_index`` (a lost frame) the images count as changed."""
        cid, frame = camera.camera_id, camera.frame_id
        topics = self.topics(cid)
        stamp = self.writer.stamp_ns(t if stamp_ns is None else stamp_ns)  # header: bag time (timebase.py)
        if cid not in self._info:
            self._info[cid] = self.writer.serialize(topics["camera_info"], M.camera_info(0, camera))
        self.writer.write_serialized(topics["camera_info"], t, M.restamp(self._info[cid], stamp))
        # a new image version when the render changed, or may have: a frame index skipped (a lost
        # frame, sensors.timing) hides a change the render reported only for the lost frame
        fresh = images.changed or cid not in self._version or self._last_index.get(cid) != frame_index - 1
        version = self._version.get(cid, -1) + int(fresh)
        self._version[cid] = version
        self._last_index[cid] = frame_index
        arrays: dict[str, np.ndarray | None] = {"rgb": images.rgb}
        if "depth" in topics and frame_index % self.depth_every == 0:
            arrays["depth"] = images.depth_m
        if "semantic" in topics and frame_index % self.semantic_every == 0:
            arrays["semantic"] = images.labels
        rgb_encoded = None
        for stream, array in arrays.items():
            topic, key = topics[stream], (cid, stream, phase if stream == "rgb" else -1)
            cached = self._cache.get(key)
            if cached is not None and cached[0] == version:
                _, encoded, pending = cached
                self.writer.write_pending(topic, t, _Restamped(pending, stamp))
            else:
                assert array is not None  # (the streams recorded are the streams rendered)
                if key not in self._encoders:
                    self._encoders[key] = self._encoder(stream, key[2])
                encode = self._encoders[key]
                if encode is None:
                    encoded = None
                    build = (
                        functools.partial(_raw_depth, stamp, frame, RAW_DEPTH[self.rec.depth_encoding], array)
                        if stream == "depth"
                        else functools.partial(M.raw_image, stamp, frame, array)
                    )
                    pending = self.writer.submit(topic, t, build)
                else:
                    encoded = self.writer.run_async(encode, array)
                    pending = self.writer.submit(
                        topic, t, functools.partial(_compressed, stamp, frame, encoded)
                    )
                self.encoded += 1
                self._cache[key] = (version, encoded, pending)
            if stream == "rgb":
                rgb_encoded = encoded
        return rgb_encoded
