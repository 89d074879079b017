"""A user's coordinator in a tmp module, selected by import path, steering the fleet live.

The coordinator holds every robot (speed limit 0) until ``release_s``, then lets all drive. The
run's commands, read back with the independent reader, show the hold and the release; the built-in
``gpss`` on the same scenario lets them drive from the start. A config value its dataclass refuses
is one line, exit 2.
"""

from __future__ import annotations

import os
import subprocess
import textwrap
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import run_cli
from simlan_data.recording.timebase import DEFAULT_EPOCH_NS

MODULE = textwrap.dedent(
    """
    from dataclasses import dataclass

    from simlan_data.algorithms.coordinator import Decision


    @dataclass(frozen=True)
    class HoldConfig:
        release_s: float = 2.0

        def __post_init__(self):
            if not self.release_s >= 0:
                raise ValueError(f"release_s must be >= 0, got {self.release_s}")


    class HoldThenGo:
        role = "coordinator"
        config_class = HoldConfig

        def __init__(self, config, context):
            self.release_ns = round(config.release_s * 1e9)

        def decide(self, t_ns, intents):
            if t_ns < self.release_ns:
                return {i.namespace: Decision(0.0, ()) for i in intents}
            return {}
    """
)
# four robots on crossing routes, steering on ground truth (no camera needed to move), 4 s
ARGS = [
    "scenario=multi_robot",
    "duration_s=4",
    "localization.source=ground_truth",
    "world.fidelity=light",
    "world.settle_s=0",
    "cameras=single",
    "cameras.width=320",
    "cameras.height=180",
    "progress=false",
]


def _speeds(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    mcap = next((run_dir / "recording").glob("*.mcap"))
    out: dict[str, list[tuple[int, float]]] = {}
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages(log_time_order=True):
            if channel.topic.endswith("/cmd_vel"):
                t = message.log_time - DEFAULT_EPOCH_NS  # simulated time
                out.setdefault(channel.topic.split("/")[1], []).append((t, msg.twist.linear.x))
    return out


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    root = tmp_path_factory.mktemp("coordinator_plugin")
    (root / "hold_coordinator.py").write_text(MODULE)
    return {"PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}


def _run_hold_then_go(
    env: dict[str, str], run_dir: Path, *, release_s: str
) -> subprocess.CompletedProcess[str]:
    """A run with the user's coordinator (an import path), its release time set on the command line."""
    return run_cli(
        *ARGS,
        "algorithms/coordinator=hold_coordinator:HoldThenGo",
        f"algorithms.coordinator.release_s={release_s}",
        f"hydra.run.dir={run_dir}",
        env=env,
    )


def test_a_users_coordinator_steers_the_fleet(env: dict[str, str], tmp_path: Path) -> None:
    run_dir = tmp_path / "hold"
    proc = _run_hold_then_go(env, run_dir, release_s="2.0")
    assert proc.returncode == 0, proc.stderr
    speeds = _speeds(run_dir)
    assert len(speeds) == 4
    for ns, cmds in speeds.items():
        held = [v for t, v in cmds if t < 2_000_000_000]
        after = [v for t, v in cmds if t >= 2_500_000_000]
        assert held and max(abs(v) for v in held) == 0.0, ns  # held by the plug-in
        assert max(after) > 0.2, ns  # released: it drives
    config = (run_dir / ".hydra" / "config.yaml").read_text()
    assert "name: hold_coordinator:HoldThenGo" in config and "release_s: 2.0" in config

    # the built-in on the same scenario: the robots drive from the first second
    builtin = tmp_path / "gpss"
    proc = run_cli(*ARGS, f"hydra.run.dir={builtin}", env=env)
    assert proc.returncode == 0, proc.stderr
    moving = [
        ns for ns, cmds in _speeds(builtin).items() if max(v for t, v in cmds if t < 2_000_000_000) > 0.2
    ]
    assert moving, "with the built-in some robot drives before 2 s"


def test_a_value_the_coordinators_config_refuses_is_one_line(env: dict[str, str], tmp_path: Path) -> None:
    run_dir = tmp_path / "bad"
    proc = _run_hold_then_go(env, run_dir, release_s="-1")
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "coordinator" in lines[0] and "release_s must be >= 0, got -1.0" in lines[0]
    assert not (run_dir / "recording").exists()
