"""Pose mapping: landmarks of a person -> joint targets of the humanoid (pure numpy/torch)."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "config": ["PosemapConfig"],
        "dataset": ["PoseDataset", "read_dataset", "resolve_dataset", "write_dataset"],
        "estimators": ["PoseEstimator", "make_estimator"],
        "metrics": ["mpjpe", "per_joint"],
        "models": ["GBMMapper", "MLPMapper", "PoseMapper", "load_mapper"],
        "motion": ["load_motion"],
        "source": ["SourceLandmarks", "estimate_source", "open_frames"],
        "training": ["TrainedMapper", "train", "train_from_config"],
    },
)
