"""Verdicts and the report from a metrics table alone: checks over seeds, a sweep grid, pending lines."""

from __future__ import annotations

from pathlib import Path

import cv2
import polars as pl
import yaml

from simlan_data.evaluation.suite import METRICS_SCHEMA, judge, with_derived
from simlan_data.evaluation.suite_report import print_table, write_report, write_tables
from simlan_data.evaluation.suite_spec import load_suite

DOC = {
    "suites": {
        "s": {
            "baseline": "b.parquet",
            "seeds": 3,
            "cases": {
                "sweep": {
                    "overrides": ["scenario=default"],
                    "grid": {"angle": [45, 90], "speed": [0.5, 1.0]},
                    "metrics": {"run": {"navigation.collisions": {"max": 0}}},
                },
                "later": {
                    "overrides": ["scenario=default"],
                    "requires": ["config:not_there"],
                    "pending_note": "a later issue",
                    "grid": {"k": [1, 2, 3]},
                    "metrics": {"run": {"x.y": {"max": 1}}},
                },
            },
        }
    }
}


def test_report_from_a_metrics_table(tmp_path: Path, capsys) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(DOC))
    suite = load_suite(path, "s")
    cases = list(suite.cases)
    rows = []
    for case in cases:
        if case.pending:
            continue
        # one collision in one seed of the fastest head-on cell: its interval reaches above 0
        hit = case.grid == {"angle": 90, "speed": 1.0}
        rows += [
            (case.name, seed, "run", "navigation.collisions", 1.0 if hit and seed == 2 else 0.0)
            for seed in range(3)
        ]
    table = pl.DataFrame(rows, schema=METRICS_SCHEMA, orient="row")
    summary = judge(suite, cases, [], table, pl.DataFrame(schema=METRICS_SCHEMA))
    verdicts = dict(zip(summary["case"], summary["verdict"]))
    assert verdicts["sweep[angle=90,speed=1.0]"] == "fail"
    assert verdicts["sweep[angle=45,speed=0.5]"] == "pass"
    assert [v for c, v in verdicts.items() if c.startswith("later")] == ["pending"] * 3
    write_tables(tmp_path, table, summary)
    print_table(summary)
    out = capsys.readouterr().out
    assert "later (3 grid cells)" in out and "3 checks not run" in out
    assert "3 passed, 1 failed" in out and "RED" in out
    report = write_report(
        tmp_path, suite, cases, [], table, summary, faults=[], timings={"total_s": 1.0}, reused=None
    )
    text = report.read_text()
    assert text.startswith("# V&V suite `s`: RED")
    assert "## sweep (grid of 4 cells)" in text and "![sweep grid](plots/sweep_grid.png)" in text
    assert (
        "- `later (3 grid cells)`: pending: needs config key 'not_there'; waiting for the a later issue"
        in text
    )
    grid = cv2.imread(str(tmp_path / "plots" / "sweep_grid.png"))
    assert grid is not None and grid.shape[0] > 100
    assert pl.read_csv(tmp_path / "summary.csv").height == summary.height


def test_derived_goals_missed() -> None:
    m = with_derived({"navigation.goals_total": 5.0, "navigation.goals_reached": 3.0})
    assert m["navigation.goals_missed"] == 2.0
    assert "navigation.goals_missed" not in with_derived({"navigation.goals_total": 5.0})
