"""The kinematic refinement of pose mapping (gpss/posemap/fit.py): the fit, its curve medians,
its place in training and in a saved model. Real camera calibrations (the dataset's), the real
skeleton, the real training command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from simlan_data.algorithms.posemap import fit as F
from simlan_data.algorithms.posemap.ambiguity import (
    ambiguity_floor,
    ambiguous_groups,
    curve_medians,
    curve_tangents,
)
from simlan_data.algorithms.posemap.dataset import read_dataset, split_of
from simlan_data.algorithms.posemap.estimators import CameraView, ProjectionEstimator
from simlan_data.algorithms.posemap.features import Rig
from simlan_data.algorithms.posemap.training import TrainedMapper
from simlan_data.world import skeleton as S


def _rig(ds: Path) -> Rig:
    data = read_dataset(ds)
    return Rig.from_meta(data.meta["camera_models"], list(data.cameras), data.meta["position"])


def _views(rig: Rig, q: np.ndarray, noise_px: float, seed: int = 0) -> np.ndarray:
    """Landmarks (N, C, 33, 4) of joint vectors q seen by every camera, nothing hidden."""
    est = ProjectionEstimator(noise_px=noise_px, hidden_noise_px=noise_px, z_noise=0.0, seed=seed)
    world = S.landmark_positions(q, rig.world_from_base)
    return np.stack(
        [est.estimate([CameraView(cam, landmarks_world=w) for cam in rig.cameras]) for w in world]
    )


def test_normal_equations_match_finite_differences(trained: tuple[Path, Path]) -> None:
    rig = _rig(trained[0])
    q = S.sample_joints(np.random.default_rng(3), 3)
    lm = _views(rig, S.sample_joints(np.random.default_rng(4), 3), noise_px=1.0)
    params = F.FitParams()
    obs, w, focal = F._observations(lm, rig, params)
    base_from_world = np.linalg.inv(rig.world_from_base)
    cam_from_base = np.stack(
        [np.linalg.inv(base_from_world @ c.world_from_camera.matrix()) for c in rig.cameras]
    )
    r0, normal = F._residuals(q, obs, w, focal, cam_from_base, normal=True)
    assert normal is not None
    J = np.zeros((len(q), r0.shape[1], S.NUM_JOINTS))
    for j in range(S.NUM_JOINTS):
        dq = q.copy()
        dq[:, j] += 1e-6
        J[:, :, j] = (F._residuals(dq, obs, w, focal, cam_from_base, normal=False)[0] - r0) / 1e-6
    H, g = normal
    assert np.abs(J.transpose(0, 2, 1) @ J - H).max() < 1e-4 * np.abs(H).max()
    assert np.abs((J.transpose(0, 2, 1) @ r0[..., None])[..., 0] - g).max() < 1e-4 * np.abs(g).max()


def test_fit_puts_the_skeleton_on_the_landmarks_from_the_mean_pose(trained: tuple[Path, Path]) -> None:
    """Perfect views of 40 random bodies, the fit starting from the mean pose: the fitted skeleton's
    landmarks land on the true ones (the arms' restarts get it out of wrong minima)."""
    rig = _rig(trained[0])
    q_true = S.sample_joints(np.random.default_rng(5), 40)
    lm = _views(rig, q_true, noise_px=0.0)
    lo, hi = S.sampling_box(0.8)
    start = np.tile((lo + hi) / 2, (len(q_true), 1))  # the middle of the sampling box
    refiner = F.Refiner(rig, np.full(S.NUM_JOINTS, 0.5), F.FitParams(iterations=40, curve_median=False))
    q = refiner(lm, start)
    err = np.linalg.norm(S.landmark_positions(q) - S.landmark_positions(q_true), axis=2).mean(axis=1)
    assert np.median(err) < 0.002, np.sort(err)
    assert (err < 0.01).mean() >= 0.9, np.sort(err)
    # from the mean pose the arms often start in the wrong basin: the restarts are what fixes them
    single = F.Refiner(
        rig, np.full(S.NUM_JOINTS, 0.5), F.FitParams(iterations=40, starts=1, curve_median=False)
    )
    err1 = np.linalg.norm(S.landmark_positions(single(lm, start)) - S.landmark_positions(q_true), axis=2)
    assert err.mean() < err1.mean(axis=1).mean()


def _sd(cov: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("nii->ni", cov))


def test_posterior_sd_is_the_fits_error_scale(trained: tuple[Path, Path]) -> None:
    """The Laplace sigma the information bound is built from predicts the fit's actual error: fits
    of 150 noisy views (1 px at 480x270) started at the truth and barely pulled to it land about one sigma off
    on the joints the landmarks determine, and twice the noise almost doubles the sigma there."""
    rig = _rig(trained[0])
    q_true = S.sample_joints(np.random.default_rng(8), 150)
    lm = _views(rig, q_true, noise_px=1.0, seed=8)
    params = F.FitParams(noise_px=1.0, hidden_noise_px=1.0, iterations=30, starts=1, curve_median=False)
    sd = _sd(F.posterior_cov(lm, rig, q_true, params))
    assert sd.shape == q_true.shape and np.isfinite(sd).all()
    q_fit, _ = F.fit_from(lm, rig, q_true, q_true, 10.0, params)
    ambiguous = {n for group, _ in ambiguous_groups() for n in group}
    determined = [i for i, n in enumerate(S.JOINT_NAMES) if n not in ambiguous and np.median(sd[:, i]) < 0.08]
    assert len(determined) >= 15, len(determined)
    z = (q_fit - q_true)[:, determined] / sd[:, determined]
    assert 0.7 < z.std() < 1.4, z.std(axis=0)
    doubled = _sd(F.posterior_cov(lm, rig, q_true, F.FitParams(noise_px=2.0, hidden_noise_px=2.0)))
    ratio = np.median(doubled[:, determined] / sd[:, determined])
    assert 1.6 < ratio <= 2.0, ratio  # below 2 only by the box's share of the information


def test_curve_median_depends_on_the_curve_not_on_the_point() -> None:
    """Two configurations with identical landmarks (one arm's shoulder + elbow twist moved along its
    curve) get the same best estimate; and the ambiguity floor keeps its measured value."""
    from scipy.spatial.transform import Rotation

    q = S.sample_joints(np.random.default_rng(1), 1)[0]
    idx = [
        S.JOINT_NAMES.index(n)
        for n in ("jLeftShoulder_rotx", "jLeftShoulder_roty", "jLeftShoulder_rotz", "jLeftElbow_roty")
    ]
    R = Rotation.from_euler("XYZ", q[idx[:3]]).as_matrix() @ Rotation.from_euler("Y", q[idx[3]]).as_matrix()
    other = q.copy()
    other[idx[3]] = q[idx[3]] - 0.2
    other[idx[:3]] = Rotation.from_matrix(R @ Rotation.from_euler("Y", -other[idx[3]]).as_matrix()).as_euler(
        "XYZ"
    )
    assert np.allclose(S.landmark_positions(other[None]), S.landmark_positions(q[None]), atol=1e-9)
    a, b = curve_medians(np.stack([q, other]), grid=801)
    assert np.abs(a[idx] - b[idx]).max() < 0.02  # one grid step apart at most
    assert np.abs(a[idx] - q[idx]).max() > 0.0  # it did move the ambiguous angles
    floor = sum(ambiguity_floor(n=300).values()) / S.NUM_JOINTS
    assert 0.06 < floor < 0.075, floor


def test_curve_tangents_leave_the_landmarks_unchanged() -> None:
    """A step along an ambiguous group's tangent moves its joints but not the landmarks (to second
    order); the same step along any other direction of those joints moves them."""
    q = S.sample_joints(np.random.default_rng(2), 20)
    T = curve_tangents(q)
    assert T.shape == (20, S.NUM_JOINTS, 4)
    base = S.landmark_positions(q)
    for k in range(4):
        t = T[:, :, k] / np.linalg.norm(T[:, :, k], axis=1, keepdims=True)
        along = np.abs(S.landmark_positions(q + 1e-3 * t) - base).max()
        other = np.roll(t, 1, axis=1)  # the same joints' step, shuffled: off the curve
        across = np.abs(S.landmark_positions(q + 1e-3 * other) - base).max()
        assert along < 1e-5 and across > 1e-4, (k, along, across)


def test_training_with_refine_beats_the_learned_model_alone(trained: tuple[Path, Path]) -> None:
    ds, run = trained
    metrics = json.loads((run / "metrics.json").read_text())
    # tiny model (450 samples): learned alone about 0.36 rad; the fit brings it far below
    assert metrics["posemap.mae_rad"] < 0.75 * metrics["posemap.learned.mae_rad"], metrics
    assert metrics["posemap.mpjpe_m"] < 0.5 * metrics["posemap.baseline.mean_pose.mpjpe_m"]
    info = json.loads((run / "model" / "model.json").read_text())
    # (algorithms.posemap.refine=fit: the fit is saved with the model)
    assert info["refine"] is not None and len(info["refine"]["prior_sigma"]) == S.NUM_JOINTS
    # the saved model refines the same way when loaded (the drive and the replay use this path)
    data = read_dataset(ds)
    te = np.flatnonzero(split_of(data.sample_ids, val_fraction=0.1, test_fraction=0.15) == "test")[:12]
    q = TrainedMapper(str(run)).predict(data.landmarks[te])
    assert np.abs(q - data.joints[te]).mean() < metrics["posemap.learned.mae_rad"]


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("algorithms.posemap.refine=icp", "invalid algorithms.posemap.refine='icp'"),
        ("algorithms.posemap.refine_starts=0", "invalid algorithms.posemap.refine_starts=0"),
        ("algorithms.posemap.refine_iterations=0", "invalid algorithms.posemap.refine_iterations=0"),
    ],
)
def test_bad_refine_config_is_one_line_and_exit_2(tmp_path: Path, override: str, expected: str) -> None:
    from conftest import run_cli

    proc = run_cli(
        "experiment=posemap_train", "posemap.dataset=/tmp", override, f"hydra.run.dir={tmp_path / 'r'}"
    )
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], proc.stderr


def test_pixel_noise_recovers_the_projection_estimators_noise(trained: tuple[Path, Path]) -> None:
    """What the fit measures for an estimator without a noise model (MediaPipe), checked where the
    truth is known: the projection estimator's 1 px (seen) and 8 px (hidden) at 480x270."""
    data = read_dataset(trained[0])
    seen, hidden = F.pixel_noise(data.landmarks, data.joints, _rig(trained[0]))
    assert seen == pytest.approx(1.0, rel=0.1) and hidden == pytest.approx(8.0, rel=0.15), (seen, hidden)
