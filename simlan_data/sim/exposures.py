"""When each camera exposes the frame a camera tick delivers (issue 24: exposure instants, delay).

A free-running camera exposes at its own phase, and its frame reaches the algorithms a transport
delay later: the frame delivered at the camera tick ``d`` was exposed ``lag`` before it
(``CameraSensor.lag_s``: phase + delay). The simulation renders each camera *at* the physics step
of its exposure, the scene as it truly was then (every agent, joint, pushed pallet and light;
nothing is moved back and forth), holds the images, and hands them on at the delivery tick.

The lags are drawn ``ahead`` camera ticks before their delivery (the longest lag the config allows
fits in that window), per camera in delivery order, so a run stays deterministic. An exposure
instant is the physics step nearest to ``d - lag`` (``world.physics_hz``: 4.2 ms at 240 Hz);
what a frame's lag truly was is recorded (``/camera_<id>/effects``: ``delay_s``). No frame shows
the scene before the run began (a first tick's exposure is at step 0 at the latest).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from simlan_data.sim.rendering import CameraImages
from simlan_data.sim.sensors import CameraSensor


@dataclass(frozen=True)
class Exposed:
    """A camera's frame, rendered at its exposure step, waiting for its delivery tick."""

    images: CameraImages
    step: int  # the physics step of its exposure (its end)
    subframes: int  # renders averaged into it (motion blur)


class ExposureSchedule:
    """Which cameras expose at which physics step, and the held frames until their tick."""

    def __init__(
        self, sensors: Sequence[CameraSensor], camera_every: int, physics_hz: int, max_lag_s: float
    ) -> None:
        self.sensors, self.camera_every, self.hz = list(sensors), camera_every, physics_hz
        self.max_lag_steps = math.ceil(max_lag_s * physics_hz)
        self.ahead = math.ceil(self.max_lag_steps / camera_every)  # ticks drawn before delivery
        self._due: dict[int, list[tuple[int, int]]] = {}  # exposure step -> [(camera, delivery step)]
        self._held: dict[tuple[int, int], Exposed] = {}  # (camera, delivery step) -> frame
        for tick in range(self.ahead + 1):
            self._schedule(tick)

    def _schedule(self, tick: int) -> None:
        """Draw every camera's lag for the frame delivered at camera tick ``tick``."""
        delivery = tick * self.camera_every
        for i, sensor in enumerate(self.sensors):
            lag = min(round(sensor.lag_s() * self.hz), self.max_lag_steps)
            self._due.setdefault(max(0, delivery - lag), []).append((i, delivery))

    def exposing(self, step: int) -> list[tuple[int, int]]:
        """(camera, delivery step) of every frame whose exposure ends at ``step``, in camera order."""
        return sorted(self._due.pop(step, []))

    def hold(self, camera: int, delivery: int, frame: Exposed) -> None:
        self._held[(camera, delivery)] = frame

    def deliver(self, step: int) -> list[Exposed]:
        """Every camera's frame for the tick at ``step`` (in camera order); draws the lags of the
        tick ``ahead`` ticks later."""
        frames = [self._held.pop((i, step)) for i in range(len(self.sensors))]
        self._schedule(step // self.camera_every + self.ahead + 1)
        return frames

    def lag_ns(self, frame: Exposed, step: int) -> int:
        """How long before the tick at ``step`` the frame's exposure ended (simulated clock)."""
        return step * 1_000_000_000 // self.hz - frame.step * 1_000_000_000 // self.hz
