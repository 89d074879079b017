"""Reading untrusted input files without hanging: regular files only, YAML without aliases.

A FIFO opened for reading blocks until something writes to it, a character device such as
``/dev/zero`` never ends, and a YAML alias bomb of a few hundred bytes expands to gigabytes in
anything that walks it. Every reader checks a path with :func:`require_regular` (``os.stat``,
which never blocks) before opening it, and loads YAML it did not write with
:func:`load_yaml_without_aliases` (simlan_data writes YAML without anchors or aliases).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import yaml

from simlan_data.errors import RecordingInputError

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def file_kind(mode: int) -> str:
    """``a FIFO (named pipe)``, ``a directory``...: what a ``st_mode`` that is not a regular file is."""
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def require_regular(path: Path, what: str, *, missing_ok: bool = True) -> os.stat_result | None:
    """``os.stat(path)`` if it is a regular file (after symlinks); None if it does not exist and
    ``missing_ok``.

    Raises:
        RecordingInputError: the path exists but is a FIFO, device, socket or directory (opening
            a FIFO would block until something writes to it), or does not exist (not
            ``missing_ok``), or cannot be examined.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if missing_ok:
            return None
        raise RecordingInputError(f"{what} missing", str(path), "no such file", "check the path") from None
    except OSError as err:
        raise RecordingInputError(
            f"{what} unreadable", str(path), f"{type(err).__name__}: {err.strerror or err}", "check the path"
        ) from None
    if not stat.S_ISREG(st.st_mode):
        raise RecordingInputError(
            f"{what} is not a regular file",
            str(path),
            f"it is {file_kind(st.st_mode)}, which is never read",
            "replace it by the real file (a recording's files are regular files)",
        )
    return st


class YAMLAliasError(yaml.YAMLError):
    """A YAML document that uses an alias (``*name``): refused, never expanded."""


class _NoAliasLoader(yaml.SafeLoader):
    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise YAMLAliasError(
                f"YAML alias at line {mark.line + 1}, column {mark.column + 1} (simlan_data writes none; "
                "aliases can expand to gigabytes)"
            )
        return super().compose_node(parent, index)


def load_yaml_without_aliases(text: str | bytes) -> Any:
    """``yaml.safe_load`` that raises :class:`YAMLAliasError` (a ``yaml.YAMLError``) at the first
    alias instead of building the document."""
    return yaml.load(text, Loader=_NoAliasLoader)
