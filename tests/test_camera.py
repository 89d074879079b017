"""Camera model: projection, distortion, scaling, OpenGL conventions, rotations (vs OpenCV/scipy)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simlan_data.geometry import rotations as rot
from simlan_data.geometry.calibration import load_calibration
from simlan_data.geometry.camera import opengl_projection
from simlan_data.geometry.transforms import Transform


@pytest.fixture(scope="module")
def cam():
    return load_calibration("163").camera.scaled(960, 540)


def _floor_points(cam, n: int = 400, z: float = 0.0) -> np.ndarray:
    """World points that project inside the valid image area of ``cam``."""
    rng = np.random.default_rng(0)
    uv = rng.uniform([60, 40], [900, 500], size=(n, 2))
    pts, ok = cam.intersect_plane_z(uv, z)
    return pts[ok]


def test_project_matches_opencv_projectpoints(cam) -> None:
    pts = _floor_points(cam)
    uv, ok = cam.project(pts)
    assert ok.all()
    rvec, _ = cv2.Rodrigues(cam.camera_from_world.rotation)
    ref, _ = cv2.projectPoints(pts, rvec, cam.camera_from_world.translation, cam.K, cam.D)
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-6)


def test_pixel_to_plane_round_trip(cam) -> None:
    rng = np.random.default_rng(1)
    uv = rng.uniform([100, 60], [860, 480], size=(500, 2))
    for z in (0.0, 1.3):
        pts, ok = cam.intersect_plane_z(uv, z)
        assert ok.all()
        np.testing.assert_allclose(pts[:, 2], z, atol=1e-9)
        back, ok2 = cam.project(pts)
        assert ok2.all()
        np.testing.assert_allclose(back, uv, atol=1e-6)


def test_undistort_inverts_distort_everywhere_valid(cam) -> None:
    u, v = np.meshgrid(np.arange(0, 960, 7.0), np.arange(0, 540, 7.0))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    xy, ok = cam.undistort_pixels(uv)
    assert 0.75 < ok.mean() < 0.95  # strong barrel distortion: the corners have no valid ray
    np.testing.assert_allclose(cam.distort_normalized(xy[ok]), uv[ok], atol=1e-6)
    # the centre is always valid, the far corners never
    _, ok_c = cam.undistort_pixels([[cam.K[0, 2], cam.K[1, 2]], [0.0, 0.0]])
    assert ok_c.tolist() == [True, False]


def test_valid_radius_is_where_the_radial_model_stops_growing(cam) -> None:
    k1, k2, _, _, k3 = cam.D
    r = np.linspace(0, cam.valid_radius, 1000)
    slope = 1 + 3 * k1 * r**2 + 5 * k2 * r**4 + 7 * k3 * r**6
    assert slope.min() == pytest.approx(0.1, abs=1e-3)
    assert np.all(np.diff(r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)) > 0)


def test_scaling_is_pixel_centre_aware() -> None:
    native = load_calibration("160").camera
    small = native.scaled(960, 540)
    assert small.K[0, 0] == pytest.approx(native.K[0, 0] / 4)
    # the same world point lands on corresponding pixel coordinates: u' = (u + 0.5) / 4 - 0.5
    pts = _floor_points(small, 50)
    uv_n, _ = native.project(pts)
    uv_s, _ = small.project(pts)
    np.testing.assert_allclose(uv_s, (uv_n + 0.5) / 4 - 0.5, atol=1e-9)


def test_position_is_minus_rt_t(cam) -> None:
    R, t = cam.camera_from_world.rotation, cam.camera_from_world.translation
    np.testing.assert_allclose(cam.position, -R.T @ t)
    np.testing.assert_allclose(cam.world_from_camera.apply(np.zeros(3)), cam.position)


def test_opengl_matrices_map_points_to_opencv_pixels(cam) -> None:
    pts = _floor_points(cam, 100)
    uv, _ = cam.project(pts, distort=False)
    view = np.array(cam.opengl_view()).reshape(4, 4).T
    for u0, v0, w, h in ((0, 0, 960, 540), (300, 200, 128, 64)):
        K = cam.K.copy()
        K[0, 2] -= u0
        K[1, 2] -= v0
        proj = np.array(opengl_projection(K, w, h, near_m=1.0, far_m=100.0)).reshape(4, 4).T
        clip = (proj @ view @ np.c_[pts, np.ones(len(pts))].T).T
        ndc = clip[:, :3] / clip[:, 3:4]
        # window coordinates (x right, y up from the bottom), pixel centres at +0.5
        xw, yw = (ndc[:, 0] + 1) * w / 2, (ndc[:, 1] + 1) * h / 2
        np.testing.assert_allclose(xw - 0.5 + u0, uv[:, 0], atol=1e-6)
        np.testing.assert_allclose((h - yw) - 0.5 + v0, uv[:, 1], atol=1e-6)
        assert np.all(np.abs(ndc[:, 2]) < 1)


def test_rotation_conversions_agree_with_opencv_and_scipy() -> None:
    rng = np.random.default_rng(2)
    for rv in rng.normal(size=(20, 3)):
        R_cv, _ = cv2.Rodrigues(rv)
        np.testing.assert_allclose(rot.matrix_from_rodrigues(rv), R_cv, atol=1e-12)
        np.testing.assert_allclose(rot.rodrigues_from_matrix(R_cv), cv2.Rodrigues(R_cv)[0].ravel(), atol=1e-9)
        q = rot.quat_from_matrix(R_cv)
        assert q[3] >= 0
        np.testing.assert_allclose(rot.matrix_from_quat(q), R_cv, atol=1e-12)
        np.testing.assert_allclose(
            Rotation.from_matrix(R_cv).as_quat() * np.sign(Rotation.from_matrix(R_cv).as_quat()[3]),
            q,
            atol=1e-12,
        )
    # the closed form used for single quaternions equals scipy's batch conversion
    quats = Rotation.random(50, random_state=3).as_quat()
    np.testing.assert_allclose(
        np.array([rot.matrix_from_quat(q) for q in quats]), rot.matrix_from_quat(quats), atol=1e-12
    )
    yaw = 2.5
    assert rot.yaw_from_quat(rot.quat_from_yaw(yaw)) == pytest.approx(yaw)
    assert rot.yaw_from_matrix(rot.matrix_from_quat(rot.quat_from_rpy(0.0, 0.0, yaw))) == pytest.approx(yaw)


def test_transform_compose_and_inverse() -> None:
    a = Transform.from_xyz_rpy([1, 2, 3], [0.1, -0.2, 0.3])
    b = Transform.from_pose2d(-4.0, 0.5, 1.0)
    p = np.array([[0.3, -0.7, 2.0]])
    np.testing.assert_allclose((a @ b).apply(p), a.apply(b.apply(p)))
    np.testing.assert_allclose((a @ a.inverse()).matrix(), np.eye(4), atol=1e-12)


def test_few_points_undistort_like_many(cam) -> None:
    """A marker's corners take the plain-float path; it gives what the array path gives."""
    from simlan_data.geometry import camera as camera_module

    rng = np.random.default_rng(3)
    uv = rng.uniform([-30, -30], [990, 570], size=(400, 2))  # valid and invalid pixels
    many_xy, many_ok = cam.undistort_pixels(uv)
    assert len(uv) > camera_module.SCALAR_MAX_POINTS
    few = [cam.undistort_pixels(uv[i : i + 4]) for i in range(0, len(uv), 4)]
    few_xy = np.concatenate([f[0] for f in few])
    few_ok = np.concatenate([f[1] for f in few])
    assert 0 < many_ok.sum() < len(uv)
    np.testing.assert_array_equal(few_ok, many_ok)
    np.testing.assert_allclose(few_xy[many_ok], many_xy[many_ok], rtol=0, atol=1e-13)


