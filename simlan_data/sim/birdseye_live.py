"""Publish the live bird's-eye view: every n-th camera tick, stitch the frames, encode JPEG.

Camera tick (``Simulation``)::

    rendered frames of all cameras --stitcher (algorithms.stitcher)--> canvas --JPEG on an
        encoder thread--> /birdseye/image (sensor_msgs/CompressedImage, frame ``map``)

The stitcher is the one ``algorithms/stitcher`` selects (the built-in ``gpss`` by default), built
through the registry from its own config and a :class:`StitcherContext`: the cameras exactly as a
replay rebuilds them from the recording (camera_info + /tf_static) and the ``birdseye`` canvas. So
replaying a recording whose colour images are lossless reproduces the live canvas bit for bit.
When no camera image changed since the last canvas, its encoded message is reused with a new stamp.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from simlan_data.algorithms import registry
from simlan_data.algorithms.roles import StitcherContext
from simlan_data.config.algorithms import selected_algorithm
from simlan_data.config.schema import Config
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.cameras import camera_from_messages
from simlan_data.recording.incremental import RgbStream
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.camera_recording import _Restamped
from simlan_data.sim.rendering import CameraImages


def cameras_as_recorded(cameras: Sequence[CameraModel]) -> list[CameraModel]:
    """The camera models a replay rebuilds from this run's camera_info and /tf_static messages."""
    out = []
    for cam in cameras:
        info = M.camera_info(0, cam)
        tf = M.transform_stamped(0, schema.MAP_FRAME, cam.frame_id, cam.world_from_camera)
        out.append(camera_from_messages(info, tf.transform, cam.camera_id))
    return out


def build_stitcher(cfg: Config, cameras: Sequence[CameraModel]) -> registry.Guarded:
    """The selected stitcher (``algorithms.stitcher``) on the ``birdseye`` canvas, guarded: an
    exception inside it names it and the simulated time (exit 1)."""
    spec, config = selected_algorithm(cfg.algorithms, "stitcher")
    context = StitcherContext(cameras_as_recorded(cameras), cfg.birdseye.canvas())
    return registry.Guarded(spec.build(config, context), spec)


def birdseye_topic() -> schema.Topic:
    return next(t for t in schema.GLOBAL_TOPICS if t.name == schema.BIRDSEYE_IMAGE)


class BirdseyeRecorder:
    """Stitch and record ``/birdseye/image`` at ``birdseye.rate_hz``."""

    def __init__(self, writer: RecordingWriter, cfg: Config, cameras: Sequence[CameraModel]) -> None:
        bcfg = cfg.birdseye
        self.writer = writer
        self._encode = RgbStream("jpeg", jpeg_quality=bcfg.jpeg_quality)  # only changed rows again
        self.every = round(cfg.cameras.rate_hz / bcfg.rate_hz)
        self.stitcher = build_stitcher(cfg, cameras)
        self.topic = birdseye_topic()
        self._last: Any = None
        self.canvases = 0
        self.stitch_wall_s = 0.0

    @staticmethod
    def create(
        writer: RecordingWriter, cfg: Config, cameras: Sequence[CameraModel]
    ) -> BirdseyeRecorder | None:
        """A recorder if ``birdseye.rate_hz`` > 0, else None."""
        return BirdseyeRecorder(writer, cfg, cameras) if cfg.birdseye.rate_hz > 0 else None

    def tick(self, stamp_ns: int, frame_index: int, images: Sequence[CameraImages]) -> None:
        """Called at every camera tick with every camera's images, in the cameras' order."""
        if frame_index % self.every:
            return
        if self._last is not None and not any(im.changed for im in images):
            self.writer.write_pending(
                self.topic, stamp_ns, _Restamped(self._last, self.writer.stamp_ns(stamp_ns))
            )
            return
        t0 = time.perf_counter()
        canvas = self.stitcher.at(stamp_ns).stitch([im.rgb for im in images])  # (a failure names the time)
        self.stitch_wall_s += time.perf_counter() - t0
        self.canvases += 1
        encode, header_ns = self._encode, self.writer.stamp_ns(stamp_ns)
        self._last = self.writer.submit(
            self.topic, stamp_ns, lambda: M.compressed_image(header_ns, schema.MAP_FRAME, *encode(canvas))
        )
