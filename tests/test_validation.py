"""Every boundary refuses bad input with one clear line (table-driven), and the CLIs exit with 2.

The tables live in ``reliability_cases.py`` (``benchmarks/reliability.py`` counts them for
docs/benchmarks/reliability.md). Each case runs the real loading path: config composed by Hydra and checked as a
run checks it, calibration files loaded by OpenCV, URDFs parsed, layouts read by polars,
recordings opened and read by rosbags.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from reliability_cases import BOUNDARIES, Case, one_line, real_layout_loads, small_recording

from conftest import run_cli
from simlan_data.config.validation import (
    REFERENCE_CHECKS,
    compose_config,
    register_reference_check,
    require_known,
)
from simlan_data.errors import EXIT_BAD_INPUT, ConfigError, SimlanError

ALL = [(name, case) for name, (cases, _, _) in BOUNDARIES.items() for case in cases]


@pytest.mark.parametrize(("boundary", "case"), ALL, ids=[f"{b}: {c.id}" for b, c in ALL])
def test_bad_input_gives_one_clear_line(boundary: str, case: Case, tmp_path: Path) -> None:
    _, runner, wants_tmp = BOUNDARIES[boundary]
    with pytest.raises(SimlanError, match=case.match) as info:
        runner(case, tmp_path) if wants_tmp else runner(case)
    assert info.value.exit_code == EXIT_BAD_INPUT
    line = one_line(info.value)
    assert line.count(" in ") >= 1 and len(line) < 600, line


def test_the_unmodified_inputs_pass_the_same_checks(tmp_path: Path) -> None:
    """The cases start from good inputs: those load (so each case fails because of its change)."""
    cfg = compose_config(["cameras.ids=[163]"])
    assert cfg.cameras.ids == [163]
    assert real_layout_loads() > 100
    _, run_urdf, _ = BOUNDARIES["urdf"]
    run_urdf(Case("unchanged", lambda _: None, ""), tmp_path / "u")
    _, run_calibration, _ = BOUNDARIES["calibration"]
    run_calibration(Case("unchanged", lambda _: None, ""), tmp_path / "c")
    _, run_recording, _ = BOUNDARIES["recording"]
    run_recording(Case("unchanged", lambda _: None, ""), tmp_path / "r")


def test_reference_checks_registered_by_other_sections_run_with_the_config() -> None:
    """A section naming agents (e.g. safety zones) registers a check; it runs in to_config."""

    def zones_name_agents(cfg: object) -> None:
        require_known("safety.zones.dock.agents", ["robot_agent_1", "robot_agent_9"], cfg.agents, "agent")  # type: ignore[attr-defined]

    register_reference_check(zones_name_agents)
    try:
        with pytest.raises(
            ConfigError,
            match=r"unknown agent 'robot_agent_9' in safety.zones.dock.agents in config: no agent of that name \(known: robot_agent_1\); did you mean robot_agent_1\?",
        ):
            compose_config(["cameras=single"])
    finally:
        REFERENCE_CHECKS.remove(zones_name_agents)
    compose_config(["cameras=single"])


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["duration_s=60s"], "units are part of the key's name (duration_s: seconds): write duration_s=60"),
        (["recording.flush_period=2"], "did you mean recording.flush_period_s?"),
        (
            ["algorithms.localizer.bias_m=[nan,0]"],
            "invalid algorithms.localizer.bias_m[0]=nan in config: not a finite number",
        ),
        (["scenario=multi_robot", "agents=single_truck"], "unknown agent robot_agent_2 in config"),
        (["agents.robot_agent_1.pose=[-16,0.4,90]"], "(this looks like degrees)"),
        (["world.layout=/nonexistent/layout.csv"], "layout file missing in /nonexistent/layout.csv"),
        (["faults=${now:%Y}"], "invalid faults='${now:%Y}' in config: Invalid type assigned"),
    ],
)
def test_run_cli_exit_2_and_nothing_written(tmp_path: Path, args: list[str], expected: str) -> None:
    run_dir = tmp_path / "run"
    proc = run_cli(*args, f"hydra.run.dir={run_dir}", "progress=false")
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], proc.stderr
    assert not (run_dir / "recording").exists() and not (run_dir / "RUNNING").exists()


def test_replay_cli_refuses_bad_recordings_with_exit_2(tmp_path: Path) -> None:
    bag = small_recording(tmp_path / "only_clock" / "recording", topics=("/clock",))
    digest = hashlib.sha256((bag / "recording.mcap").read_bytes()).hexdigest()
    proc = run_cli(str(bag), "--out", str(tmp_path / "out"), module="simlan_data.replay")
    assert proc.returncode == 2 and proc.stderr.startswith("error: recording lacks required topics in ")
    assert len(proc.stderr.strip().splitlines()) == 1
    assert hashlib.sha256((bag / "recording.mcap").read_bytes()).hexdigest() == digest
    crashed = small_recording(tmp_path / "crashed" / "recording")
    (crashed / "metadata.yaml").unlink()
    proc = run_cli(str(tmp_path / "crashed"), "--info", module="simlan_data.replay")
    assert proc.returncode == 2 and "python -m simlan_data.recover" in proc.stderr
    proc = run_cli(str(tmp_path / "nothing"), "--info", module="simlan_data.replay")
    assert proc.returncode == 2 and "no such file or directory" in proc.stderr


def test_check_nulls_names_the_nested_key() -> None:
    from simlan_data.config.validation import check_nulls

    with pytest.raises(ConfigError, match=r"invalid recording.jpeg_quality=None in config: must not be null"):
        check_nulls({"recording": {"jpeg_quality": None, "enabled": True}, "duration_s": 5.0})
    check_nulls({"recording": {"jpeg_quality": 85}, "duration_s": 5.0, "unknown": None})  # not ours to judge
