"""Replay a recording through algorithms without the simulator.

A replay algorithm is a function ``(ReplayContext) -> dict[str, float]`` registered under a name
in :data:`REPLAY_ALGORITHMS`; it reads what it needs from the recording, writes its artifacts into
``context.out_dir`` and returns dotted metrics, which the CLI merges into ``<out>/metrics.json``.

Cameras are rebuilt from the recording's own messages (``camera_info`` + ``/tf_static``), the same
way the live run builds the models its algorithms use, so that a replay reproduces live outputs
bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import ConfigError, RecordingInputError
from ..geometry.camera import CameraModel
from ..geometry.transforms import Transform
from ..recording import schema
from ..recording.reader import RecordingReader
from .faults import CameraFaults


def camera_from_messages(info: Any, map_from_camera: Any, camera_id: str) -> CameraModel:
    """A camera model from a sensor_msgs/CameraInfo and its geometry_msgs/Transform in ``map``."""
    t, q = map_from_camera.translation, map_from_camera.rotation
    world_from_camera = Transform.from_quat([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
    K = np.asarray(info.k, dtype=np.float64).reshape(3, 3)
    D = np.asarray(info.d, dtype=np.float64).reshape(-1)[:5]
    return CameraModel(camera_id, int(info.width), int(info.height), K, D, world_from_camera.inverse())


def cameras_in_recording(reader: RecordingReader) -> dict[str, CameraModel]:
    """Every camera of a recording, from its first camera_info and the static transforms."""
    infos = [t for t in sorted(reader.topics) if t.startswith("/camera_") and t.endswith("/camera_info")]
    first = reader.firsts([schema.TF_STATIC, *infos])  # (one pass)
    tf_static = first.get(schema.TF_STATIC)
    if tf_static is None:
        raise RecordingInputError(
            "recording lacks /tf_static",
            str(reader.path),
            "camera poses are unknown",
            "record with simlan_data >= 0.1",
        )
    frames = {t.child_frame_id: t.transform for t in tf_static.msg.transforms}
    out: dict[str, CameraModel] = {}
    for topic in infos:
        cid = topic.split("/")[1].removeprefix("camera_")
        info = first.get(topic)
        frame = schema.camera_frame(cid)
        if info is None or frame not in frames:
            continue
        out[cid] = camera_from_messages(info.msg, frames[frame], cid)
    return out


@dataclass
class ReplayContext:
    """What a replay algorithm gets: the open recording, where to write, options."""

    reader: RecordingReader
    out_dir: Path
    options: dict[str, Any] = field(default_factory=dict)

    @cached_property
    def config(self) -> dict[str, Any]:
        """The run's resolved config as a plain dict (from /simlan/config)."""
        msg = self.reader.first(schema.CONFIG)
        if msg is None:
            raise RecordingInputError(
                "recording lacks /simlan/config",
                str(self.reader.path),
                "the run's config is unknown",
                "record with simlan_data",
            )
        return yaml.safe_load(msg.msg.data)

    @cached_property
    def cameras(self) -> dict[str, CameraModel]:
        """The cameras as recorded (the truth: what rendered the images)."""
        return cameras_in_recording(self.reader)

    @cached_property
    def camera_faults(self) -> CameraFaults:
        """Faults of the recorded run's ``faults`` section, overridden by the replay's options."""
        return CameraFaults.from_settings(self.config, self.options)

    @cached_property
    def believed_cameras(self) -> dict[str, CameraModel]:
        """The cameras as the algorithms are given them: without dropped ones, with injected
        calibration errors (see :mod:`~simlan_data.evaluation.faults`). Metrics that ask what
        the cameras could see use :attr:`cameras`."""
        return self.camera_faults.apply(self.cameras, where=f"replay of {self.reader.path}")


ReplayAlgorithm = Callable[[ReplayContext], dict[str, float]]
REPLAY_ALGORITHMS: dict[str, ReplayAlgorithm] = {}
# options of an algorithm that name files: a suite file resolves them relative to itself
PATH_OPTIONS: dict[str, tuple[str, ...]] = {}


def check_options(
    options: dict[str, Any], known: tuple[str, ...] | list[str], what: str, where: str, fix: str
) -> None:
    """Refuse an unknown ``--set`` option of a replay algorithm with one line naming the known ones."""
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ConfigError(f"unknown {what} option {unknown[0]!r}", where, f"known: {', '.join(known)}", fix)


def register(
    name: str, *, path_options: tuple[str, ...] = ()
) -> Callable[[ReplayAlgorithm], ReplayAlgorithm]:
    """Decorator: make ``fn`` available as ``--algorithms name``.

    ``path_options``: its options that are paths (in a suite file, relative to the file, as the
    cases' recordings; on the command line, relative to the working directory).
    """

    def deco(fn: ReplayAlgorithm) -> ReplayAlgorithm:
        REPLAY_ALGORITHMS[name] = fn
        PATH_OPTIONS[name] = tuple(path_options)
        return fn

    return deco
