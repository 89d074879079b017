"""What no landmark-based model can recover: joints the 33 landmarks cannot tell apart.

Two groups of SIMLAN's joints have one more angle than the orientation they produce:

- per arm, the shoulder (x, y, z) and the elbow's ``roty``: the elbow's y axis is the upper arm's
  own axis, so ``Rx(a) Ry(b) Rz(c) Ry(d)`` has four angles for a 3-DoF orientation, and the
  landmarks (shoulder, elbow, wrist, hand) only see that orientation;
- per leg, the knee's ``rotz`` and the ankle (x, y, z): the knee's z axis is the shank's own axis,
  ``Rz(k) Rx Ry Rz`` again four angles for the foot's 3-DoF orientation.

Every configuration thus lies on a curve of configurations with identical landmarks. Given the
uniform prior of the dataset (0.8 x the limits), the best an estimator can do for the MAE is the
median along that curve; :func:`ambiguity_floor` measures its error by sampling the curve (the
curve is sampled uniformly in its free angle, an approximation of the posterior).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from .skeleton import JOINT_NAMES, LOWER, UPPER, sample_joints


def ambiguous_groups() -> list[tuple[list[str], bool]]:
    """The joint groups (names, is_leg) with one angle more than their orientation."""
    out = []
    for side in ("Right", "Left"):
        out.append(
            (
                [
                    f"j{side}Shoulder_rotx",
                    f"j{side}Shoulder_roty",
                    f"j{side}Shoulder_rotz",
                    f"j{side}Elbow_roty",
                ],
                False,
            )
        )
        out.append(
            ([f"j{side}Knee_rotz", f"j{side}Ankle_rotx", f"j{side}Ankle_roty", f"j{side}Ankle_rotz"], True)
        )
    return out


def ambiguity_floor(
    n: int = 600, *, limit_scale: float = 0.8, grid: int = 801, seed: int = 0
) -> dict[str, float]:
    """Per-joint MAE (rad) of the best estimate from perfect landmarks, for the ambiguous joints."""
    q = sample_joints(np.random.default_rng(seed), n, limit_scale=limit_scale)
    lo, hi = limit_scale * LOWER, limit_scale * UPPER
    index = {name: i for i, name in enumerate(JOINT_NAMES)}
    out: dict[str, float] = {}
    for names, leg in ambiguous_groups():
        idx = [index[nm] for nm in names]
        free = idx[0] if leg else idx[3]
        values = np.linspace(lo[free], hi[free], grid)
        G = Rotation.from_euler("Z" if leg else "Y", -values[:, None]).as_matrix()
        errors = np.zeros((n, 4))
        for s in range(n):
            a = q[s, idx]
            cand: NDArray[np.float64]
            if leg:
                R = Rotation.from_euler("Z", a[0]).as_matrix() @ Rotation.from_euler("XYZ", a[1:]).as_matrix()
                cand = np.c_[values, Rotation.from_matrix(G @ R).as_euler("XYZ")]
            else:
                R = Rotation.from_euler("XYZ", a[:3]).as_matrix() @ Rotation.from_euler("Y", a[3]).as_matrix()
                cand = np.c_[Rotation.from_matrix(R @ G).as_euler("XYZ"), values]
            ok = np.all((cand >= lo[idx] - 1e-9) & (cand <= hi[idx] + 1e-9), axis=1)
            errors[s] = np.abs(np.median(cand[ok], axis=0) - a)
        out.update({nm: float(e) for nm, e in zip(names, errors.mean(axis=0))})
    return out
