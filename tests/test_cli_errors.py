"""Bad input: one clear error line, exit code 2, nothing written over an existing recording."""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
from pathlib import Path

import pytest

from conftest import compose_config, run_cli
from simlan_data.config.schema import AgentConfig
from simlan_data.config.validation import to_config
from simlan_data.constants import CALIBRATION_DIR, CONF_DIR
from simlan_data.errors import ConfigError
from simlan_data.sim.scene import load_inputs


def _one_error_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: "), stderr
    return lines[0]


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        (["cameras.ids=[160,999]"], "unknown camera id 999 in cameras.ids"),
        (["duration_s=-5"], "invalid duration_s=-5.0"),
        (["duration_s=abc"], "invalid duration_s='abc' in config: expected Float"),
        (["no_such_key=1"], "unknown key no_such_key in config"),
        (["cameras=no_such_set"], "unknown cameras=no_such_set in config: no such option in conf/cameras/"),
        (["world.fidelity=ultra"], "invalid world.fidelity='ultra'"),
        (["agents.robot_agent_1.type=hovercraft"], "unknown agent type 'hovercraft'"),
        (["agents.robot_agent_1.pose=[-13.0,4.0,0.0]"], "footprint overlaps"),
        (["agents.robot_agent_1.pose=[100.0,0.0,0.0]"], "footprint leaves the building"),
        (["cameras.rate_hz=7"], "invalid cameras.rate_hz=7.0"),
        (["cameras.count=12"], "invalid cameras.count=12 in config: must be within 0..11"),
        (["streams=rgbx"], "options: rgb, rgbds, rgbds_full"),
        # spawn lists
        (
            ["agents=four_robots", "agents.robot_agent_3.marker_id=1"],
            "marker_id=1 in config: already used by robot_agent_1",
        ),
        (
            ["agents=four_robots", "agents.robot_agent_2.pose=[-20.5,1.5,0.0]"],
            "agents.robot_agent_2.pose=[-20.5, 1.5, 0.0] in config: its footprint overlaps robot_agent_1's",
        ),
        (["agents.robot_agent_1.marker_id=1000"], "DICT_5X5_1000 has ids 0..999"),
        (
            ["agents.robot_agent_1.goals=[[0.0,3.5]]"],
            "goals[0]=[0.0, 3.5] in config: the goal is inside an obstacle",
        ),
        (
            ["+agents.robot_agent_5={type:jackal,pose:[0.0,0.0,0.0]}"],
            "new agents go in a spawn list file; write DIR/agents/NAME.yaml",
        ),
    ],
)
def test_bad_config_gives_one_line_and_exit_2(tmp_path: Path, overrides: list[str], expected: str) -> None:
    run_dir = tmp_path / "run"
    proc = run_cli(*overrides, f"hydra.run.dir={run_dir}", "progress=false")
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert expected in line, line
    assert not (run_dir / "recording").exists()
    assert not (run_dir / "RUNNING").exists()  # nothing ran: no crashed run to recover


def test_spawn_list_files_from_the_users_directory(tmp_path: Path) -> None:
    """Spawn lists outside the package (hydra.searchpath); a repeated namespace is a clear error."""
    (tmp_path / "conf" / "agents").mkdir(parents=True)
    spawn = tmp_path / "conf" / "agents" / "mine.yaml"
    header = "# @package _global_\nagents:\n  robot_agent_1: {type: pallet_truck, pose: [-16.0, 0.4, 0.0]}\n"
    spawn.write_text(header + "  robot_agent_1: {type: jackal, pose: [-10.0, 0.4, 0.0]}\n")
    common = [f"hydra.searchpath=[file://{tmp_path / 'conf'}]", "agents=mine", "progress=false"]
    proc = run_cli(*common, f"hydra.run.dir={tmp_path / 'run1'}")
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert "mine.yaml, line 4: found duplicate key robot_agent_1" in line, line
    spawn.write_text(header + "  robot_agent_01: {type: jackal, pose: [-10.0, 0.4, 0.0]}\n")
    proc = run_cli(*common, f"hydra.run.dir={tmp_path / 'run2'}")
    assert proc.returncode == 2 and "invalid agents='robot_agent_01'" in _one_error_line(proc.stderr)
    spawn.write_text(header + "  robot_agent_7: {type: jackal, pose: [-10.0, 0.4, 0.0]}\n")
    cfg = to_config(compose_config("agents=mine", f"hydra.searchpath=[file://{tmp_path / 'conf'}]"))
    assert [(a.namespace, a.type, a.marker_id) for a in cfg.agent_list] == [
        ("robot_agent_1", "pallet_truck", 1),
        ("robot_agent_7", "jackal", 7),
    ]


