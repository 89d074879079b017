"""Typed configuration: the schema behind ``conf/`` (Hydra structured configs).

Hydra checks types and unknown keys when it composes; ``__post_init__`` checks ranges, units and
references when ``OmegaConf.to_object`` builds these dataclasses. Every failure is a
:class:`~simlan_data.errors.ConfigError` naming the field, the value and the fix.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from simlan_data.algorithms.birdseye import CanvasSpec
from simlan_data.algorithms.people import PeopleParams
from simlan_data.algorithms.posemap.config import PosemapConfig
from simlan_data.config import collision as collision_scenario
from simlan_data.config import missions as fleet_missions
from simlan_data.config import trajectory as trajectory_setup
from simlan_data.config.agent import AgentConfig
from simlan_data.config.algorithms import AlgorithmsConfig, register_algorithms, selected_algorithm
from simlan_data.config.collision import CollisionScenarioConfig
from simlan_data.config.live import LiveConfig
from simlan_data.config.missions import MissionsConfig
from simlan_data.config.randomize import RandomizeConfig
from simlan_data.config.sensors import SensorsConfig
from simlan_data.config.trajectory import TrajectoryConfig
from simlan_data.errors import ConfigError
from simlan_data.recording.timebase import DEFAULT_EPOCH, parse_epoch
from simlan_data.world.physics import PhysicsParams

STREAMS = ("rgb", "depth", "semantic")  # the default set
# instance: instance ids, 2D and 3D boxes per frame (issue 25; off by default: a dataset asks for it)
STREAM_CHOICES = (*STREAMS, "instance")
RGB_ENCODINGS = ("jpeg", "png", "raw")
DEPTH_ENCODINGS = ("16UC1", "png", "raw")  # 16UC1 Image mm | compressedDepth PNG mm | 32FC1 Image m
SEMANTIC_ENCODINGS = ("png", "raw")
CHUNK_COMPRESSIONS = ("zstd", "none")
CALIBRATION_CHECKS = ("warn", "error")
RENDER_BACKENDS = ("auto", "egl", "tiny")
FIDELITIES = ("empty", "light", "medium", "default")


def _incomplete(obj: Any) -> bool:
    """True while OmegaConf builds the schema itself (fields still MISSING): skip checks then."""
    return any(
        getattr(obj, f) == MISSING for f in obj.__dataclass_fields__ if isinstance(getattr(obj, f), str)
    )


_bad = ConfigError.invalid  # invalid KEY=VALUE in config: WHY; FIX


def _positive(field_name: str, value: float, fix: str) -> None:
    if not value > 0:
        raise _bad(field_name, value, "must be > 0", fix)


def _choice(field_name: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise _bad(
            field_name, value, f"expected one of {', '.join(choices)}", f"set {field_name}={choices[0]}"
        )


def _divides(field_name: str, rate_hz: float, physics_hz: int) -> None:
    if not rate_hz > 0:
        raise _bad(field_name, rate_hz, "must be > 0", f"use a divisor of world.physics_hz={physics_hz}")
    steps = physics_hz / rate_hz
    if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
        whole = [d for d in range(1, physics_hz + 1) if physics_hz % d == 0]
        below = max((d for d in whole if d < rate_hz), default=whole[0])
        above = min((d for d in whole if d > rate_hz), default=whole[-1])
        raise _bad(
            field_name,
            rate_hz,
            f"the simulation steps at world.physics_hz={physics_hz}; a rate must be a whole number of steps",
            f"use a divisor of {physics_hz}, e.g. {below} or {above}",
        )


def _default_physics() -> dict[str, PhysicsParams]:
    return {
        "floor": PhysicsParams(lateral_friction=1.0),
        "structure": PhysicsParams(lateral_friction=0.7),
        "shelf": PhysicsParams(lateral_friction=0.6),
        "box": PhysicsParams(mass_kg=30.0, lateral_friction=0.6, restitution=0.05),
        "pallet": PhysicsParams(mass_kg=25.0, lateral_friction=0.7, restitution=0.05),
    }


@dataclass
class WorldConfig:
    """The warehouse: SIMLAN's layout table, a fidelity level and physics."""

    layout: str = "warehouse_layout.csv"
    fidelity: str = "default"
    physics_hz: int = 240
    gravity_mps2: float = 9.81
    settle_s: float = 2.0
    physics: dict[str, PhysicsParams] = field(default_factory=_default_physics)

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        _choice("world.fidelity", self.fidelity, FIDELITIES)
        if not 60 <= self.physics_hz <= 2000:
            raise _bad("world.physics_hz", self.physics_hz, "must be within 60..2000 Hz", "use 240")
        if not 0 <= self.settle_s <= 60:
            raise _bad("world.settle_s", self.settle_s, "must be within 0..60 s", "use 2.0")
        if not 0 <= self.gravity_mps2 <= 100:
            raise _bad("world.gravity_mps2", self.gravity_mps2, "must be within 0..100 m/s^2", "use 9.81")


