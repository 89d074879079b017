"""The safety layer in a real (short) run, read back with an independent MCAP reader.

One 5 s run of three agents under cameras 162-163 (480x270, walls and floor markings only):

- robot_agent_1, a pallet truck, drives east into a zone it may not enter: stopped in front of it;
- robot_agent_2, a Jackal, drives north out of the cameras' coverage (observability timeout 0.5 s,
  navigation kept going on its dead-reckoned estimate): stopped blind;
- robot_agent_3, a person, walks along the aisle: found in the segmentation images (the oracle:
  the light world differs from the RGB detector's plates).

Then the counterfactual replay: unchanged it reproduces the live events; with a zone on the
Jackal's path it turns "entered" into "prevented"; bad zones are refused with one line, exit 2.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from shapely.geometry import Polygon

from conftest import run_cli
from simlan_data.algorithms.safety.geometry import footprint_polygon
from simlan_data.metrics_io import load_metrics
from simlan_data.recording import schema
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS
from simlan_data.world.agent_types import AGENT_TYPES

ZONE = [[2.6, -2.4], [4.5, -2.4], [4.5, 3.2], [2.6, 3.2]]
SPAWN = """# @package _global_
agents:
  robot_agent_1: {type: pallet_truck, pose: [-2.0, 1.5, 0.0], goals: [[9.0, 1.5]], speed_mps: 1.0}
  robot_agent_2: {type: jackal, pose: [8.0, 1.0, 1.5708], goals: [[8.0, 8.0]], speed_mps: 1.0}
  robot_agent_3: {type: humanoid, pose: [-1.0, -1.5, 0.0], goals: [[5.0, -1.5]], speed_mps: 1.0}
"""
SCENARIO = f"""# @package _global_
defaults:
  - override /agents: safety_test
scenario: {{name: safety_test}}
duration_s: 5.0
world: {{fidelity: light, settle_s: 0.0}}
people: {{detector: segmentation_oracle}}  # (the RGB detector's plates show the full warehouse, not this light one)
cameras: {{ids: [162, 163], width: 480, height: 270}}
algorithms:
  localizer: {{lost_timeout_s: 30.0}}
  safety:
    observability: {{timeout_s: 0.5}}
    zones:
      - {{name: test_bay, polygon: {ZONE}, namespaces: [robot_agent_1]}}
"""


@pytest.fixture(scope="module")
def safety_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("safety")
    conf = root / "conf"
    (conf / "agents").mkdir(parents=True)
    (conf / "scenario").mkdir()
    (conf / "agents" / "safety_test.yaml").write_text(SPAWN)
    (conf / "scenario" / "safety_test.yaml").write_text(SCENARIO)
    run_dir = root / "run"
    proc = run_cli(
        f"hydra.searchpath=[file://{conf}]",
        "scenario=safety_test",
        f"hydra.run.dir={run_dir}",
        "progress=false",
    )
    assert proc.returncode == 0, proc.stderr
    return run_dir


@dataclass
class _Msg:
    log_time_ns: int
    ros_msg: Any


def _read(run_dir: Path, topics: list[str]) -> list[_Msg]:
    """Messages of ``topics`` decoded by mcap + mcap_ros2 (not simlan_data's reader)."""
    mcap = next((run_dir / "recording").glob("*.mcap"))
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [
            _Msg(message.log_time - DEFAULT_EPOCH_NS, decoded)  # simulated time
            for _, _, message, decoded in reader.iter_decoded_messages(topics=topics, log_time_order=True)
        ]


def _truth(run_dir: Path, ns: str) -> np.ndarray:
    rows = []
    for m in _read(run_dir, ["/ground_truth/poses"]):
        for tf in m.ros_msg.transforms:
            if tf.child_frame_id == schema.ground_truth_frame(ns):
                q, p = tf.transform.rotation, tf.transform.translation
                yaw = np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2))
                rows.append((m.log_time_ns, p.x, p.y, yaw))
    return np.array(rows)


def _events(run_dir: Path) -> list:
    return [m.ros_msg for m in _read(run_dir, ["/safety/events"])]


