"""How the run's log records read on the console (Hydra's job logging, conf/config.yaml).

The console shows a record's message as it is, the way the run printed it before it logged:
``warning: ...`` and ``error: ...`` for those levels; the run's ``run.log`` keeps Hydra's
``[time][logger][LEVEL] - message`` lines.
"""

from __future__ import annotations

import logging
import sys


class ConsoleFormatter(logging.Formatter):
    """The message alone; prefixed with its level from WARNING up."""

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        return text if record.levelno < logging.WARNING else f"{record.levelname.lower()}: {text}"


class RunLogHandler(logging.FileHandler):
    """Hydra's ``run.log``: a record that cannot be written (a full disk) is dropped quietly,
    without logging's traceback on stderr: the run's own error line says what happened, once."""

    def handleError(self, record: logging.LogRecord) -> None:  # noqa: N802 (logging's name)
        if isinstance(sys.exc_info()[1], OSError):
            return
        super().handleError(record)
