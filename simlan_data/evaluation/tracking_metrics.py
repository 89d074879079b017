"""Multi-object tracking metrics by TrackEval (issue 25): HOTA, MOTA and IDF1 of a tracker's
output against ground truth, per camera (image boxes, IoU) and in world coordinates (floor
positions, a distance similarity).

TrackEval computes every number: this module only builds the per-timestep data its metrics take
(``gt_ids``, ``tracker_ids``, ``similarity_scores``: what its datasets' preprocessing hands them)
and uses its own similarity functions, so a camera sequence scores exactly as TrackEval's
``MotChallenge2DBox`` scores the same files (tests/test_tracking.py checks that).

Similarity:

- per camera: the IoU of the boxes (TrackEval's ``_calculate_box_ious``, x y w h);
- world: ``max(0, 1 - d / zero_distance_m)`` of the floor distance ``d`` (TrackEval's
  ``_calculate_euclidean_similarity``, as its MOT15 3D and point datasets). With the default
  ``zero_distance_m`` of 2 m, MOTA's and IDF1's match threshold (similarity 0.5) is a distance of
  1 m, and HOTA (averaged over thresholds 0.05..0.95) asks for 0.1 m to 1.9 m.

TrackEval is the ``tracking`` extra (``pip install -e ".[tracking]"``): the import is lazy so
that the rest of the evaluation runs without it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.errors import ConfigError

ZERO_DISTANCE_M = 2.0  # world similarity reaches 0 here (TrackEval's default for 3D points)
METRICS = ("hota", "deta", "assa", "loca", "mota", "motp", "idf1", "idsw", "gt_dets", "tracker_dets")


@dataclass(frozen=True)
class Timestep:
    """One frame of one sequence: ground-truth and tracker ids and their similarity (N, M)."""

    gt_ids: NDArray[np.int64]
    tracker_ids: NDArray[np.int64]
    similarity: NDArray[np.float64]


def _trackeval() -> Any:
    try:
        import trackeval
    except ImportError:
        raise ConfigError(
            "TrackEval is not installed",
            "tracking metrics",
            "HOTA, MOTA and IDF1 are computed by the trackeval package",
            'pip install -e ".[tracking]"',
        ) from None
    return trackeval


def box_similarity(gt_xywh: NDArray[np.float64], tracker_xywh: NDArray[np.float64]) -> NDArray[np.float64]:
    """IoU (N, M) of boxes given as x y w h (TrackEval's own function)."""
    base = _trackeval().datasets._base_dataset._BaseDataset
    gt, tr = (
        np.asarray(gt_xywh, dtype=float).reshape(-1, 4),
        np.asarray(tracker_xywh, dtype=float).reshape(-1, 4),
    )
    return np.asarray(base._calculate_box_ious(gt, tr, box_format="xywh"), dtype=float)


def distance_similarity(
    gt_xy: NDArray[np.float64], tracker_xy: NDArray[np.float64], zero_distance_m: float = ZERO_DISTANCE_M
) -> NDArray[np.float64]:
    """``max(0, 1 - d / zero_distance_m)`` (N, M) of floor positions (TrackEval's own function)."""
    base = _trackeval().datasets._base_dataset._BaseDataset
    gt, tr = np.asarray(gt_xy, dtype=float).reshape(-1, 2), np.asarray(tracker_xy, dtype=float).reshape(-1, 2)
    return np.asarray(
        base._calculate_euclidean_similarity(gt, tr, zero_distance=zero_distance_m), dtype=float
    )


def _sequence_data(name: str, steps: list[Timestep]) -> dict[str, Any]:
    """TrackEval's per-sequence data: ids relabelled 0..K-1 in order of first use, as its
    datasets' preprocessing does (the metrics index arrays by them)."""
    gt_all = np.unique(np.concatenate([s.gt_ids for s in steps] or [np.zeros(0, dtype=np.int64)]))
    tr_all = np.unique(np.concatenate([s.tracker_ids for s in steps] or [np.zeros(0, dtype=np.int64)]))
    gt_map = {int(i): k for k, i in enumerate(gt_all)}
    tr_map = {int(i): k for k, i in enumerate(tr_all)}
    for t, s in enumerate(steps):
        if len(np.unique(s.tracker_ids)) != len(s.tracker_ids):
            raise ConfigError(
                "duplicate tracker id",
                f"sequence {name}, timestep {t + 1}",
                "a tracker gives one object one id per frame",
                "give each object in a frame its own id",
            )
    return {
        "seq": name,
        "num_timesteps": len(steps),
        "num_gt_ids": len(gt_all),
        "num_tracker_ids": len(tr_all),
        "num_gt_dets": int(sum(len(s.gt_ids) for s in steps)),
        "num_tracker_dets": int(sum(len(s.tracker_ids) for s in steps)),
        "gt_ids": [np.array([gt_map[int(i)] for i in s.gt_ids], dtype=int) for s in steps],
        "tracker_ids": [np.array([tr_map[int(i)] for i in s.tracker_ids], dtype=int) for s in steps],
        "similarity_scores": [np.asarray(s.similarity, dtype=float) for s in steps],
    }


def _summary(
    hota: Mapping[str, Any], clear: Mapping[str, Any], identity: Mapping[str, Any]
) -> dict[str, float]:
    return {
        "hota": float(np.mean(hota["HOTA"])),
        "deta": float(np.mean(hota["DetA"])),
        "assa": float(np.mean(hota["AssA"])),
        "loca": float(np.mean(hota["LocA"])),
        "mota": float(clear["MOTA"]),
        "motp": float(clear["MOTP"]),
        "idf1": float(identity["IDF1"]),
        "idsw": float(clear["IDSW"]),
        "gt_dets": float(clear["CLR_TP"] + clear["CLR_FN"]),
        "tracker_dets": float(clear["CLR_TP"] + clear["CLR_FP"]),
    }


def evaluate(sequences: Mapping[str, Iterable[Timestep]]) -> dict[str, dict[str, float]]:
    """TrackEval's HOTA, CLEAR and Identity per sequence, and over all of them (``"combined"``:
    its ``combine_sequences``, which sums the counts, not a mean of the scores).

    Returns:
        sequence name (and ``combined``) -> :data:`METRICS` -> value.
    """
    te = _trackeval()
    quiet = {"PRINT_CONFIG": False}
    metrics = {
        "hota": te.metrics.HOTA(),
        "clear": te.metrics.CLEAR(quiet),
        "identity": te.metrics.Identity(quiet),
    }
    per: dict[str, dict[str, Any]] = {key: {} for key in metrics}
    for name, steps in sequences.items():
        data = _sequence_data(name, list(steps))
        for key, metric in metrics.items():
            per[key][name] = metric.eval_sequence(data)
    out = {name: _summary(per["hota"][name], per["clear"][name], per["identity"][name]) for name in sequences}
    if sequences:
        combined = {key: metric.combine_sequences(per[key]) for key, metric in metrics.items()}
        out["combined"] = _summary(combined["hota"], combined["clear"], combined["identity"])
    return out
