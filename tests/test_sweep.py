"""Sweeps: every job writes its own run directory; one step aggregates all metrics.json (polars)."""

from __future__ import annotations

import json
from pathlib import Path

import polars as pl
import pytest

from conftest import run_cli
from simlan_data.errors import ConfigError
from simlan_data.evaluation.sweep import aggregate, collect_sweep, register_sweep_report


def _job(root: Path, name: str, overrides: list[str], metrics: dict[str, float] | None) -> None:
    job = root / name
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    if metrics is not None:
        (job / "metrics.json").write_text(json.dumps(metrics))


def test_collect_reads_overrides_and_metrics_and_flags_failed_jobs(tmp_path: Path) -> None:
    _job(tmp_path, "0", ["seed=1", "cameras=single"], {"sim.rtf": 2.0})
    _job(tmp_path, "1", ["seed=2", "cameras=single"], {"sim.rtf": 3.0, "extra.metric": 1.0})
    _job(tmp_path, "2", ["seed=3", "cameras=single"], None)
    _job(tmp_path, "10", ["seed=4", "+cameras.rate_hz=2.5"], {"sim.rtf": 5.0})
    (tmp_path / "not_a_job").mkdir()
    table = collect_sweep(tmp_path)
    assert table["job"].to_list() == ["0", "1", "2", "10"]  # numeric order, not "10" < "2"
    assert table["status"].to_list() == ["ok", "ok", "failed", "ok"]
    assert table["override.seed"].to_list() == [1, 2, 3, 4]
    assert table["override.cameras.rate_hz"].to_list() == [None, None, None, 2.5]
    assert table["sim.rtf"].to_list() == [2.0, 3.0, None, 5.0]
    assert table["extra.metric"].to_list() == [None, 1.0, None, None]


def test_aggregate_writes_tables_and_runs_the_named_report(tmp_path: Path) -> None:
    _job(tmp_path, "0", ["seed=1"], {"sim.rtf": 2.0})
    seen: list[int] = []

    @register_sweep_report("test_only")
    def _report(table: pl.DataFrame, sweep_dir: Path) -> None:
        seen.append(table.height)
        (sweep_dir / "report.txt").write_text("ok")

    aggregate(tmp_path, "test_only")
    assert seen == [1]
    assert pl.read_parquet(tmp_path / "sweep_metrics.parquet")["sim.rtf"].to_list() == [2.0]
    assert (tmp_path / "sweep_metrics.csv").read_text().startswith("job,")
    with pytest.raises(ConfigError, match="unknown sweep report 'nope'"):
        aggregate(tmp_path, "nope")


def test_collect_refuses_what_is_not_a_sweep(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not a sweep directory"):
        collect_sweep(tmp_path / "missing")
    with pytest.raises(ConfigError, match="no sweep jobs"):
        collect_sweep(tmp_path)


def test_two_job_sweep_through_the_cli_is_aggregated(tmp_path: Path) -> None:
    sweep = tmp_path / "sweep"
    proc = run_cli(
        "-m",
        "seed=0,1",
        "duration_s=0.4",
        "cameras=single",
        "cameras.width=320",
        "cameras.height=180",
        "world.fidelity=empty",
        "world.settle_s=0",
        "recording.depth_rate_hz=5",
        "recording.semantic_rate_hz=5",
        "progress=false",
        f"hydra.sweep.dir={sweep}",
    )
    assert proc.returncode == 0, proc.stderr
    table = pl.read_parquet(sweep / "sweep_metrics.parquet")
    assert table["override.seed"].to_list() == [0, 1]
    assert table["status"].to_list() == ["ok", "ok"]
    assert all(d > 0 for d in table["sim.camera_frames"].to_list())
    for job in ("0", "1"):
        assert (sweep / job / "recording" / "metadata.yaml").is_file()
