"""Replay algorithm ``tracking``: HOTA, MOTA and IDF1 (TrackEval) of a tracker against a
recording's instance ground truth, per camera and in world coordinates (issue 25).

    python -m simlan_data.replay RUN --out DIR --algorithms tracking                    # the localizer
    python -m simlan_data.replay RUN --out DIR --algorithms tracking --set tracks=FILE  # a tracker's file

The run must have been recorded with stream instance (``cameras.streams=[rgb,semantic,instance]``).
Options (``--set``):

- ``tracks``: the tracker's output, a MOTChallenge folder (``camera_<id>.txt`` per camera) or an
  AI City file (``export --format aicity``'s columns); default: the recording's localizer
  estimates, scored against the agents they estimate;
- ``box``: the ground-truth boxes, ``visible`` (default for a file, the MOT export's) or
  ``amodal`` (default for the localizer, whose boxes are projected 3D boxes);
- ``zero_distance_m``: where the world similarity reaches 0 (default 2: matches within 1 m);
- ``classes``: class names of the ground truth scored against a file (default: every object).

Data flow::

    instance frames (instance_truth.frames) --read_truth--> per camera boxes, world positions
    tracks file | localizer estimates        --Tracks-----> the same frames
        --IoU per camera frame, distance per camera tick--> TrackEval HOTA, CLEAR, Identity
    --> tracking.* (world), tracking.camera.* (cameras combined), tracking.camera_<id>.*
        DIR/tracking.csv (every sequence and metric)

A world score needs world positions: a MOTChallenge folder gives none (``tracking.*`` then absent).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from simlan_data.errors import ConfigError
from simlan_data.evaluation.instance_truth import instance_table
from simlan_data.evaluation.replay import ReplayContext, check_options, register
from simlan_data.evaluation.tracking_inputs import (
    Boxes,
    Points,
    Tracks,
    Truth,
    localized_namespaces,
    localizer_tracks,
    read_aicity,
    read_mot,
    read_truth,
)
from simlan_data.evaluation.tracking_metrics import (
    METRICS,
    ZERO_DISTANCE_M,
    Timestep,
    box_similarity,
    distance_similarity,
    evaluate,
)

OPTIONS = ("tracks", "box", "zero_distance_m", "classes")
CSV = "tracking.csv"
_EMPTY: Boxes = (np.zeros(0, dtype=np.int64), np.zeros((0, 4)))


def _option_box(ctx: ReplayContext) -> str:
    box = ctx.options.get("box", "visible" if "tracks" in ctx.options else "amodal")
    if box not in ("visible", "amodal"):
        raise ConfigError.invalid(
            "box", box, "known: visible, amodal", "e.g. --set box=visible", "replay --set"
        )
    return str(box)


def _option_distance(ctx: ReplayContext) -> float:
    value = ctx.options.get("zero_distance_m", ZERO_DISTANCE_M)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= 100:
        raise ConfigError.invalid(
            "zero_distance_m",
            value,
            "must be a number of metres in (0, 100]",
            "e.g. --set zero_distance_m=2",
            "replay --set",
        )
    return float(value)


def _option_tracks(ctx: ReplayContext) -> Path | None:
    value = ctx.options.get("tracks")
    if value is None:
        return None
    path = Path(str(value))
    if not path.exists():
        raise ConfigError.invalid(
            "tracks",
            str(value),
            "no such file or folder",
            "give a MOTChallenge folder or an AI City file",
            "replay --set",
        )
    return path


def _camera_steps(truth: Truth, tracks: Tracks) -> dict[str, list[Timestep]]:
    out = {}
    for cid, cam in sorted(truth.cameras.items()):
        given = tracks.cameras.get(cid, {})
        steps = []
        for index, (gt_ids, gt_boxes) in enumerate(cam.boxes):
            ids, boxes = given.get(index, _EMPTY)
            steps.append(Timestep(gt_ids, ids, box_similarity(gt_boxes, boxes)))
        out[f"camera_{cid}"] = steps
    return out


def _points(points: Points) -> tuple[np.ndarray, np.ndarray]:
    ids = sorted(points)
    return np.array(ids, dtype=np.int64), np.array([points[i] for i in ids], dtype=float).reshape(-1, 2)


def _world_steps(truth: Truth, world: dict[int, Points], zero_distance_m: float) -> list[Timestep]:
    steps = []
    for stamp in sorted(truth.world):
        gt_ids, gt_xy = _points(truth.world[stamp])
        ids, xy = _points(world.get(stamp, {}))
        steps.append(Timestep(gt_ids, ids, distance_similarity(gt_xy, xy, zero_distance_m)))
    return steps


def _truth_and_tracks(ctx: ReplayContext, path: Path | None, box: str) -> tuple[Truth, Tracks]:
    """The ground truth of the objects scored, and the tracker's output in its frames."""
    reader = ctx.reader
    objects, class_names = instance_table(reader)
    classes = ctx.options.get("classes")
    if classes is not None:
        known = sorted({class_names.get(o.class_id, "") for o in objects.values()})
        if not isinstance(classes, list) or not set(map(str, classes)) <= set(known):
            raise ConfigError.invalid(
                "classes",
                classes,
                f"known: {', '.join(known)}",
                "e.g. --set classes=[pallet_truck]",
                "replay --set",
            )
        if path is None:
            raise ConfigError.invalid(
                "classes",
                classes,
                "the localizer is scored against the agents it estimates",
                "leave classes out, or give tracks",
                "replay --set",
            )
    if path is None:
        namespaces = localized_namespaces(reader, sorted((ctx.config.get("agents") or {}).keys()))
        ids = {o.namespace: o.id for o in objects.values() if o.namespace in namespaces}
        truth = read_truth(reader, box=box, keep=lambda i: i in ids.values())
        return truth, localizer_tracks(reader, truth, ids, ctx.cameras)
    wanted = {o.id for o in objects.values() if classes is None or class_names.get(o.class_id) in classes}
    truth = read_truth(reader, box=box, keep=lambda i: i in wanted)
    return truth, (read_aicity(path, truth) if path.is_file() else read_mot(path, truth))


@register("tracking", path_options=("tracks",))
def tracking_replay(ctx: ReplayContext) -> dict[str, float]:
    """Score a tracker's file (``tracks``) or the recording's localizer; write ``tracking.csv``."""
    check_options(ctx.options, OPTIONS, "tracking", "replay --set", "e.g. --set tracks=mot/")
    box, zero_distance_m, path = _option_box(ctx), _option_distance(ctx), _option_tracks(ctx)
    truth, tracks = _truth_and_tracks(ctx, path, box)
    scores = evaluate(_camera_steps(truth, tracks))
    metrics: dict[str, float] = {}
    for seq, values in scores.items():
        if values["gt_dets"] == values["tracker_dets"] == 0:
            continue  # (a camera that sees nothing scored: TrackEval's 0s would read as a failure)
        prefix = "tracking.camera" if seq == "combined" else f"tracking.{seq}"
        metrics.update({f"{prefix}.{m}": values[m] for m in METRICS})
    if tracks.world is not None:
        world = evaluate({"world": _world_steps(truth, tracks.world, zero_distance_m)})["world"]
        scores["world"] = world
        metrics.update({f"tracking.{m}": world[m] for m in METRICS})
    _write_csv(ctx.out_dir / CSV, scores)
    return metrics


def _write_csv(path: Path, scores: dict[str, dict[str, Any]]) -> None:
    rows = [f"{seq},{m},{values[m]:.9g}\n" for seq, values in sorted(scores.items()) for m in METRICS]
    path.write_text("sequence,metric,value\n" + "".join(rows))
