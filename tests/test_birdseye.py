"""Bird's-eye stitcher: lookup tables against the camera model, a synthetic floor texture stitched
within the error bound, coverage of the default network, and bad canvas configs."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import compose_config, run_cli
from simlan_data.algorithms.birdseye import BirdseyeStitcher, CanvasSpec, camera_footprint, project_points
from simlan_data.algorithms.birdseye_simlan import SimlanBirdseye
from simlan_data.config.schema import BirdseyeConfig
from simlan_data.config.validation import to_config
from simlan_data.errors import ConfigError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.sim.pybullet_client import Client
from simlan_data.sim.rendering import CameraRenderer, LabelTable

DEFAULT_IDS = range(160, 171)


def _camera(cid: int, width: int = 960, height: int = 540):
    return load_calibration(cid).camera.scaled(width, height)


def test_canvas_geometry() -> None:
    spec = CanvasSpec()
    assert (spec.width, spec.height) == (2100, 1000)
    x, y = spec.pixel_to_world(np.array([0, 2099]), np.array([0, 999]))
    assert np.allclose(x, [-7.99, 33.99]) and np.allclose(y, [9.99, -9.99])
    col, row = spec.world_to_pixel(x, y)
    assert np.allclose(col, [0, 2099]) and np.allclose(row, [0, 999])


@pytest.mark.parametrize("cid", [160, 163, 168])
def test_lookup_table_matches_camera_model(cid: int) -> None:
    """Every valid canvas pixel maps where cv2.projectPoints puts its world point, onto a pixel
    whose bilinear neighbours all have a ray in the rendered image."""
    cam = _camera(cid)
    spec = CanvasSpec()
    fp = camera_footprint(cam, spec)
    assert fp is not None
    rows, cols = np.nonzero(fp.valid)
    pick = np.random.default_rng(cid).choice(rows.size, 3000, replace=False)
    r, c = rows[pick], cols[pick]
    x, y = spec.pixel_to_world(c + fp.cols.start, r + fp.rows.start)
    uv, ok = cam.project(np.stack([x, y, np.zeros_like(x)], 1))  # cv2.projectPoints
    assert ok.all()
    lut = np.stack([fp.map_x[r, c], fp.map_y[r, c]], 1)
    assert np.abs(lut - uv).max() < 2e-3  # float32 maps
    # the renderer's own mask of pixels with a valid ray (no PyBullet call needed to build it)
    valid = CameraRenderer(Client(-1, "egl"), cam, LabelTable()).valid_mask
    iu, iv = np.floor(lut[:, 0]).astype(int), np.floor(lut[:, 1]).astype(int)
    assert (valid[iv, iu] & valid[iv + 1, iu] & valid[iv, iu + 1] & valid[iv + 1, iu + 1]).all()
    assert (fp.density[r, c] > 0).all()
    # the numpy projection the tables use is cv2.projectPoints' model, everywhere
    pts = np.stack([x, y, np.full_like(x, 1.3)], 1)
    a, oka = cam.project(pts)
    b, okb = project_points(cam, pts)
    assert (oka == okb).all() and np.abs(a - b)[oka].max() < 1e-6


def _ground_texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A known colour texture on the floor: smooth waves of 0.7-1.3 m, different per channel."""
    r = 128 + 90 * np.sin(2 * np.pi * x / 1.3) * np.cos(2 * np.pi * y / 0.9)
    g = 128 + 90 * np.cos(2 * np.pi * (x + y) / 1.1)
    b = 128 + 90 * np.sin(2 * np.pi * (x - 0.5 * y) / 0.7)
    return np.stack([r, g, b], axis=-1)


