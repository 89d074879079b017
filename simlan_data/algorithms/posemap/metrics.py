"""Accuracy of a pose mapper on held-out samples: ``posemap.*`` metrics.

- ``mae_rad`` / ``mse_rad2`` (and ``_deg``): mean over joints and samples of |error| and error^2;
  per joint under ``posemap.joint.<name>.*``;
- ``mpjpe_m``: mean per-joint position error of the 33 landmarks after re-posing the humanoid with
  the predicted joints (numpy forward kinematics of the same skeleton), and ``mpjpe_body_m``
  without the support arm's global rotation (both bodies re-posed about the same base);
- ``baseline.mean_pose.*``: the same for predicting the training set's mean pose everywhere.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from simlan_data.world.skeleton import JOINT_NAMES, NUM_JOINTS, SUPPORT_JOINTS, landmark_positions

F64 = NDArray[np.float64]
SUPPORT_INDEX = [JOINT_NAMES.index(n) for n in SUPPORT_JOINTS]


def joint_errors(y_pred: F64, y_true: F64, prefix: str = "posemap") -> dict[str, float]:
    err = y_pred - y_true
    mae_j, mse_j = np.abs(err).mean(axis=0), (err**2).mean(axis=0)
    return {
        f"{prefix}.mae_rad": float(mae_j.mean()),
        f"{prefix}.mse_rad2": float(mse_j.mean()),
        f"{prefix}.mae_deg": float(np.degrees(mae_j.mean())),
        f"{prefix}.mse_deg2": float(np.degrees(np.degrees(mse_j.mean()))),
        f"{prefix}.human.mae_rad": float(mae_j[:44].mean()),
        f"{prefix}.support.mae_rad": float(mae_j[44:].mean()),
    }


def per_joint(y_pred: F64, y_true: F64, prefix: str = "posemap.joint") -> dict[str, float]:
    err = y_pred - y_true
    out: dict[str, float] = {}
    for j, name in enumerate(JOINT_NAMES):
        mae, mse = float(np.abs(err[:, j]).mean()), float((err[:, j] ** 2).mean())
        out[f"{prefix}.{name}.mae_rad"] = mae
        out[f"{prefix}.{name}.mae_deg"] = float(np.degrees(mae))
        out[f"{prefix}.{name}.mse_rad2"] = mse
        out[f"{prefix}.{name}.mse_deg2"] = float(np.degrees(np.degrees(mse)))
    return out


def mpjpe(y_pred: F64, y_true: F64, *, max_samples: int = 5000) -> tuple[float, float]:
    """Mean landmark distance (m) between the bodies posed by y_pred and y_true; and without the
    support arm's rotation (body pose alone)."""
    y_pred, y_true = y_pred[:max_samples], y_true[:max_samples]
    a, b = landmark_positions(y_pred), landmark_positions(y_true)
    full = float(np.linalg.norm(a - b, axis=2).mean())
    body_pred = y_pred.copy()
    body_pred[:, SUPPORT_INDEX] = y_true[:, SUPPORT_INDEX]
    body = float(np.linalg.norm(landmark_positions(body_pred) - b, axis=2).mean())
    return full, body


def evaluate(y_pred: F64, y_true: F64, y_train_mean: F64) -> dict[str, float]:
    """Every posemap metric of predictions on a held-out split."""
    assert y_pred.shape == y_true.shape and y_pred.shape[1] == NUM_JOINTS
    out = joint_errors(y_pred, y_true)
    out.update(per_joint(y_pred, y_true))
    out["posemap.mpjpe_m"], out["posemap.mpjpe_body_m"] = mpjpe(y_pred, y_true)
    mean_pose = np.broadcast_to(y_train_mean, y_true.shape)
    out.update(joint_errors(mean_pose, y_true, "posemap.baseline.mean_pose"))
    out["posemap.baseline.mean_pose.mpjpe_m"], _ = mpjpe(np.array(mean_pose), y_true)
    return out