@dataclass
class CameraSetConfig:
    """A set of calibrated cameras and how they render."""

    name: str = "gpss"
    ids: list[int] = MISSING
    count: int = 0  # use only the first `count` of ids (0: all); sweeps take subsets with it
    rate_hz: float = 5.0
    width: int = 960
    height: int = 540
    streams: list[str] = field(default_factory=lambda: list(STREAMS))
    distortion: bool = True
    near_m: float = 1.0
    far_m: float = 100.0
    calibration_dir: str = ""
    calibration_check: str = "warn"

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        if len(self.ids) == 0:
            raise _bad(
                "cameras.ids",
                list(self.ids),
                "no camera selected",
                "list at least one id, e.g. cameras.ids=[160]",
            )
        if len(set(self.ids)) != len(self.ids):
            raise _bad("cameras.ids", list(self.ids), "an id appears twice", "list each camera once")
        if not 0 <= self.count <= len(self.ids):
            raise _bad(
                "cameras.count",
                self.count,
                f"must be within 0..{len(self.ids)} (the number of cameras.ids; 0 = all)",
                f"use e.g. cameras.count={min(4, len(self.ids))}",
            )
        if self.count:
            self.ids = list(self.ids[: self.count])
        _positive("cameras.rate_hz", self.rate_hz, "use e.g. cameras.rate_hz=5")
        if not (16 <= self.width <= 7680 and 16 <= self.height <= 4320):
            raise _bad(
                "cameras.width x height",
                f"{self.width}x{self.height}",
                "must be within 16x16..7680x4320",
                "use e.g. 960x540",
            )
        for s in self.streams:
            _choice("cameras.streams[]", s, STREAM_CHOICES)
        if "rgb" not in self.streams:
            raise _bad(
                "cameras.streams",
                list(self.streams),
                "rgb is required (localization and recording need it)",
                "add rgb",
            )
        if not 0 < self.near_m < self.far_m:
            raise _bad(
                "cameras.near_m/far_m",
                (self.near_m, self.far_m),
                "need 0 < near_m < far_m",
                "use near_m=1.0 far_m=100.0",
            )
        _choice("cameras.calibration_check", self.calibration_check, CALIBRATION_CHECKS)


@dataclass
class RenderConfig:
    """Renderer: PyBullet's EGL plugin (software or GPU) or TinyRenderer, layered or full."""

    backend: str = "auto"
    layered: bool = True
    software_gl_threads: int = 1

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        _choice("render.backend", self.backend, RENDER_BACKENDS)
        if not 0 <= self.software_gl_threads <= 64:
            raise _bad(
                "render.software_gl_threads",
                self.software_gl_threads,
                "must be within 0..64 (0: Mesa's default)",
                "use 1",
            )


