"""Inspection of recordings in Rerun: the blueprint and the export of a bag."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.viz` stays light (rerun loads on first use).
_EXPORTS: dict[str, str] = {
    "build_blueprint": "blueprint",
    "export": "rerun_export",
}

__all__ = [
    "build_blueprint",
    "export",
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
