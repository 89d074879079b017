"""The safety scenarios end to end, guarding the figures of docs/benchmarks/safety.md (slow: about a minute each).

Over restricted_zone, blind_spot and humanoid_crossing: no violation missed, every stop within
one control period + one camera period of the hazard's onset in ground truth, no zone entered,
no collision, no false stop. And SIMLAN's collision case at 90 degrees: unguarded the Jackal
hits the truck's side, guarded they keep apart.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from conftest import run_cli
from simlan_data.metrics_io import load_metrics

pytestmark = pytest.mark.slow


def _run(tmp_path: Path, *overrides: str) -> dict[str, float]:
    run_dir = tmp_path / "run"
    proc = run_cli(*overrides, f"hydra.run.dir={run_dir}", "progress=false", timeout=1800)
    assert proc.returncode == 0, proc.stderr
    (tmp_path / "stdout.txt").write_text(proc.stdout)
    return load_metrics(run_dir / "metrics.json")  # strict JSON: NaN is null


@pytest.mark.parametrize("scenario", ["restricted_zone", "blind_spot", "humanoid_crossing"])
def test_safety_scenario_figures(scenario: str, tmp_path: Path) -> None:
    m = _run(tmp_path, f"scenario={scenario}")
    assert m["safety.missed"] == 0
    assert m["safety.stops"] >= 1
    assert m["safety.false_stops"] == 0
    assert m["safety.hazards_unanswered"] == 0
    latency = m["safety.max_latency_s"]
    assert math.isnan(latency) or latency <= m["safety.latency_budget_s"] + 1e-9
    assert m["safety.violations.zone_entries"] == 0
    assert m["safety.violations.collisions"] == 0
    if scenario == "restricted_zone":
        assert m["safety.stops.restricted_area"] == 1 and m["safety.min_clearance_zone_m"] > 0.2
        assert m["navigation.robot_agent_2.goals_reached"] == 1  # the Jackal may cross the bay
        # the truck stands before the bay to the end, and the summary says why it missed its goal
        assert m["safety.robot_agent_1.stopped_at_end.restricted_area"] == 1
        summary = (tmp_path / "stdout.txt").read_text()
        assert "a safety stop held it at the end (restricted_area" in summary, summary
    if scenario == "blind_spot":
        assert m["safety.stops.unobserved"] == 1
    if scenario == "humanoid_crossing":
        assert m["safety.stops.ttc"] >= 1 and m["navigation.goals_reached"] == m["navigation.goals_total"]
        assert m["safety.robot_agent_1.stopped_at_end"] == 0  # it drove on once the person had passed


@pytest.mark.parametrize(("guarded", "collides"), [("none", True), ("both", False)])
def test_simlan_collision_case_with_and_without_the_safety_layer(
    guarded: str, collides: bool, tmp_path: Path
) -> None:
    m = _run(
        tmp_path,
        "scenario=collision",
        "collision.angle=90",
        "collision.truck_speed_mps=1.0",
        "collision.collision_type=1",
        f"collision.guarded={guarded}",
    )
    assert (m["safety.violations.collisions"] > 0) is collides
    if not collides:
        assert m["safety.min_clearance_agents_m"] > 0.3 and m["safety.stops.ttc"] >= 1
