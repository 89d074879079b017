"""Run a V&V suite: simulate (or reuse) every case and seed, replay, measure, judge.

Data flow::

    evals/base.yaml --load_suite--> cases x seeds (+ injected faults)
        --simulate: ONE Hydra multirun of `python -m simlan_data.run -m +vv_job=...`
          (a generated config group, one option per case and seed; the launcher spreads the
          jobs: joblib over local cores, Ray over a cluster)          --> OUT/runs/<job>/
        --or reuse: the runs of an earlier suite output (same overrides, checked)
        --replay every recording through the case's algorithms (joblib, in parallel)
                                                                        --> OUT/replays/<job>/<algorithm>/
        --> one long polars table: case, seed, source, metric, value   --> OUT/metrics.parquet + .csv
        --> verdicts on intervals over seeds against bounds and the baseline (stats.py)
                                                                        --> OUT/summary.parquet + .csv
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import polars as pl
import yaml
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from simlan_data.constants import CONF_DIR, METRICS_FILENAME, RECORDING_DIRNAME, RUNNING_MARKER
from simlan_data.errors import ConfigError, SimlanError
from simlan_data.evaluation.stats import Interval, baseline_change, bound_ok, difference_interval, interval
from simlan_data.evaluation.suite_spec import RUN_SOURCE, Case, Check, Fault, Suite
from simlan_data.metrics_io import load_metrics, write_metrics

JOB_GROUP = "vv_job"
JOBS_FILE = "jobs.json"
METRICS_SCHEMA = {
    "case": pl.String,
    "seed": pl.Int64,
    "source": pl.String,
    "metric": pl.String,
    "value": pl.Float64,
}
BASELINE_SCHEMA = METRICS_SCHEMA

# Metrics computed from others, for every source that has the inputs (one small function each).
DERIVED = {
    "navigation.goals_missed": lambda m: m["navigation.goals_total"] - m["navigation.goals_reached"],
}
DERIVED_INPUTS = {"navigation.goals_missed": ("navigation.goals_total", "navigation.goals_reached")}

FAILING = ("fail", "regression", "missing", "error")


@dataclass
class Job:
    """One recording of one case and seed."""

    case: Case
    seed: int
    name: str
    run_dir: Path
    error: str = ""
    sources: dict[str, dict[str, float]] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)  # source -> why it has no metrics


def job_name(case: str, seed: int) -> str:
    return f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', case).strip('_')}__s{seed}"


def plan_jobs(cases: list[Case], runs_dir: Path) -> list[Job]:
    jobs = []
    for case in cases:
        for seed in case.seeds:
            if case.recording is not None:
                jobs.append(Job(case, seed, job_name(case.name, seed), case.recording))
            else:
                name = job_name(case.name, seed)
                jobs.append(Job(case, seed, name, runs_dir / name))
    names = [j.name for j in jobs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(
            f"two cases map to the run directory {dup[0]!r}",
            "the suite",
            "names differ only in symbols",
            "rename one",
        )
    return jobs


# ------------------------------------------------------------------------------- simulating
def _job_config(overrides: list[str], seed: int) -> dict[str, Any]:
    """A config-group file (package _global_) equivalent to ``overrides`` plus ``seed``."""
    defaults: list[Any] = []
    body = OmegaConf.create({})
    for ov in OverridesParser.create().parse_overrides(overrides):
        key = ov.key_or_group
        if ov.is_delete() or ov.is_sweep_override():
            raise ConfigError(
                f"invalid override {ov.input_line!r}",
                "the suite",
                "deletions and sweeps are not case overrides",
                "use grid: for sweeps",
            )
        # (a config group: a folder of conf/, hydra's, or a role's algorithms, registered in code)
        if (CONF_DIR / key).is_dir() or key.startswith(("hydra/", "algorithms/")):
            defaults.append({f"override /{key}": ov.value()})
        else:
            OmegaConf.update(body, key, ov.value(), force_add=True)
    body.seed = seed
    doc = OmegaConf.to_container(body)
    assert isinstance(doc, dict)
    return {"defaults": [*defaults, "_self_"], **doc}


def write_job_configs(
    suite: Suite, jobs: list[Job], conf_dir: Path, faults: list[Fault] | None = None
) -> None:
    """One config per job: the suite's and the case's overrides, then those of the injected
    faults that act on the case."""
    group = conf_dir / JOB_GROUP
    group.mkdir(parents=True, exist_ok=True)
    for job in jobs:
        injected = [o for f in job.case.subject_to(faults or []) for o in f.run]
        doc = _job_config([*suite.overrides, *job.case.overrides, *injected], job.seed)
        text = "# @package _global_\n# generated by simlan_data.apps.evals for case " + job.case.name + "\n"
        (group / f"{job.name}.yaml").write_text(text + yaml.safe_dump(doc, sort_keys=False))


def check_jobs(jobs: list[Job], conf_dir: Path, overrides: list[str]) -> None:
    """Compose and type-check every job's config as the run will (no process, no simulation).

    Raises:
        ConfigError: a case's overrides (or a fault's, or --set) do not make a valid run.
    """
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from simlan_data.config.schema import register_configs
    from simlan_data.config.validation import to_config

    register_configs([*overrides, *(o for job in jobs for o in job.case.overrides)])
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        for job in jobs:
            where = f"case {job.case.name} (seed {job.seed})"
            try:
                cfg = compose(
                    "config",
                    overrides=[
                        f"hydra.searchpath=[file://{conf_dir.resolve()}]",
                        f"+{JOB_GROUP}={job.name}",
                        *overrides,
                    ],
                )
                to_config(cfg)
            except ConfigError as err:
                raise ConfigError(err.what, f"{where}: {err.where}", err.why, err.fix) from None
            except (HydraException, OmegaConfBaseException) as err:
                lines = [ln.strip() for ln in str(err.__cause__ or err).splitlines() if ln.strip()]
                first = (
                    " ".join(lines[:2])
                    if lines and lines[0].endswith(":")
                    else (lines or [type(err).__name__])[0]
                )
                raise ConfigError(
                    "invalid overrides", where, first, "fix the case in the suite file"
                ) from None


def simulate(
    suite: Suite,
    jobs: list[Job],
    faults: list[Fault],
    out_dir: Path,
    *,
    launcher: str,
    n_jobs: int,
    extra: list[str],
    log: Any = print,
) -> float:
    """Run every job as one Hydra multirun; returns the wall time (s). Failed jobs get ``error``."""
    if not jobs:
        return 0.0
    conf_dir = out_dir / "conf"
    write_job_configs(suite, jobs, conf_dir, faults)
    check_jobs(jobs, conf_dir, list(extra))
    runs_dir = jobs[0].run_dir.parent
    cmd = [
        sys.executable,
        "-m",
        "simlan_data.run",
        "-m",
        f"hydra/launcher={launcher}",
        f"hydra.searchpath=[file://{conf_dir.resolve()}]",
        f"+{JOB_GROUP}={','.join(j.name for j in jobs)}",
        f"hydra.sweep.dir={runs_dir.resolve()}",
        f"hydra.sweep.subdir=${{hydra:runtime.choices.{JOB_GROUP}}}",
        "hydra.callbacks.aggregate_sweep.report=",
        "progress=false",
    ]
    if launcher == "joblib":
        cmd.append(f"hydra.launcher.n_jobs={n_jobs}")
    cmd += extra  # (the faults' overrides are in the job configs: only where they act)
    (out_dir / "simulate_command.txt").write_text(" ".join(cmd) + "\n")
    log_path = out_dir / "simulate.log"
    log(
        f"simulating {len(jobs)} runs through Hydra's {launcher} launcher ({n_jobs} workers); log: {log_path}"
    )
    t0 = time.perf_counter()
    done: set[str] = set()
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    with log_path.open("w") as fh:
        proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env)
        while proc.poll() is None:
            time.sleep(1.0)
            for job in jobs:
                if job.name not in done and (job.run_dir / METRICS_FILENAME).is_file():
                    done.add(job.name)
                    log(f"  done  {job.case.name} seed {job.seed}  ({time.perf_counter() - t0:.0f} s)")
    wall = time.perf_counter() - t0
    tail = log_path.read_text().strip().splitlines()[-1:] if log_path.stat().st_size else []
    for job in jobs:
        if not (job.run_dir / METRICS_FILENAME).is_file() or (job.run_dir / RUNNING_MARKER).exists():
            job.error = f"run failed (see {log_path})"
            log(f"  FAILED {job.case.name} seed {job.seed}")
    if proc.returncode != 0 and all(j.error for j in jobs):
        cls = ConfigError if proc.returncode == 2 else SimlanError  # Hydra refused the overrides
        raise cls(
            "simulation failed",
            "the suite's Hydra multirun",
            tail[0] if tail else f"exit code {proc.returncode}",
            f"see {log_path}",
        )
    return wall


def reusable(reuse_dir: Path) -> tuple[Path, dict[str, Any]]:
    """The runs directory and the job table of an earlier suite output.

    Raises:
        ConfigError: ``reuse_dir`` is not the output of a suite.
    """
    out = reuse_dir.parent if reuse_dir.name == "runs" else reuse_dir
    path = out / JOBS_FILE
    if not path.is_file():
        raise ConfigError(
            "nothing to reuse",
            str(reuse_dir),
            f"no {JOBS_FILE} (not a suite output)",
            "give the --out of an earlier run",
        )
    try:
        return out / "runs", dict(json.loads(path.read_text()))
    except (ValueError, TypeError) as err:
        raise ConfigError(
            "nothing to reuse", str(path), f"unreadable: {err}", "give the --out of an earlier run"
        ) from err


def reuse(jobs: list[Job], suite: Suite, reuse_dir: Path) -> None:
    """Point the jobs at the runs of an earlier suite output; refuse if the overrides changed."""
    root, recorded = reusable(reuse_dir)
    for job in jobs:
        if job.case.recording is not None:
            continue
        entry = recorded.get(job.name)
        # where that output found the run (itself a reuse of an earlier one), else its own runs/
        run_dir = root / job.name
        if not run_dir.is_dir() and entry and entry.get("run_dir"):
            run_dir = Path(entry["run_dir"])
        if entry is None or not (run_dir / RECORDING_DIRNAME).is_dir():
            job.error = f"no recording of this case and seed in {reuse_dir}"
            continue
        want = [*suite.overrides, *job.case.overrides]
        if entry.get("overrides") != want or entry.get("faults"):
            raise ConfigError(
                "recordings made differently",
                f"{run_dir}",
                f"case {job.case.name} was recorded with overrides {entry.get('overrides')} and faults {entry.get('faults') or 'none'}",
                "simulate again (drop --reuse)",
            )
        job.run_dir = run_dir


def write_jobs_file(jobs: list[Job], suite: Suite, faults: list[Fault], out_dir: Path) -> None:
    doc = {
        j.name: {
            "case": j.case.name,
            "seed": j.seed,
            "overrides": [*suite.overrides, *j.case.overrides],
            "faults": [f.name for f in j.case.subject_to(faults)],
            "run_dir": str(j.run_dir.resolve()),
        }
        for j in jobs
    }
    (out_dir / JOBS_FILE).write_text(json.dumps(doc, indent=2) + "\n")


# ---------------------------------------------------------------------------------- replaying
def replay_one(
    recording: str, out_dir: str, algorithm: str, options: dict[str, Any], *, one_thread: bool = False
) -> tuple[dict[str, float], str]:
    """Replay one recording through one algorithm (in a worker); returns (metrics, error).

    ``one_thread``: OpenCV on one thread, for workers that run side by side (no oversubscription).
    """
    if one_thread:
        import cv2

        cv2.setNumThreads(1)
    from simlan_data.evaluation import replay_algorithms  # noqa: F401 - registers the algorithms
    from simlan_data.evaluation.replay import REPLAY_ALGORITHMS, ReplayContext
    from simlan_data.recording.reader import RecordingReader

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    try:
        with RecordingReader(recording) as reader:
            metrics = REPLAY_ALGORITHMS[algorithm](ReplayContext(reader, out, dict(options)))
    except SimlanError as err:
        return {}, err.line()
    except Exception as err:  # an algorithm that crashes is a failed check, not a crashed suite
        return {}, f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
    write_metrics(out / METRICS_FILENAME, metrics)  # strict JSON: null for NaN and inf
    return metrics, ""


def replay_all(
    jobs: list[Job], faults: list[Fault], out_dir: Path, *, n_jobs: int, log: Any = print
) -> float:
    """Run every case's replays on its recordings, in parallel; returns the wall time (s)."""
    from joblib import Parallel, delayed

    tasks = []
    for job in jobs:
        if job.error:
            continue
        for algorithm, options in job.case.replay.items():
            merged = dict(options)
            for fault in job.case.subject_to(faults):
                merged.update(fault.replay_options(algorithm))
            tasks.append((job, algorithm, merged))
    if not tasks:
        return 0.0
    # longest first (the bag's size stands for its length and agents): better balance over workers
    tasks.sort(
        key=lambda t: -sum(f.stat().st_size for f in (t[0].run_dir / RECORDING_DIRNAME).glob("*.mcap"))
    )
    log(f"replaying {len(tasks)} recording x algorithm pairs ({n_jobs} workers)")
    t0 = time.perf_counter()
    results = Parallel(n_jobs=n_jobs, backend="loky")(
        delayed(replay_one)(
            str(job.run_dir / RECORDING_DIRNAME),
            str(out_dir / "replays" / job.name / algorithm),
            algorithm,
            options,
            one_thread=n_jobs > 1,
        )
        for job, algorithm, options in tasks
    )
    for (job, algorithm, _), (metrics, error) in zip(tasks, results):
        if error:
            job.errors[algorithm] = error
            log(f"  replay {algorithm} of {job.case.name} seed {job.seed} failed: {error}")
        else:
            job.sources[algorithm] = metrics
    return time.perf_counter() - t0


