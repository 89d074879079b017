"""The entry points: run, replay, evals, view (Rerun), recover, export; shared command-line handling."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "cli": ["run_cli"],
        "evals": ["run_suite"],
        "run": ["execute", "execute_posemap"],
    },
)