@dataclass
class RecordingConfig:
    """What the ROS 2 bag holds and how it is encoded and flushed."""

    enabled: bool = True
    rgb_encoding: str = "jpeg"
    jpeg_quality: int = 85
    depth_encoding: str = "16UC1"
    semantic_encoding: str = "png"
    depth_rate_hz: float = 1.0
    semantic_rate_hz: float = 1.0
    ground_truth_rate_hz: float = 60.0
    compression: str = "zstd"
    compression_level: int = 2
    flush_period_s: float = 1.0
    fsync: bool = False  # also force each flush to the disk: bounded loss on a power cut, not just a kill
    encode_threads: int = 2
    # bag time = epoch + simulated time (recording/timebase.py): a fixed date keeps runs
    # reproducible to the byte; set it to your wall time (`date -u +%FT%TZ`) if you prefer
    epoch: str = DEFAULT_EPOCH

    @property
    def epoch_ns(self) -> int:
        """The epoch in ns since 1970 (checked in ``__post_init__``)."""
        return parse_epoch(self.epoch)

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        try:
            parse_epoch(self.epoch)
        except ValueError as err:
            raise _bad(
                "recording.epoch",
                self.epoch,
                str(err),
                f"give an ISO 8601 UTC time such as recording.epoch={DEFAULT_EPOCH} (the default)",
            ) from None
        _choice("recording.rgb_encoding", self.rgb_encoding, RGB_ENCODINGS)
        _choice("recording.depth_encoding", self.depth_encoding, DEPTH_ENCODINGS)
        _choice("recording.semantic_encoding", self.semantic_encoding, SEMANTIC_ENCODINGS)
        _choice("recording.compression", self.compression, CHUNK_COMPRESSIONS)
        if not -7 <= self.compression_level <= 22:
            raise _bad(
                "recording.compression_level",
                self.compression_level,
                "zstd levels are -7..22",
                "use 2 (the default)",
            )
        if not 1 <= self.jpeg_quality <= 100:
            raise _bad("recording.jpeg_quality", self.jpeg_quality, "must be within 1..100", "use 90")
        if not 50 <= self.ground_truth_rate_hz <= 1000:
            raise _bad(
                "recording.ground_truth_rate_hz",
                self.ground_truth_rate_hz,
                "ground truth must be recorded at 50 Hz or more",
                "use 60",
            )
        _positive(
            "recording.flush_period_s",
            self.flush_period_s,
            "use 1.0 (at most one second of data lost on a crash)",
        )
        if not 0 <= self.encode_threads <= 16:
            raise _bad(
                "recording.encode_threads",
                self.encode_threads,
                "must be within 0..16 (0 encodes on the simulation thread)",
                "use 2",
            )


@dataclass
class BirdseyeConfig:
    """The live bird's-eye view (``/birdseye/image``) and the canvas replays use by default.

    The canvas (region, scale, plane) is what every stitcher fills and the metrics score; the
    stitcher's own parameters are its config, ``algorithms.stitcher`` (e.g. ``feather_m``).
    """

    rate_hz: float = 0.0  # 0: no live topic
    x_m: list[float] = field(default_factory=lambda: [-8.0, 34.0])
    y_m: list[float] = field(default_factory=lambda: [-10.0, 10.0])
    px_per_m: float = 50.0
    plane_z_m: float = 0.0
    jpeg_quality: int = 85

    def canvas(self, where: str = "config") -> CanvasSpec:
        """The canvas; raises ConfigError naming the field if it is unusable."""
        return CanvasSpec(self.x_m, self.y_m, self.px_per_m, self.plane_z_m, where=where)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        if not 0 <= self.rate_hz <= 100:
            raise _bad(
                "birdseye.rate_hz",
                self.rate_hz,
                "must be within 0..100 Hz (0: off)",
                "use e.g. birdseye.rate_hz=1",
            )
        if not 1 <= self.jpeg_quality <= 100:
            raise _bad("birdseye.jpeg_quality", self.jpeg_quality, "must be within 1..100", "use 85")
        self.canvas()


@dataclass
class LocalizationConfig:
    """What the robots steer on; the localizer itself and its config: ``algorithms.localizer``."""

    source: str = "camera"  # camera (the localizer's estimates: GPSS) | ground_truth

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        _choice("localization.source", self.source, ("camera", "ground_truth"))