def collect_run_metrics(jobs: list[Job]) -> None:
    for job in jobs:
        path = job.run_dir / METRICS_FILENAME
        if job.error:
            job.errors[RUN_SOURCE] = job.error
        elif path.is_file():
            job.sources[RUN_SOURCE] = {k: float(v) for k, v in load_metrics(path).items()}
        else:
            job.errors[RUN_SOURCE] = f"no {METRICS_FILENAME} in {job.run_dir}"


def with_derived(metrics: dict[str, float]) -> dict[str, float]:
    out = dict(metrics)
    for name, fn in DERIVED.items():
        if name not in out and all(k in out for k in DERIVED_INPUTS[name]):
            out[name] = float(fn(out))
    return out


def metrics_table(jobs: list[Job]) -> pl.DataFrame:
    """Every metric of every source, case and seed: one long table."""
    rows = [
        (job.case.name, job.seed, source, metric, float(value))
        for job in jobs
        for source, metrics in sorted(job.sources.items())
        for metric, value in sorted(with_derived(metrics).items())
    ]
    return pl.DataFrame(rows, schema=METRICS_SCHEMA, orient="row")


# ----------------------------------------------------------------------------------- verdicts
def read_baseline(path: Path) -> pl.DataFrame:
    if not path.is_file():
        return pl.DataFrame(schema=BASELINE_SCHEMA)
    try:
        table = (
            pl.read_parquet(path) if path.suffix == ".parquet" else pl.read_csv(path, schema=BASELINE_SCHEMA)
        )
    except (pl.exceptions.PolarsError, OSError) as err:
        raise ConfigError(
            "baseline unreadable", str(path), str(err).splitlines()[0], "restore it from git or --accept"
        ) from err
    missing = [c for c in BASELINE_SCHEMA if c not in table.columns]
    if missing:
        raise ConfigError(
            "baseline lacks columns", str(path), ", ".join(missing), "restore it from git or --accept"
        )
    return table.select(list(BASELINE_SCHEMA)).cast(BASELINE_SCHEMA)  # type: ignore[arg-type]


