"""Inspection of recordings in Rerun: the blueprint and the export of a bag."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "blueprint": ["build_blueprint"],
        "rerun_export": ["export"],
    },
)
