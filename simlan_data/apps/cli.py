"""Command-line plumbing shared by the entry points: one-line errors and exit codes."""

from __future__ import annotations

import errno
import logging
import os
import re
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn, TextIO

import yaml
from hydra.errors import HydraException
from omegaconf.errors import OmegaConfBaseException

from simlan_data.apps.pipes import flush_stdout
from simlan_data.config.safe_yaml import check_config_dirs
from simlan_data.config.validation import config_error_from
from simlan_data.constants import CONF_DIR, METRICS_FILENAME, RECORDING_DIRNAME, REPORT_FILENAME
from simlan_data.errors import EXIT_BAD_INPUT, EXIT_FAILED_RUN, RunError, SimlanError

log = logging.getLogger("simlan_data")


def _root_simlan_error(err: BaseException) -> SimlanError | None:
    seen: set[int] = set()
    cur: BaseException | None = err
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, SimlanError):
            return cur
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return None


def _first_line(text: str) -> str:
    lines = [ln.strip() for ln in str(text).splitlines() if ln.strip()]
    return lines[0] if lines else ""


class _StderrWithoutHydraJobError:
    """Hydra writes 'Error executing job with overrides: ...' straight to stderr before
    re-raising; we print our own one-line error instead, so that line is dropped."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        if text.startswith("Error executing job with overrides"):
            return len(text)
        return self._stream.write(text)

    def __getattr__(self, name: str) -> object:
        return getattr(self._stream, name)


def _group_options(message: str) -> str:
    """For "Could not find 'group/option'": the options that do exist."""
    m = re.search(r"Could not find '([^'/]+)/[^']*'", message)
    if not m:
        return ""
    options = sorted(p.stem for p in (CONF_DIR / m.group(1)).glob("*.yaml"))
    return f" (options: {', '.join(options)})" if options else ""


def _in_chain(err: BaseException | None, kind: type[BaseException]) -> BaseException | None:
    """The first exception of type ``kind`` among ``err`` and its causes."""
    seen = 0
    while err is not None and seen < 20:
        if isinstance(err, kind):
            return err
        err, seen = err.__cause__ or err.__context__, seen + 1
    return None


DISK_ERRORS = {  # errno: what the disk said (a failed run, never a bad config)
    errno.ENOSPC: "no space left on",
    errno.EDQUOT: "disk quota exceeded on",
    errno.EIO: "input/output error on",
    errno.EROFS: "read-only file system at",
}


def disk_error(err: BaseException) -> RunError | None:
    """A full (or failing, or read-only) disk anywhere among ``err`` and its causes, as one
    line naming the file and what of the run survived; None if the disk is not the cause."""
    found = _in_chain(err, OSError)
    seen = 0
    cur: BaseException | None = err
    while cur is not None and seen < 20:  # the first OSError whose errno says the disk
        if isinstance(cur, OSError) and cur.errno in DISK_ERRORS:
            found = cur
            break
        cur, seen = cur.__cause__ or cur.__context__, seen + 1
    if not isinstance(found, OSError) or found.errno not in DISK_ERRORS:
        return None
    path = Path(os.fsdecode(found.filename)) if found.filename else _output_dir()
    kept = survivors(path)
    return RunError(
        f"{DISK_ERRORS[found.errno]} {path}",
        "",
        f"{os.strerror(found.errno)} (errno {errno.errorcode[found.errno]}); "
        + (f"kept: {', '.join(kept)}" if kept else "nothing of the run was kept"),
        "free space there (or choose another hydra.run.dir) and rerun",
    )


def _output_dir() -> Path:
    """Hydra's run directory once it has one (the file a write failed on is not always known)."""
    try:
        from hydra.core.hydra_config import HydraConfig

        if HydraConfig.initialized() and HydraConfig.get().runtime.output_dir:
            return Path(HydraConfig.get().runtime.output_dir)
    except Exception:  # not in a Hydra job (yet): the command line says
        pass
    for arg in reversed(sys.argv[1:]):
        key, _, value = arg.lstrip("+").partition("=")
        if key in ("hydra.run.dir", "hydra.sweep.dir") and value:
            return Path(value)
    return Path.cwd()


def survivors(path: Path) -> list[str]:
    """What a run directory at or above ``path`` holds of a run's outputs (recording, metrics,
    report), for the line that says a run failed."""
    for run_dir in [path, *list(path.parents)[:3]]:
        if (run_dir / ".hydra").is_dir() or (run_dir / RECORDING_DIRNAME).is_dir():
            names = (RECORDING_DIRNAME, METRICS_FILENAME, REPORT_FILENAME)
            return [str(run_dir / n) for n in names if (run_dir / n).exists()]
    return []


