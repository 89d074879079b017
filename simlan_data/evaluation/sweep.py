"""Aggregate a Hydra sweep: every job's ``metrics.json`` into one polars table.

    python -m simlan_data.run -m KEY=A,B ...      # each job writes <sweep dir>/<n>/metrics.json
        -> on_multirun_end (any launcher: basic, joblib, ray; runs where the sweep was started)
        -> <sweep dir>/sweep_metrics.parquet + .csv   one row per job
        -> the experiment's report (``sweep_reports.SWEEP_REPORTS``), if ``report`` names one

Columns: ``job`` (the sweep subdirectory), ``override.<key>`` for every command-line or sweeper
override of the job (as Hydra recorded it in ``.hydra/overrides.yaml``), ``status`` (ok, or
failed when the job left no metrics.json), then every metric.

An experiment names its report in its config::

    hydra:
      callbacks:
        aggregate_sweep:
          report: rtf
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import polars as pl
import yaml
from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from simlan_data.config.safe_yaml import load_yaml
from simlan_data.constants import METRICS_FILENAME
from simlan_data.errors import ConfigError
from simlan_data.evaluation.sweep_reports import SWEEP_REPORTS, SweepReport, register_sweep_report
from simlan_data.metrics_io import load_metrics

__all__ = [
    "SWEEP_REPORTS",
    "AggregateSweep",
    "SweepReport",
    "aggregate",
    "collect_sweep",
    "register_sweep_report",
    "write_sweep_table",
]

log = logging.getLogger(__name__)

SWEEP_TABLE_STEM = "sweep_metrics"


def _overrides(job_dir: Path) -> dict[str, Any]:
    path = job_dir / ".hydra" / "overrides.yaml"
    if not path.is_file():
        return {}
    out: dict[str, Any] = {}
    for item in load_yaml(path, what="Hydra overrides file") or []:
        key, _, value = str(item).partition("=")
        key = key.lstrip("+~")
        try:
            out[f"override.{key}"] = yaml.safe_load(value)
        except yaml.YAMLError:
            out[f"override.{key}"] = value
    return out


def _job_dirs(sweep_dir: Path) -> list[Path]:
    """Sweep subdirectories that hold a Hydra job (``.hydra/``), in job order."""
    dirs = [p for p in sweep_dir.iterdir() if p.is_dir() and (p / ".hydra").is_dir()]
    return sorted(dirs, key=lambda p: (not p.name.isdigit(), int(p.name) if p.name.isdigit() else 0, p.name))


def collect_sweep(sweep_dir: str | Path) -> pl.DataFrame:
    """One row per job of the sweep in ``sweep_dir``: its overrides, status and metrics.

    Raises:
        ConfigError: ``sweep_dir`` is not a directory or holds no Hydra job.
    """
    root = Path(sweep_dir)
    if not root.is_dir():
        raise ConfigError(
            "not a sweep directory", str(root), "it does not exist", "give the directory of a -m run"
        )
    jobs = _job_dirs(root)
    if not jobs:
        raise ConfigError(
            "no sweep jobs",
            str(root),
            "no subdirectory with a .hydra/ folder",
            "give the directory of a -m run",
        )
    rows: list[dict[str, Any]] = []
    for job in jobs:
        row: dict[str, Any] = {"job": job.name, **_overrides(job)}
        metrics_path = job / METRICS_FILENAME
        if metrics_path.is_file():
            row["status"] = "ok"
            row.update({k: float(v) for k, v in load_metrics(metrics_path).items()})  # null: NaN
        else:
            row["status"] = "failed"
        rows.append(row)
    # overrides may mix types across jobs (1 and 1.5): let polars widen, strings stay strings
    return pl.DataFrame(rows, infer_schema_length=None, strict=False)


def write_sweep_table(table: pl.DataFrame, sweep_dir: Path) -> tuple[Path, Path]:
    """Write ``sweep_metrics.parquet`` and ``.csv`` into ``sweep_dir``; returns both paths."""
    parquet = sweep_dir / f"{SWEEP_TABLE_STEM}.parquet"
    csv = sweep_dir / f"{SWEEP_TABLE_STEM}.csv"
    table.write_parquet(parquet)
    flat = table.select([c for c, t in table.schema.items() if not isinstance(t, (pl.List, pl.Struct))])
    flat.write_csv(csv)
    return parquet, csv


def aggregate(sweep_dir: str | Path, report: str = "") -> pl.DataFrame:
    """Collect, write the table and run the named report; returns the table."""
    root = Path(sweep_dir)
    if report and report not in SWEEP_REPORTS:
        raise ConfigError(
            f"unknown sweep report {report!r}",
            "hydra.callbacks.aggregate_sweep.report",
            f"known: {', '.join(sorted(SWEEP_REPORTS)) or '(none)'}",
            "pick one or leave it empty",
        )
    table = collect_sweep(root)
    parquet, _ = write_sweep_table(table, root)
    failed = table.filter(pl.col("status") == "failed").height
    print(f"sweep: {table.height} jobs ({failed} failed) -> {parquet}", flush=True)
    if report:
        SWEEP_REPORTS[report](table, root)
    return table


class AggregateSweep(Callback):
    """Hydra callback: aggregate the sweep's metrics when every job has returned."""

    def __init__(self, report: str = "") -> None:
        self.report = report

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:  # noqa: ARG002 - Hydra API
        sweep_dir = Path(str(config.hydra.sweep.dir))
        if not sweep_dir.is_dir():
            return
        try:
            aggregate(sweep_dir, self.report)
        except ConfigError as err:
            log.warning("sweep aggregation skipped: %s", err.line())
