"""benchmarks/robustness.py: the BENCHMARKS rows of the robustness sweeps, from their CSVs.

A hand-made ``robustness.csv`` of the shipped ``robustness_safety`` sweep (its real promises from
evals/base.yaml), read by the script in a process of its own as a user runs it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
METRICS = {  # the sweep's promises: missed, zone entries, false stops <= 0, clearance >= 0, age <= 0.25
    "safety.missed": 0.0,
    "safety.violations.zone_entries": 0.0,
    "safety.false_stops": 0.0,
    "safety.min_clearance_zone_m": 0.85,
    "localization.latency_s": 0.1,
}


def write_csv(path: Path, effect: str, key: str, bad: dict[float, dict[str, float]]) -> None:
    """Every strength and seed at the good values, except the metrics ``bad`` sets per strength."""
    path.mkdir(parents=True)
    rows = ["effect,key,strength,seed,source,metric,value"]
    for strength in (0.0, 0.2, 0.5, 0.8) if effect == "drops" else (0.0, 0.05, 0.2, 0.5):
        for seed in (0, 1):
            for metric, value in {**METRICS, **bad.get(strength, {})}.items():
                rows.append(f"{effect},{key},{strength},{seed},run,{metric},{value}")
    (path / "robustness.csv").write_text("\n".join(rows) + "\n")


def test_the_first_breaking_strength_and_what_breaks_there(tmp_path: Path) -> None:
    write_csv(
        tmp_path / "a",
        "drops",
        "sensors.timing.drop_rate",
        {0.5: {"safety.false_stops": 1.0}, 0.8: {"safety.false_stops": 2.0, "localization.latency_s": 0.5}},
    )
    write_csv(tmp_path / "b", "delay", "sensors.timing.delay_s", {})
    out = tmp_path / "fig.json"
    proc = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "robustness.py"), "--sweep", "robustness_safety",
         "--from", str(tmp_path / "a"), str(tmp_path / "b"), "--json", str(out)],
        capture_output=True, text=True, cwd=REPO, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    figures = {f["id"]: f for f in json.loads(out.read_text())["figures"]}
    drops = figures["robustness_safety_drops"]
    assert drops["value"] == "0.5"  # false stops appear there
    assert "safety.false_stops 1 (<= 0)" in drops["note"] and "holds up to 0.2" in drops["note"]
    assert figures["robustness_safety_delay"]["value"] == "none"  # every promise holds to 0.5 s
