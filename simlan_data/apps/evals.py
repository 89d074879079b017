"""``python -m simlan_data.evals SUITE``: run a V&V suite of ``evals/base.yaml`` and judge it.

    python -m simlan_data.evals base [--seeds N] [--reuse DIR] [--inject FAULT ...] [--accept] [--out DIR]
    python -m simlan_data.evals base --candidate algorithms/localizer=NAME [--candidate KEY=VALUE ...]
    python -m simlan_data.evals golden [--inject FAULT ...] [--accept] [--regenerate]
    python -m simlan_data.evals robustness [--seeds N] [--only EFFECT ...] [--set KEY=VALUE ...]
    python -m simlan_data.evals --list

Simulates every case and seed through Hydra's launcher (or reuses the runs of an earlier output),
replays every recording through the case's algorithms, compares each metric's 95 % interval over
seeds with its bound and with the accepted baseline, prints a pass/fail table and writes
``OUT/report.md`` with plots, ``OUT/metrics.parquet|csv`` (every metric) and
``OUT/summary.parquet|csv`` (verdicts). Exit code 0: every check holds; 1: a check failed or
regressed; 2: bad arguments. Pending checks (waiting for a capability) never count as passed.

With ``--candidate`` (Hydra overrides of the candidate's runs, repeatable) it runs the suite's jobs
twice with the same seeds, the baseline (the suite as it is) into ``OUT/baseline/`` and the
candidate into ``OUT/candidate/``, and writes ``OUT/compare.md|parquet|csv``: per case and checked
metric both sides' intervals, the paired difference and a verdict (better, worse, no difference;
:mod:`simlan_data.evaluation.compare`). Exit code 0: the comparison ran (whatever its verdict);
1: a run or replay failed; 2: bad arguments.

A robustness sweep (``robustness:`` in the suite file, :mod:`simlan_data.evaluation.robustness`)
runs its scene under each effect at each strength over the seeds, through the same jobs, launcher
and replays, and writes ``OUT/robustness.csv``, one plot per effect (``OUT/plots/``) and
``OUT/robustness.md`` (where each metric's curve leaves its promise). Exit code 0: the sweep ran
(whatever broke); 1: a run or replay failed; 2: bad arguments or a bad sweep (nothing written).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import polars as pl

from simlan_data.apps.cli import run_cli
from simlan_data.constants import CONF_DIR, EVALS_DIR, EVALS_OUTPUT_ROOT, METRICS_FILENAME, RECORDING_DIRNAME
from simlan_data.errors import EXIT_FAILED_RUN, ConfigError, SimlanError
from simlan_data.evaluation import (
    replay_algorithms,  # noqa: F401 - registers the algorithms
    robustness_report,
)
from simlan_data.evaluation.compare import compare_tables, print_comparison, suite_checks, write_comparison
from simlan_data.evaluation.robustness import (
    Robustness,
    breaking_points,
    load_robustness,
    robustness_table,
    sweep_names,
)
from simlan_data.evaluation.suite import (
    FAILING,
    JOBS_FILE,
    Job,
    accepted,
    check_jobs,
    collect_run_metrics,
    judge,
    metrics_table,
    plan_jobs,
    read_baseline,
    replay_all,
    reusable,
    reuse,
    simulate,
    write_baseline,
    write_job_configs,
    write_jobs_file,
)
from simlan_data.evaluation.suite_report import print_table, write_report, write_tables
from simlan_data.evaluation.suite_spec import Case, Suite, load_suite, select_faults

DEFAULT_FILE = EVALS_DIR / "base.yaml"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m simlan_data.evals",
        description="Run a V&V suite: simulate or reuse, replay, compare with bounds and baselines.",
    )
    p.add_argument(
        "suite", nargs="?", help="suite or robustness sweep in the suite file (base, golden, robustness, ...)"
    )
    p.add_argument("--file", type=Path, default=DEFAULT_FILE, help=f"suite file (default {DEFAULT_FILE})")
    p.add_argument("--list", action="store_true", help="list suites, cases and faults, and exit")
    p.add_argument("--seeds", type=int, help="seeds per case (0..N-1; default: the suite's)")
    p.add_argument(
        "--only",
        nargs="+",
        default=[],
        metavar="CASE",
        help="run only these cases (or case families; of a robustness sweep: effects)",
    )
    p.add_argument(
        "--reuse", type=Path, metavar="DIR", help="reuse the runs of an earlier suite output (no simulation)"
    )
    p.add_argument("--inject", nargs="+", default=[], metavar="FAULT", help="inject faults (see --list)")
    p.add_argument("--accept", action="store_true", help="make the results the new baseline (on purpose)")
    p.add_argument(
        "--regenerate",
        action="store_true",
        help="re-simulate the suite's fixed recordings (golden), then accept",
    )
    p.add_argument("--out", type=Path, help=f"output directory (default {EVALS_OUTPUT_ROOT}/SUITE_DATE_TIME)")
    p.add_argument(
        "--launcher", default="joblib", help="Hydra launcher for the runs: joblib (default), basic, ray"
    )
    p.add_argument(
        "--jobs", type=int, default=os.cpu_count() or 1, help="parallel runs and replays (default: cores)"
    )
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override of every run (repeatable)"
    )
    p.add_argument(
        "--candidate",
        action="append",
        default=[],
        metavar="OVERRIDE",
        help="compare: run the suite as it is (baseline) and with this Hydra override (candidate; "
        "repeatable, e.g. algorithms/localizer=centroid), write OUT/compare.md|parquet|csv",
    )
    p.add_argument("--no-report", action="store_true", help="skip report.md and its plots")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    return p


def list_suite_file(path: Path) -> str:
    from simlan_data.config.safe_yaml import load_yaml

    doc = load_yaml(path, what="suite file") or {}
    lines = [f"suite file {path}"]
    for name in doc.get("suites") or {}:
        suite = load_suite(path, name)
        lines.append(f"suite {name}: {len(suite.cases)} cases, baseline {suite.baseline}")
        listed: set[str] = set()
        for c in suite.cases:
            cells = [x for x in suite.cases if x.family == c.family]
            if c.family in listed:
                continue
            listed.add(c.family)
            name = f"{c.family} (grid of {len(cells)})" if c.grid else c.name
            status = f"pending: {c.pending}" if c.pending else f"{len(c.seeds)} seeds, {len(c.checks)} checks"
            if c.faults is not None:
                status += f"; faults acting: {', '.join(c.faults) or 'none'}"
            lines.append(f"  {name:<28} {status}")
    for name in sweep_names(path):
        sweep = load_robustness(path, name)
        lines.append(
            f"robustness sweep {name}: {len(sweep.suite.cases)} strengths x {len(sweep.suite.cases[0].seeds)} seeds"
        )
        for e in sweep.effects:
            lines.append(f"  {e.name:<28} {e.key} = {', '.join(map(str, e.values))}")
    suite = load_suite(path, next(iter(doc.get("suites") or {})))
    lines.append("faults (--inject):")
    for f in suite.faults.values():
        status = f"pending: {f.pending}" if f.pending else "available"
        lines.append(f"  {f.name:<20} {f.description} [{status}]")
    return "\n".join(lines)


def _select(suite: Suite, only: list[str]) -> list[Case]:
    if not only:
        return list(suite.cases)
    names = {c.name for c in suite.cases} | {c.family for c in suite.cases}
    unknown = [o for o in only if o not in names]
    if unknown:
        raise ConfigError(
            f"unknown case {unknown[0]!r}", "--only", f"cases: {', '.join(sorted(names))}", "pick from --list"
        )
    return [c for c in suite.cases if c.name in only or c.family in only]


def check_launcher(name: str) -> None:
    """Refuse a Hydra launcher that is neither built in, installed as a plugin, nor configured."""
    if name == "basic" or (CONF_DIR / "hydra" / "launcher" / f"{name}.yaml").is_file():
        return
    try:
        found = importlib.util.find_spec(f"hydra_plugins.hydra_{name}_launcher") is not None
    except ModuleNotFoundError:
        found = False
    if not found:
        raise ConfigError(
            f"unknown launcher {name!r}",
            "--launcher",
            f"no Hydra plugin hydra_plugins.hydra_{name}_launcher and no conf/hydra/launcher/{name}.yaml",
            "use joblib or basic, or install the plugin (Ray: pip install -e '.[ray]')",
        )


def _check_run_args(args: argparse.Namespace) -> None:
    """The launcher exists and --jobs is positive (a suite and a comparison run alike)."""
    check_launcher(args.launcher)
    if args.jobs < 1:
        raise ConfigError(f"invalid --jobs {args.jobs}", "arguments", "must be >= 1", "e.g. --jobs 2")


def _out_dir(args: argparse.Namespace) -> Path:
    stamp = f"{datetime.now():%Y%m%d_%H%M%S}"  # audit-ok: names the output directory, as Hydra's ${now}
    out: Path = args.out or Path(EVALS_OUTPUT_ROOT) / f"{args.suite}_{stamp}"
    if out.exists() and any(out.iterdir()):
        raise ConfigError(
            "output exists", str(out), "the suite never overwrites results", "choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    return out


def _regenerate(suite: Suite, jobs: list[Job], out: Path, args: argparse.Namespace) -> None:
    """Re-simulate the fixed recordings in a scratch directory, then replace them."""
    fixed = [j for j in jobs if j.case.recording is not None and not j.case.pending]
    if not fixed:
        raise ConfigError(
            "nothing to regenerate", f"suite {suite.name}", "no case has a recording:", "drop --regenerate"
        )
    targets = {j.name: j.run_dir for j in fixed}
    for j in fixed:
        j.run_dir = out / "runs" / j.name
    simulate(suite, fixed, [], out, launcher=args.launcher, n_jobs=args.jobs, extra=list(args.set))
    for j in fixed:
        if j.error:
            raise ConfigError("regeneration failed", str(j.run_dir), j.error, f"see {out / 'simulate.log'}")
        target = targets[j.name]
        target.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
            staged = Path(tmp) / "new"
            staged.mkdir()
            shutil.copytree(j.run_dir / RECORDING_DIRNAME, staged / RECORDING_DIRNAME)
            shutil.copy2(j.run_dir / METRICS_FILENAME, staged / METRICS_FILENAME)
            shutil.rmtree(target)
            staged.rename(target)
        j.run_dir = target
        print(f"regenerated {target}")


def run_suite(args: argparse.Namespace) -> int:
    suite = load_suite(args.file, args.suite, seeds=args.seeds)
    faults = select_faults(suite, args.inject)
    if args.accept and faults:
        raise ConfigError(
            "--accept with --inject", "arguments", "a faulty run is no baseline", "drop one of them"
        )
    if args.reuse and args.regenerate:
        raise ConfigError(
            "--reuse with --regenerate", "arguments", "regenerating simulates", "drop one of them"
        )
    _check_run_args(args)
    cases = _select(suite, args.only)
    if args.reuse is not None:
        reusable(args.reuse)
    out = _out_dir(args)
    jobs = plan_jobs([c for c in cases if not c.pending], out / "runs")
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    if args.regenerate:
        _regenerate(suite, jobs, out, args)
    if args.reuse:
        reuse(jobs, suite, args.reuse)
        if faults and any(f.run for f in faults):
            print("note: reused recordings: the faults act through the replays only (not in closed loop)")
    else:
        to_run = [j for j in jobs if j.case.recording is None]
        try:
            timings["simulate_s"] = simulate(
                suite, to_run, faults, out, launcher=args.launcher, n_jobs=args.jobs, extra=list(args.set)
            )
        except ConfigError:
            shutil.rmtree(out, ignore_errors=True)  # refused before any run: leave nothing behind
            raise
    write_jobs_file(jobs, suite, faults if not args.reuse else [], out)
    collect_run_metrics(jobs)
    timings["replay_s"] = replay_all(jobs, faults, out, n_jobs=args.jobs)
    table = metrics_table(jobs)
    baseline = read_baseline(suite.baseline)
    if args.accept or args.regenerate:
        baseline = accepted(table, cases, baseline)
        write_baseline(baseline, suite.baseline)
        print(f"accepted as the new baseline: {suite.baseline}")
    summary = judge(suite, cases, jobs, table, baseline)
    timings["total_s"] = time.perf_counter() - t0
    write_tables(out, table, summary)
    (out / "timings.json").write_text(json.dumps(timings, indent=2) + "\n")
    print_table(summary)
    if not args.no_report:
        report = write_report(
            out, suite, cases, jobs, table, summary, faults=faults, timings=timings, reused=args.reuse
        )
        print(f"report: {report}")
    failing = summary.filter(pl.col("verdict").is_in(FAILING)).height
    return EXIT_FAILED_RUN if failing else 0


# ------------------------------------------------------------------ candidate vs baseline
SIDES = ("baseline", "candidate")


def _check_candidate(suite: Suite, cases: list[Case], extra: list[str], candidate: list[str]) -> None:
    """Compose every job's config on both sides before anything is written.

    Raises:
        ConfigError: the suite's own cases do not compose (as for a plain suite run), or a
            candidate override does not (named: the first one that breaks the composition).
    """
    with tempfile.TemporaryDirectory() as tmp:
        conf = Path(tmp) / "conf"
        jobs = plan_jobs(cases, Path(tmp) / "runs")
        write_job_configs(suite, jobs, conf)
        check_jobs(jobs, conf, extra)
        try:
            check_jobs(jobs, conf, [*extra, *candidate])
        except ConfigError as err:
            culprit = candidate[-1]
            for i in range(1, len(candidate)):  # the first prefix that does not compose names it
                try:
                    check_jobs(jobs[:1], conf, [*extra, *candidate[:i]])
                except ConfigError:
                    culprit = candidate[i - 1]
                    break
            raise ConfigError(
                f"invalid --candidate {culprit}",
                err.where,
                f"{err.what}: {err.why}" if err.what != "invalid overrides" else err.why,
                "fix the override (python -m simlan_data.run --help lists the groups and keys)",
            ) from None


def _mark_candidate(side_out: Path, candidate: list[str]) -> None:
    """Record the candidate's overrides in its jobs.json (so --reuse never takes it for a baseline)."""
    path = side_out / JOBS_FILE
    doc = json.loads(path.read_text())
    for entry in doc.values():
        entry["overrides"] = [*entry["overrides"], *candidate]
        entry["candidate"] = list(candidate)
    path.write_text(json.dumps(doc, indent=2) + "\n")


