"""Run a scenario on the simulated clock and record it.

One physics step at a time (``world.physics_hz``); every rate is a whole number of steps::

    step k, t = k / physics_hz
      truth tick     /clock, /ground_truth/poses
      control tick   posed humanoid: targets (motion / drive) -> joints -> /<ns>/joint_states
      camera tick    layered render per camera -> encode (workers) -> bag
                     JPEG -> decode, marker search (workers, while the next cameras render)
                          -> localizer (in camera order: poses, fuse) -> /camera_<id>/marker_detections
                     segmentation -> person detector -> /people/detections
                     (posemap.landmarks_rate_hz) projection estimator -> /camera_<id>/pose_landmarks
      control tick   collision sensing; estimates -> coordinator + safety trees -> navigators
                     -> cmd_vel (after the safety layer) -> wheel motors; /tf, /<ns>/pose_estimate,
                     plan, goal, status, /safety/events, /<ns>/safety_state
                     (every n-th: all frames -> bird's-eye stitcher -> JPEG -> /birdseye/image)
      physics step
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from simlan_data import __version__
from simlan_data.algorithms import registry
from simlan_data.algorithms.localization import ImageSearch
from simlan_data.algorithms.roles import CameraFrame
from simlan_data.algorithms.stack import AgentPlan, ControlOutput, GpssStack, NavigationParams
from simlan_data.config.algorithms import selected_algorithm
from simlan_data.config.faults import CameraFaults
from simlan_data.config.schema import Config
from simlan_data.constants import FORMAT_VERSION, NS_PER_S
from simlan_data.errors import PluginError
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording import messages as M
from simlan_data.recording.cameras import camera_from_messages
from simlan_data.recording.writer import NullWriter, RecordingWriter, WriteListener
from simlan_data.sim.agent_base import CollisionReading
from simlan_data.sim.birdseye_live import BirdseyeRecorder
from simlan_data.sim.camera_recording import CameraRecorder
from simlan_data.sim.dynamic_layer import MovedAgents
from simlan_data.sim.exposures import Exposed, ExposureSchedule
from simlan_data.sim.instances import INSTANCE_STREAM, InstanceRecorder, people_instances
from simlan_data.sim.posemap_drive import PoseDriver, make_driver
from simlan_data.sim.publishing import Publisher, camera_tf
from simlan_data.sim.rendering import CameraImages
from simlan_data.sim.scene import Inputs, Scene
from simlan_data.sim.sensors import CameraSensor, camera_sensors
from simlan_data.sim.shutter import expose
from simlan_data.sim.trajectory_drive import TrajectoryDriver, make_trajectory_driver
from simlan_data.world._pybullet import pb


@dataclass
class RunStats:
    """What a run measured besides what the recording holds; part of metrics.json."""

    sim_duration_ns: int = 0
    wall_s: float = 0.0
    cameras: int = 0
    cpu_s: float = 0.0  # CPU time of the whole process (every thread) during the loop
    main_cpu_s: float = 0.0  # CPU time of the simulation thread during the loop
    physics_steps: int = 0
    camera_frames: int = 0
    camera_frames_changed: int = 0
    camera_frames_dropped: int = 0  # lost by the camera stage (sensors.timing.drop_rate)
    camera_subframes: int = 0  # camera ticks' renders of every camera (> ticks: motion blur, sensors.shutter)
    render_wall_s: float = 0.0
    localize_wall_s: float = 0.0
    renderer: str = ""
    collisions: dict[str, int] = field(default_factory=dict)
    distance_m: dict[str, float] = field(default_factory=dict)
    message_counts: dict[str, int] = field(default_factory=dict)
    byte_counts: dict[str, int] = field(default_factory=dict)
    calibration_issues: list[str] = field(default_factory=list)
    layout_notes: list[str] = field(default_factory=list)
    navigation: dict[str, object] = field(default_factory=dict)  # namespace -> NavigationStatus
    recording_bytes: int = 0
    extra_metrics: dict[str, float] = field(default_factory=dict)  # e.g. posemap.drive.*
    stopped_early: bool = False  # ``stop()`` ended the loop before ``duration_s`` (a signal)

    def metrics(self) -> dict[str, float]:
        sim_s = self.sim_duration_ns / NS_PER_S
        out: dict[str, float] = {
            "sim.rtf": sim_s / self.wall_s if self.wall_s > 0 else 0.0,
            "sim.duration_s": sim_s,
            "sim.cameras": float(self.cameras),
            "sim.wall_s": self.wall_s,
            "sim.cpu_s": self.cpu_s,
            "sim.main_thread_cpu_s": self.main_cpu_s,
            "sim.physics_steps": float(self.physics_steps),
            "sim.camera_frames": float(self.camera_frames),
            "sim.camera_frames_changed": float(self.camera_frames_changed),
            "sim.camera_frames_dropped": float(self.camera_frames_dropped),
            "sim.camera_subframes": float(self.camera_subframes),
            "sim.render_wall_s": self.render_wall_s,
            "sim.localize_wall_s": self.localize_wall_s,
            "agents.collisions": float(sum(self.collisions.values())),
            "recording.bytes": float(self.recording_bytes),
            "recording.messages": float(sum(self.message_counts.values())),
        }
        for ns in sorted(self.collisions):
            out[f"agents.{ns}.collisions"] = float(self.collisions[ns])
            out[f"agents.{ns}.distance_m"] = round(self.distance_m.get(ns, 0.0), 6)
        out.update(self.extra_metrics)
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

    def run(
        self,
        bag_path: Path,
        *,
        progress: Callable[[float], None] | None = None,
        stop: Callable[[], bool] | None = None,
        listeners: Sequence[WriteListener] = (),
    ) -> RunStats:
        """Simulate ``duration_s`` and write the bag at ``bag_path`` (which must not exist).

        ``stop()`` is asked at every step boundary; once it says yes the loop ends there and the
        recording is finished as after a complete run (``stats.stopped_early``). ``listeners``
        get every message the recording writes (``RecordingWriter.add_listener``: a live view).
        """
        cfg = self.cfg
        stats = RunStats(
            calibration_issues=list(self.inputs.calibration_issues), cameras=len(self.inputs.cameras)
        )
        scene = Scene.build(cfg, self.inputs)
        stats.renderer = scene.client.backend
        stats.layout_notes = list(scene.world.layout_conflicts)
        failed: PluginError | None = None
        try:
            writer = (
                RecordingWriter(
                    bag_path,
                    compression=cfg.recording.compression,
                    compression_level=cfg.recording.compression_level,
                    flush_period_ns=int(cfg.recording.flush_period_s * NS_PER_S),
                    encode_threads=cfg.recording.encode_threads,
                    fsync=cfg.recording.fsync,
                    epoch_ns=cfg.recording.epoch_ns,
                )
                if cfg.recording.enabled
                else NullWriter()
            )
            for listener in listeners:
                writer.add_listener(listener)
            with writer:
                for key, value in (
                    ("format_version", FORMAT_VERSION),
                    ("version", __version__),
                    ("seed", str(cfg.seed)),
                    ("scenario", cfg.scenario.name),
                    ("renderer", scene.client.backend),
                ):
                    writer.set_metadata(f"simlan.{key}", value)
                # set up before the clock starts, like the scene (lookup tables take a second or two)
                self.birdseye = BirdseyeRecorder.create(writer, cfg, scene.cameras)
                # and the camera stage (its noise bank: a few tenths of a second with sensors on)
                true_cameras = [r.camera for r in scene.renderers]  # (drifted once, by the scene)
                sensors = camera_sensors(cfg.sensors, cfg.seed, scene.cameras, true_cameras)
                wall0, cpu0, main0 = time.perf_counter(), time.process_time(), time.thread_time()
                try:
                    self._loop(scene, writer, stats, sensors, progress, stop)
                except PluginError as err:  # the recording up to the failure is finished and kept
                    failed = err
                stats.wall_s = time.perf_counter() - wall0
                stats.main_cpu_s = time.thread_time() - main0
            stats.cpu_s = time.process_time() - cpu0  # after the writer drained its queue
            stats.message_counts = dict(writer.message_counts)
            stats.byte_counts = dict(writer.byte_counts)
            if cfg.recording.enabled:
                stats.recording_bytes = sum(f.stat().st_size for f in bag_path.iterdir() if f.is_file())
        finally:
            scene.close()
        if failed is not None:
            raise failed
        return stats

    def _stack(self, scene: Scene) -> GpssStack:
        """The GPSS algorithms, on camera models rebuilt from the messages the bag holds (as replay does)."""
        cfg = self.cfg
        cameras = {
            c.camera_id: camera_from_messages(M.camera_info(0, c), camera_tf(c).transform, c.camera_id)
            for c in scene.cameras
        }
        # injected faults (V&V): the localizer loses cameras or believes a wrong calibration
        cameras = CameraFaults.from_settings({"faults": asdict(cfg.faults)}).apply(
            cameras, where="config faults"
        )
        plans = [
            AgentPlan(
                a.namespace,
                a.number,
                self.inputs.agent_types[a.namespace],
                a.marker_id,
                [list(g) for g in a.goals],
                a.speed_mps,
                a.loop,
                (float(a.pose[0]), float(a.pose[1]), float(a.pose[2])),
            )
            for a in cfg.agent_list
        ]
        nav = cfg.navigation
        loc = cfg.localization
        return GpssStack(
            plans,
            cameras,
            self.inputs.grid,
            nav=NavigationParams(
                nav.clearance_m,
                nav.lookahead_m,
                nav.goal_tolerance_m,
                nav.max_yaw_rate_rps,
                nav.coordination,
                nav.safety_distance_m,
                nav.unseen_cost,
            ),
            localizer=self._factory("localizer"),
            coordinator=self._factory("coordinator"),
            source=loc.source,
            safety=self._factory("safety"),
            people=cfg.people,
            control_period_s=1.0 / cfg.control_rate_hz,
            camera_period_s=1.0 / cfg.cameras.rate_hz,
            processing_delay_s=float(getattr(cfg.algorithms.localizer, "processing_delay_s", 0.0)),
        )

    def _factory(self, role: str) -> Callable[[Any], Any]:
        """Build the selected algorithm of ``role`` from its own config, as the replay does
        (guarded: an exception inside it names it and the simulated time)."""
        spec, config = selected_algorithm(self.cfg.algorithms, role)
        return lambda ctx: registry.Guarded(spec.build(config, ctx), spec)

    def _search(
        self,
        stack: GpssStack,
        writer: RecordingWriter,
        camera: CameraModel,
        plan: str | list,
        images: CameraImages,
        encoded: Any,
    ) -> Future[ImageSearch]:
        """Search one image for markers, on an encoder thread when there is one.

        The localizer sees what the bag holds (the decoded JPEG, which the encoder thread
        decodes right after encoding it), so replay reproduces it; the search runs while the
        simulation thread renders the next cameras, and its result is taken in camera order.
        """
        localizer, cid = stack.localizer, camera.camera_id

        def search() -> ImageSearch:
            rgb = encoded.result() if encoded is not None else None
            if rgb is not None:
                return localizer.detect(cid, plan, jpeg=rgb.data, gray=rgb.gray)
            gray = np.asarray(cv2.cvtColor(np.asarray(images.rgb), cv2.COLOR_RGB2GRAY), dtype=np.uint8)
            return localizer.detect(cid, plan, gray=gray)

        if self.cfg.recording.enabled:
            return writer.run_async(search)  # type: ignore[return-value]
        done: Future[ImageSearch] = Future()
        done.set_result(search())
        return done

    def _frame(self, t_ns: int, camera_id: str, images: CameraImages, encoded: Any) -> CameraFrame:
        """A camera's frame as the bag holds it (the JPEG the recorder wrote), for a localizer
        without the searching protocol; the replay hands it the same bytes."""
        rgb = encoded.result() if encoded is not None else None
        if rgb is not None and rgb.format == "jpeg":
            return CameraFrame(camera_id, t_ns, bytes(rgb.data))
        quality = [cv2.IMWRITE_JPEG_QUALITY, self.cfg.recording.jpeg_quality]
        _ok, data = cv2.imencode(".jpg", cv2.cvtColor(np.asarray(images.rgb), cv2.COLOR_RGB2BGR), quality)
        return CameraFrame(camera_id, t_ns, data.tobytes())

    # --------------------------------------------------------------------------- the loop
    def _loop(
        self,
        scene: Scene,
        writer: RecordingWriter,
        stats: RunStats,
        sensors: list[CameraSensor],
        progress: Callable[[float], None] | None,
        stop: Callable[[], bool] | None,
    ) -> None:
        """Step the scene ``steps`` times, running each tick whose rate divides the step."""
        run = self._start(scene, writer, stats, sensors)
        dt_control = self.control_every / self.physics_hz
        last = self.steps
        for step in range(self.steps + 1):
            if stop is not None and stop():
                last, stats.stopped_early = max(step - 1, 0), True
                break
            t = self.stamp_ns(step)
            if run.tracks is not None:  # replayed trajectories: where the tracker saw them at t
                run.tracks.place(t)
            if step % self.truth_every == 0:
                run.pub.ground_truth(t)
            if run.driver is not None and step % self.control_every == 0:
                run.driver.control_tick(t)  # before the cameras: the images at t show the pose at t
            if run.schedule is not None:  # late cameras expose now, their frames wait for their tick
                for camera, delivery in run.schedule.exposing(step):
                    self._expose_one(run, camera, delivery, step)
            if step % self.camera_every == 0:
                self._camera_tick(run, step, t)
                if progress is not None:
                    progress(t / NS_PER_S)
            if step % self.control_every == 0:
                self._control_tick(run, t, dt_control)
            if step < self.steps:
                self._physics_step(run)
        stats.sim_duration_ns = self.stamp_ns(last)
        run.pub.navigation_end(stats.sim_duration_ns, run.stack.navigators)  # goals left: why not reached
        if run.driver is not None:
            stats.extra_metrics.update(run.driver.finish())
        stats.navigation = {ns: nav.status for ns, nav in run.stack.navigators.items()}
        self.stack = run.stack

    def _start(
        self, scene: Scene, writer: RecordingWriter, stats: RunStats, sensors: list[CameraSensor]
    ) -> _Run:
        """Publish the static messages and set up the stack, the recorders and the counters."""
        cfg = self.cfg
        pub = Publisher(writer, cfg, scene.agents)
        pub.static(config_yaml=self.config_yaml, renderer=scene.client.backend, cameras=scene.cameras)
        if scene.randomizer is not None:  # what randomize drew (once; randomize=off: nothing)
            scene.randomizer.publish(writer)
        stack = self._stack(scene)
        pub.safety_zones(getattr(stack.safety, "zones", ()))  # a monitor's restricted areas, if it has any
        recorder = CameraRecorder(
            writer,
            cfg.recording,
            list(cfg.cameras.streams),
            depth_every=self.depth_every,
            semantic_every=self.semantic_every,
            decode_gray=stack.source == "camera",
        )
        for a in scene.agents:
            stats.collisions[a.namespace] = 0
            stats.distance_m[a.namespace] = 0.0
        in_contact = {a.namespace: False for a in scene.agents}
        last_xy = {a.namespace: a.pose().translation[:2].copy() for a in scene.agents}
        driver = make_driver(cfg, scene.agents, writer, self.inputs.posemap)  # motion files or the drive
        run = _Run(scene, writer, stats, pub, stack, recorder, driver, in_contact, last_xy, sensors, {})
        if cfg.sensors.lagged:  # frames show the scene before their tick: keep the agents' past
            lag = cfg.sensors.timing.max_lag_s
            run.schedule = ExposureSchedule(sensors, self.camera_every, self.physics_hz, lag)
            if scene.moved is not None:
                run.drawn = [MovedAgents(scene.agents) for _ in scene.renderers]
        run.tracks = make_trajectory_driver(cfg, scene.agents)
        if INSTANCE_STREAM in cfg.cameras.streams:
            run.instances = InstanceRecorder(
                writer,
                scene.client.id,
                scene.instances,
                people=people_instances(scene.agents, scene.instances),
                depth={c.camera_id: r for c, r in zip(scene.cameras, scene.renderers, strict=True)},
            )
        return run

    def _camera_tick(self, run: _Run, step: int, t: int) -> None:
        """Render and record every camera, then localize and detect people on the frames."""
        render0 = time.perf_counter()
        frames = self._render(run, step, t)
        loc0 = time.perf_counter()
        run.stats.render_wall_s += loc0 - render0
        self._localize(run, t, frames)
        run.stats.localize_wall_s += time.perf_counter() - loc0

    def _render(self, run: _Run, step: int, t: int) -> list[_Frame]:
        """Render, pass through the camera stage, record and start searching each camera; feed the
        bird's-eye stitcher and the driver."""
        scene, stats, stack = run.scene, run.stats, run.stack
        if run.schedule is not None:  # late cameras: rendered when they exposed (_expose_one)
            held = run.schedule.deliver(step)
            rendered, counts = [f.images for f in held], [f.subframes for f in held]
            lags = [run.schedule.lag_ns(f, step) for f in held]
            subframes = max(counts, default=1)
        else:
            scene.refresh_static_layers()

            def render_all() -> list[CameraImages]:
                moved = scene.moved_boxes()
                return [renderer.render(moved) for renderer in scene.renderers]

            # the agents' motion within each camera's exposure (sensors.shutter), or one render
            exposures = [sensor.exposure_time_s() for sensor in run.sensors]
            rendered, subframes = expose(
                self.cfg.sensors.shutter, scene.agents, scene.cameras, exposures, render_all
            )
            counts, lags = [subframes] * len(rendered), [0] * len(rendered)
        stats.camera_subframes += subframes
        if run.instances is not None:  # 3D boxes as the scene stands at the tick
            run.instances.tick(t)
        frames = []
        index = step // self.camera_every
        for images, camera, sensor, k, lag in zip(
            rendered, scene.cameras, run.sensors, counts, lags, strict=True
        ):
            stats.camera_frames += 1
            stats.camera_frames_changed += int(images.changed)
            shot = sensor.capture(t, index, images, subframes=k, lag_ns=lag)
            run.pub.camera_effects(t, camera, shot, sensor)
            if shot.dropped:
                stats.camera_frames_dropped += 1
                continue
            run.delivered[camera.camera_id] = shot.images
            encoded = run.recorder.record(
                t, index, camera, shot.images, stamp_ns=shot.stamp_ns, phase=shot.noise_phase
            )
            if run.instances is not None:
                run.instances.record(t, camera, shot.images, stamp_ns=shot.stamp_ns)
            plan = stack.search_plan(shot.stamp_ns, camera.camera_id)
            search = (
                None if plan is None else self._search(stack, run.writer, camera, plan, shot.images, encoded)
            )
            frames.append(_Frame(camera, shot.images, plan, search, encoded, shot.stamp_ns))
        if self.birdseye is not None:  # a lost frame: the stitcher keeps the camera's last image
            # (a camera that has delivered none yet: black, what a stitcher has of it)
            last = [
                run.delivered.get(c.camera_id) or CameraImages(np.zeros_like(im.rgb), None, None)
                for c, im in zip(scene.cameras, rendered, strict=True)
            ]
            self.birdseye.tick(t, index, last)
        if run.driver is not None:
            run.driver.camera_tick(t, index, [(f.camera, f.images) for f in frames])
        return frames

    def _expose_one(self, run: _Run, i: int, delivery: int, step: int) -> None:
        """Late camera ``i`` exposes now (its frame for the tick at ``delivery``): render it as the
        scene is (over its exposure: sensors.shutter) and hold it until then. It redraws what moved
        since it last drew (its own tracker: the cameras draw at different steps)."""
        assert run.schedule is not None
        scene, renderer = run.scene, run.scene.renderers[i]
        scene.refresh_static_layers()

        def render() -> list[CameraImages]:
            return [renderer.render(run.drawn[i].boxes() if run.drawn else scene.agent_aabbs())]

        exposure = run.sensors[i].exposure_time_s()
        (images,), k = expose(self.cfg.sensors.shutter, scene.agents, [scene.cameras[i]], [exposure], render)
        run.schedule.hold(i, delivery, Exposed(images, step, k))

    def _localize(self, run: _Run, t: int, frames: list[_Frame]) -> None:
        """Hand the frames to the localizer and person detector in camera order; publish detections."""
        stack, pub = run.stack, run.pub
        for f in frames:
            camera = f.camera
            # (one decoded frame for the localizer and the RGB person detector: the recorded JPEG)
            wants = stack.wants_frames(camera.camera_id) or stack.people_reads == "rgb"
            frame = self._frame(f.stamp_ns, camera.camera_id, f.images, f.encoded) if wants else None
            if f.plan is not None and f.search is not None:
                found = f.search.result()
                mode = stack.camera_detections(f.stamp_ns, camera.camera_id, f.plan, found)
                pub.detections(t, camera, found.detections, mode, stamp_ns=f.stamp_ns)
            elif frame is not None and stack.wants_frames(camera.camera_id):
                stack.camera_image(frame)
            stack.people_frame(camera.camera_id, f.images.labels, frame)
        stack.close_camera_tick(t)
        if stack.last_people is not None:
            pub.people(t, stack.last_people)

    def _control_tick(self, run: _Run, t: int, dt_control: float) -> None:
        """Sense poses and contacts, run the stack, drive the wheels and publish the tick."""
        truth = self._truth(run)
        # sensed before the control step: the safety trees read this tick's contacts
        scene, stack, pub = run.scene, run.stack, run.pub
        hits = {agent.namespace: agent.collisions(scene.world.floor, scene.names) for agent in scene.agents}
        contacts = {ns: (hit.max_force_n, tuple(hit.others)) for ns, hit in hits.items()}
        n_events = len(stack.safety_events)
        out = stack.control(t, dt_control, truth, contacts)
        if stack.source == "camera":
            pub.estimates(t, out.estimates, stack.localized)
        pub.safety(t, stack.safety_states(), stack.safety_events[n_events:])
        self._drive(run, t, out, hits)

    def _truth(self, run: _Run) -> dict[str, tuple[float, float, float]]:
        """Read every agent's true pose and add the distance it moved since the last control tick."""
        truth = {}
        for agent in run.scene.agents:
            pose = agent.pose()
            truth[agent.namespace] = (float(pose.translation[0]), float(pose.translation[1]), pose.yaw())
            xy = pose.translation[:2]
            run.stats.distance_m[agent.namespace] += float(np.linalg.norm(xy - run.last_xy[agent.namespace]))
            run.last_xy[agent.namespace] = xy.copy()
        return truth

    def _drive(self, run: _Run, t: int, out: ControlOutput, hits: dict[str, CollisionReading]) -> None:
        """Apply each agent's command to its wheels, count new collisions, publish command and plan."""
        stack, pub, stats = run.stack, run.pub, run.stats
        tracked = {} if run.tracks is None else run.tracks.commands(t)  # the tracker moves these
        for agent in run.scene.agents:
            ns = agent.namespace
            v, w = agent.apply_command(*out.commands.get(ns, (0.0, 0.0)))
            v, w = tracked.get(ns, (v, w))
            stack.localizer.command(t, ns, v, w)
            hit = hits[ns]
            if hit.in_collision and not run.in_contact[ns]:
                stats.collisions[ns] += 1
            run.in_contact[ns] = hit.in_collision
            pub.command(t, ns, v, w, hit)
            nav = stack.navigators.get(ns)
            if nav is not None:
                decision = out.decisions.get(ns)
                pub.navigation(t, ns, nav, decision.blocked_by if decision is not None else ())

    def _physics_step(self, run: _Run) -> None:
        """Advance the agents' kinematics and the physics by one step."""
        for agent in run.scene.agents:
            agent.step_kinematics(1.0 / self.physics_hz)
        pb.stepSimulation(physicsClientId=run.scene.client.id)
        run.stats.physics_steps += 1


