"""Kinematic refinement: fit the humanoid's skeleton to the landmarks of every camera.

A learned map (``models.py``) gives a first estimate ``q0`` of the 47 joint targets; this module
refines it the way model-based human pose fitting does (SMPLify, SPIN's "regression, then
optimisation"): it searches the joint vector whose landmarks, placed by the skeleton's forward
kinematics and projected by each calibrated camera, land on the pixels the estimator reported,
weighted by how much the estimator trusts each one (``noise_px`` for a landmark it sees,
``hidden_noise_px`` for one it guesses), within the sampling limits, pulled towards ``q0`` per
joint as far as the learned model's own errors say, for what the images cannot tell.

landmarks (N, C, 33, 4) + cameras --> undistorted image points --> damped Gauss-Newton over q
(analytic Jacobian: a revolute joint moves a point at ``axis x (point - joint origin)``) -->
q_fit --> on the curves of configurations with identical landmarks (:mod:`.ambiguity`), the
median along the curve (what minimises the expected absolute error under the uniform prior).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from functools import cache

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.posemap.ambiguity import curve_medians
from simlan_data.algorithms.posemap.features import Rig
from simlan_data.world.skeleton import (
    NUM_JOINTS,
    _chain,
    _landmark_links,
    forward_kinematics,
    landmark_positions,
    landmarks_of_links,
    sampling_box,
)

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class FitParams:
    """How the refinement weighs the evidence (pixels) against the learned estimate (radians)."""

    noise_px: float = 1.0  # sigma of a landmark the estimator marks visible
    hidden_noise_px: float = 8.0  # ... of one it marks hidden (a guess)
    iterations: int = 15
    starts: int = 4  # 1 + random restarts of the arms for a fit whose residual stays too large
    restart_chi2: float = 1.5  # ... "too large": mean squared whitened residual above this
    limit_scale: float = 0.8  # the dataset's sampling box (0.8 x the limits, as SIMLAN)
    curve_median: bool = True  # replace the unrecoverable angles by their median along the curve
    seed: int = 0


@cache
def _ancestors() -> NDArray[np.bool_]:
    """(33, 47): True where joint j moves landmark k (j lies on the chain from the base to k's link)."""
    _, steps = _chain()
    parent_of = {child: (parent, qi) for parent, child, qi, _, _ in steps}
    links, _ = _landmark_links()
    mask = np.zeros((len(links), NUM_JOINTS), dtype=bool)
    for k, link in enumerate(links):
        node = int(link)
        while node in parent_of:
            parent, qi = parent_of[node]
            if qi >= 0:
                mask[k, qi] = True
            node = parent
    return mask


@cache
def _joint_children() -> NDArray[np.int64]:
    """(47,): the link index each joint moves (its child)."""
    _, steps = _chain()
    out = np.zeros(NUM_JOINTS, dtype=np.int64)
    for _, child, qi, _, _ in steps:
        if qi >= 0:
            out[qi] = child
    return out


@cache
def _joint_axes() -> F64:
    _, steps = _chain()
    out = np.zeros((NUM_JOINTS, 3))
    for _, _, qi, _, axis in steps:
        if qi >= 0:
            out[qi] = axis / np.linalg.norm(axis)
    return out


def _landmarks_base(q: F64) -> tuple[F64, F64]:
    """Landmarks (N, 33, 3) in the base frame and every link's pose (N, links, 4, 4)."""
    T = forward_kinematics(q)
    return landmarks_of_links(T), T


def _point_jacobian(pts: F64, T: F64) -> F64:
    """d landmark / d q (N, 33, 3, 47): ``axis x (point - joint origin)`` for the joints above it."""
    child = T[:, _joint_children()]  # (N, 47, 4, 4)
    a = np.einsum("njab,jb->nja", child[..., :3, :3], _joint_axes())  # joint axes in the base frame
    m = np.cross(a, child[..., :3, 3])  # axis x origin, (N, 47, 3)
    ax, ay, az = (a[:, None, :, i] for i in range(3))
    px, py, pz = (pts[:, :, None, i] for i in range(3))
    mask = _ancestors()[None]
    out = np.empty((len(pts), pts.shape[1], 3, NUM_JOINTS))
    np.multiply(ay * pz - az * py - m[:, None, :, 0], mask, out=out[:, :, 0])
    np.multiply(az * px - ax * pz - m[:, None, :, 1], mask, out=out[:, :, 1])
    np.multiply(ax * py - ay * px - m[:, None, :, 2], mask, out=out[:, :, 2])
    return out


def _observations(landmarks: NDArray[np.float32], rig: Rig, params: FitParams) -> tuple[F64, F64, F64]:
    """Undistorted normalised image points (N, C, 33, 2), weights (N, C, 33) and focal lengths (C, 2)."""
    n, c = landmarks.shape[:2]
    obs = np.zeros((n, c, landmarks.shape[2], 2))
    focal = np.zeros((c, 2))
    for k, cam in enumerate(rig.cameras):
        uv = landmarks[:, k, :, :2].reshape(-1, 2).astype(np.float64) * [cam.width, cam.height]
        d, ok = cam.pixel_rays(uv)
        z = np.where(ok & (d[:, 2] > 1e-6), d[:, 2], 1.0)
        obs[:, k] = (d[:, :2] / z[:, None]).reshape(n, -1, 2)
        focal[k] = cam.K[0, 0], cam.K[1, 1]
    detected = (landmarks[..., 3] > 0).any(axis=2, keepdims=True)
    sigma = np.where(landmarks[..., 3] > 0, params.noise_px, params.hidden_noise_px)
    weights = np.where(detected, 1.0 / sigma**2, 0.0)
    return obs, weights, focal


def _residuals(
    q: F64, obs: F64, weights: F64, focal: F64, cam_from_base: F64, *, normal: bool
) -> tuple[F64, tuple[F64, F64] | None]:
    """Whitened residuals (N, R), R = C * 33 * 2, and if asked the normal equations' J^T J, J^T r.

    ``J = A D`` per landmark: ``A`` (2 x 3 per camera) projects a move of the landmark in the base
    frame, ``D`` (3 x 47) is the landmark's kinematic Jacobian; so ``J^T J = sum_k D_k^T (sum_c
    A_ck^T A_ck) D_k`` without ever forming J (4x less work than the per-camera product).
    """
    n = len(q)
    pts, T = _landmarks_base(q)
    R, t = cam_from_base[:, :3, :3], cam_from_base[:, :3, 3]
    P = np.einsum("cab,nkb->ncka", R, pts) + t[None, :, None, :]  # (N, C, 33, 3)
    Z = np.maximum(P[..., 2], 1e-3)
    proj = P[..., :2] / Z[..., None]
    sw = np.sqrt(weights)[..., None] * focal[None, :, None, :]  # whitened: pixels / sigma
    res = (proj - obs) * sw  # (N, C, 33, 2)
    if not normal:
        return res.reshape(n, -1), None
    # A: d(whitened residual)/d(point in the base frame), (N, C, 33, 2, 3)
    A = (R[None, :, None, :2, :] - proj[..., :, None] * R[None, :, None, 2:3, :]) * (sw / Z[..., None])[
        ..., None
    ]
    M = (A[..., :, :, None] * A[..., :, None, :]).sum(axis=(1, 3))  # (N, 33, 3, 3)
    v = (A * res[..., None]).sum(axis=(1, 3))  # (N, 33, 3)
    D = _point_jacobian(pts, T)  # (N, 33, 3, 47)
    E = M @ D
    Dt = D.reshape(n, -1, NUM_JOINTS).transpose(0, 2, 1)
    H = Dt @ E.reshape(n, -1, NUM_JOINTS)
    g = (Dt @ v.reshape(n, -1, 1))[..., 0]
    return res.reshape(n, -1), (H, g)


def _cameras_from_base(rig: Rig) -> F64:
    """(C, 4, 4): each camera's pose relative to the support base (the skeleton's frame)."""
    base_from_world = np.linalg.inv(rig.world_from_base)
    return np.stack([np.linalg.inv(base_from_world @ cam.world_from_camera.matrix()) for cam in rig.cameras])


def posterior_cov(landmarks: NDArray[np.float32], rig: Rig, q: F64, params: FitParams) -> F64:
    """(N, 47, 47): how well the landmarks pin the joints down around ``q`` (radians^2).

    The Laplace approximation of the posterior under the estimator's noise model: the
    Gauss-Newton information ``J^T W J`` of the landmarks (what the fit's normal equations
    hold) plus the sampling box's, approximated by a Gaussian of the box's variance ``w^2 / 12``;
    inverted. Evaluated at the *true* joints it tells what any estimate is left with (a Gaussian
    posterior's MAE is ``0.798 sigma`` per joint); along the ambiguous groups' curves
    (:mod:`.ambiguity`) the landmarks say nothing and only the box bounds it.
    """
    obs, weights, focal = _observations(landmarks, rig, params)
    q = np.asarray(q, dtype=np.float64)
    _, normal = _residuals(q, obs, weights, focal, _cameras_from_base(rig), normal=True)
    assert normal is not None
    lo, hi = sampling_box(params.limit_scale)
    return np.asarray(np.linalg.inv(normal[0] + np.diag(12.0 / (hi - lo) ** 2)), dtype=np.float64)


def fit_from(
    landmarks: NDArray[np.float32],
    rig: Rig,
    start: F64,
    prior: F64,
    prior_sigma: F64 | float,
    params: FitParams,
) -> tuple[F64, F64]:
    """Damped Gauss-Newton from ``start`` pulled towards ``prior`` (sigma per joint); (q, final cost)."""
    obs, weights, focal = _observations(landmarks, rig, params)
    cam_from_base = _cameras_from_base(rig)
    lo, hi = sampling_box(params.limit_scale)
    w_prior = np.broadcast_to(1.0 / np.asarray(prior_sigma, dtype=np.float64) ** 2, (NUM_JOINTS,))
    q = np.clip(start, lo, hi)
    mu = np.full(len(q), 1e-2)
    eye = np.eye(NUM_JOINTS)

    def cost(qq: F64, rr: F64) -> F64:
        return (rr**2).sum(1) + (w_prior * (qq - prior) ** 2).sum(1)

    r, normal = _residuals(q, obs, weights, focal, cam_from_base, normal=True)
    c = cost(q, r)
    for _ in range(params.iterations):
        assert normal is not None
        H = normal[0] + np.diag(w_prior)
        g = normal[1] + w_prior * (q - prior)
        damp = mu[:, None, None] * (np.einsum("nii->ni", H)[:, :, None] * eye)
        step = np.linalg.solve(H + damp, -g[..., None])[..., 0]
        q_new = np.clip(q + step, lo, hi)
        r_new, _ = _residuals(q_new, obs, weights, focal, cam_from_base, normal=False)
        c_new = cost(q_new, r_new)
        better = c_new < c
        q = np.where(better[:, None], q_new, q)
        c = np.where(better, c_new, c)
        mu = np.where(better, np.maximum(mu / 3.0, 1e-6), np.minimum(mu * 4.0, 1e6))
        r, normal = _residuals(q, obs, weights, focal, cam_from_base, normal=True)
    return q, c


def pixel_noise(landmarks: NDArray[np.float32], q: F64, rig: Rig) -> tuple[float, float]:
    """How far an estimator's landmarks lie from the skeleton's own, projected (robust sigma per
    axis, pixels): (seen, hidden), from samples with known joints q. For an estimator without a
    declared noise model (MediaPipe), measured on the training split."""
    world = landmark_positions(q, rig.world_from_base)
    errors: dict[bool, list[F64]] = {True: [], False: []}
    for k, cam in enumerate(rig.cameras):
        uv, ok = cam.project_camera_points(cam.world_to_camera(world.reshape(-1, 3)))
        obs = landmarks[:, k, :, :2].reshape(-1, 2).astype(np.float64) * [cam.width, cam.height]
        detected = np.repeat((landmarks[:, k, :, 3] > 0).any(axis=1), landmarks.shape[2])
        seen = landmarks[:, k, :, 3].reshape(-1) > 0
        for flag in (True, False):
            keep = ok & detected & (seen == flag)
            errors[flag].append((uv[keep] - obs[keep]).ravel())

    def sigma(e: list[F64], fallback: float) -> float:
        v = np.concatenate(e)
        return float(1.4826 * np.median(np.abs(v - np.median(v)))) if len(v) >= 20 else fallback

    seen_px = max(sigma(errors[True], 1.0), 0.1)
    return seen_px, max(sigma(errors[False], 8.0 * seen_px), seen_px)


@cache
def _arm_joints() -> NDArray[np.int64]:
    from simlan_data.world.skeleton import JOINT_NAMES

    arms = ("Shoulder_rot", "Elbow_rot", "Wrist_rot")
    return np.array([i for i, n in enumerate(JOINT_NAMES) if "C7" not in n and any(a in n for a in arms)])


class Refiner:
    """The learned estimate, refined by the fit: what ``algorithms.posemap.refine=fit`` adds to a model.

    Args:
        rig: the cameras the landmarks come from and where the support base stands.
        prior_sigma: (47,) how far the learned model is typically off per joint (its validation
            RMSE): the fit trusts it where the landmarks say little and overrules it elsewhere.
        params: noise model, iterations, restarts.
    """

    def __init__(self, rig: Rig, prior_sigma: NDArray[np.float64], params: FitParams) -> None:
        self.rig = rig
        self.prior_sigma = np.maximum(np.asarray(prior_sigma, dtype=np.float64), 1e-3)
        self.params = params
        self.restarted = 0  # samples that needed restarts, over all calls

    def __call__(self, landmarks: NDArray[np.float32], q_learned: F64, *, batch: int = 512) -> F64:
        q_learned = np.atleast_2d(np.asarray(q_learned, dtype=np.float64))
        out = np.empty_like(q_learned)
        for s in range(0, len(q_learned), batch):
            out[s : s + batch] = self._batch(np.asarray(landmarks[s : s + batch]), q_learned[s : s + batch])
        return curve_medians(out, limit_scale=self.params.limit_scale) if self.params.curve_median else out

    def _arm_starts(self) -> F64:
        """(starts - 1, arm joints): where the restarts put the arms, drawn once from the seed."""
        lo, hi = sampling_box(self.params.limit_scale)
        arms = _arm_joints()
        rng = np.random.default_rng(self.params.seed)
        return rng.uniform(lo[arms], hi[arms], size=(self.params.starts - 1, len(arms)))

    def _batch(self, landmarks: NDArray[np.float32], q0: F64) -> F64:
        p = self.params
        q, c = fit_from(landmarks, self.rig, q0, q0, self.prior_sigma, p)
        detected = (landmarks[..., 3] > 0).any(axis=2)  # (N, C)
        dof = np.maximum(2 * landmarks.shape[2] * detected.sum(axis=1), 1)
        again = np.flatnonzero(c / dof > p.restart_chi2)
        if p.starts > 1 and len(again):
            self.restarted += len(again)
            arms = _arm_joints()
            for arm_start in self._arm_starts():  # the same for every sample: batching changes nothing
                start = q0[again].copy()
                start[:, arms] = arm_start
                q2, c2 = fit_from(landmarks[again], self.rig, start, q0[again], self.prior_sigma, p)
                better = c2 < c[again]
                q[again[better]], c[again[better]] = q2[better], c2[better]
        return q

    def to_dict(self) -> dict:
        return {"prior_sigma": self.prior_sigma.tolist(), "params": asdict(self.params)}

    @staticmethod
    def from_dict(d: dict, rig: Rig) -> Refiner:
        known = {f.name for f in fields(FitParams)}  # models saved with keys since dropped still load
        return Refiner(
            rig,
            np.asarray(d["prior_sigma"]),
            FitParams(**{k: v for k, v in d["params"].items() if k in known}),
        )