def test_missing_calibration_file(tmp_path: Path) -> None:
    calib = tmp_path / "calib"
    for kind in ("intrinsic", "extrinsic"):
        (calib / kind).mkdir(parents=True)
        shutil.copy(CALIBRATION_DIR / kind / "163.yaml", calib / kind / "163.yaml")
    shutil.copy(CALIBRATION_DIR / "intrinsic" / "164.yaml", calib / "intrinsic" / "164.yaml")
    # 164 lacks its extrinsic file: not a usable camera
    proc = run_cli(
        "cameras.ids=[163,164]", f"cameras.calibration_dir={calib}", f"hydra.run.dir={tmp_path / 'run'}"
    )
    assert proc.returncode == 2
    assert "unknown camera id 164" in _one_error_line(proc.stderr)
    # a file that exists but is broken is named
    (calib / "extrinsic" / "164.yaml").write_text("%YAML:1.0\n---\nrot_mat: 3\n")
    proc = run_cli(
        "cameras.ids=[163,164]", f"cameras.calibration_dir={calib}", f"hydra.run.dir={tmp_path / 'run2'}"
    )
    assert proc.returncode == 2
    line = _one_error_line(proc.stderr)
    assert "164.yaml" in line and "rot_mat" in line


def test_existing_recording_is_never_touched(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    bag = run_dir / "recording"
    bag.mkdir(parents=True)
    (bag / "metadata.yaml").write_text("precious: true\n")
    digest = hashlib.sha256((bag / "metadata.yaml").read_bytes()).hexdigest()
    proc = run_cli("duration_s=1", "cameras=single", f"hydra.run.dir={run_dir}", "progress=false")
    assert proc.returncode == 2
    assert "run directory not empty" in _one_error_line(proc.stderr)  # (an earlier run: never written into)
    assert hashlib.sha256((bag / "metadata.yaml").read_bytes()).hexdigest() == digest
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml"]


@pytest.mark.usefixtures("installed_packages_unchanged")  # (the cache key includes the plug-ins)
def test_fast_help_is_hydras_help_word_for_word(tmp_path: Path) -> None:
    """``--help`` is composed once by simlan_data.apps.help, then served from its cache; with a
    config directory on the command line Hydra renders its own: the three texts must be the same."""
    env = {"SIMLAN_DATA_CACHE_DIR": str(tmp_path)}
    ours = run_cli("--help", "duration_s=7", env=env)
    cached = run_cli("--help", "duration_s=7", env=env)
    hydras = run_cli("--help", "duration_s=7", "--config-dir", str(CONF_DIR), env=env)
    assert ours.returncode == cached.returncode == hydras.returncode == 0, (ours.stderr, hydras.stderr)
    assert ours.stdout == cached.stdout == hydras.stdout and "duration_s: 7.0" in ours.stdout
    assert len(list((tmp_path / "help").glob("*.txt"))) == 1  # (Hydra's own help is not cached)


@pytest.mark.usefixtures("installed_packages_unchanged")  # (the cache key includes the plug-ins)
def test_help_cache_is_used_and_a_changed_config_file_invalidates_it(tmp_path: Path) -> None:
    """The second --help prints the stored text (planted here to tell it apart); touching a
    config file the help is made of, or asking for another config, composes it again."""
    env = {"SIMLAN_DATA_CACHE_DIR": str(tmp_path)}
    assert run_cli("--help", env=env).returncode == 0
    (stored,) = (tmp_path / "help").glob("*.txt")
    stored.write_text("PLANTED\n")
    assert run_cli("--help", env=env).stdout == "PLANTED\n"
    assert run_cli("-h", env=env).stdout == "PLANTED\n"
    assert "duration_s: 3.0" in run_cli("--help", "duration_s=3", env=env).stdout
    config_yaml = CONF_DIR / "config.yaml"
    st = config_yaml.stat()
    try:
        os.utime(config_yaml, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
        fresh = run_cli("--help", env=env)
    finally:
        os.utime(config_yaml, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert fresh.returncode == 0 and "PLANTED" not in fresh.stdout and "duration_s" in fresh.stdout
    unwritable = tmp_path / "file"
    unwritable.write_text("")  # a cache "directory" that is a file: help still works
    assert "duration_s" in run_cli("--help", env={"SIMLAN_DATA_CACHE_DIR": str(unwritable)}).stdout


def test_help_lists_groups_and_keys() -> None:
    proc = run_cli("--help")
    assert proc.returncode == 0
    assert "cameras: gpss, gpss_all" in proc.stdout.replace("\n", " ") or "gpss_all" in proc.stdout
    assert "duration_s" in proc.stdout and "world" in proc.stdout


def test_config_checks_without_a_process() -> None:
    cfg = to_config(compose_config("cameras=single", "duration_s=2"))
    assert cfg.cameras.ids == [163] and cfg.agents["robot_agent_1"].marker_id == 1
    with pytest.raises(ConfigError, match=r"invalid agents='truck_1'.*must be robot_agent_N"):
        AgentConfig(type="jackal").check("truck_1")
    with pytest.raises(
        ConfigError, match=r"invalid agents.robot_agent_1.goals\[0\]=\[-13.0, 3.5\].*inside an obstacle"
    ):
        load_inputs(to_config(compose_config("cameras=single", "agents.robot_agent_1.goals=[[-13.0,3.5]]")))
    with pytest.raises(ConfigError, match=r"recording.depth_rate_hz=2.0 in config: must divide"):
        to_config(compose_config("recording.depth_rate_hz=2"))
    with pytest.raises(ConfigError, match=r"unknown camera id 777"):
        load_inputs(to_config(compose_config("cameras.ids=[777]")))


def test_the_summary_notes_calibration_disagreements_of_the_users_files_only(
    caplog: pytest.LogCaptureFixture, tmp_path: Path
) -> None:
    """The packaged calibrations' stale derived fields are known (docs/twin.md): no 'note' on
    every run; a user's calibration directory with disagreements gets the line."""
    from simlan_data.apps.run import log_summary
    from simlan_data.sim.simulation import RunStats

    caplog.set_level(logging.INFO, logger="simlan_data")
    metrics = {"recording.messages": 1.0, "sim.duration_s": 1.0, "sim.wall_s": 1.0, "sim.rtf": 1.0}
    stats = RunStats(calibration_issues=["160.yaml: position disagrees with -R^T t by 0.010 m"])
    log_summary(to_config(compose_config("duration_s=1")), stats, metrics, tmp_path)
    assert "finished" in caplog.text and "calibration fields disagree" not in caplog.text
    caplog.clear()
    shutil.copytree(CALIBRATION_DIR, tmp_path / "mine")
    log_summary(
        to_config(compose_config(f"cameras.calibration_dir={tmp_path / 'mine'}")), stats, metrics, tmp_path
    )
    assert "1 calibration fields disagree with K, R, t (listed in report.md)" in caplog.text


def test_the_seed_sweep_example_gives_different_runs() -> None:
    """README: `-m seed=0,1,2 perturbation.spawn_xy_m=0.2` must sweep something (without a
    perturbation the seed changes nothing: docs/running.md says so)."""
    poses = {
        seed: to_config(compose_config(f"seed={seed}", "perturbation.spawn_xy_m=0.2"))
        .agents["robot_agent_1"]
        .pose
        for seed in (0, 1, 2)
    }
    assert len({tuple(p) for p in poses.values()}) == 3
    plain = {tuple(to_config(compose_config(f"seed={seed}")).agents["robot_agent_1"].pose) for seed in (0, 1)}
    assert len(plain) == 1


def test_the_summary_says_when_no_camera_ever_saw_a_robot(
    caplog: pytest.LogCaptureFixture, tmp_path: Path
) -> None:
    from simlan_data.apps.run import log_summary
    from simlan_data.sim.simulation import RunStats

    caplog.set_level(logging.INFO, logger="simlan_data")
    metrics = {"recording.messages": 1.0, "sim.duration_s": 1.0, "sim.wall_s": 1.0, "sim.rtf": 1.0}
    stats = RunStats(collisions={"robot_agent_1": 0})
    cfg = to_config(compose_config("duration_s=1"))
    log_summary(cfg, stats, metrics | {"localization.robot_agent_1.availability": 0.4}, tmp_path)
    assert "finished" in caplog.text and "never seen" not in caplog.text
    caplog.clear()
    log_summary(cfg, stats, metrics | {"localization.robot_agent_1.availability": 0.0}, tmp_path)
    notes = [ln for ln in caplog.text.splitlines() if "never seen by a camera" in ln]
    assert notes == [notes[0]] and "robot_agent_1" in notes[0]


def test_a_robot_never_in_any_cameras_view_gets_the_note(tmp_path: Path) -> None:
    """README's ``duration_s=10 cameras=single``: camera 163 never has the truck in view, so its
    availability is NaN (not 0) and it has no valid estimate; the summary must still say so."""
    args = ("duration_s=1", "cameras=single", "world.fidelity=empty", "progress=false")
    proc = run_cli(*args, f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode == 0, proc.stderr
    notes = [ln for ln in proc.stdout.splitlines() if "never seen by a camera" in ln]
    assert len(notes) == 1 and "robot_agent_1" in notes[0], proc.stdout