def _values(table: pl.DataFrame, case: str, source: str, metric: str) -> dict[int, float]:
    sel = table.filter((pl.col("case") == case) & (pl.col("source") == source) & (pl.col("metric") == metric))
    return {int(s): float(v) for s, v in sel.select("seed", "value").iter_rows()}


def _fmt(v: float) -> float | None:
    return None if v is None or math.isnan(v) else v


JUDGE_SCHEMA = {
    "case": pl.String,
    "source": pl.String,
    "metric": pl.String,
    "n": pl.Int64,
    "mean": pl.Float64,
    "ci_low": pl.Float64,
    "ci_high": pl.Float64,
    "bound": pl.String,
    "baseline_mean": pl.Float64,
    "tolerance": pl.Float64,
    "diff_low": pl.Float64,
    "diff_high": pl.Float64,
    "comparison": pl.String,
    "verdict": pl.String,
    "note": pl.String,
}


def judge(
    suite: Suite, cases: list[Case], jobs: list[Job], table: pl.DataFrame, baseline: pl.DataFrame
) -> pl.DataFrame:
    """One row per (case, source, metric): interval, bound, baseline difference, verdict."""
    by_case: dict[str, list[Job]] = {}
    for job in jobs:
        by_case.setdefault(job.case.name, []).append(job)
    rows = [
        _judge_check(suite, case, check, by_case.get(case.name, []), table, baseline)
        for case in cases
        for check in case.checks
    ]
    return pl.DataFrame([{k: r.get(k) for k in JUDGE_SCHEMA} for r in rows], schema=JUDGE_SCHEMA)


