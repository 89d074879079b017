"""``--help`` answered from a cache before anything heavy is imported (issue 22: <= 0.5 s).

Composing the help costs the app's imports (Hydra, OmegaConf, numpy, OpenCV, the config schema and
every algorithm: about 0.4 s) and one composition (0.25 s). Its text only changes when what it is
made of changes, so the first ``--help`` stores it and later ones print it. The key covers
everything the text depends on: the help's own overrides, the package version, the size and
modification time of every file of the package and of its config directory, and every installed
algorithm plug-in (entry point, distribution version, and its module file's size and time). A
cache that cannot be read or written is skipped silently: help is then composed as before.

Standard library only: this module is imported by the ``-m`` shim before the app.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Iterable, Sequence
from importlib.metadata import entry_points
from importlib.util import find_spec
from pathlib import Path

from simlan_data import __version__
from simlan_data.constants import CONF_DIR

HELP_FLAGS = ("--help", "-h")
PLUGIN_GROUP = "simlan_data.algorithms"  # (= registry.ENTRY_POINT_GROUP; the registry is not light)
CACHE_ENV = "SIMLAN_DATA_CACHE_DIR"  # where caches go; default $XDG_CACHE_HOME/simlan_data
PACKAGE_DIR = Path(__file__).resolve().parents[1]


def wants_fast_help(argv: Sequence[str]) -> bool:
    """``--help`` with nothing that changes where configs come from."""
    if not any(a in HELP_FLAGS for a in argv):
        return False
    other = (
        "--hydra-help",
        "--config-dir",
        "-cd",
        "--config-path",
        "-cp",
        "--config-name",
        "-cn",
        "-m",
        "--multirun",
    )
    return not any(a in other or a.startswith(other) for a in argv) and not any(
        a.lstrip("+~").startswith("hydra.searchpath") for a in argv
    )


def help_overrides(argv: Sequence[str]) -> list[str]:
    """The overrides the help is composed for (``--help KEY=VALUE`` shows that config)."""
    return [a for a in argv if a not in HELP_FLAGS and not a.startswith("-")]


def cache_dir() -> Path:
    explicit = os.environ.get(CACHE_ENV)
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "simlan_data"


def _stat_rows(files: Iterable[Path], root: Path) -> Iterable[str]:
    for path in files:
        st = path.stat()
        yield f"{path.relative_to(root)}:{st.st_size}:{st.st_mtime_ns}"


def _package_rows() -> Iterable[str]:
    for root in (PACKAGE_DIR, CONF_DIR):
        files = sorted(p for p in root.rglob("*") if p.suffix in (".py", ".yaml"))
        yield f"root {root}"
        yield from _stat_rows(files, root)


def _plugin_rows() -> Iterable[str]:
    for ep in sorted(entry_points(group=PLUGIN_GROUP), key=lambda e: (e.name, e.value)):
        dist = f"{ep.dist.name}=={ep.dist.version}" if ep.dist is not None else "?"
        spec = find_spec(ep.value.split(":")[0].split(".")[0])  # the top-level module: no import
        origin = Path(spec.origin) if spec is not None and spec.origin else None
        stamp = f"{origin.stat().st_size}:{origin.stat().st_mtime_ns}" if origin and origin.is_file() else "-"
        yield f"plugin {ep.name}={ep.value} {dist} {stamp}"


def cache_key(argv: Sequence[str]) -> str:
    rows = [f"simlan_data {__version__}", f"python {sys.version}", *help_overrides(argv)]
    rows += [*_package_rows(), *_plugin_rows()]
    return hashlib.sha256("\n".join(rows).encode()).hexdigest()[:32]


def _path(argv: Sequence[str]) -> Path:
    return cache_dir() / "help" / f"{cache_key(argv)}.txt"


def cached_help(argv: Sequence[str]) -> str | None:
    """The stored help for this command line, if nothing it depends on changed since."""
    try:
        return _path(argv).read_text(encoding="utf-8")
    except (OSError, ValueError, ImportError):
        return None


def store_help(argv: Sequence[str], text: str) -> None:
    """Keep ``text`` for the next ``--help`` (best effort: a read-only home just skips it)."""
    try:
        path = _path(argv)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)  # atomic: a concurrent --help reads the old file or the whole new one
    except (OSError, ValueError, ImportError):
        pass


def serve_cached_help(argv: Sequence[str]) -> bool:
    """Print the cached help and return True, or return False (the app composes it)."""
    if not wants_fast_help(argv):
        return False
    text = cached_help(argv)
    if text is None:
        return False
    sys.stdout.write(text)
    return True