def run_compare(args: argparse.Namespace) -> int:
    """Baseline and candidate over the same seeds, then OUT/compare.md|parquet|csv."""
    suite = load_suite(args.file, args.suite, seeds=args.seeds)
    selected, cases = _compared_cases(args, suite)
    reuse_dir = None
    if args.reuse is not None:
        nested = args.reuse / SIDES[0]
        reuse_dir = nested if (nested / JOBS_FILE).is_file() else args.reuse
        reusable(reuse_dir)
    _check_candidate(suite, cases, list(args.set), list(args.candidate))
    out = _out_dir(args)
    for c in selected:
        if c.recording is not None:
            print(f"note: case {c.name} replays a fixed recording: not compared")
    tables: dict[str, pl.DataFrame] = {}
    failures: list[str] = []
    for side in SIDES:
        tables[side], side_failures = _run_side(args, suite, cases, side, out / side, reuse_dir)
        failures += side_failures
    comparison = compare_tables(
        tables["baseline"], tables["candidate"], suite_checks(cases), suite.confidence
    )
    path = write_comparison(
        out,
        comparison,
        suite=suite.name,
        candidate=list(args.candidate),
        seeds={c.name: list(c.seeds) for c in cases},
        baseline_dir=reuse_dir or out / "baseline",
        candidate_dir=out / "candidate",
        failures=failures,
    )
    print()
    print_comparison(comparison)
    for f in failures:
        print(f"FAILED {f}")
    print(f"comparison: {path} (+ {path.with_suffix('.parquet').name}, {path.with_suffix('.csv').name})")
    return EXIT_FAILED_RUN if failures else 0


