"""Golden recordings: replayed through today's algorithms, they must give the accepted metrics.

The recordings under ``recordings/golden/`` (two 14 s runs at 480x270 under cameras 162 and 163)
and their expected metrics (``recordings/golden/expected_metrics.csv``) are the ``golden`` suite
of ``evals/base.yaml``. When an algorithm changes on purpose, accept its new metrics with

    python -m simlan_data.evals golden --accept

and when the simulator or the recording format changes, re-simulate the recordings (and accept) with

    python -m simlan_data.evals golden --regenerate

Each injected fault of the suite must turn the golden suite red: the fault tests below replay one
golden recording with the fault and check that the metrics the fault names fail.
"""

from __future__ import annotations

from pathlib import Path

import polars as pl
import pytest
import yaml

from conftest import REPO
from simlan_data.apps import evals
from simlan_data.errors import ConfigError
from simlan_data.evaluation.suite import FAILING
from simlan_data.evaluation.suite_spec import load_suite

SUITE = load_suite(evals.DEFAULT_FILE, "golden")
READY = [
    c for c in SUITE.cases if not c.pending
]  # a golden case waiting for a capability has no recording yet


def summary(out: Path) -> pl.DataFrame:
    return pl.read_parquet(out / "summary.parquet")


def test_golden_recordings_are_small_and_committed() -> None:
    assert {c.name for c in READY} >= {"golden_single_truck", "golden_two_robots"}
    for case in READY:
        assert case.recording is not None and (case.recording / "recording" / "metadata.yaml").is_file()
    total = sum(f.stat().st_size for c in READY for f in c.recording.rglob("*") if f.is_file())  # type: ignore[union-attr]
    assert total < 5 * 2**20, f"golden recordings take {total / 2**20:.1f} MiB"
    assert SUITE.baseline.is_file()


def test_golden_replay_matches_expected_metrics(tmp_path: Path) -> None:
    """Replays both golden recordings through localization and the bird's-eye stitcher (no
    simulator); fails when an algorithm change moves a metric beyond its tolerance."""
    out = tmp_path / "golden"
    code = evals.main(["golden", "--out", str(out), "--jobs", "1"])
    table = summary(out)
    failing = table.filter(pl.col("verdict").is_in(FAILING))
    assert code == 0, (
        f"golden metrics moved (see {out}/report.md):\n{failing.select('case', 'metric', 'mean', 'baseline_mean', 'note')}"
    )
    ran = table.filter(pl.col("verdict") != "pending")
    assert ran.height == sum(len(c.checks) for c in READY)
    assert set(ran["verdict"]) == {"pass"}
    # every check was compared with an accepted value, not just with itself
    assert ran["baseline_mean"].null_count() == 0
    report = (out / "report.md").read_text()
    assert "GREEN" in report and "golden_single_truck" in report
    plots = {p.name for p in (out / "plots").glob("*.png")}
    assert {
        "golden_single_truck_trajectories.png",
        "golden_single_truck_error.png",
        "golden_single_truck_birdseye.png",
    } <= plots
    metrics = pl.read_parquet(out / "metrics.parquet")
    assert set(metrics["source"]) == {"run", "localization", "birdseye", "safety"}
    assert (out / "metrics.csv").is_file() and (out / "summary.csv").is_file()


@pytest.mark.parametrize("name", sorted(SUITE.faults))
def test_each_injected_fault_turns_the_suite_red(name: str, tmp_path: Path) -> None:
    fault = SUITE.faults[name]
    if fault.pending:
        pytest.skip(f"pending: {fault.pending}")
    # one golden case that replays what the fault acts on; without the bird's-eye replay (slow: it
    # renders a ground truth) unless the fault acts on nothing else
    touched = set(fault.replay)
    cases = sorted((c for c in SUITE.cases if touched & set(c.replay)), key=lambda c: "birdseye" in c.replay)
    assert cases, f"no golden case replays {sorted(touched)}: add one to the golden suite for fault {name}"
    out = tmp_path / name
    args = [
        "golden",
        "--only",
        cases[0].name,
        "--inject",
        name,
        "--out",
        str(out),
        "--jobs",
        "1",
        "--no-report",
    ]
    code = evals.main(args)
    table = summary(out)
    red = set(table.filter(pl.col("verdict").is_in(FAILING))["metric"])
    assert code == 1
    assert set(fault.expect) <= red, f"{name} should fail {fault.expect}, failed {sorted(red)}"


def test_a_pending_fault_cannot_be_injected(tmp_path: Path) -> None:
    """A fault whose capability has not landed (here: a config key that does not exist) is
    refused before anything runs; the golden suite's own faults have all landed."""
    spec = yaml.safe_load((REPO / "evals" / "base.yaml").read_text())
    spec["faults"]["future"] = {
        "description": "a capability that has not landed",
        "requires": ["config:safety.no_such_condition"],
        "pending_note": "some later issue",
        "run": ["safety.no_such_condition.enabled=false"],
        "expect": ["safety.missed"],
    }
    for case in spec["suites"]["golden"]["cases"].values():
        case["recording"] = str((REPO / "evals" / case["recording"]).resolve())
    spec["suites"]["golden"]["baseline"] = str(SUITE.baseline)
    suite_file = tmp_path / "suite.yaml"
    suite_file.write_text(yaml.safe_dump(spec, sort_keys=False))
    with pytest.raises(ConfigError, match="fault 'future' is pending in --inject: needs"):
        evals.main(["golden", "--file", str(suite_file), "--inject", "future", "--out", str(tmp_path / "x")])
    assert not (tmp_path / "x").exists()
