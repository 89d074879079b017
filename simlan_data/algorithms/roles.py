"""The roles an algorithm can play, as small protocols over numpy arrays and plain dataclasses.

A plug-in is a class with three class attributes and the methods of its role::

    class MyLocalizer:
        role = "localizer"            # one of ROLES
        config_class = MyConfig       # a dataclass: defaults, checks in __post_init__
        def __init__(self, config: MyConfig, context: LocalizerContext) -> None: ...
        def observe(self, t_ns, frames): ...      # the role's methods (below)

The live loop and the replay construct it from the same config and context and call it in the same
order with the same inputs, so a replay reproduces the live outputs bit for bit. Time is the
simulated clock in integer nanoseconds; nothing here is a simulator, file-format or Hydra type.

    role         context (constructor)        called with                      returns
    localizer    cameras, robots              observe(t_ns, frames)            None
                                              command(t_ns, ns, v, w)          None
                                              estimate(t_ns)                   {ns: PoseEstimate}
    coordinator  safety_distance_m            decide(t_ns, intents)            {ns: Decision}
    safety       robots, static, run clocks   step(world)                      {ns: SafetyDecision}
    stitcher     cameras, canvas region       stitch(frames)                   canvas (HxWx3 uint8)
    posemap      cameras                      predict(landmarks, position=)    joint targets (47,)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, ClassVar, Protocol, runtime_checkable

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.birdseye import CanvasSpec
from simlan_data.algorithms.coordinator import Decision, Intent
from simlan_data.algorithms.localization import PoseEstimate
from simlan_data.algorithms.markers import MarkerMount
from simlan_data.algorithms.occupancy import OccupancyGrid
from simlan_data.algorithms.safety import Mover, RobotSpec, SafetyDecision, SafetyWorld
from simlan_data.geometry.camera import CameraModel

ROLES = ("localizer", "coordinator", "safety", "stitcher", "posemap")


@dataclass(frozen=True)
class CameraFrame:
    """One camera's image at one camera tick, as recorded: JPEG bytes (decoded on demand)."""

    camera_id: str
    stamp_ns: int
    jpeg: bytes | NDArray[np.uint8]

    @cached_property
    def bgr(self) -> NDArray[np.uint8]:
        """The image, decoded by OpenCV (HxWx3 BGR)."""
        return np.asarray(cv2.imdecode(np.frombuffer(self.jpeg, np.uint8), cv2.IMREAD_COLOR), dtype=np.uint8)

    @cached_property
    def gray(self) -> NDArray[np.uint8]:
        """The image in grey levels (what marker detectors read)."""
        return np.asarray(
            cv2.imdecode(np.frombuffer(self.jpeg, np.uint8), cv2.IMREAD_GRAYSCALE), dtype=np.uint8
        )


@dataclass(frozen=True)
class LocalizerContext:
    """What a localizer is built with: the believed camera models and the robots it must find."""

    cameras: Mapping[str, CameraModel]
    robots: Sequence[MarkerMount]


@dataclass(frozen=True)
class CoordinatorContext:
    """What a coordinator is built with: the fleet's safety distance, the occupancy grid the
    robots plan on (None where a caller has none; the built-in ``gpss`` does not need it) and,
    where robots steer on the cameras, the floor the cameras see: ``seen[k, row, col]`` is true
    where every robot of the run facing ``k * 45`` degrees has its marker in some camera's view
    (``coverage.SeenFloor.by_heading``; None: every floor counts as seen)."""

    safety_distance_m: float
    grid: OccupancyGrid | None = None
    seen: NDArray[np.bool_] | None = None


@dataclass(frozen=True)
class SafetyContext:
    """What a safety monitor is built with: every agent's footprint and drive (``kind`` robot,
    person or static), obstacles that stand, and what the run adds that is not the monitor's
    configuration: its control and camera periods, the localizer's processing delay and whether
    the central coordinator is on (``navigation.coordination``)."""

    robots: Sequence[RobotSpec]
    static: Sequence[Mover] = ()
    control_period_s: float = 0.05
    camera_period_s: float = 0.2
    processing_delay_s: float = 0.0
    coordinated: bool = False


@dataclass(frozen=True)
class StitcherContext:
    """What a stitcher is built with: the camera models and the canvas (region, scale, plane)."""

    cameras: Sequence[CameraModel]
    canvas: CanvasSpec