def _compared_cases(args: argparse.Namespace, suite: Suite) -> tuple[list[Case], list[Case]]:
    """Check the comparison's arguments; select the cases (all, and the simulated ones compared)."""
    for flag, on, why in (
        ("--accept", args.accept, "a comparison accepts no baseline"),
        ("--regenerate", args.regenerate, "a comparison regenerates no recordings"),
        ("--inject", args.inject, "a comparison compares algorithms, not faults"),
    ):
        if on:
            raise ConfigError(f"--candidate with {flag}", "arguments", why, "drop one of them")
    _check_run_args(args)
    selected = [c for c in _select(suite, args.only) if not c.pending]
    pinned = {c.name: g for c in selected if (g := _pinned_group(c, list(args.candidate)))}
    for name, group in pinned.items():
        print(f"note: case {name} pins its own {group} (it tests that one): not compared")
    cases = [c for c in selected if c.recording is None and c.name not in pinned]
    if not cases:
        raise ConfigError(
            "nothing to compare",
            f"suite {suite.name}",
            "no simulated case (a fixed recording replays the algorithms it was recorded with)",
            "pick simulated cases (e.g. suite base)",
        )
    return selected, cases


def _candidate_group(override: str) -> str:
    """The config group an override selects or sets a key of (``algorithms/localizer=x`` and
    ``algorithms.localizer.alpha=1``: ``algorithms/localizer``); "" for other keys."""
    key = override.partition("=")[0].lstrip("+~")
    if "/" in key:
        return key
    parts = key.split(".")
    return f"{parts[0]}/{parts[1]}" if parts[0] == "algorithms" and len(parts) > 2 else ""


