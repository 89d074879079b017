"""Output directories of the CLIs: rejected input leaves nothing behind.

A CLI checks every argument before it creates an output directory; when an error about the input
comes only later (a recording that turns out to be bad while it is read), it removes the
directories it created itself, if nothing was written into them.
"""

from __future__ import annotations

from pathlib import Path


def make_dirs(path: Path) -> list[Path]:
    """``path.mkdir(parents=True, exist_ok=True)``; returns the directories it created, deepest first."""
    created = [p for p in (path, *path.parents) if not p.exists()]
    path.mkdir(parents=True, exist_ok=True)
    return created


def remove_if_empty(created: list[Path]) -> None:
    """Remove the directories :func:`make_dirs` created, deepest first, while they are empty."""
    for p in created:
        try:
            p.rmdir()
        except OSError:
            return
