"""The static world: agent types, semantic labels, the layout, models and the humanoid skeleton."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "agent_types": ["AGENT_TYPES", "AgentType", "MARKER_SIZE_M", "agent_type"],
        "builder": ["WorldBodies", "build_world"],
        "labels": ["LABEL_NAMES", "SEMANTIC_CLASSES", "label_id"],
        "layout": ["Placement", "load_layout", "resolve_layout_path"],
        "mesh": ["MeshBuilder"],
        "models": ["ModelSpec", "Part"],
        "physics": ["PhysicsParams"],
        "skeleton": [
            "JOINT_NAMES",
            "LANDMARK_NAMES",
            "NUM_JOINTS",
            "NUM_LANDMARKS",
            "forward_kinematics",
            "landmark_positions",
        ],
    },
)
