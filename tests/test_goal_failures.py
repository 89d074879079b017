"""Failed goals and collision kinds in a real (short) run, read back with an independent MCAP reader.

One 12 s run in the warehouse with its shelves (world.fidelity=medium), robots steering on ground
truth (no camera needed to drive), two cameras at 480x270:

- robot_agent_1, a Jackal, gets a goal beside a shelf (free floor, so the config accepts it, but
  closer to the shelf than the planner's clearance: no path), then a goal 10 m away at 0.5 m/s
  (still on its way when the run ends);
- robot_agent_2, a forklift in the aisle between two shelf rows, facing away from its goal: its
  first in-place turn sweeps its forks into a shelf, the safety layer stops it, and it stays
  stopped for the rest of the run (the issue's forklift).

So the Jackal fails one goal ``unreachable`` and one ``timeout``, the forklift one ``blocked``;
every failure is in metrics.json, the printed summary, report.md and the recorded navigation
status, and the forklift's collision counts as ``safety.collisions_static``, not as standing
(which is being hit by another agent).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import run_cli
from simlan_data.recording import schema

SPAWN = """# @package _global_
agents:
  robot_agent_1: {type: jackal, pose: [10.3, 0.5, 0.0], goals: [[10.3, 4.5], [0.3, 0.5]], speed_mps: 0.5}
  robot_agent_2: {type: forklift, pose: [12.3, 5.3, 0.0], goals: [[6.0, 5.3]], speed_mps: 0.5}
"""
SCENARIO = """# @package _global_
defaults:
  - override /agents: goal_failures
scenario: {name: goal_failures}
duration_s: 12.0
world: {fidelity: medium, settle_s: 0.0}
cameras: {ids: [162, 163], width: 480, height: 270}
localization: {source: ground_truth}
"""


@pytest.fixture(scope="module")
def failures_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    root = tmp_path_factory.mktemp("goal_failures")
    conf = root / "conf"
    (conf / "agents").mkdir(parents=True)
    (conf / "scenario").mkdir()
    (conf / "agents" / "goal_failures.yaml").write_text(SPAWN)
    (conf / "scenario" / "goal_failures.yaml").write_text(SCENARIO)
    run_dir = root / "run"
    proc = run_cli(
        f"hydra.searchpath=[file://{conf}]",
        "scenario=goal_failures",
        f"hydra.run.dir={run_dir}",
        "progress=false",
    )
    assert proc.returncode == 0, proc.stderr  # a failed goal is a result, not a failed run
    return run_dir, proc.stdout + proc.stderr


def _statuses(run_dir: Path, ns: str) -> list:
    """The robot's navigation status messages, decoded by mcap + mcap_ros2 (not simlan_data)."""
    mcap = next((run_dir / "recording").glob("*.mcap"))
    topic = schema.agent_topics(ns)["navigation"].name
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [m for _, _, _, m in reader.iter_decoded_messages(topics=[topic], log_time_order=True)]


def test_failed_goals_with_their_reason_in_metrics(failures_run: tuple[Path, str]) -> None:
    run_dir, _ = failures_run
    m = json.loads((run_dir / "metrics.json").read_text())
    jackal = {k.split(".", 2)[2]: v for k, v in m.items() if k.startswith("navigation.robot_agent_1.goals")}
    assert jackal == {
        "goals_reached": 0.0,
        "goals_total": 2.0,
        "goals_failed": 2.0,
        "goals_failed.unreachable": 1.0,
        "goals_failed.blocked": 0.0,
        "goals_failed.timeout": 1.0,
    }
    assert m["navigation.robot_agent_2.goals_failed"] == 1.0
    assert m["navigation.robot_agent_2.goals_failed.blocked"] == 1.0
    assert (m["navigation.goals_failed"], m["navigation.goals_failed.unreachable"]) == (3.0, 1.0)
    assert (m["navigation.goals_failed.blocked"], m["navigation.goals_failed.timeout"]) == (1.0, 1.0)


def test_failed_goals_in_the_summary_and_the_report(failures_run: tuple[Path, str]) -> None:
    run_dir, console = failures_run
    jackal = (
        "robot_agent_1 reached 0 of 2 goals in 12 s simulated; 2 failed: "
        "1 unreachable (no path), 1 timeout (the run ended first)"
    )
    forklift = (  # it turned into a shelf: the safety layer's collision stop holds it to the end
        "robot_agent_2 reached 0 of 1 goals in 12 s simulated; 1 failed: 1 blocked (no progress for 10 s "
        "at the end); a safety stop held it at the end (collision; see the safety events)"
    )
    notes = [
        line.split("note", 1)[1].strip() for line in console.splitlines() if line.strip().startswith("note ")
    ]
    assert jackal in notes and forklift in notes
    report = (run_dir / "report.md").read_text()
    top = report[: report.index("| | value | unit |")]
    assert f"- {jackal}" in top and f"- {forklift}" in top
    assert "| `navigation.goals_failed.unreachable` | 1 | count |" in report


def test_failed_goals_recorded_on_navigation_status(failures_run: tuple[Path, str]) -> None:
    run_dir, _ = failures_run
    jackal = [(s.state, s.goals_failed) for s in _statuses(run_dir, "robot_agent_1")]
    assert jackal[0] == ("failed_unreachable", 1)  # given up at its first tick: no path
    assert jackal[-1] == ("failed_timeout", 2)  # the run ended on the way to the second
    assert [s for s, _ in jackal].count("failed_unreachable") == 1
    forklift = [(s.state, s.goals_failed) for s in _statuses(run_dir, "robot_agent_2")]
    assert ("safety_stop", 0) in forklift and forklift[-1] == ("failed_blocked", 1)


def test_turning_into_a_shelf_is_a_static_collision(failures_run: tuple[Path, str]) -> None:
    run_dir, _ = failures_run
    m = json.loads((run_dir / "metrics.json").read_text())
    assert m["agents.robot_agent_2.collisions"] == 1.0 and m["agents.robot_agent_2.distance_m"] < 0.1
    assert m["safety.violations.collisions"] == 1.0
    assert m["safety.collisions_static"] == 1.0
    assert m["safety.collisions_standing"] == 0.0 and m["safety.collisions_moving"] == 0.0
    mcap = next((run_dir / "recording").glob("*.mcap"))
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        touched = {
            body
            for _, _, _, c in reader.iter_decoded_messages(
                topics=[schema.agent_topics("robot_agent_2")["collision"].name]
            )
            for body in c.other_bodies
        }
    assert touched and all(body.startswith("shelf") for body in touched), touched
