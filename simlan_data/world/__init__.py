"""The static world: agent types, semantic labels, the layout, models and the humanoid skeleton."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.world` stays light (pybullet loads with the builder, not with the package).
_EXPORTS: dict[str, str] = {
    "AGENT_TYPES": "agent_types",
    "MARKER_SIZE_M": "agent_types",
    "AgentType": "agent_types",
    "agent_type": "agent_types",
    "PhysicsParams": "physics",
    "WorldBodies": "builder",
    "build_world": "builder",
    "LABEL_NAMES": "labels",
    "SEMANTIC_CLASSES": "labels",
    "label_id": "labels",
    "Placement": "layout",
    "load_layout": "layout",
    "resolve_layout_path": "layout",
    "MeshBuilder": "mesh",
    "ModelSpec": "models",
    "Part": "models",
    "JOINT_NAMES": "skeleton",
    "LANDMARK_NAMES": "skeleton",
    "NUM_JOINTS": "skeleton",
    "NUM_LANDMARKS": "skeleton",
    "forward_kinematics": "skeleton",
    "landmark_positions": "skeleton",
}

__all__ = [
    "AGENT_TYPES",
    "JOINT_NAMES",
    "LABEL_NAMES",
    "LANDMARK_NAMES",
    "MARKER_SIZE_M",
    "NUM_JOINTS",
    "NUM_LANDMARKS",
    "SEMANTIC_CLASSES",
    "AgentType",
    "MeshBuilder",
    "ModelSpec",
    "Part",
    "PhysicsParams",
    "Placement",
    "WorldBodies",
    "agent_type",
    "build_world",
    "forward_kinematics",
    "label_id",
    "landmark_positions",
    "load_layout",
    "resolve_layout_path",
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
