"""Import PyBullet quietly: it prints its build time from C on import.

PyBullet and its EGL plugin print diagnostics from C straight to file descriptors 1 and 2; they
would interleave with our progress bar and summary, so they are silenced at the descriptor level.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator

_LIBC: ctypes.CDLL | None
try:
    _LIBC = ctypes.CDLL(None)
except OSError:  # pragma: no cover - no C library to flush
    _LIBC = None


def _flush_c_stdio() -> None:
    """Flush C's stdio buffers, so text printed from C goes where the descriptor points now."""
    if _LIBC is not None:
        _LIBC.fflush(None)


@contextlib.contextmanager
def silence_c_output(*, stderr: bool = False) -> Iterator[None]:
    """Redirect the process's stdout (and stderr) descriptors to /dev/null for the block."""
    streams = [sys.stdout] + ([sys.stderr] if stderr else [])
    fds = []
    for stream in streams:
        try:
            fds.append(stream.fileno())
        except (AttributeError, OSError, ValueError):  # pytest capture or no real descriptor
            continue
    for stream in streams:
        stream.flush()
    saved = [os.dup(fd) for fd in fds]
    try:
        with open(os.devnull, "w") as devnull:
            for fd in fds:
                os.dup2(devnull.fileno(), fd)
        yield
    finally:
        _flush_c_stdio()
        for stream in streams:
            stream.flush()
        for fd, keep in zip(fds, saved):
            os.dup2(keep, fd)
            os.close(keep)


with silence_c_output(stderr=True):
    import pybullet as pb

__all__ = ["pb", "silence_c_output"]
