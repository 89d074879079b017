"""Recordings: ROS 2 bags (MCAP) written and read, their messages, codecs and recovery."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "cameras": ["cameras_in_recording"],
        "reader": ["Message", "RecordingReader", "TopicInfo"],
        "recover": ["RecoveryReport", "resolve_bag"],
        "run_marker": ["RunMarker"],
        "salvage": ["Salvage"],
        "writer": ["NullWriter", "RecordingWriter"],
    },
)
