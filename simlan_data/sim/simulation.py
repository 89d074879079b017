"""Run a scenario on the simulated clock and record it.

One physics step at a time (``world.physics_hz``); every rate is a whole number of steps::

    step k, t = k / physics_hz
      control tick   agents: ground-truth pose -> follower -> cmd_vel -> wheel motors; collisions
      truth tick     /clock, /ground_truth/poses
      camera tick    movable AABBs -> layered render per camera -> encode (worker threads) -> bag
                     (every n-th: all frames -> bird's-eye stitcher -> JPEG -> /birdseye/image)
      physics step
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from .. import __version__
from .._pybullet import pb
from ..config import Config
from ..constants import FORMAT_VERSION, NS_PER_S
from ..geometry.transforms import Transform
from ..gpss.follower import FollowerParams, WaypointFollower
from ..recording import messages as M
from ..recording import schema
from ..recording.writer import NullWriter, RecordingWriter
from ..world.labels import SEMANTIC_CLASSES
from .birdseye_live import BirdseyeRecorder
from .camera_recording import CameraRecorder
from .scene import Inputs, Scene

DEPENDENCIES = (
    "pybullet",
    "rosbags",
    "mcap",
    "opencv-python-headless",
    "numpy",
    "scipy",
    "polars",
    "hydra-core",
    "omegaconf",
)


def dependency_versions() -> dict[str, str]:
    out = {}
    for name in DEPENDENCIES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


@dataclass
class RunStats:
    """What a run measured; becomes metrics.json."""

    sim_duration_ns: int = 0
    wall_s: float = 0.0
    physics_steps: int = 0
    camera_frames: int = 0
    camera_frames_changed: int = 0
    render_wall_s: float = 0.0
    renderer: str = ""
    collisions: dict[str, int] = field(default_factory=dict)
    goals_reached: dict[str, int] = field(default_factory=dict)
    goals_total: dict[str, int] = field(default_factory=dict)
    distance_m: dict[str, float] = field(default_factory=dict)
    message_counts: dict[str, int] = field(default_factory=dict)
    byte_counts: dict[str, int] = field(default_factory=dict)
    calibration_issues: list[str] = field(default_factory=list)
    layout_notes: list[str] = field(default_factory=list)
    recording_bytes: int = 0

    def metrics(self) -> dict[str, float]:
        sim_s = self.sim_duration_ns / NS_PER_S
        out: dict[str, float] = {
            "sim.rtf": sim_s / self.wall_s if self.wall_s > 0 else 0.0,
            "sim.duration_s": sim_s,
            "sim.wall_s": self.wall_s,
            "sim.physics_steps": float(self.physics_steps),
            "sim.camera_frames": float(self.camera_frames),
            "sim.camera_frames_changed": float(self.camera_frames_changed),
            "sim.render_wall_s": self.render_wall_s,
            "agents.collisions": float(sum(self.collisions.values())),
            "recording.bytes": float(self.recording_bytes),
            "recording.messages": float(sum(self.message_counts.values())),
        }
        for ns in sorted(self.collisions):
            out[f"agents.{ns}.collisions"] = float(self.collisions[ns])
            out[f"agents.{ns}.distance_m"] = round(self.distance_m.get(ns, 0.0), 6)
            out[f"agents.{ns}.waypoints_reached"] = float(self.goals_reached.get(ns, 0))
            out[f"agents.{ns}.waypoints_total"] = float(self.goals_total.get(ns, 0))
        return out


class Simulation:
    """A configured run: build the scene, step it, record everything."""

    def __init__(self, cfg: Config, inputs: Inputs, *, config_yaml: str) -> None:
        self.cfg, self.inputs, self.config_yaml = cfg, inputs, config_yaml
        hz = cfg.world.physics_hz
        self.physics_hz = hz
        self.control_every = round(hz / cfg.control_rate_hz)
        self.truth_every = round(hz / cfg.recording.ground_truth_rate_hz)
        self.camera_every = round(hz / cfg.cameras.rate_hz)
        self.depth_every = round(cfg.cameras.rate_hz / cfg.recording.depth_rate_hz)
        self.semantic_every = round(cfg.cameras.rate_hz / cfg.recording.semantic_rate_hz)
        self.steps = round(cfg.duration_s * hz)
        self.birdseye: BirdseyeRecorder | None = None

    def stamp_ns(self, step: int) -> int:
        return step * NS_PER_S // self.physics_hz

    def run(self, bag_path: Path, *, progress: Callable[[float], None] | None = None) -> RunStats:
        """Simulate ``duration_s`` and write the bag at ``bag_path`` (which must not exist)."""
        cfg = self.cfg
        stats = RunStats(calibration_issues=list(self.inputs.calibration_issues))
        scene = Scene.build(cfg, self.inputs)
        stats.renderer = scene.client.backend
        stats.layout_notes = list(scene.world.layout_conflicts)
        try:
            writer = (
                RecordingWriter(
                    bag_path,
                    compression=cfg.recording.compression,
                    flush_period_ns=int(cfg.recording.flush_period_s * NS_PER_S),
                    encode_threads=cfg.recording.encode_threads,
                )
                if cfg.recording.enabled
                else NullWriter()
            )
            with writer:
                writer.set_metadata("simlan.format_version", FORMAT_VERSION)
                writer.set_metadata("simlan.version", __version__)
                writer.set_metadata("simlan.seed", str(cfg.seed))
                writer.set_metadata("simlan.scenario", cfg.scenario.name)
                writer.set_metadata("simlan.renderer", scene.client.backend)
                # set up before the clock starts, like the scene (lookup tables take a second or two)
                self.birdseye = BirdseyeRecorder.create(writer, cfg, scene.cameras)
                wall0 = time.perf_counter()
                self._loop(scene, writer, stats, progress)
                stats.wall_s = time.perf_counter() - wall0
            stats.message_counts = dict(writer.message_counts)
            stats.byte_counts = dict(writer.byte_counts)
            if cfg.recording.enabled:
                stats.recording_bytes = sum(f.stat().st_size for f in bag_path.iterdir() if f.is_file())
        finally:
            scene.close()
        return stats

    # --------------------------------------------------------------------------- the loop
    def _loop(
        self, scene: Scene, writer: RecordingWriter, stats: RunStats, progress: Callable[[float], None] | None
    ) -> None:
        cfg = self.cfg
        self._publish_static(scene, writer)
        agent_topics = {a.namespace: schema.agent_topics(a.namespace) for a in scene.agents}
        followers = {
            a.namespace: WaypointFollower(ac.waypoints, FollowerParams(speed_mps=ac.speed_mps), loop=ac.loop)
            for a, ac in zip(scene.agents, cfg.agents)
        }
        for ac in cfg.agents:
            stats.goals_total[ac.namespace] = len(ac.waypoints)
            stats.collisions[ac.namespace] = 0
            stats.distance_m[ac.namespace] = 0.0
        in_contact = {a.namespace: False for a in scene.agents}
        last_xy = {a.namespace: a.pose().translation[:2].copy() for a in scene.agents}
        recorder = CameraRecorder(
            writer,
            cfg.recording,
            list(cfg.cameras.streams),
            depth_every=self.depth_every,
            semantic_every=self.semantic_every,
        )
        birdseye = self.birdseye
        ignore = scene.world.floor
        dt_control = self.control_every / self.physics_hz
        cid = scene.client.id
        for step in range(self.steps + 1):
            t = self.stamp_ns(step)
            if step % self.control_every == 0:
                for agent in scene.agents:
                    ns, topics = agent.namespace, agent_topics[agent.namespace]
                    pose = agent.pose()
                    xy = pose.translation[:2]
                    stats.distance_m[ns] += float(((xy - last_xy[ns]) ** 2).sum() ** 0.5)
                    last_xy[ns] = xy.copy()
                    cmd = followers[ns].step(float(xy[0]), float(xy[1]), pose.yaw(), dt_control)
                    v, w = agent.apply_command(cmd.linear_mps, cmd.angular_rps)
                    stats.goals_reached[ns] = followers[ns].reached
                    writer.write(topics["cmd_vel"], t, M.twist_stamped(t, schema.base_link_frame(ns), v, w))
                    hit = agent.collisions(ignore, scene.names)
                    if hit.in_collision and not in_contact[ns]:
                        stats.collisions[ns] += 1
                    in_contact[ns] = hit.in_collision
                    writer.write(
                        topics["collision"],
                        t,
                        M.collision_state(
                            t,
                            schema.base_link_frame(ns),
                            in_collision=hit.in_collision,
                            max_force_n=hit.max_force_n,
                            total_force_n=hit.total_force_n,
                            others=hit.others,
                        ),
                    )
            if step % self.truth_every == 0:
                writer.write(_topic(schema.CLOCK), t, M.clock(t))
                poses = [
                    M.transform_stamped(t, schema.MAP_FRAME, schema.base_link_frame(a.namespace), a.pose())
                    for a in scene.agents
                ]
                writer.write(_topic(schema.GROUND_TRUTH_POSES), t, M.tf_message(poses))
            if step % self.camera_every == 0:
                render0 = time.perf_counter()
                scene.refresh_static_layers()
                aabbs = scene.agent_aabbs()
                frames = []
                for renderer in scene.renderers:
                    images = renderer.render(aabbs)
                    stats.camera_frames += 1
                    stats.camera_frames_changed += int(images.changed)
                    recorder.record(t, step // self.camera_every, renderer.camera, images)
                    frames.append(images)
                if birdseye is not None:
                    birdseye.tick(t, step // self.camera_every, frames)
                stats.render_wall_s += time.perf_counter() - render0
                if progress is not None:
                    progress(t / NS_PER_S)
            if step < self.steps:
                pb.stepSimulation(physicsClientId=cid)
                stats.physics_steps += 1
        stats.sim_duration_ns = self.stamp_ns(self.steps)

    def _publish_static(self, scene: Scene, writer: RecordingWriter) -> None:
        cfg = self.cfg
        writer.write(_topic(schema.CONFIG), 0, M.string(self.config_yaml))
        info = M.run_info(
            format_version=FORMAT_VERSION,
            version=__version__,
            scenario=cfg.scenario.name,
            seed=cfg.seed,
            renderer=scene.client.backend,
            renderer_info=f"{'layered' if cfg.render.layered else 'full'}; distortion {'on' if cfg.cameras.distortion else 'off'}; near {cfg.cameras.near_m} m",
            dependencies=dependency_versions(),
        )
        writer.write(_topic(schema.RUN_INFO), 0, info)
        writer.write(_topic(schema.SEMANTIC_LABELS), 0, M.semantic_labels(dict(SEMANTIC_CLASSES)))
        static = [
            M.transform_stamped(0, schema.MAP_FRAME, c.frame_id, c.world_from_camera) for c in scene.cameras
        ]
        for agent in scene.agents:
            static.append(
                M.transform_stamped(
                    0,
                    schema.MAP_FRAME,
                    schema.odom_frame(agent.namespace),
                    Transform.from_pose2d(*agent.pose().translation[:2], agent.pose().yaw()),
                )
            )
        writer.write(_topic(schema.TF_STATIC), 0, M.tf_message(static))
        for agent, ac in zip(scene.agents, cfg.agents):
            if ac.waypoints:
                writer.write(
                    schema.agent_topics(agent.namespace)["plan"],
                    0,
                    M.path(0, schema.MAP_FRAME, [list(w) for w in ac.waypoints]),
                )


def _topic(name: str) -> schema.Topic:
    for t in schema.GLOBAL_TOPICS:
        if t.name == name:
            return t
    raise KeyError(name)
