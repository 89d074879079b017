"""Health of the camera network, from what the localizer saw: who delivers, who disagrees.

Accuracy against ground truth can hide a faulty camera when others cover for it (the network is
redundant). These metrics look at the cameras themselves:

- ``cameras_detecting``: cameras in which the localizer found a robot's marker at least once. A
  camera that drops out stops counting.
- ``camera_disagreement_m`` per camera: RMS distance between the camera's own marker position
  and the mean of the other cameras' positions of the same marker in the same frame set (only
  frame sets where at least two cameras saw it). A camera whose calibration has drifted
  disagrees with its neighbours even where the fused estimate stays good;
  ``camera_disagreement_max_m`` is the worst camera's. A camera with fewer than
  ``MIN_SHARED_FRAMES`` such frame sets gets no figure: a single frame set (at the edge of a fisheye
  image, 1.8 cm off) set restricted_zone's worst camera in one seed of the base suite while every
  camera with more stayed within 0.5 cm.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from simlan_data.algorithms.markers import MarkerObservation

MIN_SHARED_FRAMES = 2  # one frame set is no statistic (the golden recordings share 2-5 per camera)


@dataclass
class CameraConsistency:
    """Accumulates the localizer's per-camera observations, frame set by frame set."""

    detecting: set[str] = field(default_factory=set)
    squared: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))

    def add(self, observations: list[MarkerObservation]) -> None:
        by_marker: dict[int, list[MarkerObservation]] = defaultdict(list)
        for obs in observations:
            self.detecting.add(obs.camera_id)
            by_marker[obs.marker_id].append(obs)
        for group in by_marker.values():
            if len({o.camera_id for o in group}) < 2:
                continue
            xy = np.array([[o.x_m, o.y_m] for o in group])
            for i, obs in enumerate(group):
                others = np.delete(xy, i, axis=0).mean(axis=0)
                self.squared[obs.camera_id].append(float(np.sum((xy[i] - others) ** 2)))

    def metrics(self, prefix: str) -> dict[str, float]:
        out = {f"{prefix}cameras_detecting": float(len(self.detecting))}
        rms = {
            cid: float(np.sqrt(np.mean(v))) for cid, v in self.squared.items() if len(v) >= MIN_SHARED_FRAMES
        }
        for cid, value in sorted(rms.items()):
            out[f"{prefix}camera_{cid}.disagreement_m"] = value
        if rms:
            out[f"{prefix}camera_disagreement_max_m"] = max(rms.values())
        return out
