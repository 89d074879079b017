"""Photometric sensor model (issue 24) against physics: the shot-noise law, exposure against gain,
cos^4 vignetting through the real lens model, ADC quantization, saturation, and the exactness and
determinism of the noise-phase row cache. Real numpy/OpenCV on SIMLAN camera 160 at 960x540."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from simlan_data.config.sensors import PhotometricConfig
from simlan_data.geometry.calibration import load_calibration
from simlan_data.geometry.camera import CameraModel
from simlan_data.imaging.sensor_model import (
    CHUNK_PX,
    NOISE_SCALE,
    NoiseBank,
    PhotometricParams,
    SensorModel,
    changed_blocks,
    dirty_rects,
    realistic_defaults,
    vignetting_map,
)
from simlan_data.seeding import run_rng
from simlan_data.sim.sensors import AutoExposure

H, W = 540, 960
# a small full well keeps the 8-bit output's code step well below the noise (test 1)
NOISY = PhotometricParams(full_well_e=1000.0, read_noise_e=3.0)
CLEAN = PhotometricParams(full_well_e=10000.0, read_noise_e=0.0, noise=False)


@pytest.fixture(scope="module")
def camera() -> CameraModel:
    return load_calibration(160).camera.scaled(W, H)


def model(camera: CameraModel, params: PhotometricParams, seed: int = 7) -> SensorModel:
    return SensorModel(params, camera, run_rng(seed, "camera_noise", camera.camera_id))


def flat(value: int) -> np.ndarray:
    return np.full((H, W, 3), value, np.uint8)


def linear(out: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    return (out.astype(np.float64) / 255.0) ** gamma


def electron_stats(out: np.ndarray, params: PhotometricParams, gain: float) -> tuple[float, float]:
    """Mean and variance in electrons of a flat output image: each 8-bit code inverted exactly,
    less the output code step's own variance (step^2 / 12, the step in electrons at the mean)."""
    e = linear(out, params.gamma) * params.full_well_e / gain
    mean_code = float(out.mean())
    step_e = params.full_well_e / gain * params.gamma * (mean_code / 255.0) ** (params.gamma - 1) / 255.0
    return float(e.mean()), float(e.var()) - step_e**2 / 12.0


def test_variance_against_mean_is_the_shot_noise_line_with_read_noise_as_intercept(camera) -> None:
    sensor = model(camera, NOISY)
    stats = [
        electron_stats(sensor.apply(flat(v), 0), NOISY, 1.0) for v in (40, 60, 90, 120, 150, 180, 210, 235)
    ]
    mean, var = np.array(stats).T
    assert mean.min() < 25 and mean.max() > 800  # the levels span ~17 to ~840 electrons
    slope, intercept = np.polyfit(mean, var, 1)
    adc_step_e = NOISY.full_well_e / (2**NOISY.adc_bits - 1)
    assert slope == pytest.approx(1.0, abs=0.02)  # Poisson: variance = mean
    assert intercept == pytest.approx(NOISY.read_noise_e**2 + adc_step_e**2 / 12, abs=1.5)


def test_four_times_the_gain_at_a_quarter_exposure_keeps_brightness_and_doubles_relative_noise(
    camera,
) -> None:
    sensor = model(camera, NOISY)
    base = sensor.apply(flat(180), 0)
    traded = sensor.apply(flat(180), 0, exposure_scale=0.25, gain=4.0)
    assert abs(float(base.mean()) - float(traded.mean())) < 0.3
    rel = []
    for out, gain, exposure in ((base, 1.0, 1.0), (traded, 4.0, 0.25)):
        mean, var = electron_stats(out, NOISY, gain)
        signal = (180 / 255) ** 2.2 * NOISY.full_well_e * exposure
        expected = np.sqrt(signal + NOISY.read_noise_e**2) / signal
        assert np.sqrt(var) / mean == pytest.approx(expected, rel=0.02)
        rel.append(np.sqrt(var) / mean)
    assert rel[1] / rel[0] == pytest.approx(2.0, rel=0.04)


