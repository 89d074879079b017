"""Config input that is bounded: keys the schema lacks (forced in with ``+``) and user YAML whose
aliases expand without bound (an "alias bomb"), in every place a user YAML enters."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from conftest import run_cli
from simlan_data.config.validation import compose_config
from simlan_data.errors import ConfigError
from simlan_data.evaluation.suite_spec import load_suite

BOMB_MATCH = r"YAML aliases expand to more than \d+ nodes \(an alias bomb\?\); write the values out"


def alias_bomb(levels: int = 9, width: int = 9, indent: str = "") -> str:
    """About 400 bytes that stand for width**levels values (9**9: 387 million)."""
    lines = [f"{indent}a0: &a0 [" + ",".join(["x"] * width) + "]"]
    lines += [f"{indent}a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * width) + "]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def _one_error_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    return lines[0]


# ------------------------------------------------------------------------------- unknown keys
def test_plus_forced_typo_is_exit_2_and_writes_nothing(tmp_path: Path) -> None:
    """``+recording.fsynk=true`` used to be accepted (exit 0, fsync off)."""
    run_dir = tmp_path / "run"
    proc = run_cli("+recording.fsynk=true", "duration_s=1", f"hydra.run.dir={run_dir}", "progress=false")
    assert proc.returncode == 2, proc.stderr
    assert _one_error_line(proc.stderr) == (
        "error: unknown key recording.fsynk in config: RecordingConfig has no such key; "
        "did you mean recording.fsync?"
    )
    assert not run_dir.exists()


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        (
            ["+world.physics.box.mas_kg=1"],
            r"unknown key world.physics.box.mas_kg in config: PhysicsParams has no such key; did you mean world.physics.box.mass_kg\?",
        ),
        (
            ["+posemap.epoch=3"],
            r"unknown key posemap.epoch in config: PosemapConfig has no such key; did you mean posemap.epochs\?",
        ),
        (["+seeed=3"], r"unknown key seeed in config: Config has no such key; did you mean seed\?"),
        (
            ["+algorithms.localizer.bias=[0.0,0.0]"],
            r"unknown key algorithms.localizer.bias in config: \w+ has no such key; did you mean algorithms.localizer.bias_m\?",
        ),
        (
            ["~recording", "+recording={fsynk: true}"],
            r"unknown key recording.fsynk in config: RecordingConfig has no such key",
        ),
    ],
)
def test_every_typed_node_refuses_forced_keys(overrides: list[str], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        compose_config(["cameras=single", *overrides])


@pytest.mark.parametrize(
    ("override", "match"),
    [
        (
            "posemap.hidden=[[]]",
            r"invalid posemap.hidden=\[\[\]\] in config: each element must be an integer",
        ),
        (
            "posemap.position=[[],1,2]",
            r"invalid posemap.position=.* each element must be a number, not a list",
        ),
        # the large fuzz budget: the duplicate check crashed on the unhashable element
        ("cameras.ids=[[]]", r"invalid cameras.ids=\[\[\]\] in config: each element must be an integer"),
    ],
)
def test_nested_lists_where_numbers_belong_are_refused(override: str, match: str) -> None:
    """Found by the fuzzer: OmegaConf lets ``[[]]`` into a list[int] field; the checks then failed
    with a TypeError ('<=' between list and int, an unhashable list) instead of naming the key.
    One check now refuses a list or mapping inside any list of scalars (validation.check_nulls)."""
    with pytest.raises(ConfigError, match=match):
        compose_config(["cameras=single", override])


def test_open_nodes_stay_open() -> None:
    """Hydra's own keys are Hydra's business; the packaged groups all compose."""
    compose_config(["cameras=single", "+hydra.job.env_set.FOO=1"])
    for overrides in (["agents=four_robots", "scenario=multi_robot"], ["scenario=collision"]):
        compose_config(["cameras=single", *overrides])


# ------------------------------------------------------------------------------- alias bombs
def test_alias_bomb_is_refused_at_once(tmp_path: Path) -> None:
    from simlan_data.config.safe_yaml import check_yaml_file  # (here: the tests run against older code too)

    path = tmp_path / "bomb.yaml"
    path.write_text(alias_bomb())
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=r"config file too large in .*bomb.yaml: " + BOMB_MATCH):
        check_yaml_file(path, what="config file")
    assert time.perf_counter() - start < 1.0


def test_bounded_loader_accepts_ordinary_aliases_and_refuses_the_rest(tmp_path: Path) -> None:
    from simlan_data.config.safe_yaml import MAX_NODES, load_yaml

    ok = tmp_path / "ok.yaml"
    ok.write_text("base: &b {x: 1, y: [1, 2]}\nother:\n  <<: *b\n  z: 3\n")
    assert load_yaml(ok, what="config file")["other"] == {"x": 1, "y": [1, 2], "z": 3}
    wide = tmp_path / "wide.yaml"  # just over the limit without any alias
    wide.write_text("[" + ",".join(["1"] * MAX_NODES) + "]\n")
    with pytest.raises(ConfigError, match=BOMB_MATCH):
        load_yaml(wide, what="config file")
    cyclic = tmp_path / "cyclic.yaml"
    cyclic.write_text("a: &a [*a]\n")
    with pytest.raises(ConfigError, match=BOMB_MATCH):
        load_yaml(cyclic, what="config file")
    deep = tmp_path / "deep.yaml"
    deep.write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ConfigError, match="too deeply nested"):
        load_yaml(deep, what="config file")
    big = tmp_path / "big.yaml"
    big.write_text("# " + "x" * (2 << 20) + "\n")
    with pytest.raises(ConfigError, match=r"config file too large in .*big.yaml: \d+ bytes, over 1048576"):
        load_yaml(big, what="config file")
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match=r"config file is not a regular file in .*fifo\.yaml"):
        load_yaml(fifo, what="config file")  # (reading it would block for ever)


def _bomb_dir(tmp_path: Path) -> Path:
    conf = tmp_path / "conf"
    (conf / "agents").mkdir(parents=True)
    (conf / "agents" / "boom.yaml").write_text("# @package agents\n" + alias_bomb())
    return conf


@pytest.mark.parametrize(
    "how",
    ["--config-dir", "-cd", "hydra.searchpath", "relative searchpath"],
)
def test_alias_bomb_in_a_config_dir_is_exit_2_within_seconds(tmp_path: Path, how: str) -> None:
    """Composition used to hang (killed after 150 s) copying 9**9 values out."""
    conf = _bomb_dir(tmp_path)
    run_dir = tmp_path / "run"
    args = {
        "--config-dir": ["--config-dir", str(conf)],
        "-cd": ["-cd", str(conf)],
        "hydra.searchpath": [f"hydra.searchpath=[file://{conf}]"],
        "relative searchpath": [f"hydra.searchpath=[file://{os.path.relpath(conf)}]"],
    }[how]
    start = time.perf_counter()
    proc = run_cli(*args, "agents=boom", f"hydra.run.dir={run_dir}", "progress=false", timeout=30)
    elapsed = time.perf_counter() - start
    assert proc.returncode == 2, proc.stderr[-2000:]
    line = _one_error_line(proc.stderr)
    assert line.startswith(f"error: config file too large in {conf / 'agents' / 'boom.yaml'}: "), line
    assert "alias bomb" in line
    assert elapsed < 20, elapsed  # the check itself takes milliseconds; the rest is start-up
    assert not run_dir.exists()


def test_alias_bomb_in_a_searchpath_is_refused_in_process(tmp_path: Path) -> None:
    conf = _bomb_dir(tmp_path)
    with pytest.raises(ConfigError, match=BOMB_MATCH):
        compose_config([f"hydra.searchpath=[file://{conf}]", "agents=boom"])


def test_config_dirs_found_on_the_command_line(tmp_path: Path) -> None:
    from simlan_data.config.safe_yaml import config_dirs

    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    argv = ["--config-dir", str(a), f"hydra.searchpath=[file://{b},pkg://x.y]", "--config-path=/nope"]
    assert config_dirs(argv) == [a, b]


def test_alias_bomb_in_a_suite_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "suite.yaml"
    path.write_text("suites:\n  s:\n    overrides:\n" + alias_bomb(indent="      "))
    with pytest.raises(ConfigError, match=BOMB_MATCH):
        load_suite(path, "s")
    proc = run_cli("--file", str(path), "--list", module="simlan_data.evals", timeout=60)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "alias bomb" in _one_error_line(proc.stderr)
