"""A robustness sweep's results for people: robustness.csv, one plot per effect, robustness.md.

OUT/robustness.csv        effect, key, strength, seed, source, metric, value (every promised metric)
OUT/plots/EFFECT.png      per promised metric: value against strength, per seed and the mean,
                          the promise as a red line, the first break as a dotted vertical line
OUT/robustness.md         per effect and metric: the means and where the curve leaves its promise
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display here or in CI
import matplotlib.pyplot as plt
import polars as pl

from simlan_data.evaluation.robustness import Effect, Robustness, Verdict
from simlan_data.evaluation.suite_report import PLOTS_DIR, _num, _slug

CSV_NAME = "robustness.csv"
REPORT_NAME = "robustness.md"


def write_csv(out: Path, table: pl.DataFrame) -> Path:
    path = out / CSV_NAME
    table.write_csv(path, float_precision=9)
    return path


def _log_axis(values: tuple[float, ...]) -> bool:
    """Strengths spanning a decade or more, all positive: a log axis spaces them evenly."""
    return min(values) > 0 and max(values) / min(values) >= 10


def plot_effect(
    path: Path, sweep: Robustness, effect: Effect, table: pl.DataFrame, verdicts: list[Verdict]
) -> Path:
    """Small multiples: every promised metric against the effect's strength."""
    mine = [v for v in verdicts if v.effect == effect.name]
    cols = min(3, len(mine))
    nrows = math.ceil(len(mine) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(3.3 * cols, 2.6 * nrows), squeeze=False)
    for ax, v in zip(axes.flat, mine):
        check = next(c for c in sweep.checks if c.source == v.source and c.metric == v.metric)
        sel = table.filter(
            (pl.col("effect") == effect.name)
            & (pl.col("source") == v.source)
            & (pl.col("metric") == v.metric)
        ).drop_nulls("value")
        ax.scatter(
            sel["strength"].to_list(),
            sel["value"].to_list(),
            s=12,
            color="tab:blue",
            alpha=0.6,
            label="seeds",
        )
        xs = [s for s, _ in v.means]
        ax.plot(xs, [m for _, m in v.means], "o-", color="k", ms=4, lw=1.2, label="mean")
        for bound in (check.bound.max, check.bound.min):
            if bound is not None:
                ax.axhline(bound, color="tab:red", ls="--", lw=1, label="promise")
        if v.breaks_at is not None:
            ax.axvline(v.breaks_at, color="tab:red", ls=":", lw=1)
        if _log_axis(effect.values):
            ax.set_xscale("log")
        else:  # the swept strengths as ticks, written short (3e-05, not 0.000030)
            ax.set_xticks(list(effect.values), [f"{x:g}" for x in effect.values])
        ax.set_title(
            f"{v.metric}\n{v.text()}", fontsize=7, color="tab:red" if v.breaks_at is not None else "black"
        )
        ax.set_xlabel(effect.key, fontsize=7)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(mine) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6, loc="best")
    fig.suptitle(f"{sweep.name}: {effect.name} ({effect.key})", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def plot_all(out: Path, sweep: Robustness, table: pl.DataFrame, verdicts: list[Verdict]) -> list[Path]:
    plots = out / PLOTS_DIR
    plots.mkdir(parents=True, exist_ok=True)
    return [plot_effect(plots / f"{_slug(e.name)}.png", sweep, e, table, verdicts) for e in sweep.effects]


def summary_lines(verdicts: list[Verdict]) -> list[str]:
    """The markdown table: per effect and metric, the means at each strength and the verdict."""
    lines = [
        "| effect | swept key | metric | promise | mean at each strength | verdict |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for v in verdicts:
        means = ", ".join(f"{_num(s, 'g')}: {_num(m, '.3g')}" for s, m in v.means)
        verdict = f"**{v.text()}**" if v.breaks_at is not None else v.text()
        lines.append(f"| {v.effect} | `{v.key}` | {v.metric} | {v.promise} | {means} | {verdict} |")
    return lines


def print_summary(verdicts: list[Verdict]) -> None:
    width = max((len(f"{v.effect} {v.metric}") for v in verdicts), default=10)
    for v in verdicts:
        print(f"{v.effect + ' ' + v.metric:<{width}}  {v.promise:<10} {v.text()}")


def write_report(
    out: Path,
    sweep: Robustness,
    verdicts: list[Verdict],
    plots: list[Path],
    *,
    command: str,
    failures: list[str],
) -> Path:
    lines = [
        f"# Robustness sweep `{sweep.name}`",
        "",
        sweep.description,
        "",
        f"- command: `{command}`",
        f"- case: `{' '.join([*sweep.suite.overrides, *_scene(sweep)])}`",
        f"- seeds per strength: {len(sweep.suite.cases[0].seeds)}; a strength keeps a promise when the "
        "mean over seeds does (no value: it does not)",
        f"- every value: `{CSV_NAME}`; every metric of every run: `metrics.csv`",
        "",
        *summary_lines(verdicts),
        "",
    ]
    if failures:
        lines += ["## Failed runs and replays", "", *[f"- {f}" for f in failures], ""]
    for effect, plot in zip(sweep.effects, plots):
        lines += [f"## {effect.name}", "", f"![{effect.name}]({plot.relative_to(out).as_posix()})", ""]
    path = out / REPORT_NAME
    path.write_text("\n".join(lines))
    return path


def _scene(sweep: Robustness) -> list[str]:
    """The case's own overrides (those of the first cell, less its effect's)."""
    case = sweep.suite.cases[0]
    effect, value = sweep.cells[case.name]
    extra = set(effect.overrides(value))
    return [o for o in case.overrides if o not in extra]
