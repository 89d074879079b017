"""Real tracker trajectories drive agents, and any run's ground truth exports back to that format
(issue 25 item 6): a hand-made file (a truck going straight with a constant yaw, a Jackal turning
with the file's yaw, a person appearing at the second stamp with no yaw) drives a short run; the
export of its ground truth is compared with the file at the file's stamps, the bag is read back
with the independent mcap reader between stamps (linear interpolation), and the replay scores the
localizer against the tracker's positions. The packaged real example (2 stamps) runs too.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import export_cli, made_once, run_cli
from simlan_data.algorithms.trajectory import Tracks, fake_yaw
from simlan_data.config import trajectory as setup
from simlan_data.errors import ConfigError

T0_MS = 1770030000000
CAMERAS = "cameras.ids=[160,161,162]"


def _stamps() -> list[dict]:
    out = []
    for k in range(4):  # 0..3 s
        a = 0.4 * k  # the Jackal turns 0.4 rad per second on a 1.5 m circle about (-12, 0.5)
        rows: list[list[float | None]] = [
            [1, -16.0 + 0.8 * k, -0.6, 0.0, 0.25],  # constant yaw: estimated from motion (+x: 0)
            [7, -12.0 + 1.5 * math.sin(a), 0.5 + 1.5 * (1 - math.cos(a)) - 1.5, 0.0, a],
        ]
        if k >= 1:  # appears at the second stamp, walks +y, no yaw
            rows.append([12, -10.0, -1.5 + 0.6 * (k - 1), 0.0, None])
        out.append({"time_stamp": T0_MS + 1000 * k, "object_list": rows})
    return out


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    def make(root: Path) -> None:
        (root / "in.json").write_text(json.dumps(_stamps()))
        args = ("experiment=trajectory", f"trajectory.file={root / 'in.json'}", "progress=false", CAMERAS)
        types = ("+trajectory.types.7=jackal", "+trajectory.types.12=humanoid")
        proc = run_cli(*args, *types, f"hydra.run.dir={root / 'run'}")
        assert proc.returncode == 0, proc.stderr
        proc = export_cli(root / "run", "trajectory", root / "out")
        assert proc.returncode == 0, proc.stderr
        proc = run_cli(str(root / "run"), "--out", str(root / "replay"), module="simlan_data.replay")
        assert proc.returncode == 0, proc.stderr

    return made_once(tmp_path_factory, "trajectory_runs", make)


def test_export_equals_the_file_at_its_stamps(made: Path) -> None:
    given = _stamps()
    exported = json.loads((made / "out" / "trajectory.json").read_text())
    assert [e["time_stamp"] for e in exported] == [e["time_stamp"] for e in given]  # epoch = the file's
    for want, got in zip(given, exported, strict=True):
        rows = {r[0]: r for r in got["object_list"]}
        assert sorted(rows) == sorted(r[0] for r in want["object_list"])  # 12 only from the second stamp
        for oid, x, y, z, yaw in want["object_list"]:
            assert np.allclose(rows[oid][1:4], [x, y, z], atol=3e-3), (oid, rows[oid])
            if oid == 7:  # the file's yaw (it varies)
                assert abs(math.remainder(rows[oid][4] - yaw, 2 * math.pi)) < 1e-3
    truck = [next(r for r in e["object_list"] if r[0] == 1)[4] for e in exported]
    person = [next(r for r in e["object_list"] if r[0] == 12)[4] for e in exported[1:]]
    assert np.allclose(truck, 0.0, atol=1e-6)  # constant 0.25 in the file: the heading of +x
    assert np.allclose(person, math.pi / 2, atol=1e-6)  # no yaw: the heading of +y


def test_ground_truth_is_linear_between_stamps(made: Path) -> None:
    """Read with the mcap reader (not ours): at 0.5 s the truck is half way, the person hidden."""
    (bag,) = (made / "run" / "recording").glob("*.mcap")
    at: dict[int, dict[str, list[float]]] = {}
    with bag.open("rb") as f:
        for _s, channel, _m, msg in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            if channel.topic == "/ground_truth/poses":
                t = msg.transforms[0].header.stamp
                ms = t.sec * 1000 + t.nanosec // 1_000_000 - T0_MS
                at[ms] = {
                    tr.child_frame_id: [
                        tr.transform.translation.x,
                        tr.transform.translation.y,
                        tr.transform.translation.z,
                    ]
                    for tr in msg.transforms
                }
    truck = at[500]["ground_truth/robot_agent_1/base_link"]
    assert np.allclose(truck, [-15.6, -0.6, 0.0], atol=2e-3)
    assert at[500]["ground_truth/robot_agent_12/base_link"][2] < -50  # not seen yet: below the floor
    assert np.allclose(at[1500]["ground_truth/robot_agent_12/base_link"], [-10.0, -1.2, 0.0], atol=2e-3)


def test_the_replay_scores_the_localizer_against_the_tracker(made: Path) -> None:
    live = json.loads((made / "run" / "metrics.json").read_text())
    replayed = json.loads((made / "replay" / "metrics.json").read_text())
    assert replayed["localization.robot_agent_1.ticks_valid"] > 0  # the cameras see the truck's marker
    # the localizer is told the tracker's velocities (as upstream's scenario_replay feeds cmd_vel):
    # it does not lag the truck at 0.8 m/s (measured 15 cm ATE when it was told 0)
    assert 0 < replayed["localization.robot_agent_1.ate_xy_rmse_m"] < 0.03
    assert (
        replayed["localization.robot_agent_1.ate_xy_rmse_m"]
        == live["localization.robot_agent_1.ate_xy_rmse_m"]
    )
    assert replayed["replay.localization.max_diff_to_live_m"] == 0


@pytest.mark.slow
def test_the_real_example_runs(tmp_path: Path) -> None:
    proc = run_cli("experiment=trajectory", "progress=false", CAMERAS, f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode == 0, proc.stderr
    proc = export_cli(tmp_path / "run", "trajectory", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    source = json.loads(Path(setup.TRAJECTORIES_DIR / "example_trajectory.json").read_text())
    exported = json.loads((tmp_path / "out" / "trajectory.json").read_text())
    assert [e["time_stamp"] for e in exported] == [e["time_stamp"] for e in source]
    for want, got in zip(source, exported, strict=True):
        assert np.allclose(
            [r[1:4] for r in got["object_list"]], [r[1:4] for r in want["object_list"]], atol=1e-5
        )
    again = export_cli(tmp_path / "run", "trajectory", tmp_path / "out")
    assert again.returncode == 2 and "never overwrites" in again.stderr  # refuses to overwrite
    proc = export_cli(tmp_path / "run", "trajectory", tmp_path / "out2")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out2" / "trajectory.json").read_bytes() == (
        tmp_path / "out" / "trajectory.json"
    ).read_bytes()


@pytest.mark.parametrize(
    ("text", "words"),
    [
        (None, "cannot read it"),
        ("[{", "not JSON"),
        (
            '[{"time_stamp": 1, "object_list": [[1, 0.0, 0.0, 0.0]]}, {"time_stamp": 2, "object_list": []}]',
            "object_list[0]",
        ),
        (
            '[{"time_stamp": 2, "object_list": []}, {"time_stamp": 2, "object_list": []}]',
            "stamps must increase",
        ),
    ],
)
def test_bad_files_fail_naming_field_value_and_fix(tmp_path: Path, text: str | None, words: str) -> None:
    path = tmp_path / "t.json"
    if text is not None:
        path.write_text(text)
    with pytest.raises(ConfigError) as err:
        setup.resolve("agents", {"file": str(path)})
    line = str(err.value)
    assert words in line and "trajectory.file" in line and "\n" not in line


def test_a_bad_file_exits_2_with_one_line(tmp_path: Path) -> None:
    proc = run_cli("experiment=trajectory", f"trajectory.file={tmp_path / 'missing.json'}", "progress=false")
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "trajectory.file" in proc.stderr
    assert "cannot read it" in proc.stderr
    # a file without experiment=trajectory: the spawn list's agents are not the file's
    proc = run_cli("trajectory.file=example_trajectory.json", "progress=false")
    assert proc.returncode == 2 and "experiment=trajectory" in proc.stderr


def test_commands_are_the_tracker_velocities() -> None:
    """Between two stamps the velocity of the straight line, along the heading; zero when absent."""
    tracks = Tracks.from_rows(
        [0, 1000, 2000], [[(1, 0.0, 0.0, 0.0, 0.0)], [(1, 0.5, 0.5, 0.0, 0.3)], [(2, 9.0, 9.0, 0.0, 0.0)]]
    )
    (v, w), _ = tracks.velocities(500_000_000)
    heading = 0.15  # the yaw interpolated half way
    assert v == pytest.approx(0.5 * math.cos(heading) + 0.5 * math.sin(heading))
    assert w == pytest.approx(0.3)
    assert tracks.velocities(1_500_000_000) == [(0.0, 0.0), (0.0, 0.0)]  # 1 held, then gone; 2 absent


def test_yaw_from_motion_follows_upstreams_faker() -> None:
    """Rate-limited (0.5 rad per stamp) then low-pass (0.3) towards the heading to the next point."""
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1.0, 2.0], [1.0, 3.0], [1.0, 4.0], [1.0, 4.0]])
    yaw = fake_yaw(xy)
    assert yaw[0] == 0.0  # the first heading of the motion (+x)
    assert np.allclose(yaw[1:4], [0.5, 1.0, 1.5])  # towards +y: at most 0.5 rad per stamp
    assert yaw[4] == pytest.approx(1.5 + 0.3 * (math.pi / 2 - 1.5))  # within 0.5: low-pass 0.3
    assert yaw[5] == yaw[6] == yaw[4]  # no further motion: held