def _judge_check(
    suite: Suite, case: Case, check: Check, jobs: list[Job], table: pl.DataFrame, baseline: pl.DataFrame
) -> dict[str, Any]:
    """Judge one check of a case: its interval, its baseline, then its verdict."""
    row: dict[str, Any] = {
        "case": case.name,
        "source": check.source,
        "metric": check.metric,
        "bound": check.bound.describe(),
        "tolerance": check.bound.allowed_change(float("nan")),
    }
    if case.pending:
        return {**row, "verdict": "pending", "note": f"pending: {case.pending}"}
    current = _values(table, case.name, check.source, check.metric)
    errors = sorted(
        {
            f"seed {j.seed}: {j.errors.get(check.source) or j.error}"
            for j in jobs
            if check.source in j.errors or j.error
        }
    )
    iv = interval(list(current.values()), suite.confidence)
    row.update(n=iv.n, mean=_fmt(iv.mean), ci_low=_fmt(iv.low), ci_high=_fmt(iv.high))
    base = _values(baseline, case.name, check.source, check.metric)
    base_iv = interval(list(base.values()), suite.confidence)
    row["baseline_mean"] = _fmt(base_iv.mean)
    tol = check.bound.allowed_change(base_iv.mean)
    row["tolerance"] = tol
    if errors:
        return {**row, "verdict": "error", "note": "; ".join(errors)[:500]}
    if len(current) < len(case.seeds):
        return {**row, "verdict": "missing", "note": f"{check.source} did not report {check.metric}"}
    verdict, notes = _verdict(suite, check, row, iv, current, base, base_iv, tol)
    return {**row, "verdict": verdict, "note": "; ".join(notes)}


