"""A user's safety monitor in a tmp module, selected by import path: live and in the safety replay.

The monitor stops every robot whose estimated centre is within ``radius_m`` of a point; the run
(a pallet truck driving east through that circle) and the replay with ``--set safety=mod:Cls``
both stop it there, and the replay reproduces the live events.
"""

from __future__ import annotations

import json
import os
import textwrap
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import run_cli

MODULE = textwrap.dedent(
    """
    from dataclasses import dataclass, field

    from simlan_data.algorithms.safety import FREE, STOP, SafetyDecision


    @dataclass
    class CircleConfig:
        radius_m: float = 1.5
        centre: list[float] = field(default_factory=lambda: [2.0, 1.5])

        def __post_init__(self):
            if self.radius_m <= 0:
                raise ValueError("radius_m must be > 0")


    class CircleStop:
        role = "safety"
        config_class = CircleConfig

        def __init__(self, config, context):
            self.config = config
            self.robots = [r.namespace for r in context.robots if r.kind == "robot"]

        def step(self, world):
            out = {}
            cx, cy = self.config.centre
            for ns in self.robots:
                est = world.estimates.get(ns)
                pose = None if est is None else est.pose
                inside = pose is not None and (pose[0] - cx) ** 2 + (pose[1] - cy) ** 2 <= self.config.radius_m**2
                out[ns] = SafetyDecision(STOP, "circle", 0.0, "inside the circle") if inside else FREE
            return out
    """
)
SCENARIO = """# @package _global_
defaults:
  - override /agents: single_truck
scenario: {name: circle_test}
duration_s: 6.0
world: {fidelity: light, settle_s: 0.0}
cameras: {ids: [162, 163], width: 480, height: 270}
agents:
  robot_agent_1: {pose: [-2.0, 1.5, 0.0], goals: [[9.0, 1.5]], speed_mps: 1.0}
"""


def _read(run_dir: Path, topics: list[str]) -> list:
    mcap = next((run_dir / "recording").glob("*.mcap"))
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [
            (m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=topics, log_time_order=True)
        ]


@pytest.fixture(scope="module")
def plugin_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    root = tmp_path_factory.mktemp("safety_plugin")
    (root / "circle_monitor.py").write_text(MODULE)
    conf = root / "conf" / "scenario"
    conf.mkdir(parents=True)
    (conf / "circle_test.yaml").write_text(SCENARIO)
    env = {"PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}
    run_dir = root / "run"
    proc = run_cli(
        f"hydra.searchpath=[file://{root / 'conf'}]",
        "scenario=circle_test",
        "algorithms/safety=circle_monitor:CircleStop",
        "algorithms.safety.radius_m=1.0",
        f"hydra.run.dir={run_dir}",
        "progress=false",
        env=env,
    )
    assert proc.returncode == 0, proc.stderr
    return run_dir, env


def test_the_plugin_stops_the_robot_live(plugin_run: tuple[Path, dict[str, str]]) -> None:
    run_dir, _ = plugin_run
    events = _read(run_dir, ["/safety/events"])
    stops = [e for _, e in events if e.robot == "robot_agent_1" and e.action == "stop"]
    t_stop = next(t for t, e in events if e.action == "stop")
    assert stops and stops[0].cause == "circle" and stops[0].detail == "inside the circle"
    assert np.hypot(stops[0].pose.position.x - 2.0, stops[0].pose.position.y - 1.5) <= 1.0 + 1e-6
    cmds = [(t, m.twist.linear.x) for t, m in _read(run_dir, ["/robot_agent_1/cmd_vel"])]
    after = [v for t, v in cmds if t >= t_stop]
    assert after and all(v == 0.0 for v in after)  # stopped for good: it never leaves the circle
    assert max(v for _, v in cmds) > 0.5  # it drove before
    states = [m.state for _, m in _read(run_dir, ["/robot_agent_1/safety_state"])]
    assert "stop" in states and states[0] == "drive"
    config = (run_dir / ".hydra" / "config.yaml").read_text()
    assert "name: circle_monitor:CircleStop" in config and "radius_m: 1.0" in config


def test_the_safety_replay_runs_the_plugin(plugin_run: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    run_dir, env = plugin_run
    same = run_cli(
        str(run_dir),
        "--out",
        str(tmp_path / "same"),
        "--algorithms",
        "safety",
        "--set",
        "safety=circle_monitor:CircleStop",
        "--set",
        "radius_m=1.0",
        module="simlan_data.replay",
        env=env,
    )
    assert same.returncode == 0, same.stderr
    metrics = json.loads((tmp_path / "same" / "metrics.json").read_text())
    assert metrics["replay.safety.events_diff_to_live"] == 0  # the plug-in replayed decides as live
    # the built-in trees on the same recording: they see no hazard, so they never stop it
    trees = run_cli(
        str(run_dir),
        "--out",
        str(tmp_path / "trees"),
        "--algorithms",
        "safety",
        "--set",
        "safety=trees",
        module="simlan_data.replay",
        env=env,
    )
    assert trees.returncode == 0, trees.stderr
    metrics = json.loads((tmp_path / "trees" / "metrics.json").read_text())
    assert metrics["replay.safety.events_diff_to_live"] >= 1
    bad = run_cli(
        str(run_dir),
        "--out",
        str(tmp_path / "bad"),
        "--algorithms",
        "safety",
        "--set",
        "safety=circle_monitor:CircleStop",
        "--set",
        "radius_cm=1.0",
        module="simlan_data.replay",
        env=env,
    )
    assert bad.returncode == 2
    assert "unknown key 'radius_cm' for safety 'circle_monitor:CircleStop'" in bad.stderr
