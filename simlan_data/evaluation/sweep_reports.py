"""The sweep reports an experiment can name (``hydra.callbacks.aggregate_sweep.report``).

An explicit table, not registration by import: the report modules import nothing from
:mod:`simlan_data.evaluation.sweep`, which looks reports up here, so there is no import cycle.
A new packaged report is one more entry below; code outside the package (tests, a project's own
report) adds one with ``register_sweep_report(name)``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import polars as pl

from simlan_data.evaluation.rtf_report import rtf_report
from simlan_data.evaluation.safety_sweep import collision_report

__all__ = ["SWEEP_REPORTS", "SweepReport", "register_sweep_report"]

# name -> function(table, sweep_dir) that writes the experiment's own tables and plots
SweepReport = Callable[[pl.DataFrame, Path], None]

SWEEP_REPORTS: dict[str, SweepReport] = {
    "collision": collision_report,  # experiment=collision_case1, collision_case2
    "rtf": rtf_report,  # experiment=rtf
}


def register_sweep_report(name: str) -> Callable[[SweepReport], SweepReport]:
    """Add ``fn(table, sweep_dir)`` to the table under ``name`` (for reports outside the package)."""

    def wrap(fn: SweepReport) -> SweepReport:
        SWEEP_REPORTS[name] = fn
        return fn

    return wrap