def _pinned_group(case: Case, candidate: list[str]) -> str:
    """The group of the candidate's that ``case`` selects itself (the marker-free case picks
    ``algorithms/localizer=foreground``: a test of that localizer, no place for another), else ""."""
    groups = {g for o in candidate if (g := _candidate_group(o))}
    for override in case.overrides:
        key = override.partition("=")[0].lstrip("+~")
        if key in groups:
            return override.lstrip("+~")
    return ""


def _run_side(
    args: argparse.Namespace,
    suite: Suite,
    cases: list[Case],
    side: str,
    side_out: Path,
    reuse_dir: Path | None,
) -> tuple[pl.DataFrame, list[str]]:
    """Run (or reuse), replay and judge one side of the comparison; return its metrics and failures."""
    side_out.mkdir()
    jobs = plan_jobs(cases, side_out / "runs")
    extra = [*args.set, *(args.candidate if side == "candidate" else [])]
    print(f"== {side}" + (f": {' '.join(args.candidate)}" if side == "candidate" else ": the suite as it is"))
    if side == "baseline" and reuse_dir is not None:
        reuse(jobs, suite, reuse_dir)
        print(f"reusing the baseline runs of {reuse_dir}")
    else:
        try:
            simulate(suite, jobs, [], side_out, launcher=args.launcher, n_jobs=args.jobs, extra=extra)
        except SimlanError as err:  # every run failed: a result to report, not a crash
            print(f"{side}: {err.line()}")
            for j in jobs:
                j.error = j.error or err.line()
    write_jobs_file(jobs, suite, [], side_out)
    if side == "candidate":
        _mark_candidate(side_out, list(args.candidate))
    collect_run_metrics(jobs)
    replay_all(jobs, [], side_out, n_jobs=args.jobs)
    table = metrics_table(jobs)
    write_tables(side_out, table, judge(suite, cases, jobs, table, read_baseline(suite.baseline)))
    failures = [
        f"{side}: {j.case.name} seed {j.seed}: {source}: {error}"
        for j in jobs
        for source, error in sorted({**({"run": j.error} if j.error else {}), **j.errors}.items())
    ]
    return table, failures


