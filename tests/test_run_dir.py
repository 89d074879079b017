"""A run directory is written by one run only (real processes through the public CLI):
a refused config writes nothing (not even the directory Hydra would make), a second run into an
existing run's directory is refused without touching it, and of two runs started at once into one
directory the loser exits 2 naming the winner, which owns everything in it."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from reliability_helpers import REPO, SMALL_RUN, mcap_file

from conftest import run_cli


def _snapshot(root: Path) -> dict[str, tuple[int, int, str]]:
    """Every file under ``root``: size, mtime (ns), SHA-256."""
    return {
        str(p.relative_to(root)): (
            p.stat().st_size,
            p.stat().st_mtime_ns,
            hashlib.sha256(p.read_bytes()).hexdigest(),
        )
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _one_error_line(proc: subprocess.CompletedProcess[str]) -> str:
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    return lines[0]


def test_a_refused_config_leaves_no_directory_behind(tmp_path: Path) -> None:
    target = tmp_path / "made" / "by" / "hydra"
    for bad in (["duration_s=-1"], ["+recording.fsync=maybe"], ["world.layout=no_such_layout.csv"]):
        proc = run_cli(*SMALL_RUN, *bad, f"hydra.run.dir={target}")
        assert proc.returncode == 2, (bad, proc.stderr)
        _one_error_line(proc)
        assert list(tmp_path.iterdir()) == [], (bad, list(tmp_path.rglob("*")))


def test_an_existing_empty_directory_given_by_the_user_is_kept_when_refused(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    proc = run_cli(*SMALL_RUN, "world.layout=no_such_layout.csv", f"hydra.run.dir={mine}")
    assert proc.returncode == 2, proc.stderr
    assert mine.is_dir() and list(mine.iterdir()) == []


def test_a_second_run_into_a_run_directory_is_refused_and_touches_nothing(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    first = run_cli(*SMALL_RUN, "duration_s=0.5", f"hydra.run.dir={run_dir}")
    assert first.returncode == 0, first.stderr
    assert (run_dir / ".hydra" / "overrides.yaml").is_file() and (
        run_dir / ".hydra" / "config.yaml"
    ).is_file()
    before = _snapshot(run_dir)
    for second in (["duration_s=0.5", "seed=7"], ["experiment=posemap_dataset"]):
        proc = run_cli(*SMALL_RUN, *second, f"hydra.run.dir={run_dir}")
        assert proc.returncode == 2, (second, proc.stderr)
        line = _one_error_line(proc)
        assert line.startswith(f"error: run directory not empty in {run_dir}: it holds .hydra/"), line
        assert _snapshot(run_dir) == before, second


def test_of_two_runs_started_at_once_the_loser_names_the_winner_and_writes_nothing(tmp_path: Path) -> None:
    run_dir = tmp_path / "shared"
    procs = {
        seed: subprocess.Popen(
            [
                sys.executable,
                "-m",
                "simlan_data.run",
                *SMALL_RUN,
                "duration_s=1",
                f"seed={seed}",
                f"hydra.run.dir={run_dir}",
            ],
            cwd=REPO,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for seed in (11, 22)
    }
    results = {seed: (p.wait(timeout=300), p.stderr.read() if p.stderr else "") for seed, p in procs.items()}
    codes = sorted(code for code, _ in results.values())
    assert codes == [0, 2], results
    winner = next(seed for seed, (code, _) in results.items() if code == 0)
    loser_err = next(err for code, err in results.values() if code == 2).strip()
    assert loser_err.startswith(
        f"error: run directory in use in {run_dir}: process {procs[winner].pid} on "
    ), loser_err
    assert "recover" not in loser_err  # no hint at the winner's live recording
    # everything in the directory is the winner's: its provenance, its recording
    assert yaml.safe_load((run_dir / ".hydra" / "config.yaml").read_text())["seed"] == winner
    assert f"seed={winner}" in yaml.safe_load((run_dir / ".hydra" / "overrides.yaml").read_text())
    with mcap_file(run_dir / "recording").open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        config = next(m.data for _, _, _, m in reader.iter_decoded_messages(topics=["/simlan/config"]))
    assert yaml.safe_load(config)["seed"] == winner
