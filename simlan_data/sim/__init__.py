"""The simulation: PyBullet scene and agents, rendering, recording the cameras, publishing."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.sim` stays light (pybullet loads with the first module that needs it).
_EXPORTS: dict[str, str] = {
    "Agent": "agents",
    "CollisionReading": "agents",
    "DiffDriveAgent": "agents",
    "StaticAgent": "agents",
    "WalkerAgent": "agents",
    "spawn_agent": "agents",
    "PosedHumanoidAgent": "humanoid",
    "generate_dataset": "posemap_dataset",
    "PoseDriver": "posemap_drive",
    "make_driver": "posemap_drive",
    "Publisher": "publishing",
    "Client": "pybullet_client",
    "connect": "pybullet_client",
    "CameraRenderer": "rendering",
    "Inputs": "scene",
    "Scene": "scene",
    "load_inputs": "scene",
    "RunStats": "simulation",
    "Simulation": "simulation",
}

__all__ = [
    "Agent",
    "CameraRenderer",
    "Client",
    "CollisionReading",
    "DiffDriveAgent",
    "Inputs",
    "PoseDriver",
    "PosedHumanoidAgent",
    "Publisher",
    "RunStats",
    "Scene",
    "Simulation",
    "StaticAgent",
    "WalkerAgent",
    "connect",
    "generate_dataset",
    "load_inputs",
    "make_driver",
    "spawn_agent",
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