def _verdict(
    suite: Suite,
    check: Check,
    row: dict[str, Any],
    iv: Interval,
    current: dict[int, float],
    base: dict[int, float],
    base_iv: Interval,
    tol: float | None,
) -> tuple[str, list[str]]:
    """Hold the interval to the bound and the values to the baseline (its difference goes into ``row``)."""
    notes = []
    verdict = "pass"
    if (check.bound.max is not None or check.bound.min is not None) and not bound_ok(check.bound, iv):
        verdict = "fail"
        notes.append(f"interval [{iv.low:.4g}, {iv.high:.4g}] not within {check.bound.describe()}")
    if base and tol is not None:
        diff, how = difference_interval(current, base, suite.confidence)
        row.update(diff_low=_fmt(diff.low), diff_high=_fmt(diff.high), comparison=how)
        change = baseline_change(check.bound, diff, base_iv.mean)
        if change == "regression":
            notes.append(f"worse than baseline by [{diff.low:+.4g}, {diff.high:+.4g}] ({how}) beyond {tol:g}")
            verdict = "regression" if verdict == "pass" else verdict
        elif change == "improved":
            notes.append(f"better than baseline by [{diff.low:+.4g}, {diff.high:+.4g}]: --accept to keep it")
    elif tol is not None:
        notes.append("no baseline yet (--accept)")
    return verdict, notes


def accepted(table: pl.DataFrame, cases: list[Case], baseline: pl.DataFrame) -> pl.DataFrame:
    """The new baseline: the checked metrics of the cases that ran, the old rows of the rest."""
    ran = [c for c in cases if not c.pending]
    keys = pl.DataFrame(
        [(c.name, ch.source, ch.metric) for c in ran for ch in c.checks],
        schema={"case": pl.String, "source": pl.String, "metric": pl.String},
        orient="row",
    )
    new = table.join(keys, on=["case", "source", "metric"], how="semi")
    old = baseline.filter(~pl.col("case").is_in([c.name for c in ran]))
    return pl.concat([old, new]).sort("case", "source", "metric", "seed")


def write_baseline(table: pl.DataFrame, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".parquet":
        table.write_parquet(path, statistics=False)
    else:
        table.write_csv(path)  # full precision: an unchanged result must equal its baseline exactly