def test_zone_entry_is_prevented_in_a_real_run(safety_run: Path) -> None:
    events = [e for e in _events(safety_run) if e.robot == "robot_agent_1"]
    assert [(e.action, e.cause, e.other) for e in events] == [("stop", "restricted_area", "test_bay")]
    zone = Polygon(ZONE)
    truck = AGENT_TYPES["pallet_truck"].footprint_m
    gaps = [
        footprint_polygon((x, y, yaw), truck).distance(zone)
        for _, x, y, yaw in _truth(safety_run, "robot_agent_1")
    ]
    assert min(gaps) > 0.2  # its true footprint never came near the zone
    assert gaps[-1] < 1.5  # and it did drive up to it (it would have entered)
    stop_ns = events[0].header.stamp.sec * 10**9 + events[0].header.stamp.nanosec - DEFAULT_EPOCH_NS
    after = [
        m.ros_msg.twist.linear.x
        for m in _read(safety_run, ["/robot_agent_1/cmd_vel"])
        if m.log_time_ns >= stop_ns
    ]
    assert after and all(v == 0.0 for v in after)  # the recorded command is the one after the layer
    metrics = json.loads((safety_run / "metrics.json").read_text())
    assert metrics["safety.robot_agent_1.violations"] == 0
    assert metrics["safety.violations.zone_entries"] == 0
    assert metrics["safety.min_clearance_zone_m"] > 0.2
    zones = _read(safety_run, ["/safety/zones"])
    assert len(zones) == 1
    ring = zones[0].ros_msg.markers[0]
    assert ring.text == "" and [(p.x, p.y) for p in ring.points][:4] == [tuple(c) for c in ZONE]
    assert zones[0].ros_msg.markers[1].text == "test_bay"


def test_blind_spot_stop_in_a_real_run(safety_run: Path) -> None:
    events = [e for e in _events(safety_run) if e.robot == "robot_agent_2"]
    assert [(e.action, e.cause) for e in events] == [("stop", "unobserved")]
    stop = events[0]
    stop_s = (stop.header.stamp.sec * 10**9 + stop.header.stamp.nanosec - DEFAULT_EPOCH_NS) * 1e-9
    assert stop.pose_valid and stop.speed_mps > 0.5  # it was driving blind on its estimate
    status = [
        (m.log_time_ns * 1e-9, m.ros_msg.fix_age_s)
        for m in _read(safety_run, ["/robot_agent_2/localization_status"])
    ]
    last_fresh = max(t for t, age in status if age == 0.0)
    assert 0.5 < stop_s - last_fresh <= 0.5 + 0.05 + 1e-6  # the timeout, then within one control period
    truth = _truth(safety_run, "robot_agent_2")
    assert truth[-1, 2] > 4.3  # it really left the cameras' view (y > 4.25 m)
    metrics = json.loads((safety_run / "metrics.json").read_text())
    assert metrics["safety.robot_agent_2.missed"] == 0
    assert metrics["safety.robot_agent_2.max_latency_s"] <= metrics["safety.latency_budget_s"] + 1e-9
    assert metrics["safety.false_stops"] == 0
    state = [m.ros_msg.state for m in _read(safety_run, ["/robot_agent_2/safety_state"])]
    assert state[0] == "drive" and state[-1] == "stop"


def test_people_are_found_in_the_segmentation_images(safety_run: Path) -> None:
    truth = _truth(safety_run, "robot_agent_3")
    errors = []
    for m in _read(safety_run, ["/people/detections"]):
        i = int(np.searchsorted(truth[:, 0], m.log_time_ns))
        errors.append(
            min(np.hypot(p.position.x - truth[i, 1], p.position.y - truth[i, 2]) for p in m.ros_msg.poses)
        )
    assert len(errors) == 26  # every camera tick of the 5 s run (5 Hz), each with the person
    assert np.median(errors) < 0.15 and max(errors) < 0.35


