"""SIGTERM and SIGINT: stop a run at the next step boundary, finish what was recorded, exit 143 / 130.

SLURM, ``docker stop``, systemd and Ray stop a job with SIGTERM; a user at a terminal presses
Ctrl-C (SIGINT). The first of either only asks the simulation to stop: it finishes the step it is
in, the recorder finalizes the bag (footer, ``metadata.yaml``), the report of what ran is written
and the run directory is marked ``INTERRUPTED``. A second signal while that shutdown runs exits at
once (the bag is then left as after a crash, and ``python -m simlan_data.recover`` reads it).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from types import FrameType

from simlan_data.errors import RunError

HANDLED = (signal.SIGTERM, signal.SIGINT)


def exit_code(signum: int) -> int:
    """The shell's convention: 128 + the signal number (SIGINT 130, SIGTERM 143)."""
    return 128 + int(signum)


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name


class RunInterruptedError(RunError):
    """The run was stopped by a signal; what ran is finalized. Exit 128 + the signal number."""

    def __init__(self, signum: int, what: str, where: str = "", why: str = "", fix: str = "") -> None:
        self.signum = signum
        self.exit_code = exit_code(signum)
        super().__init__(what, where, why, fix)


@dataclass
class StopRequest:
    """Set by the first SIGTERM/SIGINT; the simulation polls it at every step boundary."""

    signum: int | None = None
    on_second: Callable[[int], None] | None = field(default=None, repr=False)

    def __call__(self) -> bool:
        return self.signum is not None

    @property
    def name(self) -> str:
        return signal_name(self.signum) if self.signum is not None else ""

    def _handle(self, signum: int, _frame: FrameType | None) -> None:
        if self.signum is None:
            self.signum = signum
            return
        # a second signal during the shutdown: stop now, the bag stays recoverable
        if self.on_second is not None:
            self.on_second(signum)
        os._exit(exit_code(signum))


def exit_on_early_signal() -> None:
    """Until a run installs :func:`graceful_stop` (while Python imports the app and Hydra composes
    the config: nothing is written yet), SIGTERM ends the process at once with one line and exit
    143 instead of killing it without a word. Called by the ``-m`` shims first, then by ``main``."""
    if threading.current_thread() is not threading.main_thread():
        return

    def leave(signum: int, _frame: FrameType | None) -> None:
        with suppress(OSError):
            os.write(2, f"error: interrupted by {signal_name(signum)}\n".encode())
        os._exit(exit_code(signum))

    signal.signal(signal.SIGTERM, leave)


@contextmanager
def graceful_stop(on_second: Callable[[int], None] | None = None) -> Iterator[StopRequest]:
    """Handle SIGTERM and SIGINT as a request to stop (see the module doc) inside the block.

    Off the main thread (a launcher running jobs in threads) signals cannot be handled: the
    request then never fires and the launcher's own handling applies.
    """
    request = StopRequest(on_second=on_second)
    if threading.current_thread() is not threading.main_thread():
        yield request
        return
    previous = {s: signal.getsignal(s) for s in HANDLED}
    for s in HANDLED:
        signal.signal(s, request._handle)
    try:
        yield request
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def say_stopped_at_once(line: str) -> Callable[[int], None]:
    """``on_second`` for :func:`graceful_stop`: one line on stderr before exiting at once."""

    def report(signum: int) -> None:
        with suppress(OSError):
            os.write(sys.stderr.fileno(), f"error: {line.format(signal=signal_name(signum))}\n".encode())

    return report
