"""Import every module that registers a sweep report (``hydra.callbacks.aggregate_sweep.report``)."""

from __future__ import annotations

# Each import registers with simlan_data.evaluation.sweep.register_sweep_report(name). Add new ones here.
from simlan_data.evaluation import rtf_report  # noqa: F401
