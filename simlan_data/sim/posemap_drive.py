"""Pose a humanoid during a run: from motion files, or from a landmark stream through a pose mapper.

    posemap.motion=[...]            keyframes (SIMLAN motion files), each held then blended over
                                    posemap.motion_period_s, in turn
    posemap.drive=SOURCE            landmark frames (a dataset, or a recording's
                                    /camera_<id>/pose_landmarks) --> the pose mapper algorithms.posemap
                                    (the built-in ``trained``: algorithms.posemap.model=MODEL) -->
                                    joint targets, frame k at k / cameras.rate_hz (dataset) or at its
                                    recorded stamp
    posemap.source=FILE             a video, an image or a folder of images --> MediaPipe Pose per
                                    frame (:mod:`~simlan_data.algorithms.posemap.source`) --> the same
                                    pose mapper (one camera's) --> joint targets, frame k at k / fps;
                                    a frame without a person holds the last pose

The pose mapper is built through the registry (:mod:`simlan_data.algorithms.registry`) from its
own config, as the ``posemap`` replay builds it from a recording's, with the landmark source's
cameras as its context; an exception inside it names it (``Guarded``, exit 1).

Every control tick the posed humanoid ``posemap.namespace`` takes its targets and its joint
positions are recorded on ``/<ns>/joint_states`` (sensor_msgs/JointState). With
``posemap.landmarks_rate_hz > 0`` the projection estimator runs on the rendered camera frames and
publishes ``/camera_<id>/pose_landmarks`` (a landmark stream a later drive can replay). The
drive's input landmarks are published on the same topics (estimator ``replay``); a
``posemap.source``'s frames and landmarks on ``/posemap/source/...`` (they are not the twin's cameras).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms import registry
from simlan_data.algorithms.posemap.config import TrainedMapperParams
from simlan_data.algorithms.posemap.estimators import CameraView, MediaPipeEstimator, ProjectionEstimator
from simlan_data.algorithms.posemap.metrics import mpjpe
from simlan_data.algorithms.posemap.motion import load_motion
from simlan_data.algorithms.posemap.source import (
    FrameReader,
    SourceLandmarks,
    estimate_source,
    hold_undetected,
    open_frames,
)
from simlan_data.algorithms.roles import PosemapContext
from simlan_data.algorithms.trained_posemap import TrainedPoseMapper, camera_ids
from simlan_data.config.algorithms import selected_algorithm
from simlan_data.config.schema import Config
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.codecs import JPEG_FORMAT, encode_rgb
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.humanoid import PosedHumanoidAgent
from simlan_data.sim.posemap_inputs import LandmarkStream, load_stream, source_cameras, stream_from_source
from simlan_data.sim.rendering import CameraImages
from simlan_data.world.skeleton import JOINT_NAMES

# the scenario of conf/experiment/posemap_video.yaml, which needs posemap.source (a `???` there would
# not do: OmegaConf's merge keeps the schema's "" under a missing value)
VIDEO_SCENARIO = "posemap_video"
SOURCE_IMAGE = next(t for t in schema.GLOBAL_TOPICS if t.name == schema.POSEMAP_SOURCE_IMAGE)
SOURCE_LANDMARKS = next(t for t in schema.GLOBAL_TOPICS if t.name == schema.POSEMAP_SOURCE_LANDMARKS)


@dataclass
class DriveInputs:
    """What posing needs from files, read and checked before a run writes anything."""

    keys: NDArray[np.float64] | None = None  # motion keyframes (K, 47)
    stream: LandmarkStream | None = None
    predicted: NDArray[np.float64] | None = None  # the model's joint targets per stream frame
    predict_s: float = 0.0
    source: SourceLandmarks | None = None  # posemap.source: its frames and MediaPipe's landmarks


def selected_mapper(cfg: Config) -> tuple[registry.AlgorithmSpec, Any]:
    """The pose mapper ``algorithms.posemap`` and its checked config (a Config built without
    Hydra's defaults: the built-in with its defaults)."""
    return selected_algorithm(cfg.algorithms, "posemap")


def trained_mapper_params(cfg: Config) -> TrainedMapperParams:
    """The built-in mapper's config, which training reads (refine and the fit's parameters).

    Raises:
        ConfigError: another pose mapper is selected (training makes the built-in's models).
    """
    spec, config = selected_mapper(cfg)
    if not issubclass(spec.cls, TrainedPoseMapper):
        raise ConfigError(
            "posemap training trains the built-in pose mapper",
            f"algorithms/posemap={spec.name}",
            f"{spec.name} is not {registry.DEFAULTS['posemap']!r} (a model trained here, with its kinematic fit)",
            f"select algorithms/posemap={registry.DEFAULTS['posemap']} (or leave it out)",
        )
    return config


def build_mapper(cfg: Config, source: str) -> tuple[Any, list[str]]:
    """The selected pose mapper (guarded) with the landmark source's cameras, and the camera ids
    it reads (its ``cameras``, else all of them)."""
    spec, config = selected_mapper(cfg)
    context = PosemapContext(tuple(source_cameras(source)))
    mapper = registry.Guarded(spec.build(config, context, where="config algorithms.posemap"), spec)
    return mapper, camera_ids(mapper, context)


def load_drive_inputs(cfg: Config) -> DriveInputs | None:
    """Motion files, or the landmark source and the model (which predicts every frame now)."""
    pm = cfg.posemap
    if not (
        pm.drive or pm.source or pm.motion or pm.landmarks_rate_hz > 0 or cfg.scenario.name == VIDEO_SCENARIO
    ):
        return None
    agent = cfg.agents.get(pm.namespace)
    if agent is None or agent.type != "posed_humanoid":
        raise ConfigError(
            f"no posed humanoid {pm.namespace}",
            "posemap.namespace",
            "posemap.drive, posemap.source, posemap.motion and posemap.landmarks_rate_hz pose an agent of type posed_humanoid",
            "add one (agents=posed_humanoid) or set posemap.namespace",
        )
    if pm.landmarks_rate_hz > 0:
        every = cfg.cameras.rate_hz / pm.landmarks_rate_hz
        if every < 1 - 1e-9 or abs(every - round(every)) > 1e-9:
            raise ConfigError(
                f"invalid posemap.landmarks_rate_hz={pm.landmarks_rate_hz}",
                "config",
                f"must divide the camera rate cameras.rate_hz={cfg.cameras.rate_hz}",
                f"use e.g. {cfg.cameras.rate_hz:g}",
            )
    out = DriveInputs()
    if cfg.scenario.name == VIDEO_SCENARIO and not pm.source:
        raise ConfigError.invalid(
            "posemap.source",
            pm.source,
            f"experiment={VIDEO_SCENARIO} drives the humanoid from images or a video",
            "set posemap.source=FILE (a video, an image or a folder of images)",
        )
    if pm.drive or pm.source:
        # (the file first: a video that cannot be read says so before a model is loaded)
        frames = (
            open_frames(
                pm.source, fps=pm.source_fps, image_fps=cfg.cameras.rate_hz, duration_s=cfg.duration_s
            )
            if pm.source
            else None
        )
        mapper, cameras = build_mapper(cfg, pm.drive or pm.source)
        if frames is not None:
            out.source = source_landmarks(cfg, frames, cameras)
            out.stream = stream_from_source(out.source, cameras[0])
        else:
            out.stream = load_stream(
                pm.drive, cameras, period_ns=round(NS_PER_S / cfg.cameras.rate_hz), namespace=pm.namespace
            )
        t0 = time.perf_counter()
        # (a source's frames without a person are not mapped: the humanoid holds the last pose)
        landmarks = out.stream.landmarks if out.source is None else out.stream.landmarks[out.source.detected]
        # rig features are in the frame of the source's person (where it stood), not the driven one
        predicted = mapper.predict(landmarks, position=out.stream.position)
        out.predicted = check_targets(predicted, len(landmarks), "config algorithms.posemap")
        if out.source is not None:
            out.predicted = hold_undetected(out.predicted, out.source.detected)
        out.predict_s = time.perf_counter() - t0
    elif pm.motion:
        out.keys = np.stack([load_motion(m) for m in pm.motion])
    return out


def source_landmarks(cfg: Config, frames: FrameReader, cameras: list[str]) -> SourceLandmarks:
    """MediaPipe Pose on every frame of ``posemap.source``, each frame kept as the recorder's JPEG."""
    check_one_camera(cfg, cameras)
    estimator = MediaPipeEstimator(cfg.posemap.mediapipe_python)
    try:
        return estimate_source(frames, estimator, lambda rgb: encode_rgb(rgb, "jpeg")[1])
    finally:
        estimator.close()


def check_one_camera(cfg: Config, cameras: list[str]) -> None:
    """An image or video source is one camera's view: the pose mapper must read one camera.

    Raises:
        ConfigError: it reads several (or none).
    """
    if len(cameras) == 1:
        return
    model = getattr(selected_mapper(cfg)[1], "model", "")
    raise ConfigError(
        "pose mapper reads several cameras",
        f"algorithms.posemap.model={model}" if model else "config algorithms.posemap",
        f"posemap.source is one camera's view; the mapper reads {len(cameras)} ({', '.join(cameras) or 'none'})",
        "train a one-camera model: experiment=posemap_train posemap.cameras=[502] posemap.features=image",
    )


def check_targets(predicted: Any, frames: int, where: str) -> NDArray[np.float64]:
    """A pose mapper's output as (frames, 47) joint targets; anything else is a ConfigError."""
    q = np.asarray(predicted)
    if q.dtype.kind != "f":  # (a float array stays as it is: the metrics see what it returned)
        q = q.astype(np.float64)
    if q.ndim == 1 and frames == 1:
        q = q[None]
    if q.shape != (frames, len(JOINT_NAMES)) or not np.isfinite(q).all():
        raise ConfigError(
            "pose mapper gave no joint targets",
            where,
            f"predict() of {frames} frames returned shape {q.shape}"
            + ("" if q.shape != (frames, len(JOINT_NAMES)) else " with non-finite values"),
            f"return ({frames}, {len(JOINT_NAMES)}) finite joint targets in radians",
        )
    return q


class PoseDriver:
    """Targets for the posed humanoid each control tick; records joint states and landmarks."""

    def __init__(
        self, cfg: Config, agent: PosedHumanoidAgent, writer: RecordingWriter, inputs: DriveInputs
    ) -> None:
        pm = cfg.posemap
        self.agent, self.writer = agent, writer
        self.topic = schema.agent_topics(agent.namespace)["joint_states"]
        self.frame_id = schema.base_link_frame(agent.namespace)
        self.keys = inputs.keys
        self.period_ns = round(pm.motion_period_s * NS_PER_S)
        self.stream = inputs.stream
        self.predicted = inputs.predicted
        self.source = inputs.source
        self.metrics: dict[str, float] = {}
        self._published_frame = -1
        if self.predicted is not None:
            self.metrics["posemap.drive.frames"] = float(len(self.predicted))
            self.metrics["posemap.drive.predict_ms_per_frame"] = (
                1e3 * inputs.predict_s / max(1, len(self.predicted))
            )
        if self.source is not None:
            self.metrics.update(self.source.metrics())
        self.estimator = ProjectionEstimator(seed=cfg.seed + 1) if pm.landmarks_rate_hz > 0 else None
        self.landmarks_every = (
            round(cfg.cameras.rate_hz / pm.landmarks_rate_hz) if pm.landmarks_rate_hz > 0 else 0
        )

    def targets(self, t_ns: int) -> NDArray[np.float64] | None:
        if self.stream is not None and self.predicted is not None:
            k = int(np.searchsorted(self.stream.stamps_ns, t_ns, side="right")) - 1
            return self.predicted[max(0, k)]
        if self.keys is not None:
            n = len(self.keys)
            phase = t_ns / self.period_ns
            k = int(phase) % n
            # hold each keyframe for half the period, blend to the next over the other half
            a = min(1.0, max(0.0, 2.0 * (phase - int(phase)) - 1.0))
            return (1 - a) * self.keys[k] + a * self.keys[(k + 1) % n]
        return None

    def control_tick(self, t_ns: int) -> None:
        q = self.targets(t_ns)
        if q is not None:
            self.agent.set_joints(q)
        self.writer.write(
            self.topic,
            t_ns,
            M.joint_state(
                self.writer.stamp_ns(t_ns), self.frame_id, JOINT_NAMES, self.agent.joint_positions()
            ),
        )
        self._publish_input(t_ns)

    def _publish_input(self, t_ns: int) -> None:
        """The drive's input landmarks, once per frame, on the cameras' landmark topics."""
        if self.stream is None:
            return
        k = int(np.searchsorted(self.stream.stamps_ns, t_ns, side="right")) - 1
        if k < 0 or k == self._published_frame:
            return
        self._published_frame = k
        if self.source is not None:
            self._publish_source(t_ns, k)
            return
        for c, cam in enumerate(self.stream.cameras):
            width, height = self.stream.sizes.get(cam, (0, 0))
            topic = schema.camera_topics(cam, rgb="jpeg", depth=None, semantic=None)["pose_landmarks"]
            self.writer.write(
                topic,
                t_ns,
                M.pose_landmarks(
                    self.writer.stamp_ns(t_ns),
                    schema.camera_frame(cam),
                    self.stream.landmarks[k, c],
                    estimator="replay",
                    width=width,
                    height=height,
                ),
            )

    def _publish_source(self, t_ns: int, k: int) -> None:
        """Frame k of an image or video source and MediaPipe's landmarks of it."""
        assert self.source is not None
        stamp = self.writer.stamp_ns(t_ns)
        reader = self.source.reader
        self.writer.write(
            SOURCE_IMAGE,
            t_ns,
            M.compressed_image(stamp, schema.POSEMAP_SOURCE_FRAME, JPEG_FORMAT, self.source.jpeg[k]),
        )
        self.writer.write(
            SOURCE_LANDMARKS,
            t_ns,
            M.pose_landmarks(
                stamp,
                schema.POSEMAP_SOURCE_FRAME,
                self.source.landmarks[k],
                estimator=MediaPipeEstimator.name,
                width=reader.width,
                height=reader.height,
            ),
        )

    def camera_tick(
        self, t_ns: int, frame_index: int, frames: list[tuple[CameraModel, CameraImages]]
    ) -> None:
        """Live landmarks of the rendered frames (projection estimator, rendered depth for occlusion)."""
        if self.estimator is None or frame_index % self.landmarks_every:
            return
        world = self.agent.landmarks_world()
        views = [CameraView(cam, None, images.depth_m, world) for cam, images in frames]
        out = self.estimator.estimate(views)
        for (cam, _), lm in zip(frames, out):
            topic = schema.camera_topics(cam.camera_id, rgb="jpeg", depth=None, semantic=None)[
                "pose_landmarks"
            ]
            self.writer.write(
                topic,
                t_ns,
                M.pose_landmarks(
                    self.writer.stamp_ns(t_ns),
                    cam.frame_id,
                    lm,
                    estimator=self.estimator.name,
                    width=cam.width,
                    height=cam.height,
                ),
            )

    def finish(self) -> dict[str, float]:
        """Drive metrics: the driven joints against the source's true joints, where known."""
        if self.stream is not None and self.predicted is not None and self.stream.truth is not None:
            err = self.predicted - self.stream.truth
            self.metrics["posemap.drive.mae_rad"] = float(np.abs(err).mean())
            self.metrics["posemap.drive.mpjpe_m"], _ = mpjpe(self.predicted, self.stream.truth)
        return self.metrics


def make_driver(
    cfg: Config, agents: list, writer: RecordingWriter, inputs: DriveInputs | None
) -> PoseDriver | None:
    """The driver of the posed humanoid ``posemap.namespace``; without inputs it records its joint states."""
    for a in agents:
        if isinstance(a, PosedHumanoidAgent) and a.namespace == cfg.posemap.namespace:
            return PoseDriver(cfg, a, writer, inputs or DriveInputs())
    return None
