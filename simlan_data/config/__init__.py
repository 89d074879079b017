"""The run's configuration: Hydra structured-config schemas, loading and validation."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.config` stays light (hydra loads with the schema).
_EXPORTS: dict[str, str] = {
    "CollisionSetup": "collision",
    "collision_setup": "collision",
    "CameraFaults": "faults",
    "Config": "schema",
    "register_configs": "schema",
    "compose_config": "validation",
    "to_config": "validation",
}

__all__ = [
    "CameraFaults",
    "CollisionSetup",
    "Config",
    "collision_setup",
    "compose_config",
    "register_configs",
    "to_config",
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
