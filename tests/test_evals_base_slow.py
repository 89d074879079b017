"""The base suite end to end (slow; CI runs it with ``pytest -m slow``).

Guards the issue's promises: the base suite passes on the current code against the committed
baseline (evals/baselines/base.parquet), and a fault injected into the closed loop turns it red.
Accept a new baseline on purpose with ``python -m simlan_data.evals base --accept``.
"""

from __future__ import annotations

from pathlib import Path

import polars as pl
import pytest

from conftest import run_cli
from simlan_data.evaluation.suite import FAILING

pytestmark = pytest.mark.slow


def test_the_base_suite_passes_on_the_current_code(tmp_path: Path) -> None:
    out = tmp_path / "base"
    proc = run_cli("base", "--out", str(out), module="simlan_data.evals", timeout=3600)
    summary = pl.read_parquet(out / "summary.parquet")
    failing = summary.filter(pl.col("verdict").is_in(FAILING))
    assert proc.returncode == 0, f"{proc.stdout[-3000:]}\n{proc.stderr[-2000:]}\n{failing}"
    ran = summary.filter(pl.col("verdict") != "pending")
    assert set(ran["case"]) >= {
        "single_truck", "multi_robot", "default", "restricted_zone", "blind_spot", "humanoid_crossing",
    }  # fmt: skip
    grid = ran["case"].str.starts_with("collision_slice[")
    assert grid.sum() == 2 * 9  # 9 cells, 2 checks each, one seed
    assert (ran.filter(grid)["n"] == 1).all() and (ran.filter(~grid)["n"] == 3).all()
    # every check with a tolerance was compared with the accepted baseline
    assert ran.filter(pl.col("tolerance").is_not_null())["baseline_mean"].null_count() == 0
    assert "GREEN" in (out / "report.md").read_text()


def test_a_fault_in_the_closed_loop_turns_the_suite_red(tmp_path: Path) -> None:
    """5 cm of bias in the live localizer: the robots steer on biased estimates, the live run's own
    metrics show it, and the replay reproduces the faulty run (from its recorded config)."""
    out = tmp_path / "bias"
    proc = run_cli(
        "base", "--only", "single_truck", "--seeds", "2", "--inject", "bias", "--out", str(out),
        "--no-report", module="simlan_data.evals", timeout=3600,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-2000:]
    metrics = pl.read_parquet(out / "metrics.parquet")
    live = metrics.filter((pl.col("source") == "run") & (pl.col("metric") == "localization.ate_xy_rmse_m"))
    assert live.height == 2 and (live["value"] > 0.04).all()
    same = metrics.filter(pl.col("metric") == "replay.localization.max_diff_to_live_m")
    assert (same["value"] == 0).all()
    summary = pl.read_parquet(out / "summary.parquet")
    red = summary.filter(pl.col("verdict").is_in(FAILING))
    assert "localization.ate_xy_rmse_m" in set(red["metric"])