def test_vignetting_centre_to_corner_is_one_minus_vignetting_and_falls_with_radius(camera) -> None:
    params = replace(CLEAN, vignetting=0.3)
    out = model(camera, params).apply(flat(255), 0)
    lin = linear(out)[..., 1]
    cx, cy = (round(float(c)) for c in camera.K[:2, 2])
    for corner in ((0, 0), (0, W - 1), (H - 1, 0), (H - 1, W - 1)):
        assert lin[corner] / lin[cy, cx] == pytest.approx(0.7, rel=0.01)
        rows = np.linspace(cy, corner[0], 200).round().astype(int)
        cols = np.linspace(cx, corner[1], 200).round().astype(int)
        assert np.all(np.diff(lin[rows, cols]) <= 0)  # monotonic out to the corner
        assert lin[rows[100], cols[100]] < lin[cy, cx]  # and actually falling
    # the map itself is cos^4 of the lens model's field angle, scaled to the corner's loss; the
    # largest field angle is the valid radius of the distortion model (the corners have no ray)
    vmap = vignetting_map(camera, 0.3)
    cos4_max_angle = (1.0 / (1.0 + camera.valid_radius**2)) ** 2
    pixels = np.array([[cx + 150, cy + 40], [cx - 300, cy - 200], [cx + 400, cy + 100], [100, 60]], float)
    rays, ok = camera.pixel_rays(pixels)
    assert ok.all()
    expected = 1 - 0.3 * (1 - rays[:, 2] ** 4) / (1 - cos4_max_angle)
    got = vmap[pixels[:, 1].astype(int), pixels[:, 0].astype(int)]
    assert got == pytest.approx(expected, abs=2e-3)
    assert (vignetting_map(camera, 0.0) == 1).all()


def test_a_twelve_bit_adc_keeps_more_output_levels_of_a_ramp_than_an_eight_bit_one(camera) -> None:
    ramp = np.broadcast_to(np.linspace(0, 255, W).round().astype(np.uint8)[None, :, None], (H, W, 3))
    levels = {}
    for bits in (8, 12):
        out = model(camera, replace(CLEAN, adc_bits=bits)).apply(ramp, 0)
        levels[bits] = np.unique(out)
        # the spec: linear, quantized to the ADC, gamma-encoded back
        qmax = 2**bits - 1
        code = np.floor((np.arange(256) / 255.0) ** 2.2 * qmax + 0.5)
        assert set(levels[bits]) == set(np.rint(255 * (code / qmax) ** (1 / 2.2)).astype(int))
    assert len(levels[12]) >= 245
    assert len(levels[8]) <= len(levels[12]) - 40  # the darks collapse at 8 bits
    # quantization error in linear space stays within half an ADC step (no noise)
    out12 = model(camera, replace(CLEAN, adc_bits=12)).apply(ramp, 0)
    err = linear(out12) - linear(ramp)
    assert np.abs(err).max() < 0.01


def test_equal_seeds_equal_outputs_and_the_row_cache_is_exact(camera) -> None:
    rng = np.random.default_rng(3)
    base = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    changed = base.copy()
    changed[100:121] = rng.integers(0, 256, (21, W, 3), dtype=np.uint8)
    frames = [base] * 9 + [changed, changed, base]
    a, b = model(camera, NOISY), model(camera, NOISY)
    outs_a = [a.apply(f, i) for i, f in enumerate(frames)]
    outs_b = [b.apply(f, i) for i, f in enumerate(frames)]
    assert all(np.array_equal(x, y) for x, y in zip(outs_a, outs_b, strict=True))
    for i in (9, 10, 11):  # cached phases give what a fresh model gives for that frame and phase
        fresh = model(camera, NOISY).apply(frames[i], i)
        assert np.array_equal(outs_a[i], fresh)
    # frame 9 reused phase 1's rows from frame 1 outside rows 100-120
    differ = np.flatnonzero((outs_a[9] != outs_a[1]).any(axis=(1, 2)))
    assert differ.min() >= 100 and differ.max() <= 120
    # the noise repeats with the phase and differs between phases
    assert np.array_equal(outs_a[0], outs_a[8]) and not np.array_equal(outs_a[0], outs_a[1])
    assert a.phase(8) == 0 and a.phase(9) == 1
    # an exposure change recomputes everything and still matches a fresh model
    dimmer = a.apply(changed, 17, exposure_scale=0.5)
    assert np.array_equal(dimmer, model(camera, NOISY).apply(changed, 17, exposure_scale=0.5))
    other = model(camera, NOISY, seed=8).apply(base, 0)
    assert np.mean(other != outs_a[0]) > 0.5


