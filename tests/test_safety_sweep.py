"""The collision sweep report on a hand-made sweep directory (the real sweep is a benchmark)."""

from __future__ import annotations

import json
from pathlib import Path

import polars as pl

from simlan_data.evaluation.sweep import aggregate


def _job(root: Path, name: str, angle: int, guarded: str, metrics: dict[str, float] | None) -> None:
    job = root / name
    (job / ".hydra").mkdir(parents=True)
    overrides = [
        f"collision.angle={angle}",
        "collision.truck_speed_mps=1.0",
        "collision.collision_type=1",
        f"collision.guarded={guarded}",
    ]
    (job / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    if metrics is not None:
        (job / "metrics.json").write_text(json.dumps(metrics))


def _metrics(collisions: int, gap: float, *, localized: float = 100.0) -> dict[str, float]:
    return {
        "safety.violations.collisions": float(collisions),
        "safety.min_clearance_agents_m": gap,
        "safety.stops": 1.0,
        "safety.slows": 0.0,
        "safety.missed": 0.0,
        "safety.false_stops": 0.0,
        "safety.max_latency_s": 0.05,
        "localization.ate_xy_rmse_m": 0.01,
        "localization.robot_agent_1.ticks_valid": localized,
        "localization.robot_agent_2.ticks_valid": localized,
    }


def test_collision_report_counts_avoided_collisions_and_leaves_out_unlocalized_cases(tmp_path: Path) -> None:
    _job(tmp_path, "0", 45, "none", _metrics(1, 0.0))
    _job(tmp_path, "1", 45, "both", _metrics(0, 1.25))
    _job(tmp_path, "2", 90, "none", _metrics(1, 0.0))
    _job(tmp_path, "3", 90, "both", _metrics(0, 0.8, localized=0.0))  # a robot never seen
    _job(tmp_path, "4", 135, "none", _metrics(0, 0.4))  # no collision even unguarded
    _job(tmp_path, "5", 135, "both", None)  # the job failed
    aggregate(tmp_path, "collision")
    md = (tmp_path / "collision_sweep.md").read_text()
    assert "| pallet-truck side | 45 | 1 | **collision** (0.00 m) | no contact (1.25 m) |" in md
    assert "| pallet-truck side | 90 | 1 | **collision** (0.00 m) | not localized |" in md
    assert "| pallet-truck side | 135 | 1 | no contact (0.40 m) | failed |" in md
    assert "- guarded none: 2 of 3 runs collided" in md
    assert (
        "- guarded both: 0 of 1 runs collided (1 not localized, left out); of the 1 cases that collide unguarded, 1 avoided"
        in md
    )
    assert (tmp_path / "collision_sweep.png").stat().st_size > 10_000
    cases = pl.read_csv(tmp_path / "collision_cases.csv")
    assert cases.height == 6 and set(cases["guarded"].to_list()) == {"none", "both"}
