"""Realistic cameras end to end (issue 24): a real run with `sensors=realistic`, its bag read back
with the independent mcap + mcap_ros2 decoder, and its replay.

The effects are made strong (20 % of frames lost, a 20 ms clock offset spread, a 1 cm / 0.5 deg
bump, cameras exposing up to 0.1 s apart, a 30 ms transport delay) so that a 3 s run shows each
of them.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import made_once, run_cli

STRONG = (
    "sensors=realistic",
    "sensors.timing.drop_rate=0.2",
    "sensors.timing.clock_offset_s=0.02",
    "sensors.drift.position_m=0.01",
    "sensors.drift.rotation_deg=0.5",
    "sensors.timing.exposure_spread_s=0.1",  # free-running cameras, up to half a frame apart
    "sensors.timing.delay_s=0.03",
    "sensors.timing.delay_jitter_s=0.01",
)
COMMON = ("duration_s=3", "progress=false", "cameras.streams=[rgb]", "seed=3")  # the 11 GPSS cameras
CAMERAS = [str(c) for c in range(160, 171)]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    def make(root: Path) -> None:
        for name, extra in (("real", STRONG), ("ideal", ())):
            proc = run_cli(*COMMON, *extra, f"hydra.run.dir={root / name}")
            assert proc.returncode == 0, proc.stderr

    root = made_once(tmp_path_factory, "sensor_runs", make)
    return {"real": root / "real", "ideal": root / "ideal"}


def read(run: Path, prefix: str = "/camera_") -> dict[str, list[tuple[int, object]]]:
    """topic -> [(log time, decoded message)] of the camera topics."""
    out: dict[str, list[tuple[int, object]]] = defaultdict(list)
    (bag,) = (run / "recording").glob("*.mcap")
    with bag.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            if channel.topic.startswith(prefix) or channel.topic == "/tf_static":
                out[channel.topic].append((message.log_time, decoded))
    return out


def ns(t) -> int:
    return t.sec * 1_000_000_000 + t.nanosec


def test_every_effect_is_in_the_recording_and_the_header_stamps_are_the_cameras_clocks(
    runs: dict[str, Path],
) -> None:
    topics = read(runs["real"])
    dropped_total = 0
    offsets, phases = [], []
    for cid in CAMERAS:
        effects = topics[f"/camera_{cid}/effects"]
        images = dict(topics[f"/camera_{cid}/image_raw/compressed"])
        assert len(effects) == 16  # 3 s at 5 Hz, and the frame at 0: every rendered frame, lost ones too
        lags = []
        for log, eff in effects:
            # the true exposure time: the arrival (log time) less the phase and transport delay
            assert ns(eff.header.stamp) == log - round(eff.delay_s * 1e9)
            lags.append(eff.delay_s)
            if eff.dropped:
                dropped_total += 1
                assert log not in images  # a lost frame is not recorded
                continue
            # the image's header carries the stamp the camera wrote, not the true time
            assert ns(images[log].header.stamp) == ns(eff.stamp_written)
            offsets.append(ns(eff.stamp_written) - ns(eff.header.stamp))
            assert 0 <= eff.noise_phase < 8
        assert lags[0] == 0.0  # nothing shows the scene before the run began
        phases.append(min(lags[1:]))
        assert min(lags[1:]) > 0.0 and max(lags) < 0.1 + 0.03 + 0.05  # phase + delay (+ jitter)
        assert len(images) == sum(not e.dropped for _, e in effects)
    assert 15 <= dropped_total <= 60  # 20 % of 176
    assert (
        max(abs(o) for o in offsets) > 1_000_000
    )  # clocks 20 ms apart (standard deviation): > 1 ms somewhere
    assert len({round(o / 1e6) for o in offsets}) > 3  # offsets differ between cameras (and jitter)
    assert max(phases) - min(phases) > 0.02  # the cameras expose at their own instants


def test_the_true_camera_pose_is_bumped_from_the_recorded_calibration(runs: dict[str, Path]) -> None:
    topics = read(runs["real"])
    believed = {}
    for _, tf in topics["/tf_static"]:
        for t in tf.transforms:
            believed[t.child_frame_id] = np.array(
                [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z]
            )
    for cid in CAMERAS:
        _, eff = topics[f"/camera_{cid}/effects"][0]
        p = eff.true_pose.position
        shift = np.linalg.norm(np.array([p.x, p.y, p.z]) - believed[f"camera_{cid}_optical_frame"])
        assert 1e-4 < shift < 0.06  # a bump of 1 cm per axis (standard deviation)


def test_realistic_images_are_noisy_and_vignetted_where_the_ideal_ones_are_not(runs: dict[str, Path]) -> None:
    real, ideal = read(runs["real"]), read(runs["ideal"])
    topic = "/camera_163/image_raw/compressed"
    ideal_by_log = dict(ideal[topic])
    log, msg = real[topic][0]
    a = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_GRAYSCALE).astype(float)
    b = cv2.imdecode(np.frombuffer(ideal_by_log[log].data, np.uint8), cv2.IMREAD_GRAYSCALE).astype(float)
    h, w = a.shape
    centre = (slice(h // 2 - 40, h // 2 + 40), slice(w // 2 - 40, w // 2 + 40))
    # the image's rim loses light against its centre (vignetting), relative to the ideal image
    # (the lens's far corners have no rays: black in both)
    yy, xx = np.mgrid[0:h, 0:w]
    r = np.hypot(xx - w / 2, yy - h / 2) / (w / 2)
    lit = b > 40
    ratio = a / np.maximum(b, 1)
    assert ratio[lit & (r > 0.85)].mean() < 0.9 * ratio[lit & (r < 0.15)].mean()
    # and the noise: frame-to-frame differences of a static region (two noise fields) exceed the ideal's
    _, msg2 = real[topic][1]
    a2 = cv2.imdecode(np.frombuffer(msg2.data, np.uint8), cv2.IMREAD_GRAYSCALE).astype(float)
    b2 = cv2.imdecode(
        np.frombuffer(dict(ideal[topic])[real[topic][1][0]].data, np.uint8), cv2.IMREAD_GRAYSCALE
    )
    assert np.std(a2[centre] - a[centre]) > 1.0 + np.std(b2.astype(float)[centre] - b[centre])


def test_replay_reproduces_the_live_run_under_every_effect(runs: dict[str, Path], tmp_path: Path) -> None:
    proc = run_cli(str(runs["real"]), "--out", str(tmp_path / "replay"), module="simlan_data.replay")
    assert proc.returncode == 0, proc.stderr
    line = next(x for x in proc.stdout.splitlines() if "replay.localization.max_diff_to_live_m" in x)
    assert float(line.split()[1]) <= 1e-9


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ("sensors.timing.drop_rate=1.5", "sensors.timing.drop_rate"),
        ("sensors.photometric.vignetting=-0.2", "sensors.photometric.vignetting"),
        ("sensors.drift.rotation_deg=45", "sensors.drift"),
        ("sensors.timing.delay_s=-0.03", "sensors.timing.delay_s"),
        ("sensors.timing.exposure_spread_s=1.5", "sensors.timing"),
        ("sensors.photometric.lighting=[[2.0,-1.0]]", "sensors.photometric.lighting"),
        ("sensors.photometric.lighting=[[5.0,0.5],[2.0,0.25]]", "sensors.photometric.lighting"),
    ],
)
def test_a_bad_sensor_setting_is_refused_in_one_line_and_nothing_is_written(
    override: str, field: str, tmp_path: Path
) -> None:
    proc = run_cli("sensors=realistic", override, f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode == 2
    lines = [x for x in proc.stderr.strip().splitlines() if x.strip()]
    assert len(lines) == 1 and field in lines[0], proc.stderr
    assert not (tmp_path / "run").exists()


@pytest.fixture(scope="module")
def dimmed(tmp_path_factory: pytest.TempPathFactory) -> dict[bool, Path]:
    """The light drops to 1/8 at 1 s (camera 163 alone), with and without auto-exposure."""

    def make(root: Path) -> None:
        for ae in (True, False):
            proc = run_cli(
                "duration_s=4",
                "progress=false",
                "cameras.ids=[163]",
                "cameras.streams=[rgb]",
                "sensors=realistic",
                "sensors.timing.enabled=false",
                "sensors.photometric.lighting=[[1.0,0.125]]",
                f"sensors.photometric.auto_exposure={str(ae).lower()}",
                f"hydra.run.dir={root / str(ae)}",
            )
            assert proc.returncode == 0, proc.stderr

    root = made_once(tmp_path_factory, "sensor_dimmed", make)
    return {True: root / "True", False: root / "False"}


def brightness_and_settings(run: Path) -> list[tuple[float, float, float, float, float]]:
    """Per frame: (t s, light, exposure, gain, mean grey level of the recorded image's centre)."""
    topics = read(run)
    images = dict(topics["/camera_163/image_raw/compressed"])
    out = []
    for log, eff in topics["/camera_163/effects"]:
        grey = cv2.imdecode(np.frombuffer(images[log].data, np.uint8), cv2.IMREAD_GRAYSCALE)
        h, w = grey.shape
        level = float(grey[h // 3 : 2 * h // 3, w // 3 : 2 * w // 3].mean())
        out.append((log / 1e9, eff.illumination, eff.exposure_scale, eff.gain, level))
    return out


@pytest.mark.slow
def test_auto_exposure_restores_the_brightness_after_the_light_drops_exposure_first_then_gain(
    dimmed: dict[bool, Path],
) -> None:
    on, off = brightness_and_settings(dimmed[True]), brightness_and_settings(dimmed[False])
    t0 = on[0][0]
    before = on[0][4]
    assert all(light == 1.0 for t, light, *_ in on if t - t0 < 1.0)
    assert all(light == 0.125 for t, light, *_ in on if t - t0 >= 1.0)
    # without it the image darkens by the gamma law: 0.125 ** (1 / 2.2) = 0.39
    assert off[-1][4] == pytest.approx(before * 0.125 ** (1 / 2.2), rel=0.05)
    assert all((e, g) == (1.0, 1.0) for *_, e, g, _ in off)
    # with it: exposure to its limit (4x), then gain makes up the rest (2x): brightness back within the deadband
    _, _, exposure, gain, level = on[-1]
    assert exposure == pytest.approx(4.0) and 1.5 < gain < 2.5
    assert level == pytest.approx(before, rel=0.1)
    assert exposure * gain * 0.125 == pytest.approx(1.0, rel=0.15)


@pytest.mark.slow
def test_cameras_whose_clocks_run_ahead_do_not_stop_the_robot(tmp_path: Path) -> None:
    """A camera clock ahead of the simulation stamps its images in the future: the fix is then
    just new, not 'never seen' (which stopped the robot for good before: seed 0's cameras 160/161
    run ahead at sensors=realistic's 2 ms)."""
    proc = run_cli(
        "duration_s=3",
        "progress=false",
        "cameras.streams=[rgb]",
        "seed=0",
        "sensors=realistic",
        "sensors.photometric.enabled=false",
        "sensors.drift.enabled=false",
        "sensors.shutter.enabled=false",
        f"hydra.run.dir={tmp_path / 'run'}",
    )
    assert proc.returncode == 0, proc.stderr
    assert "  sensors        realistic: timing; " in proc.stdout  # the summary says what is on
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["navigation.robot_agent_1.driven_m"] > 1.0
    assert metrics["safety.robot_agent_1.stops"] == 0


@pytest.mark.slow
def test_the_live_birdseye_view_survives_cameras_whose_first_frames_are_lost(tmp_path: Path) -> None:
    """With 90 % of frames lost some camera has delivered nothing when the stitcher first runs:
    it gets black for that camera (a KeyError ended the run before)."""
    proc = run_cli(
        "duration_s=2",
        "progress=false",
        "cameras.streams=[rgb]",
        "sensors=realistic",
        "sensors.timing.drop_rate=0.9",
        "birdseye.rate_hz=1",
        f"hydra.run.dir={tmp_path / 'run'}",
    )
    assert proc.returncode == 0, proc.stderr
    birdseye = read(tmp_path / "run", prefix="/birdseye")["/birdseye/image"]
    assert len(birdseye) == 3  # at 0, 1 and 2 s
