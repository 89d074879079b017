"""Evaluation: replaying recordings through the algorithms, metrics, V&V suites and sweeps."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "birdseye_metrics": ["QualityEvaluator"],
        "camera_health": ["CameraConsistency"],
        "localization_replay": ["recording_metrics"],
        "metrics": ["localization_metrics", "navigation_metrics"],
        "replay": ["ReplayContext"],
        "report": ["write_report"],
        "safety_metrics": ["recording_safety_metrics"],
        "stats": ["Interval", "difference_interval", "interval"],
        "suite_spec": ["Suite", "load_suite"],
        "sweep": ["AggregateSweep", "aggregate", "collect_sweep"],
        "sweep_reports": ["SWEEP_REPORTS", "register_sweep_report"],
    },
)
