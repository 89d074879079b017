"""Candidate against baseline: the same suite, the same seeds, two algorithm configurations.

``python -m simlan_data.evals base --candidate algorithms/localizer=NAME`` runs the suite's jobs
twice (baseline: the suite as it is; candidate: plus the ``--candidate`` overrides), and this
module turns the two metrics tables into one comparison: for every checked (case, source,
metric) both sides' means with their intervals over seeds, the difference (candidate -
baseline) with its interval (paired by seed, :func:`~simlan_data.evaluation.stats.difference_interval`),
the direction that is better (the check's ``better``) and a verdict:

- ``better``: the interval of the difference lies wholly on the better side of zero;
- ``worse``: wholly on the worse side;
- ``no difference``: it contains zero;
- ``missing``: a side has no value, or the difference is not a number.

OUT/compare.parquet|csv (one row per check), OUT/compare.md (the overall verdict first).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl

from simlan_data.evaluation.stats import Bound, Interval, bound_ok, difference_interval, interval
from simlan_data.evaluation.suite_spec import Case

COMPARE_STEM = "compare"
VERDICTS = ("better", "worse", "no difference", "missing")
SCHEMA = {
    "case": pl.String,
    "source": pl.String,
    "metric": pl.String,
    "better": pl.String,  # lower | higher
    "bound": pl.String,
    "baseline_n": pl.Int64,
    "baseline_mean": pl.Float64,
    "baseline_low": pl.Float64,
    "baseline_high": pl.Float64,
    "candidate_n": pl.Int64,
    "candidate_mean": pl.Float64,
    "candidate_low": pl.Float64,
    "candidate_high": pl.Float64,
    "diff": pl.Float64,  # candidate - baseline
    "diff_low": pl.Float64,
    "diff_high": pl.Float64,
    "comparison": pl.String,  # paired | welch | single | none
    "verdict": pl.String,  # better | worse | no difference | missing
    "baseline_bound": pl.String,  # pass | fail | - (no absolute bound)
    "candidate_bound": pl.String,
    "note": pl.String,
}

CheckKey = tuple[str, str, str, Bound]  # case, source, metric, bound


def suite_checks(cases: Iterable[Case]) -> list[CheckKey]:
    """(case, source, metric, bound) of every check of the cases that can run."""
    return [(c.name, ch.source, ch.metric, ch.bound) for c in cases if not c.pending for ch in c.checks]


def _by_seed(table: pl.DataFrame, case: str, source: str, metric: str) -> dict[int, float]:
    sel = table.filter((pl.col("case") == case) & (pl.col("source") == source) & (pl.col("metric") == metric))
    return {int(s): float(v) for s, v in sel.select("seed", "value").iter_rows() if not math.isnan(v)}


def _num(v: float) -> float | None:
    return None if v is None or math.isnan(v) else v


def _difference(cand: dict[int, float], base: dict[int, float], confidence: float) -> tuple[Interval, str]:
    """Interval of candidate - baseline, paired over the seeds both have (else Welch).

    Equal values count as a difference of 0 even where they are infinite (e.g. a clearance to a
    zone that does not exist); a difference with an infinite value is that infinity.
    """
    common = sorted(set(cand) & set(base))
    if not common:
        return difference_interval(cand, base, confidence)
    cur = {s: cand[s] for s in common}
    ref = {s: base[s] for s in common}
    if all(math.isfinite(v) for v in (*cur.values(), *ref.values())):
        return difference_interval(cur, ref, confidence)
    diffs = [0.0 if cur[s] == ref[s] else cur[s] - ref[s] for s in common]
    if all(math.isfinite(d) for d in diffs):
        return interval(diffs, confidence), "paired"
    m = float(np.mean(diffs))
    return Interval(len(diffs), m, m, m, float("nan")), "paired"


def verdict(diff: Interval, better: str) -> str:
    """``better``, ``worse`` or ``no difference`` for the interval of (candidate - baseline)."""
    if diff.n == 0 or math.isnan(diff.low) or math.isnan(diff.high):
        return "missing"
    lower_is_better = better == "lower"
    if diff.high < 0:
        return "better" if lower_is_better else "worse"
    if diff.low > 0:
        return "worse" if lower_is_better else "better"
    return "no difference"


def _bound_verdict(bound: Bound, iv: Interval) -> str:
    if bound.max is None and bound.min is None:
        return "-"
    return "pass" if bound_ok(bound, iv) else "fail"


def compare_tables(
    baseline: pl.DataFrame,
    candidate: pl.DataFrame,
    checks: Sequence[CheckKey],
    confidence: float = 0.95,
) -> pl.DataFrame:
    """One row per check: both sides' intervals, their difference and its verdict (pure).

    ``baseline`` and ``candidate`` are metrics tables (case, seed, source, metric, value) as
    :func:`~simlan_data.evaluation.suite.metrics_table` makes them; NaN values are no values.
    """
    rows = []
    for case, source, metric, bound in checks:
        base = _by_seed(baseline, case, source, metric)
        cand = _by_seed(candidate, case, source, metric)
        with np.errstate(invalid="ignore"):  # infinite values (e.g. no zone to clear) have no spread
            b_iv, c_iv = interval(list(base.values()), confidence), interval(list(cand.values()), confidence)
        row: dict[str, Any] = {
            "case": case,
            "source": source,
            "metric": metric,
            "better": bound.better,
            "bound": bound.describe(),
            "baseline_n": b_iv.n,
            "baseline_mean": _num(b_iv.mean),
            "baseline_low": _num(b_iv.low),
            "baseline_high": _num(b_iv.high),
            "candidate_n": c_iv.n,
            "candidate_mean": _num(c_iv.mean),
            "candidate_low": _num(c_iv.low),
            "candidate_high": _num(c_iv.high),
            "baseline_bound": _bound_verdict(bound, b_iv) if base else "-",
            "candidate_bound": _bound_verdict(bound, c_iv) if cand else "-",
            "note": "",
        }
        if not base or not cand:
            side = " and ".join(n for n, v in (("baseline", base), ("candidate", cand)) if not v)
            rows.append(
                {**row, "comparison": "none", "verdict": "missing", "note": f"no value from the {side}"}
            )
            continue
        diff, how = _difference(cand, base, confidence)
        v = verdict(diff, bound.better)
        notes = []
        if set(cand) != set(base):
            notes.append(f"seeds differ: baseline {sorted(base)}, candidate {sorted(cand)}")
        if v == "missing":
            notes.append("the difference is not a number")
        rows.append(
            {
                **row,
                "diff": _num(diff.mean),
                "diff_low": _num(diff.low),
                "diff_high": _num(diff.high),
                "comparison": how,
                "verdict": v,
                "note": "; ".join(notes),
            }
        )
    return pl.DataFrame([{k: r.get(k) for k in SCHEMA} for r in rows], schema=SCHEMA)


def counts(table: pl.DataFrame) -> dict[str, int]:
    out = dict.fromkeys(VERDICTS, 0)
    for v in table["verdict"].to_list():
        out[v] = out.get(v, 0) + 1
    return out


def overall(table: pl.DataFrame) -> str:
    """``candidate better``, ``candidate worse``, ``mixed`` or ``no significant difference``
    (``no comparison`` when no metric has values on both sides)."""
    c = counts(table)
    if c["missing"] == table.height:
        return "no comparison"
    if c["better"] and c["worse"]:
        return "mixed"
    if c["better"]:
        return "candidate better"
    if c["worse"]:
        return "candidate worse"
    return "no significant difference"


def summary_line(table: pl.DataFrame) -> str:
    c = counts(table)
    bounds = {
        side: (
            table.filter(pl.col(f"{side}_bound") == "pass").height,
            table.filter(pl.col(f"{side}_bound") != "-").height,
        )
        for side in ("baseline", "candidate")
    }
    return (
        f"{overall(table)}: {c['better']} better, {c['worse']} worse, {c['no difference']} no difference, "
        f"{c['missing']} missing of {table.height} metrics; bounds held: baseline "
        f"{bounds['baseline'][0]}/{bounds['baseline'][1]}, candidate {bounds['candidate'][0]}/{bounds['candidate'][1]}"
    )


def _fmt(v: Any, spec: str = ".4g") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def _ci(mean: Any, low: Any, high: Any, n: int | None = None, spec: str = ".4g") -> str:
    if mean is None:
        return "-"
    if (n is not None and n < 2) or low == high:
        return _fmt(mean, spec)
    return f"{_fmt(mean, spec)} [{_fmt(low, spec)}, {_fmt(high, spec)}]"


def _signed(mean: Any, low: Any, high: Any, spec: str = "+.4g") -> str:
    if mean is None:
        return "-"
    if low == high:
        return format(mean, spec)
    return f"{mean:{spec}} [{low:{spec}}, {high:{spec}}]"


MARK = {"better": "BETTER", "worse": "WORSE", "no difference": "same", "missing": "MISSING"}


def print_comparison(table: pl.DataFrame) -> None:
    """The compact console table and the overall verdict."""
    header = (
        f"{'verdict':<8} {'case':<16} {'source:metric':<46} {'baseline':<26} {'candidate':<26} "
        f"{'difference [95% CI]':<28} {'bounds b/c'}"
    )
    print(header)
    print("-" * len(header))
    for r in table.iter_rows(named=True):
        metric = f"{r['source']}:{r['metric']}"[-44:] + (" v" if r["better"] == "lower" else " ^")
        base = _ci(r["baseline_mean"], r["baseline_low"], r["baseline_high"], r["baseline_n"], ".3g")
        cand = _ci(r["candidate_mean"], r["candidate_low"], r["candidate_high"], r["candidate_n"], ".3g")
        diff = _signed(r["diff"], r["diff_low"], r["diff_high"], "+.3g")
        print(
            f"{MARK[r['verdict']]:<8} {r['case'][:16]:<16} {metric:<46} {base[:26]:<26} {cand[:26]:<26} "
            f"{diff[:28]:<28} {r['baseline_bound']}/{r['candidate_bound']}"
        )
    print("(v: lower is better, ^: higher is better)")
    print(f"\nverdict: {summary_line(table)}")


def write_comparison(
    out: Path,
    table: pl.DataFrame,
    *,
    suite: str,
    candidate: Sequence[str],
    seeds: dict[str, list[int]],
    baseline_dir: Path,
    candidate_dir: Path,
    failures: Sequence[str] = (),
) -> Path:
    """OUT/compare.parquet, .csv and .md; returns the path of compare.md."""
    table.write_parquet(out / f"{COMPARE_STEM}.parquet")
    table.write_csv(out / f"{COMPARE_STEM}.csv", float_precision=9)
    lines = [
        f"# Candidate vs baseline: suite {suite}",
        "",
        f"**{summary_line(table)}**",
        "",
        f"- candidate: the suite plus `{' '.join(candidate)}` ({candidate_dir})",
        f"- baseline: the suite as it is ({baseline_dir})",
        "- seeds: " + "; ".join(f"{case} {s}" for case, s in seeds.items()),
        "- difference: candidate - baseline, 95 % interval paired by seed; `better`/`worse`: the "
        "interval lies wholly on that side of zero (the check's better direction), else `no difference`",
        "- bounds: whether each side's 95 % interval lies within the case's absolute bound (`-`: none)",
    ]
    if failures:
        lines += ["", "## Failed runs", "", *(f"- {f}" for f in failures)]
    for case in table["case"].unique(maintain_order=True).to_list():
        lines += [
            "",
            f"## {case}",
            "",
            "| metric | better | baseline | candidate | difference | verdict | bound | baseline | candidate |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in table.filter(pl.col("case") == case).iter_rows(named=True):
            base = _ci(r["baseline_mean"], r["baseline_low"], r["baseline_high"], r["baseline_n"])
            cand = _ci(r["candidate_mean"], r["candidate_low"], r["candidate_high"], r["candidate_n"])
            diff = _signed(r["diff"], r["diff_low"], r["diff_high"])
            verdict_text = f"**{r['verdict']}**" if r["verdict"] in ("better", "worse") else r["verdict"]
            if r["note"]:
                verdict_text += f" ({r['note']})"
            lines.append(
                f"| {r['source']}: `{r['metric']}` | {r['better']} | {base} | {cand} | {diff} | {verdict_text} "
                f"| {r['bound']} | {r['baseline_bound']} | {r['candidate_bound']} |"
            )
    path = out / f"{COMPARE_STEM}.md"
    path.write_text("\n".join(lines) + "\n")
    return path
