"""Late cameras (issue 24): a frame shows the scene when its camera exposed, not when it arrived.

With the robot steering on ground truth (so that what the cameras see cannot change the motion), a
transport delay of exactly one camera period must deliver, at every tick, the image the ideal run
recorded one tick earlier, bit for bit, stamped with that earlier instant; and the physics must
not notice (the same ground truth). Read back with the independent mcap + mcap_ros2 decoder.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import made_once, run_cli

COMMON = (
    "duration_s=2",
    "progress=false",
    "cameras.streams=[rgb]",
    "seed=3",
    "localization.source=ground_truth",  # open loop: the images cannot change the motion
)
PERIOD_S = 0.2  # the cameras' 5 Hz


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    def make(root: Path) -> None:
        late = ("sensors.timing.enabled=true", f"sensors.timing.delay_s={PERIOD_S}")
        for name, extra in (("ideal", ()), ("late", late)):
            proc = run_cli(*COMMON, *extra, f"hydra.run.dir={root / name}")
            assert proc.returncode == 0, proc.stderr

    root = made_once(tmp_path_factory, "sensor_lag_runs", make)
    return {"ideal": root / "ideal", "late": root / "late"}


def ns(t) -> int:
    return t.sec * 1_000_000_000 + t.nanosec


def read(run: Path) -> tuple[dict[tuple[str, int], tuple[int, bytes]], list[bytes], dict[str, float]]:
    """(topic, header stamp) -> (log time, JPEG) of every image; the ground-truth messages; delays."""
    images, truth, delays = {}, [], {}
    (bag,) = (run / "recording").glob("*.mcap")
    with bag.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            if channel.topic.endswith("/image_raw/compressed"):
                images[(channel.topic, ns(decoded.header.stamp))] = (message.log_time, bytes(decoded.data))
            elif channel.topic == "/ground_truth/poses":
                truth.append(message.data)
            elif channel.topic.endswith("/effects") and message.log_time > 0:
                delays[f"{channel.topic}@{message.log_time}"] = decoded.delay_s
    return images, truth, delays


def test_a_delay_of_one_period_delivers_the_previous_ticks_image_stamped_with_its_instant(
    runs: dict[str, Path],
) -> None:
    ideal, ideal_truth, _ = read(runs["ideal"])
    late, late_truth, delays = read(runs["late"])
    matched = 0
    for key, (log, jpeg) in late.items():
        _, stamp = key
        if log - stamp == 0:  # the first tick: nothing shows the scene before the run began
            continue
        assert log - stamp == round(PERIOD_S * 1e9)  # arrives one period after it exposed
        assert jpeg == ideal[key][1]  # what the ideal run saw at that instant, bit for bit
        matched += 1
    assert matched == 11 * 10  # 11 cameras, 10 late ticks in 2 s
    assert ideal_truth == late_truth  # rendering the past never touched the physics
    assert sorted(set(delays.values()))[-1] == pytest.approx(PERIOD_S)
