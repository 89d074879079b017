"""Turn the run's state into recorded messages (topics from recording/schema.py)."""

from __future__ import annotations

import functools
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from simlan_data import __version__
from simlan_data.algorithms.localization import PoseEstimate
from simlan_data.algorithms.markers import Detection
from simlan_data.algorithms.navigation import FAILED_STATE_PREFIX, Navigator
from simlan_data.algorithms.safety import Monitor, SafetyDecision, SafetyEvent, Zone
from simlan_data.config.schema import Config
from simlan_data.constants import FORMAT_VERSION
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.agents import Agent, CollisionReading
from simlan_data.sim.sensors import CameraSensor, Capture
from simlan_data.world.labels import SEMANTIC_CLASSES

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
    "shapely",
)


def dependency_versions() -> dict[str, str]:
    out = {}
    for name in DEPENDENCIES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def global_topic(name: str) -> schema.Topic:
    for t in schema.GLOBAL_TOPICS:
        if t.name == name:
            return t
    raise KeyError(name)


def camera_tf(camera: CameraModel, stamp_ns: int = 0) -> Any:
    """The static transform message map -> camera optical frame (header stamp ``stamp_ns``)."""
    return M.transform_stamped(stamp_ns, schema.MAP_FRAME, camera.frame_id, camera.world_from_camera)