def test_a_small_change_recomputes_only_its_blocks_exactly_and_never_alters_an_image_handed_out(
    camera,
) -> None:
    rng = np.random.default_rng(4)
    base = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    moved = base.copy()
    moved[200:231, 300:341] = rng.integers(0, 256, (31, 41, 3), dtype=np.uint8)  # a robot's patch
    a = model(camera, NOISY)
    outs = [a.apply(base, i) for i in range(9)]
    kept = outs[1].copy()
    out9 = a.apply(moved, 9)  # phase 1 again: only the patch's blocks recomputed
    assert np.array_equal(out9, model(camera, NOISY).apply(moved, 9))  # exact
    rows, cols = np.nonzero((out9 != outs[1]).any(axis=2))
    assert rows.min() >= 200 and rows.max() <= 230 and cols.min() >= 300 and cols.max() <= 340
    assert out9 is not outs[1] and np.array_equal(outs[1], kept)  # copy on write
    assert not out9.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        out9[0, 0] = 0
    # the other phases catch up with the patch once; then phase 1 hands out the same array again
    later = [a.apply(moved, i, changed=False) for i in range(10, 17)]
    assert all(out is not outs[i - 8] for i, out in zip(range(10, 17), later, strict=True))
    assert a.apply(moved, 17, changed=False) is out9
    # once nobody holds phase 1's image, its next change is written into that array in place
    ident = id(out9)
    del out9, outs, later
    back = a.apply(base, 25)
    assert id(back) == ident and np.array_equal(back, model(camera, NOISY).apply(base, 25))


def test_changed_false_is_not_trusted_across_a_skipped_frame(camera) -> None:
    rng = np.random.default_rng(5)
    base = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    moved = base.copy()
    moved[400:420, 700:760] = 0
    a = model(camera, NOISY)
    for i in range(9):
        a.apply(base, i, changed=i == 0)
    # frame 9 was lost (its render changed); frame 10 reuses that render: changed=False
    out = a.apply(moved, 10, changed=False)
    assert np.array_equal(out, model(camera, NOISY).apply(moved, 10))
    # from frame to frame the claim is trusted: once every phase caught up, a (lying) claim that
    # base is unchanged is not checked and the image stays moved's
    for i in range(11, 18):
        a.apply(moved, i, changed=False)
    assert np.array_equal(a.apply(base, 18, changed=False), model(camera, NOISY).apply(moved, 18))


