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

from simlan_data.world.skeleton import JOINT_NAMES, sample_joints, sampling_box


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


def _curve(a: NDArray[np.float64], values: NDArray[np.float64], leg: bool) -> NDArray[np.float64]:
    """Configurations (N, G, 4) with the same landmarks as group angles ``a`` (N, 4), per free value."""
    n, g = len(a), len(values)
    G = Rotation.from_euler("Z" if leg else "Y", -values[:, None]).as_matrix()  # (G, 3, 3)
    if leg:
        R = Rotation.from_euler("Z", a[:, :1]).as_matrix() @ Rotation.from_euler("XYZ", a[:, 1:]).as_matrix()
        M = G[None] @ R[:, None]
    else:
        R = Rotation.from_euler("XYZ", a[:, :3]).as_matrix() @ Rotation.from_euler("Y", a[:, 3:]).as_matrix()
        M = R[:, None] @ G[None]
    euler = Rotation.from_matrix(M.reshape(-1, 3, 3)).as_euler("XYZ").reshape(n, g, 3)
    free = np.broadcast_to(values[None, :, None], (n, g, 1))
    return np.concatenate([free, euler], axis=2) if leg else np.concatenate([euler, free], axis=2)


def curve_tangents(q: NDArray[np.float64], h: float = 1e-6) -> NDArray[np.float64]:
    """(N, 47, 4): per ambiguous group, the direction in joint space along which the landmarks
    do not change at ``q`` (the curve's tangent, per unit of its free angle; zero elsewhere)."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    out = np.zeros((*q.shape, 4))
    index = {name: i for i, name in enumerate(JOINT_NAMES)}
    for k, (names, leg) in enumerate(ambiguous_groups()):
        idx = [index[nm] for nm in names]
        a = q[:, idx]
        ends = []
        for v in (a[:, 0 if leg else 3] - h, a[:, 0 if leg else 3] + h):
            if leg:  # Rz(v) Rxyz(ankle) = Rz(knee) Rxyz(ankle as given)
                R = Rotation.from_euler("Z", a[:, :1]) * Rotation.from_euler("XYZ", a[:, 1:])
                ankle = (Rotation.from_euler("Z", -v[:, None]) * R).as_euler("XYZ")
                ends.append(np.concatenate([v[:, None], ankle], axis=1))
            else:  # Rxyz(shoulder) Ry(v) = Rxyz(shoulder as given) Ry(elbow)
                R = Rotation.from_euler("XYZ", a[:, :3]) * Rotation.from_euler("Y", a[:, 3:])
                shoulder = (R * Rotation.from_euler("Y", -v[:, None])).as_euler("XYZ")
                ends.append(np.concatenate([shoulder, v[:, None]], axis=1))
        out[:, idx, k] = (ends[1] - ends[0]) / (2 * h)
    return out


def _weighted_median(values: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per row and column of ``values`` (N, G, K), the median along G under ``weights`` (N, G)."""
    order = np.argsort(values, axis=1)
    v = np.take_along_axis(values, order, axis=1)
    w = np.take_along_axis(np.broadcast_to(weights[..., None], values.shape), order, axis=1)
    cum = np.cumsum(w, axis=1)
    half = 0.5 * cum[:, -1:, :]
    pick = np.argmax(cum >= half, axis=1)  # (N, K): first sample reaching half the weight
    return np.take_along_axis(v, pick[:, None, :], axis=1)[:, 0, :]


def curve_medians(
    q: NDArray[np.float64], *, limit_scale: float = 0.8, grid: int = 401, chunk: int = 256
) -> NDArray[np.float64]:
    """``q`` (N, 47) with each ambiguous group replaced by its per-joint median along its curve.

    The curve through ``q`` (configurations with identical landmarks, within ``limit_scale`` x
    the limits) is sampled uniformly in its free angle; a group whose curve leaves no sample in
    the limits keeps its angles.
    """
    q = np.array(q, dtype=np.float64, copy=True)
    lo, hi = sampling_box(limit_scale)
    index = {name: i for i, name in enumerate(JOINT_NAMES)}
    for names, leg in ambiguous_groups():
        idx = [index[nm] for nm in names]
        free = idx[0] if leg else idx[3]
        values = np.linspace(lo[free], hi[free], grid)
        for s in range(0, len(q), chunk):
            cand = _curve(q[s : s + chunk, idx], values, leg)
            ok = np.all((cand >= lo[idx] - 1e-9) & (cand <= hi[idx] + 1e-9), axis=2)
            has = ok.any(axis=1)
            med = _weighted_median(
                cand[has], (ok / np.maximum(np.abs(np.cos(cand[..., 2 if leg else 1])), 1e-6))[has]
            )
            block = q[s : s + chunk]
            rows = block[has]
            rows[:, idx] = med
            block[has] = rows
    return q


def ambiguity_floor(
    n: int = 600, *, limit_scale: float = 0.8, grid: int = 801, seed: int = 0
) -> dict[str, float]:
    """Per-joint MAE (rad) of the best estimate from perfect landmarks, for the ambiguous joints."""
    q = sample_joints(np.random.default_rng(seed), n, limit_scale=limit_scale)
    best = curve_medians(q, limit_scale=limit_scale, grid=grid)
    names = [nm for group, _ in ambiguous_groups() for nm in group]
    idx = [JOINT_NAMES.index(nm) for nm in names]
    errors = np.abs(best[:, idx] - q[:, idx]).mean(axis=0)
    return {nm: float(e) for nm, e in zip(names, errors)}
