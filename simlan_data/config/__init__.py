"""The run's configuration: Hydra structured-config schemas, loading and validation."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "collision": ["CollisionSetup", "collision_setup"],
        "faults": ["CameraFaults"],
        "legacy": ["with_algorithms"],
        "schema": ["Config", "register_configs"],
        "validation": ["compose_config", "to_config"],
    },
)
