"""Bounded reading of user YAML: every config, spawn-list and suite file a user can hand us.

YAML aliases share one node however often they are used, so a file of 900 bytes can stand for
hundreds of millions of values (an "alias bomb"): PyYAML reads it at once, but whatever copies
the values (OmegaConf, a walk over them) hangs and fills the memory. Every user YAML file is
checked first: a regular file, at most :data:`MAX_BYTES`, and at most :data:`MAX_NODES` values
once its aliases are expanded.

- :func:`load_yaml`: ``yaml.safe_load`` of a checked file;
- :func:`check_yaml_file`: the checks alone (for files that Hydra reads itself);
- :func:`check_config_dirs`: every ``*.yaml`` in the config directories a command line gives
  Hydra (``--config-dir``, ``--config-path``, ``hydra.searchpath``), before it composes.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import yaml

from simlan_data.errors import ConfigError

MAX_BYTES = 1 << 20  # 1 MiB: the packaged configs are a few KiB
MAX_NODES = 100_000  # values once aliases are expanded: the largest packaged file has a few hundred
MAX_FILES = 10_000  # *.yaml files checked per config directory
_LOADER: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def check_yaml_text(text: str, *, what: str, where: str) -> None:
    """Refuse YAML whose aliases expand to more than :data:`MAX_NODES` values.

    Raises:
        ConfigError: naming ``what`` and ``where``.
    """
    try:
        docs = list(yaml.compose_all(text, Loader=_LOADER))
    except yaml.YAMLError as err:
        if "nesting depth" in str(err):
            raise ConfigError(f"{what} too deeply nested", where, "over 1000 levels", "flatten it") from None
        return  # not YAML: the reader's own parse says where
    except RecursionError:
        raise ConfigError(
            f"{what} too deeply nested", where, "YAML nesting beyond Python's limit", "flatten it"
        ) from None
    if _expanded_size(docs) > MAX_NODES:
        raise ConfigError(
            f"{what} too large",
            where,
            f"YAML aliases expand to more than {MAX_NODES} nodes (an alias bomb?)",
            "write the values out",
        )


def _expanded_size(roots: Iterable[yaml.Node | None]) -> int:
    """The number of nodes once every alias is replaced by a copy (memoized: shared nodes once)."""
    size: dict[int, int] = {}
    total = 0
    for root in roots:
        if root is None:
            continue
        stack: list[tuple[yaml.Node, bool]] = [(root, False)]
        on_path: set[int] = set()
        while stack:
            node, done = stack.pop()
            key = id(node)
            if done:
                on_path.discard(key)
                children = _children(node)
                size[key] = 1 + sum(size.get(id(c), 0) for c in children)
                if size[key] > MAX_NODES:
                    return size[key]
                continue
            if key in size:
                continue
            if key in on_path:  # a recursive alias (&a [*a]): unbounded once expanded
                return MAX_NODES + 1
            on_path.add(key)
            stack.append((node, True))
            stack.extend((c, False) for c in _children(node) if id(c) not in size)
        total += size[id(root)]
        if total > MAX_NODES:
            break
    return total


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def check_yaml_file(path: Path, *, what: str) -> str:
    """The text of a user YAML file that passed the checks (regular file, size, aliases).

    Raises:
        ConfigError: naming the file and what is wrong with it.
    """
    where = str(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ConfigError(f"{what} missing", where, "no such file", "check the path") from None
    except OSError as err:
        raise ConfigError(f"{what} unreadable", where, err.strerror or str(err), "check the path") from None
    if not stat.S_ISREG(st.st_mode):
        raise ConfigError(
            f"{what} is not a regular file", where, "a device, pipe or directory", "give a file"
        )
    if st.st_size > MAX_BYTES:
        raise ConfigError(
            f"{what} too large", where, f"{st.st_size} bytes, over {MAX_BYTES}", "split it or shorten it"
        )
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read(MAX_BYTES + 1)
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"{what} unreadable", where, f"not UTF-8 text ({err.reason})", "save it as UTF-8"
        ) from None
    except OSError as err:
        raise ConfigError(f"{what} unreadable", where, err.strerror or str(err), "check the file") from None
    if len(text) > MAX_BYTES:  # grew since the stat
        raise ConfigError(f"{what} too large", where, f"over {MAX_BYTES} bytes", "split it or shorten it")
    check_yaml_text(text, what=what, where=where)
    return text


def load_yaml(path: Path, *, what: str) -> Any:
    """``yaml.safe_load`` of a user file, bounded (see :func:`check_yaml_file`).

    Raises:
        ConfigError: an unusable file; ``yaml.YAMLError`` is the caller's to word (it knows the fix).
    """
    return yaml.load(check_yaml_file(path, what=what), Loader=_LOADER)


# ------------------------------------------------------------------------- Hydra's directories
_SEARCHPATH = re.compile(r"^\+{0,2}hydra\.searchpath=\[?(.*?)\]?$")


def config_dirs(argv: Sequence[str], *, app_dir: Path | None = None) -> list[Path]:
    """The user's config directories named on a Hydra command line (packaged ones excluded)."""
    out: list[str] = []
    args = list(argv)
    for i, arg in enumerate(args):
        for flag in ("--config-dir", "-cd", "--config-path", "-cp"):
            if arg == flag and i + 1 < len(args):
                out.append(args[i + 1])
            elif arg.startswith(flag + "="):
                out.append(arg.split("=", 1)[1])
        m = _SEARCHPATH.match(arg)
        if m:
            out += [p.strip().strip("'\"") for p in m.group(1).split(",")]
    dirs: list[Path] = []
    for item in out:
        if not item or item.startswith("pkg://"):
            continue
        raw = Path(item.removeprefix("file://"))
        candidates = [raw] if raw.is_absolute() else [Path.cwd() / raw] + ([app_dir / raw] if app_dir else [])
        for path in map(Path, map(os.path.abspath, candidates)):
            if path.is_dir() and path not in dirs:
                dirs.append(path)
    return dirs


def check_config_dirs(argv: Sequence[str], *, app_dir: Path | None = None) -> None:
    """Check every ``*.yaml`` in the config directories of a Hydra command line (before Hydra
    composes: OmegaConf would copy an alias bomb out in full).

    Raises:
        ConfigError: naming the first unusable file.
    """
    for directory in config_dirs(argv, app_dir=app_dir):
        for n, path in enumerate(sorted(_yaml_files(directory))):
            if n >= MAX_FILES:
                break
            check_yaml_file(path, what="config file")


def _yaml_files(directory: Path) -> Iterable[Path]:
    for root, subdirs, files in os.walk(directory):
        subdirs[:] = [d for d in subdirs if not d.startswith(".")]
        for name in files:
            if name.endswith((".yaml", ".yml")):
                yield Path(root) / name
