"""``python -m simlan_data.evals SUITE --candidate ...``: candidate vs baseline over the same seeds.

The comparison table from hand-made metrics tables (verdicts, directions, pairing, bounds), and
one real comparison (two short runs per side, real processes) plus a refused candidate.
"""

from __future__ import annotations

import math
from pathlib import Path

import polars as pl
import pytest
import yaml

from conftest import run_cli
from simlan_data.evaluation.compare import compare_tables, overall, summary_line
from simlan_data.evaluation.stats import Bound
from simlan_data.evaluation.suite import METRICS_SCHEMA

CANDIDATE = "algorithms.localizer.method=pnp"  # the built-in's other method: measurably different


def table(values: dict[tuple[str, str], list[float]]) -> pl.DataFrame:
    """A metrics table: (case, metric) -> one value per seed 0..n-1, source ``run``."""
    rows = [
        (case, seed, "run", metric, v) for (case, metric), vs in values.items() for seed, v in enumerate(vs)
    ]
    return pl.DataFrame(rows, schema=METRICS_SCHEMA, orient="row")


ERR = Bound(max=0.05, better="lower")
AVAIL = Bound(min=0.9, better="higher")


def row(cmp: pl.DataFrame, metric: str) -> dict:
    return cmp.filter(pl.col("metric") == metric).row(0, named=True)


def test_verdicts_follow_the_better_direction_and_the_paired_interval() -> None:
    base = table(
        {
            ("c", "err"): [0.010, 0.020, 0.030],
            ("c", "avail"): [0.95, 0.97, 0.99],
            ("c", "noisy"): [1.0, 2.0, 3.0],
        }
    )
    cand = table(
        {
            ("c", "err"): [0.021, 0.030, 0.042],  # larger by 0.010..0.012 on every seed: worse
            ("c", "avail"): [0.96, 0.98, 0.999],  # higher on every seed: better (higher is better)
            ("c", "noisy"): [1.5, 1.4, 3.2],  # up and down: no difference
        }
    )
    checks = [
        ("c", "run", "err", ERR),
        ("c", "run", "avail", AVAIL),
        ("c", "run", "noisy", Bound(tolerance=1)),
    ]
    cmp = compare_tables(base, cand, checks)
    assert cmp["verdict"].to_list() == ["worse", "better", "no difference"]
    err = row(cmp, "err")
    assert err["better"] == "lower" and err["comparison"] == "paired"
    assert err["diff"] == pytest.approx(err["candidate_mean"] - err["baseline_mean"], abs=1e-12)
    assert 0 < err["diff_low"] < err["diff"] < err["diff_high"]
    # baseline's interval 0.02 +- 0.025 lies within <= 0.05; the candidate's 0.031 +- 0.026 does not
    assert (err["baseline_bound"], err["candidate_bound"]) == ("pass", "fail")
    assert row(cmp, "avail")["diff_low"] > 0
    assert row(cmp, "noisy")["baseline_bound"] == "-"  # no absolute bound: nothing to pass
    assert overall(cmp) == "mixed"
    assert summary_line(cmp).startswith("mixed: 1 better, 1 worse, 1 no difference, 0 missing of 3")
    # lower error on every seed is better; the same direction flipped is worse for availability
    flipped = compare_tables(cand, base, checks)
    assert flipped["verdict"].to_list() == ["better", "worse", "no difference"]
    assert overall(flipped.filter(pl.col("metric") == "err")) == "candidate better"
    assert overall(flipped.filter(pl.col("metric") == "avail")) == "candidate worse"


def test_pairing_by_seed_bounds_missing_values_and_infinities() -> None:
    # a large spread over seeds, but the same shift on every seed: paired, the shift is certain
    base = table({("c", "err"): [0.01, 0.04, 0.07], ("c", "clear"): [math.inf] * 3})
    cand = table({("c", "err"): [0.02, 0.05, 0.08], ("c", "clear"): [math.inf] * 3})
    checks = [
        ("c", "run", "err", ERR),
        ("c", "run", "clear", Bound(min=0.0, better="higher")),
        ("c", "run", "absent", ERR),
        ("other", "run", "err", ERR),
    ]
    cmp = compare_tables(base, cand, checks)
    err = row(cmp, "err")
    assert err["verdict"] == "worse"
    assert err["diff_low"] == pytest.approx(0.01) and err["diff_high"] == pytest.approx(0.01)
    # the candidate's interval [0.05 +- t*0.03/sqrt(3)] reaches beyond 0.05: it fails the bound
    assert (err["baseline_bound"], err["candidate_bound"]) == ("fail", "fail")
    clear = row(cmp, "clear")
    assert clear["verdict"] == "no difference" and clear["diff"] == 0.0
    missing = cmp.filter(pl.col("verdict") == "missing")
    assert missing["metric"].to_list() == ["absent", "err"] and missing["case"].to_list() == ["c", "other"]
    assert missing["note"][0] == "no value from the baseline and candidate"
    assert overall(cmp) == "candidate worse"
    same = compare_tables(base, base, checks[:2])
    assert overall(same) == "no significant difference"
    assert (same["diff"] == 0).all()