def test_counterfactual_replay_reproduces_live_then_a_new_zone_changes_the_verdict(
    safety_run: Path, tmp_path: Path
) -> None:
    same = run_cli(
        str(safety_run),
        "--out",
        str(tmp_path / "same"),
        "--algorithms",
        "safety",
        module="simlan_data.replay",
    )
    assert same.returncode == 0, same.stderr
    metrics = load_metrics(tmp_path / "same" / "metrics.json")  # strict JSON: NaN is null
    assert metrics["replay.safety.events_diff_to_live"] == 0
    assert np.isnan(metrics["replay.safety.diverged_s"])
    # a bay on the Jackal's way north, which it really drove through before it was stopped blind
    bay = '[{"name": "north_bay", "polygon": [[7.0, 2.6], [9.0, 2.6], [9.0, 3.2], [7.0, 3.2]], "namespaces": ["robot_agent_2"]}]'
    proc = run_cli(
        str(safety_run),
        "--out",
        str(tmp_path / "bay"),
        "--algorithms",
        "safety",
        "--set",
        f"zones={bay}",
        module="simlan_data.replay",
    )
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((tmp_path / "bay" / "metrics.json").read_text())
    assert metrics["replay.safety.as_recorded.violations"] >= 1  # as recorded: it drove into the bay
    assert metrics["replay.safety.as_recorded.missed"] >= 1
    assert metrics["replay.safety.prevented"] == 1  # the counterfactual tree stops it in time
    assert metrics["replay.safety.not_prevented"] == 0
    report = (tmp_path / "bay" / "safety_counterfactual.md").read_text()
    assert "| robot_agent_2 | zone_entry |" in report and "**prevented**" in report
    assert "north_bay" in report


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            "algorithms.safety.zones=[{name: x, polygon: [[0,0],[2,2],[2,0],[0,2]]}]",
            "not a simple polygon (Self-intersection",
        ),
        ("algorithms.safety.zones=[{name: x, polygon: [[0,0],[2,2]]}]", "needs at least 3 distinct corners"),
        (
            "algorithms.safety.zones=[{name: x, polygon: [[0,0],[2,0],[0,2]], namespaces: [robot_agent_5]}]",
            "there is no agent 'robot_agent_5' in this run",
        ),
        (
            "algorithms.safety.ttc.namespaces=[robot_agent_8]",
            "invalid algorithms.safety.ttc.namespaces=['robot_agent_8']",
        ),
    ],
)
def test_bad_zone_configs_get_one_line_and_exit_2(override: str, message: str, tmp_path: Path) -> None:
    proc = run_cli(override, f"hydra.run.dir={tmp_path / 'run'}", "progress=false")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], proc.stderr
    assert not (tmp_path / "run" / "recording").exists()


def test_bad_counterfactual_zone_gets_one_line_and_exit_2(safety_run: Path, tmp_path: Path) -> None:
    proc = run_cli(
        str(safety_run),
        "--out",
        str(tmp_path / "bad"),
        "--algorithms",
        "safety",
        "--set",
        'zones=[{"name": "x", "polygon": [[0, 0], [2, 2], [2, 0], [0, 2]]}]',
        module="simlan_data.replay",
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: invalid algorithms.safety.zones[0].polygon=[[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]] in config: "
        "zone 'x' is not a simple polygon (Self-intersection[1 1]); list the corners in order around the area, "
        "without crossing edges"
    ]


def _pinkish(image_bgr: np.ndarray) -> int:
    """Pixels of a light red wash (a zone's fill, a stop's shading): red above equal green and blue."""
    b, g, r = (image_bgr[..., k].astype(int) for k in range(3))
    return int(((r - g >= 15) & (r - g <= 80) & (np.abs(g - b) <= 8)).sum())


def test_the_report_shows_the_notes_the_zone_and_the_stops(safety_run: Path) -> None:
    """report.md of a run with safety events: what went wrong at the top, the zone on the map,
    each robot's stop shaded on its speed timeline."""
    import cv2

    from simlan_data.evaluation.report_figures import DPI, TIMELINE_FILENAME, TRAJECTORIES_FILENAME

    report = (safety_run / "report.md").read_text()
    top = report[: report.index("## Figures")]
    assert "robot_agent_1 reached 0 of 1 goals" in top and "robot_agent_2 reached 0 of 1 goals" in top
    assert "| safety stops | 2 | count |" in top
    assert "![trajectories](report_trajectories.png)" in report
    assert _pinkish(cv2.imread(str(safety_run / TRAJECTORIES_FILENAME))) > 2000  # the bay
    timeline = cv2.imread(str(safety_run / TIMELINE_FILENAME))
    assert timeline.shape[0] == (1 + 2 * 3) * DPI  # a row per moving agent: the truck, the Jackal, the person
    rows = np.array_split(timeline, [int(timeline.shape[0] * f) for f in (0.4, 0.7)], axis=0)
    assert [_pinkish(r) > 500 for r in rows] == [True, True, False], [_pinkish(r) for r in rows]
