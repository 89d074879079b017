"""Replay a recording's landmark stream through a pose mapper: ``--algorithms posemap``.

    python -m simlan_data.replay RECORDING --out DIR --algorithms posemap --set model=TRAIN_RUN
    python -m simlan_data.replay RECORDING --out DIR --algorithms posemap --set posemap=my_pkg.pm:MyMapper

Data flow::

    /camera_<id>/pose_landmarks of the mapper's cameras --> frames (F, C, 33, 4) by stamp
        (position: where the person's support base stood, from /ground_truth/poses)
        --> the pose mapper (the recording's algorithms.posemap, built through the registry as
            the live drive builds it; the built-in ``trained``: features + MLP / boosting, then
            the kinematic fit) --> predicted joints (F, 47)
    /<ns>/joint_states at the same stamps (the targets the humanoid was posed with) = truth
        --> replay.posemap.* metrics (gpss/posemap/metrics.py), posemap_joints.parquet (per
            joint), posemap_frames.parquet (per frame: errors, predicted and true joints)

Options (``--set KEY=VALUE``; in a suite, ``replay: {posemap: {...}}``):

- ``posemap``: another pose mapper, a registered name or ``module:Class`` (default: the
  recording's ``algorithms.posemap``; recordings made before the ``algorithms`` section: the
  built-in ``trained`` with the model ``posemap.drive_model``);
- any key of the mapper's config (default: the recording's values when the mapper is the recorded
  one, else its defaults), for the built-in ``trained``: ``model`` (a training run directory or its
  ``model/``; a recording that drove no model has none: give one), ``refine``,
  ``refine_iterations``, ``refine_starts``;
- ``namespace``: the posed humanoid (default: the recording's ``posemap.namespace``);
- ``position``: ``recorded`` (default: the humanoid's recorded base pose), ``model`` (where the
  training data's humanoid stood) or ``[x, y, yaw]``.

The mapper's cameras (its ``cameras``, else every camera with landmarks) must be recorded with
landmarks and, where the mapper names their ``calibrations`` (the built-in: as the model was
trained), calibrated so (centre within 5 cm, orientation within 1 degree, normalised intrinsics
within 1 %).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
import polars as pl
from scipy.spatial.transform import Rotation

from simlan_data.algorithms import registry
from simlan_data.algorithms.posemap.metrics import joint_errors, mpjpe, per_joint
from simlan_data.algorithms.roles import PosemapContext
from simlan_data.algorithms.trained_posemap import WHERE_KEY, camera_ids
from simlan_data.config.legacy import with_algorithms
from simlan_data.errors import ConfigError, RecordingInputError
from simlan_data.evaluation.replay import ReplayContext, check_options, register
from simlan_data.geometry.camera import CameraModel
from simlan_data.sim.posemap_drive import check_targets
from simlan_data.sim.posemap_inputs import base_pose, landmark_cameras, read_landmark_stream
from simlan_data.world.skeleton import JOINT_NAMES, NUM_JOINTS, landmark_positions

PREFIX = "replay.posemap"
# replay options that are not the pose mapper's config: which mapper, whose joints, where it stood
REPLAY_OPTIONS = ("posemap", "namespace", "position")
WHERE = "posemap replay option "
JOINTS_FILE = "posemap_joints.parquet"
FRAMES_FILE = "posemap_frames.parquet"
MAX_CENTRE_M = 0.05
MAX_ANGLE_DEG = 1.0
MAX_INTRINSICS_REL = 0.01


def selected_mapper(
    config: dict[str, Any], options: dict[str, Any] | None = None
) -> tuple[registry.AlgorithmSpec, Any]:
    """The pose mapper and its config: the recording's, or ``options["posemap"]`` (a registered
    name or module:Class); the options that are not replay options are its config values.

    Raises:
        ConfigError: an unknown name or option, a value its config rejects.
    """
    options = dict(options or {})
    config = with_algorithms(config)  # (an older recording: the built-in, its model from posemap.drive_model)
    name = options.get("posemap")
    spec = registry.resolve(
        "posemap",
        registry.selection(config, "posemap")[0] if name is None else str(name),
        where="replay --set",
    )
    known = (*REPLAY_OPTIONS, *(f.name for f in dataclasses.fields(spec.config_class) if f.init))
    check_options(options, known, "posemap replay", "--set", "fix the spelling")
    overrides = {k: v for k, v in options.items() if k not in REPLAY_OPTIONS}
    return registry.from_config(
        config, "posemap", name=None if name is None else str(name), overrides=overrides, where="replay --set"
    )


def _normalised_intrinsics(cam: CameraModel) -> np.ndarray:
    K = cam.K
    return np.array(
        [K[0, 0] / cam.width, K[1, 1] / cam.height, (K[0, 2] + 0.5) / cam.width, (K[1, 2] + 0.5) / cam.height]
    )


def camera_mismatch(trained: dict[str, Any], recorded: CameraModel) -> str:
    """Why camera ``recorded`` is not the camera a model was trained with ("" if it is)."""
    world_from_camera = np.asarray(trained["world_from_camera"], dtype=np.float64)
    moved = float(np.linalg.norm(world_from_camera[:3, 3] - recorded.position))
    if moved > MAX_CENTRE_M:
        return f"camera {recorded.camera_id} stands {moved:.3f} m from where the model's stood"
    relative = world_from_camera[:3, :3].T @ recorded.world_from_camera.rotation
    turned = float(np.degrees(Rotation.from_matrix(relative).magnitude()))
    if turned > MAX_ANGLE_DEG:
        return f"camera {recorded.camera_id} is turned {turned:.2f} degrees from the model's"
    w, h = int(trained["width"]), int(trained["height"])
    K = np.asarray(trained["K"], dtype=np.float64)
    theirs = np.array([K[0, 0] / w, K[1, 1] / h, (K[0, 2] + 0.5) / w, (K[1, 2] + 0.5) / h])
    rel = float(np.max(np.abs(_normalised_intrinsics(recorded) - theirs) / np.abs(theirs)))
    if rel > MAX_INTRINSICS_REL:
        return f"camera {recorded.camera_id}'s intrinsics differ from the model's by {100 * rel:.1f} %"
    return ""


def check_cameras(mapper: Any, cameras: list[str], ctx: ReplayContext, where: str) -> None:
    """The recording has landmarks of every camera the mapper reads, calibrated as it assumes.

    Raises:
        RecordingInputError: no landmark topics at all.
        ConfigError: the model reads other cameras, or the same ids placed or calibrated otherwise.
    """
    have = landmark_cameras(ctx.reader)
    if not have:
        raise RecordingInputError(
            "recording has no landmark topics",
            str(ctx.reader.path),
            "no /camera_<id>/pose_landmarks: nothing for a pose mapper to read",
            "record with posemap.landmarks_rate_hz > 0 (experiment=posemap_motion)",
        )
    missing = [c for c in cameras if c not in have]
    if missing:
        raise ConfigError(
            "model's cameras do not match the recording's",
            where,
            f"the model reads cameras {', '.join(cameras)}; the recording has landmarks of {', '.join(have)}",
            "give a model trained on the recording's cameras (posemap.cameras=[...])",
        )
    trained = dict(getattr(mapper, "calibrations", None) or {})
    recorded = ctx.cameras
    for cid in cameras:
        if cid not in trained:  # image features: the model keeps no calibration to compare
            continue
        if cid not in recorded:
            raise RecordingInputError(
                f"camera {cid} has no calibration in the recording",
                str(ctx.reader.path),
                "no camera_info or /tf_static entry",
                "record with simlan_data",
            )
        why = camera_mismatch(trained[cid], recorded[cid])
        if why:
            raise ConfigError(
                "model's cameras do not match the recording's",
                where,
                why,
                "give a model trained on a dataset of the recording's cameras (experiment=posemap_dataset)",
            )


def _position(option: Any, ctx: ReplayContext, namespace: str, home: list[float] | None) -> list[float]:
    if option in (None, "recorded"):
        pose = base_pose(ctx.reader, namespace)
        if pose is None:
            raise RecordingInputError(
                f"no ground truth of {namespace}",
                str(ctx.reader.path),
                "the posed humanoid's base pose is unknown",
                "give --set namespace=<the posed humanoid> or --set position=model",
            )
        return list(pose)
    if option == "model":
        return [float(v) for v in (home if home is not None else [0.0, 0.0, 0.0])]
    if isinstance(option, list) and len(option) == 3 and all(isinstance(v, (int, float)) for v in option):
        return [float(v) for v in option]
    raise ConfigError(
        f"invalid posemap replay option position={option!r}",
        "--set",
        "expected recorded, model or [x_m, y_m, yaw_rad]",
        "e.g. --set position=recorded",
    )


def _frames_table(stamps: np.ndarray, pred: np.ndarray, truth: np.ndarray) -> pl.DataFrame:
    err = np.abs(pred - truth)
    dist = np.linalg.norm(landmark_positions(pred) - landmark_positions(truth), axis=2)
    return pl.DataFrame(
        {
            "stamp_ns": stamps.astype(np.int64),
            "mae_rad": err.mean(axis=1),
            "mpjpe_m": dist.mean(axis=1),
            "predicted_rad": pred,
            "truth_rad": truth,
        },
        schema={
            "stamp_ns": pl.Int64,
            "mae_rad": pl.Float64,
            "mpjpe_m": pl.Float64,
            "predicted_rad": pl.Array(pl.Float64, NUM_JOINTS),
            "truth_rad": pl.Array(pl.Float64, NUM_JOINTS),
        },
    )


def _joints_table(pred: np.ndarray, truth: np.ndarray, mean_pose: np.ndarray) -> pl.DataFrame:
    ours = per_joint(pred, truth, prefix="j")
    baseline = per_joint(np.broadcast_to(mean_pose, truth.shape), truth, prefix="j")
    return pl.DataFrame(
        {
            "joint": list(JOINT_NAMES),
            "mae_rad": [ours[f"j.{n}.mae_rad"] for n in JOINT_NAMES],
            "mae_deg": [ours[f"j.{n}.mae_deg"] for n in JOINT_NAMES],
            "mse_rad2": [ours[f"j.{n}.mse_rad2"] for n in JOINT_NAMES],
            "mean_pose_mae_rad": [baseline[f"j.{n}.mae_rad"] for n in JOINT_NAMES],
        }
    )


@register("posemap", path_options=("model",))
def posemap(ctx: ReplayContext) -> dict[str, float]:
    """Predict the posed humanoid's joints from the recorded landmarks; score against its targets."""
    options = dict(ctx.options)
    spec, config = selected_mapper(ctx.config, options)
    have = landmark_cameras(ctx.reader)
    context = PosemapContext(
        tuple(ctx.cameras[c] for c in have if c in ctx.cameras), extra={WHERE_KEY: WHERE}
    )
    model = getattr(config, "model", None)
    where = f"{WHERE}model={model}" if model is not None else f"{WHERE}posemap={spec.name}"
    mapper = registry.Guarded(spec.build(config, context, where=where), spec)
    cameras = camera_ids(mapper, context)
    check_cameras(mapper, cameras, ctx, where)
    namespace = str(options.get("namespace") or (ctx.config.get("posemap") or {}).get("namespace") or "")
    if not namespace:
        namespace = "robot_agent_1"
    stream = read_landmark_stream(ctx.reader, cameras, namespace, where=str(ctx.reader.path))
    if stream.estimators == ("replay",):
        raise RecordingInputError(
            "recording is a drive's output",
            str(ctx.reader.path),
            "its joint states are a model's predictions, not the targets the landmarks were made from",
            "replay the drive's landmark source (e.g. an experiment=posemap_motion recording)",
        )
    if stream.truth is None or stream.truth.shape[1] != NUM_JOINTS:
        raise RecordingInputError(
            f"recording lacks the joint states of {namespace}",
            str(ctx.reader.path),
            "no /<ns>/joint_states of 47 joints at every landmark stamp: the truth is unknown",
            "give --set namespace=<the posed humanoid> or record with experiment=posemap_motion",
        )
    home = getattr(mapper, "home_position", None)
    position = _position(options.get("position"), ctx, namespace, home)
    t0 = time.perf_counter()
    pred = mapper.predict(stream.landmarks, position=position)
    predict_s = time.perf_counter() - t0
    pred = check_targets(pred, len(stream.landmarks), where)
    truth = stream.truth
    own_mean = getattr(mapper, "mean_pose", None)
    mean_pose = np.asarray(own_mean if own_mean is not None else truth.mean(0))
    metrics = joint_errors(pred, truth, prefix=PREFIX)
    metrics[f"{PREFIX}.mpjpe_m"], metrics[f"{PREFIX}.mpjpe_body_m"] = mpjpe(pred, truth)
    baseline = np.broadcast_to(mean_pose, truth.shape).copy()
    metrics[f"{PREFIX}.baseline.mean_pose.mae_rad"] = float(np.abs(baseline - truth).mean())
    metrics[f"{PREFIX}.baseline.mean_pose.mpjpe_m"], _ = mpjpe(baseline, truth)
    metrics[f"{PREFIX}.frames"] = float(len(pred))
    metrics[f"{PREFIX}.predict_ms_per_frame"] = 1e3 * predict_s / max(1, len(pred))
    metrics[f"{PREFIX}.visible_fraction"] = float((stream.landmarks[..., 3] > 0.5).mean())
    trained_at = np.asarray((home if home is not None else position)[:2], dtype=np.float64)
    metrics[f"{PREFIX}.base_offset_m"] = float(np.linalg.norm(np.asarray(position[:2]) - trained_at))
    _joints_table(pred, truth, mean_pose).write_parquet(ctx.out_dir / JOINTS_FILE)
    _frames_table(stream.stamps_ns, pred, truth).write_parquet(ctx.out_dir / FRAMES_FILE)
    return metrics
