"""The full default scenario, as the README's first command runs it (slow: about a minute)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from conftest import run_cli


@pytest.mark.slow
def test_default_scenario_completes_and_stays_small(tmp_path: Path) -> None:
    run_dir = tmp_path / "default"
    proc = run_cli(f"hydra.run.dir={run_dir}", "progress=false")
    assert proc.returncode == 0, proc.stderr
    m = json.loads((run_dir / "metrics.json").read_text())
    assert m["sim.duration_s"] == 60.0
    # the default scenario is GPSS: the truck steers on the camera estimate through its goals
    assert m["navigation.robot_agent_1.goals_reached"] == m["navigation.robot_agent_1.goals_total"] == 4
    assert m["localization.ate_xy_rmse_m"] < 0.02
    assert m["agents.collisions"] == 0
    # promised in issue 2: a 60 s default run stays well under 500 MB
    assert m["recording.bytes"] < 400 * 2**20
    assert "real-time factor" in proc.stdout
