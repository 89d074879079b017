"""``metrics.json`` as strict JSON: ``null`` where a metric is not a number.

Python's ``json`` writes NaN and infinity as ``NaN`` and ``Infinity``, which strict parsers
(JavaScript's ``JSON.parse``, jq, most JSON libraries) refuse. A metric that has no value (no
localization estimate: NaN) or no finite value (a time to collision that never comes: inf) is
written as ``null``; our readers read ``null`` back as NaN (the value means "not a number"
either way; the sign of an infinity is not kept).

- :func:`dumps_metrics`: the text of a metrics file;
- :func:`write_metrics`: write it (one call for every writer);
- :func:`load_metrics`: read one (older files with ``NaN``/``Infinity`` too).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["dumps_metrics", "load_metrics", "loads_metrics", "write_metrics"]


def _strict(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if type(value).__module__ == "numpy" and hasattr(value, "item"):  # numpy scalars
        return _strict(value.item())
    return value


def dumps_metrics(metrics: Mapping[str, Any]) -> str:
    """The text of a metrics file: sorted keys, indented, non-finite numbers as ``null``."""
    return json.dumps(_strict(metrics), indent=2, sort_keys=True, allow_nan=False) + "\n"


def write_metrics(path: Path, metrics: Mapping[str, Any]) -> Path:
    """Write ``metrics`` to ``path`` as strict JSON (see :func:`dumps_metrics`)."""
    path.write_text(dumps_metrics(metrics))
    return path


def loads_metrics(text: str) -> dict[str, Any]:
    """Parse a metrics file's text: ``null`` (and an older file's ``NaN``/``Infinity``) as floats."""
    doc = json.loads(text)
    if not isinstance(doc, dict):
        raise ValueError(f"a metrics file holds an object, not {type(doc).__name__}")
    return {k: math.nan if v is None else v for k, v in doc.items()}


def load_metrics(path: Path) -> dict[str, Any]:
    """Read a metrics file (see :func:`loads_metrics`)."""
    return loads_metrics(Path(path).read_text())