# --------------------------------------------------------------------------- real processes
def tiny_suite(tmp_path: Path) -> Path:
    """One 4 s single-truck case, 3 cameras at the truck's start (480x270, RGB only), 2 seeds."""
    doc = {
        "suites": {
            "mini": {
                "baseline": "baselines/mini.csv",
                "seeds": 2,
                "overrides": ["perturbation.spawn_xy_m=0.15", "perturbation.spawn_yaw_deg=3"],
                "cases": {
                    "truck": {
                        "overrides": [
                            "scenario=single_truck",
                            "duration_s=4",
                            "cameras.ids=[160,161,162]",
                            "cameras.width=480",
                            "cameras.height=270",
                            "cameras.streams=[rgb]",
                        ],
                        "replay": {"localization": {"navigation": False}},
                        "metrics": {
                            "run": {
                                "navigation.collisions": {"max": 0},
                                "localization.ate_xy_rmse_m": {"max": 0.05},
                            },
                            "localization": {
                                "localization.ate_xy_rmse_m": {"max": 0.05, "tolerance": 0.004},
                                "localization.yaw_rmse_deg": {"max": 3.0},
                                "localization.availability": {"min": 0.9},
                            },
                        },
                    }
                },
            }
        }
    }
    path = tmp_path / "suite.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.slow  # (20 s of suite runs: the default suite stays under 10 minutes; CI runs slow too)
def test_candidate_against_baseline_end_to_end(tmp_path: Path) -> None:
    suite, out = tiny_suite(tmp_path), tmp_path / "out"
    args = ("mini", "--file", str(suite), "--jobs", "2", "--out", str(out))
    proc = run_cli(*args, "--candidate", CANDIDATE, module="simlan_data.evals", timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in ("compare.md", "compare.parquet", "compare.csv"):
        assert (out / name).is_file(), name
    for side in ("baseline", "candidate"):
        runs = {p.name for p in (out / side / "runs").iterdir() if p.is_dir()}
        assert runs == {"truck__s0", "truck__s1"}  # (beside the multirun's own files)
        assert (out / side / "metrics.parquet").is_file()
    cmp = pl.read_parquet(out / "compare.parquet")
    assert cmp.height == 5 and set(cmp["case"]) == {"truck"}
    assert set(cmp["verdict"]) <= {"better", "worse", "no difference"}  # every metric on both sides
    assert (cmp["baseline_n"] == 2).all() and (cmp["candidate_n"] == 2).all()
    assert cmp["diff"].to_list() == pytest.approx(
        (cmp["candidate_mean"] - cmp["baseline_mean"]).to_list(), abs=1e-12
    )
    # the sides really differ: the candidate steered on (and replayed) another method's estimates
    ate = cmp.filter(pl.col("metric") == "localization.ate_xy_rmse_m", pl.col("source") == "localization")
    assert ate["diff"][0] != 0
    # the difference is the means' of the sides' own metrics tables
    for side in ("baseline", "candidate"):
        m = pl.read_parquet(out / side / "metrics.parquet").filter(
            pl.col("source") == "localization", pl.col("metric") == "localization.ate_xy_rmse_m"
        )
        assert m["value"].mean() == pytest.approx(ate[f"{side}_mean"][0], abs=1e-12)
    report = (out / "compare.md").read_text()
    first = next(ln for ln in report.splitlines() if ln.startswith("**"))
    verdict = first.strip("*").split(":")[0]
    assert verdict in ("candidate better", "candidate worse", "mixed", "no significant difference")
    assert f"verdict: {verdict}:" in proc.stdout
    assert CANDIDATE in report


@pytest.mark.parametrize(
    "bad",
    [
        "algorithms.localizer.methd=pnp",  # a key the built-in does not have
        "algorithms/localizer=no_such_localizer",  # an algorithm that is not registered
    ],
)
def test_a_candidate_that_does_not_compose_is_one_line_exit_2_and_nothing_written(
    tmp_path: Path, bad: str
) -> None:
    suite, out = tiny_suite(tmp_path), tmp_path / "out"
    proc = run_cli(
        "mini", "--file", str(suite), "--out", str(out), "--candidate", "algorithms/localizer=aruco",
        "--candidate", bad, module="simlan_data.evals", timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: invalid --candidate {bad} in "), lines
    assert not out.exists()


@pytest.mark.parametrize("flag", ["--accept", "--regenerate"])
def test_candidate_refuses_accept_and_regenerate(tmp_path: Path, flag: str) -> None:
    from simlan_data.apps import evals
    from simlan_data.errors import ConfigError

    with pytest.raises(ConfigError, match=f"--candidate with {flag} in arguments") as err:
        evals.main(["mini", "--file", str(tiny_suite(tmp_path)), "--candidate", CANDIDATE, flag])
    assert err.value.exit_code == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["suite.yaml"]


@pytest.mark.parametrize("candidate", ["algorithms.localizer.method=pnp", "algorithms/localizer=foreground"])
def test_a_candidate_leaves_out_the_cases_that_pin_their_own_algorithm_of_its_role(
    candidate: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The shipped base suite's markerfree case selects algorithms/localizer=foreground itself: a
    localizer candidate does not apply there (the README's `--candidate algorithms/localizer=centroid`
    stopped with exit 2 on its start_poses key); every other simulated case composes with it."""
    from simlan_data.apps import evals
    from simlan_data.evaluation.suite_spec import load_suite

    args = evals.build_parser().parse_args(["base", "--candidate", candidate])
    suite = load_suite(args.file, args.suite)
    _, cases = evals._compared_cases(args, suite)
    families = {c.family for c in cases}
    assert "markerfree" not in families and {"single_truck", "multi_robot", "default"} <= families
    assert "note: case markerfree pins its own algorithms/localizer=foreground" in capsys.readouterr().out
    if candidate.startswith("algorithms.localizer.method"):  # (composing every job twice: 25 s)
        evals._check_candidate(suite, cases, [], [candidate])  # raised ConfigError before