def test_changed_blocks_and_their_rectangles() -> None:
    rng = np.random.default_rng(6)
    for width in (W, 100, 37):  # whole 64-bit words per chunk, and the byte-wise fallback
        before = rng.integers(0, 256, (50, width, 3), dtype=np.uint8)
        for _ in range(20):
            after = before.copy()
            r, c = int(rng.integers(0, 50)), int(rng.integers(0, width))
            after[r, c, int(rng.integers(0, 3))] ^= 1
            expected = np.zeros((50, -(-width // CHUNK_PX)), bool)
            expected[r, c // CHUNK_PX] = True
            assert np.array_equal(changed_blocks(before, after, CHUNK_PX), expected)
    dirty = np.zeros((H, W // CHUNK_PX), bool)
    dirty[10:20, 3] = dirty[25, 5] = True  # 5 rows apart: one rectangle
    dirty[300:302, 14] = True  # far below: another, clipped to the image's width
    assert dirty_rects(dirty, CHUNK_PX, W) == [(10, 26, 192, 384), (300, 302, 896, 960)]
    assert dirty_rects(np.zeros_like(dirty), CHUNK_PX, W) == []


def test_auto_exposure_meters_an_unchanged_render_once() -> None:
    cfg = PhotometricConfig(enabled=True, auto_exposure=True)
    bright, dark = flat(200), flat(60)
    trusting, metering = AutoExposure(cfg), AutoExposure(cfg)
    for ae in (trusting, metering):
        ae.settings(bright, 1.0, frame_index=0)
    # frame 1 claims to be the unchanged render: no correction (the level is frame 0's)
    assert trusting.settings(dark, 1.0, frame_index=1, changed=False) == (1.0, 1.0)
    assert metering.settings(dark, 1.0, frame_index=1, changed=True)[0] > 1.0
    # after a skipped frame the claim is not trusted: the dark image is metered and corrected
    assert trusting.settings(dark, 1.0, frame_index=3, changed=False)[0] > 1.0


def test_fresh_noise_per_frame_is_a_function_of_seed_and_frame_index(camera) -> None:
    params = replace(NOISY, noise_phases=0)
    a, b = model(camera, params), model(camera, params)
    image = flat(128)
    first = [a.apply(image, i) for i in (0, 1, 2)]
    assert np.array_equal(b.apply(image, 2), first[2])  # order of calls does not matter
    assert not np.array_equal(first[0], first[1])
    assert a.phase(5) == -1


def test_white_saturates_and_half_exposure_darkens_by_the_gamma_law(camera) -> None:
    assert (model(camera, CLEAN).apply(flat(255), 0) == 255).all()
    noisy_white = model(camera, NOISY).apply(flat(255), 0)
    assert noisy_white.max() == 255 and 0.4 < np.mean(noisy_white == 255) < 0.7  # exactly at saturation
    assert (model(camera, NOISY).apply(flat(255), 0, gain=2.0) == 255).all()  # above it: clipped
    assert (model(camera, NOISY).apply(flat(200), 0, exposure_scale=3.0) == 255).all()
    sensor = model(camera, CLEAN)
    for value in (255, 200, 128, 60):
        out = sensor.apply(flat(value), 0, exposure_scale=0.5)
        expected = 255 * (0.5 * (value / 255) ** 2.2) ** (1 / 2.2)  # = value * 0.5^(1/2.2)
        assert np.abs(out.astype(float) - expected).max() <= 0.6
    assert sensor.apply(flat(255), 0, exposure_scale=0.5)[0, 0, 0] == 186


def test_parameters_and_inputs_are_checked(camera) -> None:
    defaults = realistic_defaults()
    assert 5000 <= defaults.full_well_e <= 12000 and 2 <= defaults.read_noise_e <= 3
    binned = realistic_defaults(binning=16)
    assert (
        binned.full_well_e == 16 * defaults.full_well_e and binned.read_noise_e == 4 * defaults.read_noise_e
    )
    with pytest.raises(ValueError, match="vignetting"):
        replace(defaults, vignetting=1.0)
    with pytest.raises(ValueError, match="shape"):
        model(camera, CLEAN).apply(np.zeros((H, W), np.uint8), 0)


def test_a_shared_noise_bank_gives_each_camera_its_own_fields_as_views_and_seeded(camera) -> None:
    shape = (camera.height, camera.width, 3)
    bank = NoiseBank(np.random.default_rng(1), shape, fields=16)
    a = bank.fields_for(run_rng(0, "camera_noise", "160"), 8, shape)
    b = bank.fields_for(run_rng(0, "camera_noise", "161"), 8, shape)
    again = bank.fields_for(run_rng(0, "camera_noise", "160"), 8, shape)
    assert len(a) == 8 and all(f.shape == shape and f.flags.c_contiguous for f in a)
    assert all(np.shares_memory(f, g) for f, g in zip(a, again, strict=True))  # seeded: the same views
    assert all(np.array_equal(f, g) for f, g in zip(a, again, strict=True))
    assert any(not np.array_equal(f, g) for f, g in zip(a, b, strict=True))  # another camera, other noise
    z = np.concatenate([f.ravel()[::97] for f in a]).astype(float) / NOISE_SCALE
    assert abs(z.mean()) < 0.01 and abs(z.std() - 1.0) < 0.01  # standard normal
    # a model on the bank is exact and cached like one that draws its own fields
    params = realistic_defaults()
    m1 = SensorModel(params, camera, run_rng(0, "camera_noise", "160"), bank=bank)
    m2 = SensorModel(params, camera, run_rng(0, "camera_noise", "160"), bank=bank)
    img = flat(120)
    out = [m1.apply(img, i) for i in range(10)]
    assert all(np.array_equal(o, m2.apply(img, i)) for i, o in enumerate(out))
    assert not np.array_equal(out[0], out[1])  # frame to frame the noise changes
    with pytest.raises(ValueError, match="holds 16 fields, 20 asked"):
        bank.fields_for(run_rng(0, "x"), 20, shape)
