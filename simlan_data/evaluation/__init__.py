"""Evaluation: replaying recordings through the algorithms, metrics, V&V suites and sweeps."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.evaluation` stays light.
_EXPORTS: dict[str, str] = {
    "QualityEvaluator": "birdseye_metrics",
    "CameraConsistency": "camera_health",
    "recording_metrics": "localization_replay",
    "localization_metrics": "metrics",
    "navigation_metrics": "metrics",
    "ReplayContext": "replay",
    "write_report": "report",
    "recording_safety_metrics": "safety_metrics",
    "Interval": "stats",
    "difference_interval": "stats",
    "interval": "stats",
    "Suite": "suite_spec",
    "load_suite": "suite_spec",
    "AggregateSweep": "sweep",
    "aggregate": "sweep",
    "collect_sweep": "sweep",
    "SWEEP_REPORTS": "sweep_reports",
    "register_sweep_report": "sweep_reports",
}

__all__ = [
    "SWEEP_REPORTS",
    "AggregateSweep",
    "CameraConsistency",
    "Interval",
    "QualityEvaluator",
    "ReplayContext",
    "Suite",
    "aggregate",
    "collect_sweep",
    "difference_interval",
    "interval",
    "load_suite",
    "localization_metrics",
    "navigation_metrics",
    "recording_metrics",
    "recording_safety_metrics",
    "register_sweep_report",
    "write_report",
]


def __getattr__(name: str) -> Any:
    """Import the defining module on first use of a public name (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
