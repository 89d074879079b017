"""The built-in pose mapper (``trained``), registered like any plug-in: a trained model + the kinematic fit.

It implements the pose-mapper protocol (:class:`~simlan_data.algorithms.roles.PoseMapper`): landmarks
(F, C, 33, 4) of its cameras -> joint targets (F, 47). The live drive (``experiment=posemap_drive``)
and the ``posemap`` replay build it the same way, from ``algorithms.posemap`` (a replay: from the
recorded config), and give it the same landmarks, so they give the same joint targets.

Besides ``predict``, the drive and the replay read these attributes of a pose mapper, where it has
them (see :class:`PoseMapperInputs`): ``cameras`` (the ids whose landmarks it reads, in order;
default: the context's cameras), ``calibrations`` (per camera id, the calibration it assumes: the
replay refuses recordings whose cameras differ), ``home_position`` (where the person it learned from
stood: the replay's ``position=model``) and ``mean_pose`` (the replay's baseline).
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.posemap.config import TrainedMapperParams
from simlan_data.algorithms.roles import PosemapContext
from simlan_data.errors import ConfigError

# how the caller names this config in error lines: PosemapContext.extra[WHERE_KEY] + "model=..."
WHERE_KEY = "where"


@runtime_checkable
class PoseMapperInputs(Protocol):
    """Optional attributes of a pose mapper that the drive and the replay use where present."""

    cameras: list[str]  # camera ids whose landmarks predict() takes, in this order
    calibrations: dict[str, dict[str, Any]]  # camera id -> {world_from_camera, K, width, height}
    home_position: list[float] | None  # x, y, yaw of the support base it was trained with
    mean_pose: NDArray[np.float64] | None  # (47,) its mean pose (the replay's baseline)


def camera_ids(mapper: Any, context: PosemapContext) -> list[str]:
    """The cameras a pose mapper reads: its ``cameras``, else every camera of its context."""
    cameras = getattr(mapper, "cameras", None)
    if cameras is None:
        return [str(c.camera_id) for c in context.cameras]
    return [str(c) for c in cameras]


class TrainedPoseMapper:
    """A model trained by ``experiment=posemap_train`` (features + MLP or boosting), then, with
    ``refine=fit``, the kinematic fit saved with it. The context is not needed: the model knows
    its cameras and their calibration from training."""

    role: ClassVar[str] = "posemap"
    config_class: ClassVar[type] = TrainedMapperParams

    def __init__(self, config: TrainedMapperParams, context: PosemapContext) -> None:
        from simlan_data.algorithms.posemap.training import TrainedMapper  # torch loads with a model

        prefix = str(context.extra.get(WHERE_KEY, "algorithms.posemap."))
        if not config.model:
            raise ConfigError.invalid(
                f"{prefix}model",
                config.model,
                "no trained pose mapper given",
                "give a training run directory or its model/ (python -m simlan_data.run experiment=posemap_train ...)",
            )
        self.trained = TrainedMapper(
            config.model,
            where=f"{prefix}model={config.model}",
            refine=config.refine == "fit",
            iterations=config.refine_iterations,
            starts=config.refine_starts,
        )
        self.cameras: list[str] = list(self.trained.cameras)
        spec = self.trained.spec
        self.calibrations: dict[str, dict[str, Any]] = {
            str(m["id"]): m for m in spec.get("camera_models", [])
        }
        self.home_position = [float(v) for v in spec["position"]] if "position" in spec else None
        y_norm = self.trained.mapper.y_norm
        self.mean_pose = np.asarray(y_norm.mean) if y_norm is not None else None

    def predict(self, landmarks: NDArray[np.float32], *, position: list[float] | None = None) -> NDArray:
        """Joint targets (F, 47) of landmarks (F, C, 33, 4) in ``self.cameras`` order; ``position``:
        where the person's support base stands (x, y, yaw), if not where the model was trained."""
        return self.trained.predict(landmarks, position=position)