def _synthetic_image(cam) -> np.ndarray:
    """What the camera sees of the textured floor: each pixel's ray hits the floor at one point."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    ground, ok = cam.intersect_plane_z(np.stack([u.ravel(), v.ravel()], 1), 0.0)
    rgb = _ground_texture(ground[:, 0], ground[:, 1]) * ok[:, None]
    return np.rint(rgb).astype(np.uint8).reshape(cam.height, cam.width, 3)


def test_synthetic_floor_is_stitched_within_the_error_bound() -> None:
    """Two overlapping cameras see a known floor texture; the stitched canvas reproduces it."""
    cams = [_camera(cid, 480, 270) for cid in (163, 164)]
    spec = CanvasSpec((2.0, 24.0), (-6.0, 6.0), 25.0)
    frames = [_synthetic_image(c) for c in cams]
    rows, cols = np.mgrid[0 : spec.height, 0 : spec.width]
    truth = _ground_texture(*spec.pixel_to_world(cols, rows))
    ours = BirdseyeStitcher(cams, spec)
    assert ours.seam_fraction > 0.01  # the two cameras overlap and are blended there
    canvas = ours.stitch(frames)
    # where a camera pixel spans at most ~1.4 canvas pixels (elsewhere the camera cannot resolve
    # the texture: point-sampled images alias, whatever the stitcher does)
    resolved = ours.coverage & (ours.density >= 0.5)
    assert resolved.mean() > 0.5 * ours.coverage.mean()
    err = np.abs(canvas.astype(float) - truth)[resolved]
    # bilinear interpolation of a point-sampled image: about one grey level
    assert np.median(err) < 1.5 and np.percentile(err, 99) < 8
    mse = np.mean(err**2)
    assert 10 * np.log10(255**2 / mse) > 35
    # ignoring the distortion puts the texture metres off: the test sees geometry errors
    pinhole = BirdseyeStitcher(cams, spec, distort=False)
    bad = np.abs(pinhole.stitch(frames).astype(float) - truth)[pinhole.coverage & resolved]
    assert np.median(bad) > 10 * np.median(err)
    # SIMLAN's method: grey, min-max normalized, averaged with cameras that do not see the pixel
    simlan = SimlanBirdseye(cams, spec).stitch(frames)
    assert simlan.ndim == 2 and simlan.shape == (spec.height, spec.width)


def test_uncovered_pixels_stay_black_and_only_covering_cameras_count() -> None:
    cams = [_camera(cid, 480, 270) for cid in (163, 164)]
    spec = CanvasSpec((2.0, 24.0), (-6.0, 6.0), 25.0)
    st = BirdseyeStitcher(cams, spec)
    white = [np.full((c.height, c.width, 3), 255, np.uint8) for c in cams]
    canvas = st.stitch(white)
    assert (canvas[~st.coverage] == 0).all()
    # weights sum to one over the cameras that see a pixel: white stays white (no dark seams)
    assert (canvas[st.coverage] >= 254).all()


def test_default_network_coverage() -> None:
    """Cameras 160-170 at 960x540 see 90 % of SIMLAN's default area (x -8..34, y -10..10)."""
    cams = [_camera(cid) for cid in DEFAULT_IDS]
    st = BirdseyeStitcher(cams, CanvasSpec())
    assert all(fp is not None for fp in st.footprints)
    assert 0.89 < st.coverage.mean() < 0.92
    assert 0.03 < st.seam_fraction < 0.15
    spec = st.spec
    col, row = (
        np.rint(a).astype(int) for a in spec.world_to_pixel(np.array([6.4, 30.0]), np.array([1.0, -6.0]))
    )
    # under camera 163 (nadir) it is the primary; south-east of 165 nobody looks
    assert st.primary[row[0], col[0]] == cams.index(next(c for c in cams if c.camera_id == "163"))
    assert not st.coverage[row[1], col[1]]
    # SIMLAN's pinhole footprints cover less (the barrel lens sees wider than its pinhole)
    assert SimlanBirdseye(cams, spec).coverage.mean() < st.coverage.mean() - 0.2


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"x_m": (5.0, 5.0)}, r"invalid birdseye.x_m=\[5.0, 5.0\] in config: empty region"),
        ({"y_m": (3.0, -3.0)}, r"invalid birdseye.y_m=.*empty region"),
        ({"x_m": (0.0, float("nan"))}, r"invalid birdseye.x_m=.*expected \[min, max\]"),
        ({"x_m": "ab"}, r"invalid birdseye.x_m='ab' .*expected \[min, max\]"),
        ({"px_per_m": "fine"}, r"invalid birdseye.px_per_m='fine' .*expected a number"),
        ({"px_per_m": 0.0}, r"invalid birdseye.px_per_m=0.0 .*must be within"),
        ({"px_per_m": 1e6}, r"invalid birdseye.px_per_m=.*must be within"),
        ({"px_per_m": 1000.0}, r"invalid birdseye.px_per_m=1000.0 .*Mpx \(limit 64 Mpx\)"),
        ({"x_m": (0.0, 0.01), "px_per_m": 10.0}, r"the canvas would be 0x200 pixels"),
        ({"plane_z_m": 50.0}, r"invalid birdseye.plane_z_m=50.0 .*-5..20 m"),
    ],
)
def test_bad_canvas_is_refused(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        CanvasSpec(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"rate_hz": -1.0}, r"invalid birdseye.rate_hz=-1.0 .*0..100 Hz"),
        ({"jpeg_quality": 0}, r"invalid birdseye.jpeg_quality=0"),
        ({"x_m": [1.0, -1.0]}, r"invalid birdseye.x_m=\[1.0, -1.0\].*empty region"),
    ],
)
def test_bad_birdseye_config_is_refused(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        BirdseyeConfig(**kwargs)


def test_birdseye_rate_must_divide_the_camera_rate() -> None:
    with pytest.raises(ConfigError, match=r"invalid birdseye.rate_hz=2.0 .*must divide the camera rate"):
        to_config(compose_config("birdseye.rate_hz=2"))
    assert to_config(compose_config("birdseye.rate_hz=1")).birdseye.rate_hz == 1.0


def test_bad_canvas_in_a_run_gives_one_line_and_exit_2(tmp_path) -> None:
    proc = run_cli("birdseye.x_m=[5,5]", f"hydra.run.dir={tmp_path / 'run'}", "progress=false")
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines == [
        "error: invalid birdseye.x_m=[5.0, 5.0] in config: empty region (max must exceed min); "
        "give birdseye.x_m=[min,max] with min < max"
    ]
    assert not (tmp_path / "run" / "recording").exists()


def test_marker_plane_lookup_table() -> None:
    """On the plane z = 1.3 m (the robots' markers) the table maps points of that plane."""
    cam = _camera(163)
    spec = CanvasSpec((2.0, 12.0), (-4.0, 6.0), 20.0, plane_z_m=1.3)
    fp = camera_footprint(cam, spec)
    assert fp is not None
    rows, cols = np.nonzero(fp.valid)
    x, y = spec.pixel_to_world(cols + fp.cols.start, rows + fp.rows.start)
    uv, ok = cam.project(np.stack([x, y, np.full_like(x, 1.3)], 1))
    assert ok.all()
    assert np.abs(np.stack([fp.map_x[rows, cols], fp.map_y[rows, cols]], 1) - uv).max() < 2e-3
    # a camera 7.3 m up sees less of a plane 1.3 m closer to it
    floor = camera_footprint(cam, CanvasSpec((2.0, 12.0), (-4.0, 6.0), 20.0))
    assert floor is not None and fp.valid.sum() < floor.valid.sum()
