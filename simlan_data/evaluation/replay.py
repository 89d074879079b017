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

import yaml

from simlan_data.config.faults import CameraFaults
from simlan_data.errors import ConfigError, RecordingInputError
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording import schema
from simlan_data.recording.bounded import load_yaml_without_aliases
from simlan_data.recording.cameras import cameras_in_recording
from simlan_data.recording.reader import RecordingReader

MAX_CONFIG_CHARS = 1 << 20  # a recorded config is a few KiB


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
        text = str(msg.msg.data)
        where = f"{self.reader.path} /simlan/config"
        if len(text) > MAX_CONFIG_CHARS:
            raise RecordingInputError(
                "recorded config too large", where, f"{len(text)} characters", "record with simlan_data"
            )
        try:
            return load_yaml_without_aliases(text)  # (an alias bomb must not hang a replay)
        except yaml.YAMLError as err:
            raise RecordingInputError(
                "recorded config unreadable", where, str(err).splitlines()[0], "record with simlan_data"
            ) from None

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
        calibration errors (see :mod:`~simlan_data.config.faults`). Metrics that ask what
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
