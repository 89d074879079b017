"""Pose mapping: landmarks of a person -> joint targets of the humanoid (pure numpy/torch)."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.algorithms.posemap` stays light (torch loads with a model, not with the package).
_EXPORTS: dict[str, str] = {
    "PosemapConfig": "config",
    "PoseDataset": "dataset",
    "read_dataset": "dataset",
    "resolve_dataset": "dataset",
    "write_dataset": "dataset",
    "PoseEstimator": "estimators",
    "make_estimator": "estimators",
    "mpjpe": "metrics",
    "per_joint": "metrics",
    "GBMMapper": "models",
    "MLPMapper": "models",
    "PoseMapper": "models",
    "load_mapper": "models",
    "load_motion": "motion",
    "TrainedMapper": "training",
    "train": "training",
    "train_from_config": "training",
}

__all__ = [
    "GBMMapper",
    "MLPMapper",
    "PoseDataset",
    "PoseEstimator",
    "PoseMapper",
    "PosemapConfig",
    "TrainedMapper",
    "load_mapper",
    "load_motion",
    "make_estimator",
    "mpjpe",
    "per_joint",
    "read_dataset",
    "resolve_dataset",
    "train",
    "train_from_config",
    "write_dataset",
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