@pytest.mark.parametrize("camera_id", ["160", "163", "168", "500"])
def test_few_points_plane_and_projection_like_the_array_path(camera_id: str) -> None:
    """intersect_plane_z_few / project_few (a marker's corners) against intersect_plane_z and
    cv2.projectPoints, including pixels without a valid ray and points behind the camera."""
    cam = load_calibration(camera_id).camera.scaled(960, 540)
    rng = np.random.default_rng(int(camera_id))
    uv = rng.uniform([-30, -30], [990, 570], size=(800, 2))
    for z in (0.0, 0.35, 1.5):
        many, ok = cam.intersect_plane_z(uv, z)
        for i in range(0, len(uv), 4):
            few = cam.intersect_plane_z_few(uv[i : i + 4], z)
            assert (few is not None) == bool(ok[i : i + 4].all())
            if few is not None:
                np.testing.assert_allclose(few, many[i : i + 4, :2], rtol=0, atol=1e-9)
    rvec, _ = cv2.Rodrigues(cam.camera_from_world.rotation)
    pts = np.concatenate([_floor_points(cam, 200, 0.3), cam.position + rng.normal(0, 3, (40, 3))])
    _, ok = cam.project(pts)
    assert 0 < (~ok).sum() < len(pts)  # some behind the camera or outside the valid radius
    ref, _ = cv2.projectPoints(pts, rvec, cam.camera_from_world.translation, cam.K, cam.D)
    ref = ref.reshape(-1, 2)
    for i in range(len(pts)):
        one = cam.project_few([tuple(pts[i])])
        assert (one is not None) == bool(ok[i])
        if one is not None:
            np.testing.assert_allclose(one[0], ref[i], rtol=0, atol=1e-7)
