"""Fast pose-dataset generation (issue 26 item 2): the worker pool, the person crop, the pipe window.

Real renders (PyBullet EGL), real joblib (loky) worker processes, real MediaPipe Pose in
``.venv-mediapipe`` (the ``mediapipe_python`` fixture of test_posemap_video creates it where it
is missing, or the MediaPipe tests skip with the reason), real parquet files read back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_posemap_video import mediapipe_python  # noqa: F401 - the fixture

from conftest import DATASET_ARGS, run_cli
from simlan_data.algorithms.posemap.dataset import read_dataset
from simlan_data.algorithms.posemap.estimators import PIPE_WINDOW, CameraView, MediaPipeEstimator
from simlan_data.config.validation import compose_config
from simlan_data.errors import ConfigError
from simlan_data.sim.posemap_dataset import CaptureRig, generate_dataset, person_crop
from simlan_data.world.skeleton import sample_joints


def _dataset(tmp_path: Path, name: str, *args: str) -> Path:
    out = tmp_path / name
    proc = run_cli(*DATASET_ARGS, *args, f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr
    return out


def test_projection_dataset_is_byte_identical_for_any_worker_count(tmp_path: Path) -> None:
    # rendered depth occlusion: the workers render their slices of the samples in their own
    # processes; the seeded noise is drawn in the parent, so the parquet bytes are the same
    args = [*DATASET_ARGS, "posemap.samples=6", "posemap.occlusion=depth"]
    metrics = {}
    for workers in (1, 2):
        cfg = compose_config([*args, f"posemap.workers={workers}"])
        metrics[workers] = generate_dataset(cfg, tmp_path / str(workers), progress=False)
    serial, pooled = read_dataset(str(tmp_path / "1")), read_dataset(str(tmp_path / "2"))
    assert serial.sha256 == pooled.sha256
    assert (serial.landmarks[..., 3] > 0.5).any(axis=2).all()  # (the body is seen: not all zeros)
    assert metrics[2]["posemap.dataset.workers"] == 2


def test_person_crop_holds_the_body_with_its_margin() -> None:
    cfg = compose_config(["experiment=posemap_dataset", "world.fidelity=empty"])
    rig = CaptureRig(cfg, need_images=False)
    try:
        q = sample_joints(np.random.default_rng(3), 5, limit_scale=0.8)
        for qi in q:
            rig.humanoid.set_joints(qi)
            world, box = rig.humanoid.landmarks_world(), rig.humanoid.aabb()
            for cam in rig.cameras:
                crop = person_crop(cam, box, 0.25)
                tight = person_crop(cam, box, 0.0)
                assert crop is not None and tight is not None
                u0, v0, u1, v1 = crop
                assert 0 <= u0 < u1 <= cam.width and 0 <= v0 < v1 <= cam.height
                assert u0 <= tight[0] and v0 <= tight[1] and u1 >= tight[2] and v1 >= tight[3]
                assert (u1 - u0) * (v1 - v0) < cam.width * cam.height  # smaller than the image
                uv, ok = cam.project(world)
                inside = (uv[:, 0] >= tight[0]) & (uv[:, 0] <= tight[2]) & (uv[:, 1] >= tight[1])
                assert inside[ok].all()  # every landmark in the body's box's image
        # a box behind a camera has no crop: the full image is used
        cam = rig.cameras[0]
        behind = cam.world_from_camera.apply(np.array([[-0.1, -0.1, -2.0], [0.1, 0.1, -1.0]]))
        assert person_crop(cam, (behind.min(axis=0).tolist(), behind.max(axis=0).tolist()), 0.25) is None
    finally:
        rig.close()


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("posemap.workers=-1", "invalid posemap.workers=-1"),
        ("posemap.pool=dask", "invalid posemap.pool='dask'"),
        ("posemap.crop=head", "invalid posemap.crop='head'"),
        ("posemap.crop_margin=5", "invalid posemap.crop_margin=5"),
    ],
)
def test_bad_pool_settings_name_the_key(override: str, expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        compose_config([*DATASET_ARGS, override])
    assert expected in str(err.value).splitlines()[0]


# ------------------------------------------------------------------------------ real MediaPipe
def _rendered_views(n: int) -> list[list[CameraView]]:
    cfg = compose_config(["experiment=posemap_dataset", "posemap.estimator=mediapipe", "cameras.ids=[502]"])
    rig = CaptureRig(cfg, need_images=True)
    try:
        q = sample_joints(np.random.default_rng(cfg.seed), n, limit_scale=0.8)
        out = []
        for qi in q:
            views = rig.views(qi, rays=False)
            out.append([CameraView(v.camera, v.rgb.copy(), None, None, crop=v.crop) for v in views])  # type: ignore[union-attr]
        return out
    finally:
        rig.close()


@pytest.mark.slow
def test_mediapipe_on_the_crop_lands_where_it_does_on_the_full_frame(
    mediapipe_python: str,  # noqa: F811
) -> None:
    samples = _rendered_views(12)
    views = [s[0] for s in samples]
    full_views = [CameraView(v.camera, v.rgb) for v in views]
    with MediaPipeEstimator(mediapipe_python) as est:
        assert isinstance(est, MediaPipeEstimator)
        crop = est.estimate(views)
        full = est.estimate(full_views)
    both = (crop[..., 3].max(axis=1) > 0) & (full[..., 3].max(axis=1) > 0)
    assert both.sum() >= 6
    size = np.array([views[0].camera.width, views[0].camera.height])
    # in full-image coordinates: the landmarks MediaPipe finds agree within a few pixels (median),
    # as they would not if the crop's coordinates were taken for the image's
    seen = (crop[both, :, 3] > 0.5) & (full[both, :, 3] > 0.5)
    dist = np.linalg.norm((crop[both, :, :2] - full[both, :, :2]) * size, axis=-1)[seen]
    assert np.median(dist) < 8.0, np.median(dist)
    raw = [v.rgb[v.crop[1] : v.crop[3], v.crop[0] : v.crop[2]] for v in views]  # type: ignore[index]
    with MediaPipeEstimator(mediapipe_python) as est:
        assert isinstance(est, MediaPipeEstimator)
        in_crop = est.estimate_images(raw)
    assert not np.allclose(in_crop[both, :, :2], crop[both, :, :2], atol=0.02)


@pytest.mark.slow
def test_more_images_than_the_pipe_window_in_one_call(mediapipe_python: str) -> None:  # noqa: F811
    # the answers queue in the worker's stdout pipe while images are sent: a call with many
    # images must not stop both sides (it did with about 20: 64 KiB of answers)
    views = [s[0] for s in _rendered_views(3)]
    crops = [v.rgb[v.crop[1] : v.crop[3], v.crop[0] : v.crop[2]] for v in views]  # type: ignore[index]
    images = [crops[i % 3] for i in range(5 * PIPE_WINDOW)]
    with MediaPipeEstimator(mediapipe_python) as est:
        assert isinstance(est, MediaPipeEstimator)
        one_by_one = np.stack([est.estimate_images([im])[0] for im in crops])
        many = est.estimate_images(images)
    assert many.shape == (5 * PIPE_WINDOW, 33, 4)
    for i in range(len(images)):
        assert np.array_equal(many[i], one_by_one[i % 3])


@pytest.mark.slow
def test_mediapipe_dataset_is_the_same_for_any_worker_count(
    tmp_path: Path,
    mediapipe_python: str,  # noqa: F811
) -> None:
    args = (
        "posemap.samples=6",
        "posemap.estimator=mediapipe",
        f"posemap.mediapipe_python={mediapipe_python}",
        "cameras.ids=[502]",
    )
    serial = read_dataset(str(_dataset(tmp_path, "serial", *args, "posemap.workers=1")))
    pooled = read_dataset(str(_dataset(tmp_path, "pooled", *args, "posemap.workers=2")))
    assert serial.landmarks[..., 3].max(axis=2).min() > 0  # found in every view
    assert np.array_equal(serial.landmarks, pooled.landmarks)


@pytest.mark.slow
def test_ray_pool_gives_the_same_dataset(tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="posemap.pool=ray needs the ray extra (pip install -e '.[ray]')")
    args = ("posemap.samples=6", "posemap.occlusion=depth")
    serial = read_dataset(str(_dataset(tmp_path, "serial", *args)))
    on_ray = read_dataset(str(_dataset(tmp_path, "ray", *args, "posemap.workers=2", "posemap.pool=ray")))
    assert serial.sha256 == on_ray.sha256
