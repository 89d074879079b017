"""The run directory's markers: ``RUNNING`` while a run is in progress, ``INCOMPLETE`` after a
crashed run was recovered.

``RUNNING`` names the process that writes the run directory and how far its simulated clock got
(updated at every camera tick), so that a crash can be told from a live run, and the recovery can
say how much was lost. Both are small YAML files, written atomically (temporary file + rename).
"""

from __future__ import annotations

import os
import socket
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import yaml

from simlan_data.constants import INCOMPLETE_MARKER, RUNNING_MARKER

_RUNNING_HEADER = (
    "# This run has not finished. If no process writes here any more, it crashed: recover what it\n"
    "# recorded with `python -m simlan_data.recover {run_dir}`.\n"
)
MAX_MARKER_BYTES = 64 << 10


@dataclass(frozen=True)
class RunMarker:
    """Who writes a run directory and how far the simulated clock got."""

    pid: int
    host: str
    duration_s: float  # intended
    simulated_s: float  # reached (the camera tick last recorded)

    @staticmethod
    def for_this_process(duration_s: float) -> RunMarker:
        return RunMarker(os.getpid(), socket.gethostname(), float(duration_s), 0.0)


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_running(run_dir: Path, marker: RunMarker) -> None:
    """Create or update ``run_dir/RUNNING``."""
    text = _RUNNING_HEADER.format(run_dir=run_dir) + yaml.safe_dump(asdict(marker), sort_keys=False)
    _write_atomic(run_dir / RUNNING_MARKER, text)


def read_running(run_dir: Path) -> RunMarker | None:
    """The ``RUNNING`` marker of ``run_dir``, if any (a marker from an older version: pid 0)."""
    path = run_dir / RUNNING_MARKER
    if not path.is_file():
        return None
    data = _read_yaml(path)
    try:
        return RunMarker(
            int(data.get("pid", 0)),
            str(data.get("host", "")),
            float(data.get("duration_s", 0.0)),
            float(data.get("simulated_s", 0.0)),
        )
    except (TypeError, ValueError):
        return RunMarker(0, "", 0.0, 0.0)


def _read_yaml(path: Path) -> dict[str, Any]:
    try:
        if path.stat().st_size > MAX_MARKER_BYTES:
            return {}
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError, UnicodeDecodeError, RecursionError):
        return {}
    return data if isinstance(data, dict) else {}


def writer_alive(marker: RunMarker) -> bool:
    """True if the marker's process still runs on this host (a simlan_data process, where /proc tells)."""
    if marker.pid <= 0 or marker.host != socket.gethostname():
        return False
    try:
        os.kill(marker.pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, owned by someone else
    cmdline = Path(f"/proc/{marker.pid}/cmdline")
    try:
        return b"simlan" in cmdline.read_bytes() if cmdline.exists() else True
    except OSError:
        return True


def mark_incomplete(run_dir: Path, summary: dict[str, Any]) -> Path:
    """Replace ``RUNNING`` by ``INCOMPLETE`` holding what a recovery found."""
    path = run_dir / INCOMPLETE_MARKER
    header = (
        "# This run did not finish: its recording was recovered up to its last complete chunk.\n"
        "# It has no metrics.json or report.md; replay the recording to compute metrics.\n"
        "# `losses` names every range of messages (per topic) that recovery could not keep.\n"
    )
    _write_atomic(path, header + yaml.safe_dump(summary, sort_keys=False))
    (run_dir / RUNNING_MARKER).unlink(missing_ok=True)
    return path