@dataclass
class _Frame:
    """One camera's frame in a camera tick: its images, its encoding and its marker search."""

    camera: CameraModel
    images: CameraImages
    plan: str | list | None
    search: Future[ImageSearch] | None
    encoded: Any
    stamp_ns: int  # the stamp the camera wrote (its clock: sensors.timing)


@dataclass
class _Run:
    """What the loop's ticks share: the scene, the bag, the stack, the recorders, the counters."""

    scene: Scene
    writer: RecordingWriter
    stats: RunStats
    pub: Publisher
    stack: GpssStack
    recorder: CameraRecorder
    driver: PoseDriver | None
    in_contact: dict[str, bool]
    last_xy: dict[str, np.ndarray]
    sensors: list[CameraSensor]  # the camera stage, per camera (sensors: ideal passes images through)
    delivered: dict[str, CameraImages]  # per camera, the last frame that was not lost
    schedule: ExposureSchedule | None = None  # late cameras: when each exposes (sensors.timing)
    drawn: list[MovedAgents] = field(default_factory=list)  # per camera: what it last drew (late cameras)
    tracks: TrajectoryDriver | None = None  # experiment=trajectory: agents on a tracker's trajectories
    instances: InstanceRecorder | None = None  # stream instance: instance images, 2D and 3D boxes