# ------------------------------------------------------------------------- robustness sweep
def run_robustness(args: argparse.Namespace) -> int:
    """Every effect at every strength over the seeds, then the curves and where they break."""
    _refuse_with_sweep(args)
    sweep = load_robustness(args.file, args.suite, seeds=args.seeds, only=args.only)
    _check_run_args(args)
    out, jobs = _simulate_sweep(args, sweep)
    write_jobs_file(jobs, sweep.suite, [], out)
    collect_run_metrics(jobs)
    replay_all(jobs, [], out, n_jobs=args.jobs)
    metrics = metrics_table(jobs)
    metrics.write_csv(out / "metrics.csv", float_precision=9)
    table = robustness_table(sweep, metrics)
    verdicts = breaking_points(sweep, table)
    failures = [
        f"{j.case.name} seed {j.seed}: {source}: {error}"
        for j in jobs
        for source, error in sorted({**({"run": j.error} if j.error else {}), **j.errors}.items())
    ]
    csv = robustness_report.write_csv(out, table)
    plots = robustness_report.plot_all(out, sweep, table, verdicts)
    command = " ".join(["python -m simlan_data.evals", *args.argv])
    report = robustness_report.write_report(out, sweep, verdicts, plots, command=command, failures=failures)
    print()
    robustness_report.print_summary(verdicts)
    for f in failures:
        print(f"FAILED {f}")
    print(f"robustness: {report} (+ {csv.name}, {len(plots)} plots in {out / 'plots'})")
    return EXIT_FAILED_RUN if failures else 0