def log_to_open_files(message: str, level: int = logging.ERROR) -> None:
    """``message`` also into the log files a run has opened (Hydra's run.log): a run refused
    before it logged anything (a bad config, a directory in use) opened none and writes none."""
    record = log.makeRecord(log.name, level, __file__, 0, message, (), None)
    for handler in logging.getLogger().handlers:
        if isinstance(handler, logging.FileHandler) and handler.stream is not None:
            handler.handle(record)


def fail(message: str, code: int) -> NoReturn:
    log_to_open_files(message)
    sys.stderr.write(f"error: {message}\n")
    sys.stderr.flush()
    raise SystemExit(code)


def run_cli(
    main: Callable[[], object], *, debug: bool = False, started: Callable[[], bool] | None = None
) -> None:
    """Run an entry point; turn errors into one ``error: ...`` line and exit code 2 or 1.

    ``started()`` tells whether the work itself began: an unexpected error before that (inside
    Hydra's composition) is a bad argument (2), after it a failed run (1).

    Hydra prints multi-line reports for config errors and exits 1; with HYDRA_FULL_ERROR set
    (by us, unless the user set it) it re-raises instead, and we print one line and exit 2.
    """
    user_full = os.environ.get("HYDRA_FULL_ERROR") == "1"
    debug = debug or user_full or "--debug" in sys.argv
    if "--debug" in sys.argv:
        sys.argv.remove("--debug")
    os.environ["HYDRA_FULL_ERROR"] = "1"
    real_stderr = sys.stderr
    sys.stderr = _StderrWithoutHydraJobError(real_stderr)
    try:
        check_config_dirs(sys.argv[1:], app_dir=Path(__file__).parent)  # before Hydra reads them
        main()
        flush_stdout()  # output piped into `head`: exit 141 quietly (apps.pipes)
    except SystemExit:
        flush_stdout()
        raise
    except KeyboardInterrupt:  # Ctrl-C outside a run's graceful stop (SIGTERM: apps.signals)
        fail("interrupted by SIGINT", 128 + signal.SIGINT)
    except BaseException as err:
        if isinstance(err, BrokenPipeError):
            flush_stdout(broken_pipe_seen=True)  # (stdout's reader gone: exit 141)
        if debug:
            raise
        ours = disk_error(err) or _root_simlan_error(err) or config_error_from(err)
        if ours is not None:
            fail(ours.line(), ours.exit_code)
        bad_yaml = _in_chain(err, yaml.MarkedYAMLError)
        if isinstance(bad_yaml, yaml.MarkedYAMLError):  # a config file that is not valid YAML
            mark = bad_yaml.problem_mark
            where = f"{mark.name}, line {mark.line + 1}" if mark is not None else "a config file"
            fail(
                f"invalid configuration file {where}: {bad_yaml.problem}; fix the YAML there", EXIT_BAD_INPUT
            )
        if isinstance(err, (HydraException, OmegaConfBaseException)):
            msg = _first_line(str(err)) + _group_options(str(err))
            cause = err.__cause__
            if cause is not None and _first_line(str(cause)) and _first_line(str(cause)) not in msg:
                msg += f": {_first_line(str(cause))}"
            fix = "see --help for the valid groups and keys"
            if "is not a subclass of AgentConfig" in msg:
                # OmegaConf cannot add an entry to a typed dict from the command line
                fix = (
                    "new agents go in a spawn list file: write DIR/agents/NAME.yaml like "
                    "conf/agents/four_robots.yaml and run with 'hydra.searchpath=[file://DIR]' agents=NAME"
                )
            fail(f"invalid configuration: {msg}; {fix}", EXIT_BAD_INPUT)
        if started is not None and not started():  # composing the config itself failed
            fail(
                f"invalid configuration in command line: {type(err).__name__}: {_first_line(str(err))}; "
                "see --help for the valid groups and keys",
                EXIT_BAD_INPUT,
            )
        fail(
            f"run failed: {type(err).__name__}: {_first_line(str(err))} (rerun with --debug for the traceback)",
            EXIT_FAILED_RUN,
        )
    finally:
        sys.stderr = real_stderr
        if not user_full:
            os.environ.pop("HYDRA_FULL_ERROR", None)
