"""Recordings: ROS 2 bags (MCAP) written and read, their messages, codecs and recovery."""

from __future__ import annotations

import importlib
from typing import Any

# public name -> the submodule that defines it. Nothing is imported here: a name's module loads
# on first use (PEP 562), so `import simlan_data.recording` stays light (rosbags and mcap load with the reader or the writer).
_EXPORTS: dict[str, str] = {
    "cameras_in_recording": "cameras",
    "Message": "reader",
    "RecordingReader": "reader",
    "TopicInfo": "reader",
    "RecoveryReport": "recover",
    "resolve_bag": "recover",
    "RunMarker": "run_marker",
    "Salvage": "salvage",
    "NullWriter": "writer",
    "RecordingWriter": "writer",
}

__all__ = [
    "Message",
    "NullWriter",
    "RecordingReader",
    "RecordingWriter",
    "RecoveryReport",
    "RunMarker",
    "Salvage",
    "TopicInfo",
    "cameras_in_recording",
    "resolve_bag",
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