def _refuse_with_sweep(args: argparse.Namespace) -> None:
    """The suite-only flags mean nothing to a robustness sweep."""
    for flag, on in (
        ("--candidate", args.candidate),
        ("--inject", args.inject),
        ("--accept", args.accept),
        ("--regenerate", args.regenerate),
        ("--reuse", args.reuse),
    ):
        if on:
            raise ConfigError(
                f"{flag} with a robustness sweep",
                "arguments",
                "a sweep runs its effects; a plug-in's curves come from --set on the same sweep",
                f"drop {flag}",
            )


def _simulate_sweep(args: argparse.Namespace, sweep: Robustness) -> tuple[Path, list[Job]]:
    """Compose every run before anything is written, then simulate them all (one multirun)."""
    cases = list(sweep.suite.cases)
    with tempfile.TemporaryDirectory() as tmp:
        conf = Path(tmp) / "conf"
        planned = plan_jobs(cases, Path(tmp) / "runs")
        write_job_configs(sweep.suite, planned, conf)
        check_jobs(planned, conf, list(args.set))
    out = _out_dir(args)
    jobs = plan_jobs(cases, out / "runs")
    try:
        simulate(sweep.suite, jobs, [], out, launcher=args.launcher, n_jobs=args.jobs, extra=list(args.set))
    except ConfigError:
        shutil.rmtree(out, ignore_errors=True)  # refused before any run: leave nothing behind
        raise
    except SimlanError as err:  # every run failed: a result to report
        print(err.line())
        for j in jobs:
            j.error = j.error or err.line()
    return out, jobs


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    if args.list:
        print(list_suite_file(args.file))
        return 0
    if not args.suite:
        parser.error("give a suite (e.g. base or golden) or --list")
    if args.suite in sweep_names(args.file):
        return run_robustness(args)
    if args.candidate:
        return run_compare(args)
    return run_suite(args)


def cli() -> None:
    """The command line: run :func:`main`, turning errors into one line and an exit code."""
    run_cli(lambda: sys.exit(main()))


if __name__ == "__main__":
    cli()
