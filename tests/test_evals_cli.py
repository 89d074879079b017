"""``python -m simlan_data.evals``: arguments, accepting a baseline, reusing runs; one line per bad input."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import polars as pl
import pytest
import yaml

from conftest import REPO, run_cli
from simlan_data.apps import evals
from simlan_data.errors import ConfigError

GOLDEN = REPO / "recordings" / "golden" / "two_robots"


def tiny_suite(tmp_path: Path) -> Path:
    """A suite over one golden recording, with its baseline in tmp_path."""
    doc = {
        "faults": {
            "bias": {
                "run": ["algorithms.localizer.bias_m=[0.05,0.0]"],
                "replay": {"localization": {"bias_m": [0.05, 0.0]}},
            },
        },
        "suites": {
            "mine": {
                "baseline": "baselines/mine.csv",
                "cases": {
                    "two": {
                        "recording": str(GOLDEN),
                        "replay": {"localization": {"navigation": False}},
                        "metrics": {
                            "localization": {
                                "localization.ate_xy_rmse_m": {"max": 0.02, "tolerance": 0.002},
                                "localization.availability": {"min": 0.95, "tolerance": 0.01},
                            },
                            "run": {"navigation.goals_missed": {"max": 2}},
                        },
                    }
                },
            }
        },
    }
    path = tmp_path / "suite.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_accept_then_compare_then_a_fault_regresses(tmp_path: Path) -> None:
    suite = tiny_suite(tmp_path)
    base = ["mine", "--file", str(suite), "--jobs", "1", "--no-report"]
    # no baseline yet: bounds decide, the tolerance has nothing to compare with
    assert evals.main([*base, "--out", str(tmp_path / "a")]) == 0
    first = pl.read_parquet(tmp_path / "a" / "summary.parquet")
    assert first["baseline_mean"].null_count() == first.height
    assert evals.main([*base, "--accept", "--out", str(tmp_path / "b")]) == 0
    accepted = pl.read_csv(tmp_path / "baselines" / "mine.csv")
    assert accepted.height == 3 and set(accepted["case"]) == {"two"}
    # the same algorithms on the same recording: exactly the baseline (paired difference 0)
    assert evals.main([*base, "--out", str(tmp_path / "c")]) == 0
    same = pl.read_parquet(tmp_path / "c" / "summary.parquet")
    assert (same["diff_low"] == 0).all() and (same["diff_high"] == 0).all()
    assert evals.main([*base, "--inject", "bias", "--out", str(tmp_path / "d")]) == 1
    red = pl.read_parquet(tmp_path / "d" / "summary.parquet").filter(pl.col("verdict") != "pass")
    assert red["metric"].to_list() == ["localization.ate_xy_rmse_m"]
    assert red["verdict"].to_list() == ["fail"]  # out of its bound and beyond its tolerance
    assert "worse than baseline" in red["note"][0]
    # the faulty run left the accepted baseline alone
    assert pl.read_csv(tmp_path / "baselines" / "mine.csv").equals(accepted)


def test_reuse_replays_earlier_runs_without_simulating(tmp_path: Path) -> None:
    """Reuse a suite output whose runs are copies of a golden run (as `evals base` leaves them)."""
    doc = yaml.safe_load(tiny_suite(tmp_path).read_text())
    case = doc["suites"]["mine"]["cases"]["two"]
    del case["recording"]
    case["overrides"] = ["scenario=default", "duration_s=14"]
    doc["suites"]["mine"]["seeds"] = 2
    suite = tmp_path / "suite2.yaml"
    suite.write_text(yaml.safe_dump(doc))
    earlier = tmp_path / "earlier"
    for seed in (0, 1):
        shutil.copytree(GOLDEN, earlier / "runs" / f"two__s{seed}")
    overrides = ["scenario=default", "duration_s=14"]
    jobs = {f"two__s{seed}": {"overrides": overrides, "faults": []} for seed in (0, 1)}
    (earlier / "jobs.json").write_text(json.dumps(jobs))
    args = ["mine", "--file", str(suite), "--jobs", "1", "--no-report", "--reuse", str(earlier)]
    assert evals.main([*args, "--out", str(tmp_path / "out")]) == 0
    table = pl.read_parquet(tmp_path / "out" / "metrics.parquet")
    assert sorted(set(table["seed"])) == [0, 1]
    assert not (tmp_path / "out" / "runs").exists()  # nothing simulated
    # an output that itself reused runs can be reused again: it says where they are
    again = [a if a != str(earlier) else str(tmp_path / "out") for a in args]
    assert evals.main([*again, "--out", str(tmp_path / "again")]) == 0
    # recordings made with other overrides are not silently reused
    doc["suites"]["mine"]["cases"]["two"]["overrides"] = ["scenario=default", "duration_s=20"]
    suite.write_text(yaml.safe_dump(doc))
    with pytest.raises(
        ConfigError, match=r"recordings made differently in .*two__s0: case two was recorded with overrides"
    ):
        evals.main([*args, "--out", str(tmp_path / "out2")])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["nope"], r"unknown suite 'nope' in .*base.yaml: suites: base, golden; pick one"),
        (["golden", "--inject", "bais"], r"unknown fault 'bais' in --inject: known: bias, latency"),
        (
            ["golden", "--inject", "bias", "--accept"],
            r"--accept with --inject in arguments: a faulty run is no baseline",
        ),
        (["golden", "--only", "nothing"], r"unknown case 'nothing' in --only: cases: "),
        (["golden", "--reuse", "{tmp}"], r"nothing to reuse in .*: no jobs.json"),
        (["golden", "--out", "{tmp}"], r"output exists in .*: the suite never overwrites results"),
        (
            ["base", "--seeds", "0"],
            r"invalid seeds=0 in .*cases.single_truck: expected an integer within 1..1000",
        ),
        (["golden", "--jobs", "0"], r"invalid --jobs 0 in arguments: must be >= 1"),
        (["--file", "{tmp}/none.yaml", "base"], r"suite file missing in .*none.yaml"),
        (["golden", "--reuse", "{tmp}", "--regenerate"], r"--reuse with --regenerate in arguments"),
        (["golden", "--launcher", "slurmish"], r"unknown launcher 'slurmish' in --launcher: no Hydra plugin"),
    ],
)
def test_bad_arguments_are_refused_before_anything_runs(tmp_path: Path, args: list[str], match: str) -> None:
    (tmp_path / "keep.txt").write_text("an earlier output")
    with pytest.raises(ConfigError, match=match) as err:
        evals.main([a.format(tmp=tmp_path) for a in args])
    assert err.value.exit_code == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]
    assert (tmp_path / "keep.txt").read_text() == "an earlier output"


def test_a_bad_argument_is_one_line_on_stderr_and_exit_code_2() -> None:
    proc = run_cli("golden", "--inject", "bais", module="simlan_data.evals", timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: unknown fault 'bais' in --inject: known: bias, latency, drop_camera, calibration, "
        "safety_condition; pick from the list (python -m simlan_data.evals --list)"
    ]


def test_list_shows_cases_faults_and_what_is_pending() -> None:
    proc = run_cli("--list", module="simlan_data.evals", timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "single_truck" in proc.stdout and "golden_two_robots" in proc.stdout
    assert re.search(r"bias .*\[available\]", proc.stdout)
    lines = {
        line.split()[0]: line for line in proc.stdout.splitlines() if line.startswith("  ") and line.split()
    }
    assert "pending" not in lines["restricted_zone"] and "[available]" in lines["safety_condition"]
    assert "faults acting: none" in lines["posemap_replay"]
    assert "pending" not in lines["posemap_replay"] and re.search(
        r"\d+ seeds, \d+ checks", lines["posemap_replay"]
    )


@pytest.mark.parametrize(
    ("override", "match"),
    [
        (
            "nonexistent_key=3",
            r"invalid overrides in case c \(seed 0\): .*Key 'nonexistent_key' not in 'Config'",
        ),
        ("duration_s=-1", r"invalid duration_s=-1.0 in case c \(seed 0\): config: must be within"),
    ],
)
def test_a_case_that_cannot_run_is_refused_before_any_run(tmp_path: Path, override: str, match: str) -> None:
    suite = tmp_path / "s.yaml"
    suite.write_text(
        yaml.safe_dump(
            {
                "suites": {
                    "s": {
                        "baseline": "b.parquet",
                        "cases": {
                            "c": {
                                "overrides": ["cameras=single", override],
                                "metrics": {"run": {"navigation.collisions": {"max": 0}}},
                            }
                        },
                    }
                }
            }
        )
    )
    with pytest.raises(ConfigError, match=match):
        evals.main(["s", "--file", str(suite), "--out", str(tmp_path / "out")])
    assert not (tmp_path / "out").exists()