@dataclass(frozen=True)
class PosemapContext:
    """What a pose mapper is built with: the cameras whose landmarks it gets, in order."""

    cameras: Sequence[CameraModel] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)


@runtime_checkable
class Localizer(Protocol):
    """Camera frames + camera models -> pose estimates with covariance."""

    role: ClassVar[str]

    def observe(self, t_ns: int, frames: Mapping[str, CameraFrame]) -> None:
        """Take one camera tick: every camera's frame stamped ``t_ns``, in camera order."""

    def command(self, t_ns: int, namespace: str, linear_mps: float, angular_rps: float) -> None:
        """Take a velocity command sent to a robot at ``t_ns`` (for prediction)."""

    def estimate(self, t_ns: int) -> dict[str, PoseEstimate]:
        """The pose of every robot it knows at ``t_ns`` (a control tick)."""
        ...


@runtime_checkable
class SearchingLocalizer(Protocol):
    """Optional, for speed: a localizer that plans where to search each image and searches on
    worker threads. The live loop and the replay then search while the next cameras render or
    are read, and hand the results over in camera order; otherwise they call ``observe``."""

    def search_plans(self, t_ns: int, camera_ids: list[str]) -> list[Any]:
        """Per camera: a falsy value (skip the image), "full" or a list of regions."""
        ...

    def detect(self, camera_id: str, plan: Any, *, jpeg: Any = None, gray: Any = None) -> Any:
        """Search one image (thread-safe, no state change); returns what ``observe_search`` takes."""
        ...

    def observe_search(self, t_ns: int, camera_id: str, plan: Any, found: Any) -> None:
        """Take one image's search result (called in camera order)."""

    def close_frame(self, t_ns: int) -> Any:
        """Fuse the camera tick's results."""


def searches(localizer: object) -> bool:
    """True if ``localizer`` implements the optional searching protocol."""
    return all(
        callable(getattr(localizer, n, None))
        for n in ("search_plans", "detect", "observe_search", "close_frame")
    )


@runtime_checkable
class Coordinator(Protocol):
    """The fleet's intents (pose, footprint, planned path, priority) -> right-of-way decisions."""

    role: ClassVar[str]

    def decide(self, t_ns: int, intents: list[Intent]) -> dict[str, Decision]:
        """A decision (speed limit, who blocks, replan) for each robot that must not drive freely."""
        ...


@runtime_checkable
class SafetyMonitor(Protocol):
    """What GPSS knows of the robots, people and contacts -> stop / slow / go and events."""

    role: ClassVar[str]

    def step(self, world: SafetyWorld) -> dict[str, SafetyDecision]:
        """One control tick: a decision for every guarded robot."""
        ...


@runtime_checkable
class Stitcher(Protocol):
    """Camera frames -> one bird's-eye canvas of the floor."""

    role: ClassVar[str]

    def stitch(self, frames: Sequence[NDArray[np.uint8]]) -> NDArray[np.uint8]:
        """The canvas from one image per camera (the context's camera order)."""
        ...


@runtime_checkable
class PoseMapper(Protocol):
    """Landmarks (33 x (x, y, visibility) per camera) -> the humanoid's 47 joint targets."""

    role: ClassVar[str]

    def predict(self, landmarks: NDArray[np.float32], *, position: list[float] | None = None) -> NDArray:
        """Joint targets (radians) for a batch or one sample of landmarks."""
        ...


PROTOCOLS: dict[str, type] = {
    "localizer": Localizer,
    "coordinator": Coordinator,
    "safety": SafetyMonitor,
    "stitcher": Stitcher,
    "posemap": PoseMapper,
}
CONTEXTS: dict[str, type] = {
    "localizer": LocalizerContext,
    "coordinator": CoordinatorContext,
    "safety": SafetyContext,
    "stitcher": StitcherContext,
    "posemap": PosemapContext,
}


def missing_methods(role: str, cls: type) -> list[str]:
    """The methods of ``role``'s protocol that ``cls`` lacks (empty: it implements the role)."""
    proto = PROTOCOLS[role]
    wanted = [n for n in vars(proto) if not n.startswith("_") and callable(getattr(proto, n, None))]
    return [n for n in wanted if not callable(getattr(cls, n, None))]
