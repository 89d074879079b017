"""The entry points: run, replay, evals, view (Rerun), recover; shared command-line handling."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.apps` stays light.
_EXPORTS: dict[str, str] = {
    "run_cli": "cli",
    "run_suite": "evals",
    "execute": "run",
    "execute_posemap": "run",
}

__all__ = [
    "execute",
    "execute_posemap",
    "run_cli",
    "run_suite",
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
