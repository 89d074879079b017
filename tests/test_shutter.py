"""Motion blur and rolling shutter (issue 24, sensors.shutter): the sub-frame maths against the
physics, and a real run whose marker the localizer sees where the physics says it must be."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import made_once, run_cli
from simlan_data.geometry.calibration import load_calibration
from simlan_data.sim.shutter import combine, offsets, row_weights
from simlan_data.world.agent_types import AGENT_TYPES

H, W = 120, 200


def bar_frames(back_s: np.ndarray, speed_px_s: float, x0: float = 60.0, width: int = 30) -> list[np.ndarray]:
    """A white bar moving right at ``speed_px_s``; one frame per sub-frame time (seconds before t)."""
    frames = []
    for d in back_s:
        img = np.zeros((H, W, 3), np.uint8)
        left = round(x0 - speed_px_s * d)
        img[:, left : left + width] = 255
        frames.append(img)
    return frames


def edge_ramp_px(row: np.ndarray) -> float:
    """Width of the bar's leading edge ramp: columns strictly between black and white."""
    grey = row[:, 0].astype(float)
    return float(np.count_nonzero((grey > 0) & (grey < 255)))


def test_a_global_shutter_blurs_a_moving_edge_by_speed_times_exposure() -> None:
    speed, exposure = 1000.0, 0.02  # 1000 px/s for 20 ms: 20 px of blur
    back = offsets(exposure, 41)  # 0.5 px per sub-frame
    img = combine(bar_frames(back, speed), row_weights(back, H, exposure, 0.0))
    # two edges, each a ramp as long as the motion (in whole pixels, each sub-frame a step of 0.5 px)
    assert edge_ramp_px(img[H // 2]) / 2 == pytest.approx(speed * exposure, abs=1.0)
    # every row alike (no shear), and the ramp's mean level is the exposure's mean position
    assert all(np.array_equal(img[0], img[r]) for r in range(H))
    still = combine(bar_frames(back, 0.0), row_weights(back, H, exposure, 0.0))
    assert edge_ramp_px(still[H // 2]) == 0


def test_a_rolling_shutter_shears_a_moving_edge_by_speed_times_line_time_per_row() -> None:
    speed, line = 1000.0, 1e-4  # 0.1 px per row: 11.9 px over the 119 rows above the last
    span = (H - 1) * line
    back = offsets(span, 120)  # one sub-frame per row
    img = combine(bar_frames(back, speed), row_weights(back, H, 0.0, line))

    def left_edge(r: int) -> int:
        return int(np.argmax(img[r, :, 0] > 127))

    # the top row was exposed (H - 1) * line earlier: the bar was further left there
    assert left_edge(H - 1) - left_edge(0) == pytest.approx(speed * span, abs=1.0)
    assert left_edge(H - 1) == 60  # the last row: where the bar is at the stamp
    skew = [left_edge(r) for r in range(H)]
    assert skew == sorted(skew)  # monotonic shear


def test_row_weights_take_the_nearest_sub_frame_where_none_falls_in_a_rows_window() -> None:
    back = offsets(0.01, 3)  # 10, 5, 0 ms before t
    w = row_weights(back, 4, 0.0, 0.001)  # instantaneous rows 0-3 ms before t
    np.testing.assert_allclose(w.sum(axis=0), 1.0)
    assert w[:, 3].argmax() == 2 and w[:, 0].argmax() == 1  # rows at 0 and 3 ms: the 0 and 5 ms frames


# ------------------------------------------------------------------------------- real runs
RUN_ARGS = (
    "duration_s=4",
    "progress=false",
    "cameras.ids=[161]",
    "cameras.streams=[rgb]",
    "seed=3",
)  # 161 sees the spawn
BLUR = ("sensors.shutter.enabled=true", "sensors.shutter.exposure_s=0.04")
TRUTH = ("localization.source=ground_truth",)  # the robot steers on truth: the same physics in both


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    cases = {"truth_ideal": TRUTH, "truth_blur": (*TRUTH, *BLUR), "blur": BLUR}

    def make(root: Path) -> None:
        for name, extra in cases.items():
            proc = run_cli(*RUN_ARGS, *extra, f"hydra.run.dir={root / name}")
            assert proc.returncode == 0, proc.stderr

    root = made_once(tmp_path_factory, "shutter_runs", make)
    return {name: root / name for name in cases}


def topic_messages(run: Path, topics: list[str]) -> dict[str, list[tuple[int, object]]]:
    out: dict[str, list[tuple[int, object]]] = {t: [] for t in topics}
    with (run / "recording" / "recording.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _s, channel, message, decoded in reader.iter_decoded_messages(topics=topics):
            out[channel.topic].append((message.log_time, decoded))
    return out


def poses(msgs: list[tuple[int, object]]) -> np.ndarray:
    """(t, x, y, yaw) of the truck's ground truth."""
    rows = []
    for t, tf in msgs:
        tr = tf.transforms[0].transform
        yaw = 2 * np.arctan2(tr.rotation.z, tr.rotation.w)
        rows.append((t, tr.translation.x, tr.translation.y, yaw))
    return np.array(rows)


def test_rendering_the_sub_frames_leaves_the_simulation_untouched(runs: dict[str, Path]) -> None:
    topics = ["/ground_truth/poses", "/camera_161/effects"]
    ideal, blur = topic_messages(runs["truth_ideal"], topics), topic_messages(runs["truth_blur"], topics)
    # the robot is moved back and forth for every sub-frame, and the physics never sees it
    np.testing.assert_array_equal(poses(ideal["/ground_truth/poses"]), poses(blur["/ground_truth/poses"]))
    effects = [e for _, e in blur["/camera_161/effects"]]
    assert (
        max(e.subframes for e in effects) > 2 and min(e.subframes for e in effects) == 1
    )  # moving / standing
    assert all(e.exposure_time_s == pytest.approx(0.04) for e in effects)


def test_the_blurred_marker_is_seen_where_the_robot_was_at_mid_exposure(runs: dict[str, Path]) -> None:
    topics = ["/ground_truth/poses", "/camera_161/marker_detections", "/camera_161/effects"]
    msgs = topic_messages(runs["blur"], topics)
    gt, effects = poses(msgs["/ground_truth/poses"]), dict(msgs["/camera_161/effects"])
    camera = load_calibration(161).camera.scaled(960, 540)
    marker = np.array(AGENT_TYPES["pallet_truck"].marker_xyz)

    def marker_px(t_ns: float) -> np.ndarray:
        x, y, yaw = (np.interp(t_ns, gt[:, 0], gt[:, k]) for k in (1, 2, 3))
        c, s = np.cos(yaw), np.sin(yaw)
        world = np.array([x + c * marker[0] - s * marker[1], y + s * marker[0] + c * marker[1], marker[2]])
        return camera.project(world[None, :])[0][0]

    at_stamp, at_mid, motion = [], [], []
    for t, d in msgs["/camera_161/marker_detections"]:
        if not len(d.ids) or effects[t].subframes < 3:
            continue
        seen = np.asarray(d.corners_px[:8], dtype=float).reshape(4, 2).mean(axis=0)
        at_stamp.append(np.linalg.norm(seen - marker_px(t)))
        at_mid.append(np.linalg.norm(seen - marker_px(t - 0.02e9)))  # half of the 40 ms exposure
        motion.append(np.linalg.norm(marker_px(t) - marker_px(t - 0.02e9)))
    assert len(at_stamp) >= 5
    assert np.median(motion) > 1.0  # pixels of motion in half an exposure: blur that matters
    # a blurred marker is seen where the robot was at mid-exposure (speed x exposure / 2 back)
    assert np.median(at_stamp) == pytest.approx(np.median(motion), rel=0.3)
    assert np.median(at_mid) < 0.35 * np.median(at_stamp)