@dataclass
class NavigationConfig:
    """Occupancy grid, planner, path follower and multi-robot coordination."""

    map: str = "world"  # world (from the layout) | simlan (SIMLAN's Nav2 map)
    resolution_m: float = 0.1
    clearance_m: float = 0.4  # planned paths keep half the robot's width plus this from obstacles
    lookahead_m: float = 1.2
    goal_tolerance_m: float = 0.3
    max_yaw_rate_rps: float = 0.8
    coordination: bool = True
    safety_distance_m: float = 0.6  # robots keep at least this between footprints
    unseen_cost: float = 25.0  # camera steering: plan cost per metre no camera sees the robot (0: off)

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        _choice("navigation.map", self.map, ("world", "simlan"))
        if not (self.unseen_cost >= 0 and np.isfinite(self.unseen_cost)):
            raise _bad(
                "navigation.unseen_cost", self.unseen_cost, "must be a finite number >= 0", "use 25 (0: off)"
            )
        if not 0.02 <= self.resolution_m <= 0.5:
            raise _bad("navigation.resolution_m", self.resolution_m, "must be within 0.02..0.5 m", "use 0.1")
        for name in (
            "clearance_m",
            "lookahead_m",
            "goal_tolerance_m",
            "max_yaw_rate_rps",
            "safety_distance_m",
        ):
            _positive(f"navigation.{name}", getattr(self, name), "use a positive value")


@dataclass
class PerturbationConfig:
    """Seeded perturbations (V&V statistics): what ``seed`` changes in a run; all 0 = none.

    Each agent's spawn pose moves by a uniform offset within +-spawn_xy_m in x and y and
    +-spawn_yaw_deg in yaw, drawn from a generator seeded by (seed, agent number): deterministic
    per seed and independent of the other agents. Applied once, when the typed config is built,
    so the scene, the GPSS stack and the spawn checks all see the same pose.
    """

    spawn_xy_m: float = 0.0
    spawn_yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        if not 0 <= self.spawn_xy_m <= 2.0:
            raise _bad("perturbation.spawn_xy_m", self.spawn_xy_m, "must be within 0..2 m", "use e.g. 0.15")
        if not 0 <= self.spawn_yaw_deg <= 45.0:
            raise _bad(
                "perturbation.spawn_yaw_deg", self.spawn_yaw_deg, "must be within 0..45 degrees", "use e.g. 3"
            )


@dataclass
class FaultsConfig:
    """Injected faults (V&V): what the GPSS algorithms receive or believe, never the simulated world.

    Rendering and the recording stay true (the cameras still see and record); the localizer is
    given fewer images or a wrong calibration. ``algorithms.localizer.bias_m`` and
    ``algorithms.localizer.processing_delay_s`` are the other injectable faults.
    """

    drop_cameras: list[int] = field(default_factory=list)  # their images never reach the localizer
    yaw_error_deg: float = 0.0  # added to the believed yaw of each camera in yaw_error_cameras
    yaw_error_cameras: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        if not -30.0 <= self.yaw_error_deg <= 30.0:
            raise _bad(
                "faults.yaw_error_deg", self.yaw_error_deg, "must be within -30..30 degrees", "use 1.0"
            )


@dataclass
class ScenarioConfig:
    name: str = "default"
    description: str = ""