class Publisher:
    """Writes everything a run publishes besides camera images (see camera_recording.py).

    Methods take simulated time ``t`` (the writer adds the epoch to the log time); header stamps
    are bag time, ``writer.stamp_ns(t)`` (recording/timebase.py).
    """

    def __init__(self, writer: RecordingWriter, cfg: Config, agents: list[Agent]) -> None:
        self.writer, self.cfg = writer, cfg
        self.agents = agents
        self.topics = {a.namespace: schema.agent_topics(a.namespace) for a in agents}
        self.odom: dict[str, Transform] = {}
        self._goal_index: dict[str, int] = {}
        self._status: dict[str, tuple] = {}

    def static(self, *, config_yaml: str, renderer: str, cameras: list[CameraModel]) -> None:
        cfg, w = self.cfg, self.writer
        w.write(global_topic(schema.CONFIG), 0, M.string(config_yaml))
        renderer_info = f"{'layered' if cfg.render.layered else 'full'}; distortion {'on' if cfg.cameras.distortion else 'off'}; near {cfg.cameras.near_m} m"
        w.write(
            global_topic(schema.RUN_INFO),
            0,
            M.run_info(
                format_version=FORMAT_VERSION,
                version=__version__,
                scenario=cfg.scenario.name,
                seed=cfg.seed,
                renderer=renderer,
                renderer_info=renderer_info,
                dependencies=dependency_versions(),
            ),
        )
        w.write(global_topic(schema.SEMANTIC_LABELS), 0, M.semantic_labels(dict(SEMANTIC_CLASSES)))
        start = w.stamp_ns(0)
        static = [camera_tf(c, start) for c in cameras]
        for agent in self.agents:
            pose = agent.pose()
            self.odom[agent.namespace] = Transform.from_pose2d(
                float(pose.translation[0]), float(pose.translation[1]), pose.yaw()
            )
            static.append(
                M.transform_stamped(
                    start, schema.MAP_FRAME, schema.odom_frame(agent.namespace), self.odom[agent.namespace]
                )
            )
        w.write(global_topic(schema.TF_STATIC), 0, M.tf_message(static))

    def ground_truth(self, t: int) -> None:
        stamp = self.writer.stamp_ns(t)
        self.writer.write(global_topic(schema.CLOCK), t, M.clock(stamp))
        # each agent's own ground-truth frame: <ns>/base_link's parent is <ns>/odom (/tf)
        poses = [
            M.transform_stamped(stamp, schema.MAP_FRAME, schema.ground_truth_frame(a.namespace), a.pose())
            for a in self.agents
        ]
        self.writer.write(global_topic(schema.GROUND_TRUTH_POSES), t, M.tf_message(poses))

    def detections(
        self,
        t: int,
        camera: CameraModel,
        detections: list[Detection],
        mode: str,
        *,
        stamp_ns: int | None = None,
    ) -> None:
        """The markers found in a camera's image; ``stamp_ns``: the image's stamp (its camera's clock)."""
        topic = schema.camera_topics(camera.camera_id, rgb="jpeg", depth=None, semantic=None)["detections"]
        corners = [d.corners_px for d in detections]
        header_ns = self.writer.stamp_ns(t if stamp_ns is None else stamp_ns)
        self.writer.write(
            topic,
            t,
            M.marker_detections(header_ns, camera.frame_id, [d.marker_id for d in detections], corners, mode),
        )

    def camera_effects(self, t: int, camera: CameraModel, shot: Capture, sensor: CameraSensor) -> None:
        """What the camera stage did to this frame (only when sensors are not ideal)."""
        if not sensor.cfg.active:
            return
        topic = schema.camera_topics(camera.camera_id, rgb="jpeg", depth=None, semantic=None)["effects"]
        build = functools.partial(
            M.camera_effects,
            self.writer.stamp_ns(shot.exposed_ns),
            camera.frame_id,
            self.writer.stamp_ns(shot.stamp_ns),
            dropped=shot.dropped,
            noise_phase=shot.noise_phase,
            exposure_scale=shot.exposure_scale,
            gain=shot.gain,
            illumination=shot.light,
            true_pose=sensor.true_camera.world_from_camera,
            exposure_time_s=sensor.exposure_time_s() if sensor.cfg.shutter.enabled else 0.0,
            line_time_s=sensor.cfg.shutter.line_time_s if sensor.cfg.shutter.enabled else 0.0,
            subframes=shot.subframes,
            delay_s=(t - shot.exposed_ns) / 1e9,
        )
        self.writer.submit(topic, t, build)  # built and serialized on a worker thread

    def command(self, t: int, ns: str, v: float, w: float, collision: CollisionReading) -> None:
        topics, frame, stamp = self.topics[ns], schema.base_link_frame(ns), self.writer.stamp_ns(t)
        self.writer.write(topics["cmd_vel"], t, M.twist_stamped(stamp, frame, v, w))
        self.writer.write(
            topics["collision"],
            t,
            M.collision_state(
                stamp,
                frame,
                in_collision=collision.in_collision,
                max_force_n=collision.max_force_n,
                total_force_n=collision.total_force_n,
                others=collision.others,
            ),
        )

    def estimates(self, t: int, estimates: dict[str, PoseEstimate], tracked: list[str]) -> None:
        tfs, stamp = [], self.writer.stamp_ns(t)
        for ns in tracked:
            e = estimates.get(ns)
            self.writer.write(
                self.topics[ns]["localization"],
                t,
                M.localization_status(
                    stamp,
                    observed=e is not None and e.observed,
                    valid=e is not None and e.valid,
                    fix_age_s=e.age_s if e is not None else -1.0,
                    cameras=e.cameras if e is not None else (),
                ),
            )
            if e is None or not e.valid:
                continue
            self.writer.write(
                self.topics[ns]["pose_estimate"],
                t,
                M.pose_with_covariance(stamp, schema.MAP_FRAME, e.x_m, e.y_m, e.yaw_rad, e.covariance),
            )
            self.writer.write(
                self.topics[ns]["velocity_estimate"],
                t,
                M.twist_stamped(stamp, schema.base_link_frame(ns), e.speed_mps, e.yaw_rate_rps),
            )
            odom_from_base = self.odom[ns].inverse() @ Transform.from_pose2d(e.x_m, e.y_m, e.yaw_rad)
            tfs.append(
                M.transform_stamped(stamp, schema.odom_frame(ns), schema.base_link_frame(ns), odom_from_base)
            )
        if tfs:
            self.writer.write(global_topic(schema.TF), t, M.tf_message(tfs))

    def navigation(self, t: int, ns: str, nav: Navigator, blocked_by: tuple[str, ...]) -> None:
        """The control tick's plan, goal and navigation status (when changed) of one robot."""
        nav.clock(t)
        topics, stamp = self.topics[ns], self.writer.stamp_ns(t)
        if nav.new_plan and nav.plan is not None:
            self.writer.write(topics["plan"], t, M.path(stamp, schema.MAP_FRAME, nav.plan.points_xy.tolist()))
            nav.new_plan = False
        goal = nav.goal
        if goal is not None and self._goal_index.get(ns) != nav.index:
            self._goal_index[ns] = nav.index
            self.writer.write(
                topics["goal"],
                t,
                M.pose_stamped(stamp, schema.MAP_FRAME, float(goal[0]), float(goal[1]), 0.0),
            )
        s = nav.status
        key = (s.state, nav.index, s.goals_reached, s.goals_failed, blocked_by)
        if self._status.get(ns) != key:
            self._status[ns] = key
            self._navigation_status(t, ns, nav, s.state, s.goals_failed, blocked_by)

    def navigation_end(self, t: int, navigators: dict[str, Navigator]) -> None:
        """The run ends at ``t``: the goals each robot has left fail (blocked or timeout), one
        status per reason, so that the recording says why every goal not reached was not."""
        for ns, nav in navigators.items():
            failed = nav.status.goals_failed
            for reason, count in nav.finish(t):
                failed += count
                self._navigation_status(t, ns, nav, FAILED_STATE_PREFIX + reason, failed, ())

    def _navigation_status(
        self, t: int, ns: str, nav: Navigator, state: str, goals_failed: int, blocked_by: tuple[str, ...]
    ) -> None:
        s = nav.status
        self.writer.write(
            self.topics[ns]["navigation"],
            t,
            M.navigation_status(
                self.writer.stamp_ns(t),
                state=state,
                goal_index=nav.index,
                goals_total=s.goals_total,
                goals_reached=s.goals_reached,
                goals_failed=goals_failed,
                planned_length_m=s.planned_length_m,
                blocked_by=blocked_by,
            ),
        )

    # ------------------------------------------------------------------------------ safety
    def safety_zones(self, zones: tuple[Zone, ...]) -> None:
        """The restricted areas, once at the start (they do not change during a run)."""
        self.writer.write(
            global_topic(schema.SAFETY_ZONES),
            0,
            M.zone_markers(self.writer.stamp_ns(0), [(z.name, z.points) for z in zones]),
        )

    def safety(
        self, t: int, states: dict[str, tuple[SafetyDecision, Monitor]], events: list[SafetyEvent]
    ) -> None:
        """New safety events, and every guarded robot's state (decision and monitor values)."""
        stamp = self.writer.stamp_ns(t)
        for ev in events:
            self.writer.write(
                global_topic(schema.SAFETY_EVENTS), t, safety_event_msg(ev, self.writer.stamp_ns(ev.stamp_ns))
            )
        for ns, (decision, mon) in states.items():
            self.writer.write(
                self.topics[ns]["safety_state"],
                t,
                M.safety_state(
                    stamp,
                    state=decision.state,
                    cause=decision.cause,
                    speed_limit_mps=decision.speed_limit_mps,
                    min_ttc_s=mon.min_ttc_s,
                    cpa_m=mon.cpa_m,
                    nearest_m=mon.nearest_m,
                    nearest=mon.nearest,
                    zone_clearance_m=mon.zone_clearance_m,
                ),
            )

    def people(self, t: int, positions: list[tuple[float, float]]) -> None:
        self.writer.write(
            global_topic(schema.PEOPLE_DETECTIONS),
            t,
            M.pose_array(self.writer.stamp_ns(t), schema.MAP_FRAME, positions),
        )


def safety_event_msg(ev: SafetyEvent, stamp_ns: int) -> Any:
    """The message of ``ev``, header stamp ``stamp_ns`` (bag time)."""
    return M.safety_event(
        stamp_ns,
        namespace=ev.namespace,
        cause=ev.cause,
        action=ev.action,
        pose=ev.pose,
        pose_valid=ev.pose is not None and ev.pose_valid,
        speed_mps=ev.speed_mps,
        other=ev.other,
        detail=ev.detail,
    )
