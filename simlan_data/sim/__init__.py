"""The simulation: PyBullet scene and agents, rendering, recording the cameras, publishing."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "agents": [
            "Agent",
            "CollisionReading",
            "DiffDriveAgent",
            "StaticAgent",
            "WalkerAgent",
            "spawn_agent",
        ],
        "humanoid": ["PosedHumanoidAgent"],
        "posemap_dataset": ["generate_dataset"],
        "posemap_drive": ["PoseDriver", "make_driver"],
        "publishing": ["Publisher"],
        "pybullet_client": ["Client", "connect"],
        "rendering": ["CameraRenderer"],
        "scene": ["Inputs", "Scene", "load_inputs"],
        "simulation": ["RunStats", "Simulation"],
    },
)