@dataclass
class Config:
    """A run: (config, seed) -> recording + metrics."""

    seed: int = 0
    duration_s: float = 60.0
    control_rate_hz: float = 20.0
    progress: bool = True
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    world: WorldConfig = field(default_factory=WorldConfig)
    cameras: CameraSetConfig = field(default_factory=CameraSetConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    recording: RecordingConfig = field(default_factory=RecordingConfig)
    localization: LocalizationConfig = field(default_factory=LocalizationConfig)
    algorithms: AlgorithmsConfig = field(default_factory=AlgorithmsConfig)
    navigation: NavigationConfig = field(default_factory=NavigationConfig)
    agents: dict[str, AgentConfig] = field(default_factory=dict)
    birdseye: BirdseyeConfig = field(default_factory=BirdseyeConfig)
    posemap: PosemapConfig = field(default_factory=PosemapConfig)
    perturbation: PerturbationConfig = field(default_factory=PerturbationConfig)
    faults: FaultsConfig = field(default_factory=FaultsConfig)
    people: PeopleParams = field(default_factory=PeopleParams)  # person detection (rgb, or the oracle)
    collision: CollisionScenarioConfig = field(default_factory=CollisionScenarioConfig)
    live: LiveConfig = field(default_factory=LiveConfig)  # a live view in Foxglove (config/live.py)
    fleet: MissionsConfig = field(default_factory=MissionsConfig)  # scenario=fleet (config/missions.py)
    sensors: SensorsConfig = field(default_factory=SensorsConfig)  # realistic cameras (config/sensors.py)
    randomize: RandomizeConfig = field(default_factory=RandomizeConfig)  # domain randomization
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)  # experiment=trajectory

    def __post_init__(self) -> None:
        if _incomplete(self):
            return
        self.posemap.check()
        self.trajectory.check()
        self.live.check_recording(self.recording.enabled)
        if not 0 < self.duration_s <= 24 * 3600:
            raise _bad(
                "duration_s", self.duration_s, "must be within (0, 86400] seconds", "use e.g. duration_s=60"
            )
        if not 0 <= self.seed < 2**32:
            raise _bad("seed", self.seed, "must be within 0..2^32-1", "use e.g. seed=0")
        physics_hz = self.world.physics_hz
        _divides("control_rate_hz", self.control_rate_hz, physics_hz)
        _divides("cameras.rate_hz", self.cameras.rate_hz, physics_hz)
        _divides("recording.ground_truth_rate_hz", self.recording.ground_truth_rate_hz, physics_hz)
        for name in ("depth_rate_hz", "semantic_rate_hz"):
            rate = getattr(self.recording, name)
            _positive(f"recording.{name}", rate, f"use a divisor of cameras.rate_hz={self.cameras.rate_hz}")
            frames = self.cameras.rate_hz / rate
            if rate > self.cameras.rate_hz or abs(frames - round(frames)) > 1e-9:
                raise _bad(
                    f"recording.{name}",
                    rate,
                    f"must divide the camera rate cameras.rate_hz={self.cameras.rate_hz} (every n-th frame is recorded)",
                    f"use e.g. {self.cameras.rate_hz} or {self.cameras.rate_hz / 5:g}",
                )
        if self.birdseye.rate_hz > 0:
            frames = self.cameras.rate_hz / self.birdseye.rate_hz
            if frames < 1 - 1e-9 or abs(frames - round(frames)) > 1e-9:
                raise _bad(
                    "birdseye.rate_hz",
                    self.birdseye.rate_hz,
                    f"must divide the camera rate cameras.rate_hz={self.cameras.rate_hz} (every n-th camera frame is stitched)",
                    f"use e.g. {self.cameras.rate_hz:g} or {self.cameras.rate_hz / 5:g}",
                )
        seen_marker: dict[int, str] = {}
        ordered: dict[str, AgentConfig] = {}
        for ns in sorted(self.agents, key=lambda k: (len(k), k)):
            agent = self.agents[ns]
            agent.check(ns)
            assert agent.marker_id is not None
            if agent.marker_id in seen_marker:
                raise _bad(
                    f"agents.{ns}.marker_id",
                    agent.marker_id,
                    f"already used by {seen_marker[agent.marker_id]}",
                    "give every robot its own marker id",
                )
            seen_marker[agent.marker_id] = ns
            ordered[ns] = agent
        self.agents = ordered
        for cid in [*self.faults.drop_cameras, *self.faults.yaw_error_cameras]:
            if cid not in self.cameras.ids:
                raise _bad(
                    "faults",
                    cid,
                    "not one of cameras.ids",
                    f"use one of {', '.join(map(str, self.cameras.ids))}",
                )
        self.trajectory.check_agents(list(self.agents))
        self._jitter_spawn_poses()
        self._check_safety_namespaces()

    def _jitter_spawn_poses(self) -> None:
        """Move every agent's spawn pose by its seeded offset (see PerturbationConfig)."""
        jitter = self.perturbation
        if jitter.spawn_xy_m == 0 and jitter.spawn_yaw_deg == 0:
            return
        for agent in self.agents.values():
            rng = np.random.default_rng([self.seed, agent.number])
            dx, dy = rng.uniform(-jitter.spawn_xy_m, jitter.spawn_xy_m, size=2)
            dyaw = np.radians(rng.uniform(-jitter.spawn_yaw_deg, jitter.spawn_yaw_deg))
            x, y, yaw = (float(v) for v in agent.pose)
            agent.pose = [x + float(dx), y + float(dy), yaw + float(dyaw)]

    def _check_safety_namespaces(self) -> None:
        """The namespaces the safety monitor's config names must be agents of the run (for a
        monitor whose config can say: ``check_namespaces(known, where=)``, as the trees' does)."""
        if self.algorithms.safety is None:
            return
        _, config = selected_algorithm(self.algorithms, "safety")
        check = getattr(config, "check_namespaces", None)
        if callable(check):
            check(list(self.agents))

    @property
    def agent_list(self) -> list[AgentConfig]:
        """Agents in namespace order."""
        return list(self.agents.values())


