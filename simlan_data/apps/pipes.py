"""Output piped into a reader that stops early (``python -m simlan_data.replay R --info | head -1``).

Python ignores SIGPIPE, so writing to a pipe whose reader has gone raises ``BrokenPipeError``,
usually while flushing stdout at exit (a traceback, or ``Exception ignored ... BrokenPipeError``).
The CLIs do what a program killed by SIGPIPE does in a shell: stop quietly with exit status 141
(128 + SIGPIPE), which ``set -o pipefail`` reports like ``yes | head``'s. Python's own recipe:
point stdout at /dev/null so that the exit's flush does not fail again.
"""

from __future__ import annotations

import os
import select
import sys

EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, as shells report a process killed by SIGPIPE


def _reader_gone() -> bool:
    """True if stdout is a pipe whose reading end is closed (poll reports an error on it)."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll (Windows), no real stdout
        return False


def flush_stdout(*, broken_pipe_seen: bool = False) -> None:
    """Flush stdout; if its reader has gone, exit 141 quietly (SystemExit).

    ``broken_pipe_seen``: a BrokenPipeError was raised: also exit if nothing was left to flush
    but stdout's reader is gone (the error came from stdout, not from another pipe).
    """
    try:
        sys.stdout.flush()
        if not (broken_pipe_seen and _reader_gone()):
            return
    except BrokenPipeError:
        pass
    except (OSError, ValueError, AttributeError):
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass
    raise SystemExit(EXIT_BROKEN_PIPE)