def _collision_setup(key: str, *, _root_: DictConfig) -> Any:
    """``${collision_setup:KEY}``: agent poses and goals of scenario=collision from its ``collision`` section."""
    section = OmegaConf.to_container(_root_.collision, resolve=True)
    assert isinstance(section, dict)
    return collision_scenario.resolve(key, section)


def _fleet_missions(key: str, *, _root_: DictConfig) -> Any:
    """``${fleet_missions:KEY}``: scenario=fleet's agents (and docks, chargers) from ``fleet`` and ``seed``."""
    root = OmegaConf.to_container(_root_, resolve=False)
    assert isinstance(root, dict)
    for name in ("fleet", "world", "navigation"):  # (their own interpolations, e.g. a sweep's)
        root[name] = OmegaConf.to_container(_root_[name], resolve=True)
    root["seed"] = _root_.seed
    value = fleet_missions.resolve(key, root)
    if key == "agents":  # typed, as a spawn list's entries are (a plain dict is refused there)
        return OmegaConf.create(
            {ns: OmegaConf.structured(AgentConfig(**agent)) for ns, agent in value.items()}
        )
    return value


def _trajectory(key: str, *, _root_: DictConfig) -> Any:
    """``${trajectory:KEY}``: experiment=trajectory's agents and duration from its ``trajectory`` section."""
    section = OmegaConf.to_container(_root_.trajectory, resolve=True)
    assert isinstance(section, dict)
    value = trajectory_setup.resolve(key, section)
    if key == "agents":  # typed, as a spawn list's entries are
        return OmegaConf.create({ns: OmegaConf.structured(AgentConfig(**a)) for ns, a in value.items()})
    return value


def register_configs(overrides: list[str] | None = None) -> None:
    """Register the schema and every algorithm with Hydra's ConfigStore (conf/config.yaml lists it first).

    ``overrides`` (default: the command line) may select algorithms by import path.
    """
    cs = ConfigStore.instance()
    cs.store(name="simlan_schema", node=Config)
    register_algorithms(overrides)
    if not OmegaConf.has_resolver("collision_setup"):
        OmegaConf.register_new_resolver("collision_setup", _collision_setup)
    if not OmegaConf.has_resolver("fleet_missions"):
        OmegaConf.register_new_resolver("fleet_missions", _fleet_missions)
    if not OmegaConf.has_resolver("trajectory"):
        OmegaConf.register_new_resolver("trajectory", _trajectory)
