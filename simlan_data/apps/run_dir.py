"""The run directory: claimed by one process, written only by that process, never an earlier run's.

Hydra makes the run directory (``hydra.run.dir``) before the app runs. Our config turns off
Hydra's own ``.hydra/`` files (``hydra.output_subdir: null``) and delays its log file, and

1. :class:`CheckBeforeRunDir`, a Hydra callback, checks the whole config before Hydra makes the
   directory (a single run; a sweep's jobs are checked by the app, and a refused job's directory
   is removed again), and refuses a directory that holds anything;
2. the app takes an exclusive lock on the directory (``flock``, held until the process ends: a
   second run into the same directory is refused with one line naming the holder),
3. and finds it empty under that lock (an earlier run's directory is never written into).

Only then are the provenance files written, as Hydra would have: ``.hydra/config.yaml``,
``hydra.yaml``, ``overrides.yaml``.
"""

from __future__ import annotations

import contextlib
import copy
import fcntl
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

from simlan_data.config.validation import to_config
from simlan_data.constants import INTERRUPTED_MARKER
from simlan_data.errors import ConfigError
from simlan_data.recording.run_marker import read_running

_EXISTING: list[Path] = []  # the nearest directory above the run directory that existed before Hydra ran
HYDRA_DIRNAME = ".hydra"
HOLDER_WAIT_S = 2.0  # how long the loser of a race waits for the winner to name itself


class RunDirTakenError(ConfigError):
    """The run directory is another run's (in use, or holding an earlier run): exit 2, and the
    directory is left exactly as it was."""


@dataclass
class RunDirLock:
    """An exclusive ``flock`` on a run directory; released when closed or when the process ends."""

    fd: int

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.fd)


def _holder(run_dir: Path) -> str:
    """Who holds ``run_dir`` (its ``RUNNING`` marker), waiting briefly for a winner that has
    only just taken the lock."""
    deadline = time.monotonic() + HOLDER_WAIT_S
    while True:
        marker = read_running(run_dir)
        if marker is not None and marker.pid > 0:
            return (
                f"process {marker.pid} on {marker.host} holds it (started a run of {marker.duration_s:g} s)"
            )
        if time.monotonic() > deadline:
            return "another process holds it"
        time.sleep(0.05)


def claim(run_dir: Path) -> RunDirLock:
    """Lock ``run_dir`` for this process and check that it is empty.

    Raises:
        ConfigError: another process holds it, or it holds an earlier run (exit 2; nothing written).
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    fd = _try_lock(run_dir)
    if fd is None:
        raise RunDirTakenError(
            "run directory in use",
            str(run_dir),
            _holder(run_dir),
            "simlan_data never writes into another run's directory; choose another hydra.run.dir",
        ) from None
    entries = sorted(p.name + ("/" if p.is_dir() else "") for p in run_dir.iterdir())
    if entries:
        os.close(fd)
        shown = ", ".join(entries[:4]) + (", ..." if len(entries) > 4 else "")
        raise RunDirTakenError(
            "run directory not empty",
            str(run_dir),
            f"it holds {shown} (an earlier run's?)",
            "simlan_data never writes into an existing run directory; choose another hydra.run.dir",
        )
    return RunDirLock(fd)


def _try_lock(run_dir: Path) -> int | None:
    """An open descriptor of ``run_dir`` holding its exclusive ``flock``, or None when another
    process holds it (or the directory cannot be opened)."""
    try:
        fd = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


def write_provenance(run_dir: Path, task_cfg: DictConfig, hydra_cfg: Any, overrides: list[str]) -> None:
    """``.hydra/config.yaml``, ``hydra.yaml`` and ``overrides.yaml``, the files Hydra would have
    written (the sweep aggregator and ``--experimental-rerun`` read them)."""
    out = run_dir / HYDRA_DIRNAME
    out.mkdir()
    OmegaConf.save(task_cfg, out / "config.yaml")
    OmegaConf.save(OmegaConf.create({"hydra": hydra_cfg}), out / "hydra.yaml")
    OmegaConf.save(OmegaConf.create(list(overrides)), out / "overrides.yaml")


def mark_interrupted(run_dir: Path, signal: str, reached_s: float, duration_s: float, wall_s: float) -> Path:
    """``INTERRUPTED``: a signal stopped the run early; what ran is finalized (YAML)."""
    path = run_dir / INTERRUPTED_MARKER
    info = {
        "signal": signal,
        "simulated_s": round(reached_s, 9),
        "intended_duration_s": float(duration_s),
        "wall_s": round(wall_s, 3),
    }
    header = (
        f"# This run was stopped by {signal} before its end. Its recording, metrics.json and report.md\n"
        "# hold what ran (the recording is finalized: it needs no recovery).\n"
    )
    path.write_text(header + yaml.safe_dump(info, sort_keys=False))
    return path


def _nearest_existing(path: Path) -> Path:
    cur = path.absolute()
    while not cur.exists() and cur != cur.parent:
        cur = cur.parent
    return cur


def remove_made(run_dir: Path) -> None:
    """Undo what a refused run made: ``run_dir`` if it is empty, then each empty parent up to
    the directory that existed before Hydra ran (unknown, as in a sweep job: ``run_dir`` only)."""
    keep = _EXISTING[-1] if _EXISTING else run_dir.absolute().parent
    cur = run_dir.absolute()
    while cur != keep and keep in cur.parents:
        try:
            cur.rmdir()  # only an empty directory
        except OSError:
            return
        cur = cur.parent


class CheckBeforeRunDir(Callback):
    """Hydra callback (``hydra.callbacks.check_run``): before Hydra makes a single run's
    directory, check the whole config and refuse a directory that holds anything."""

    def on_run_start(self, config: DictConfig, **_kwargs: Any) -> None:
        run_dir = Path(str(OmegaConf.select(config, "hydra.run.dir"))).absolute()
        _EXISTING.append(_nearest_existing(run_dir))
        task = copy.deepcopy(config)
        with read_write(task), open_dict(task):
            del task["hydra"]
        try:
            if OmegaConf.select(config, "hydra.output_subdir") is not None:
                raise ConfigError.invalid(
                    "hydra.output_subdir",
                    OmegaConf.select(config, "hydra.output_subdir"),
                    "Hydra would write it before the config is checked and the directory claimed",
                    "leave it unset: the run writes .hydra/ itself once it owns the directory",
                )
            to_config(task)
            if run_dir.is_dir():  # an existing directory: refused if it is in use or holds anything
                claim(run_dir).close()
        except ConfigError as err:
            raise RefusedBeforeRunDir(err) from err


class RefusedBeforeRunDir(BaseException):
    """Carries a ConfigError out of a Hydra callback (Hydra turns an ``Exception`` raised there
    into a warning and goes on); the command line reports the ConfigError it carries."""

    def __init__(self, err: ConfigError) -> None:
        super().__init__(err.line())
        self.error = err


def clear_refused(run_dir: Path, lock: RunDirLock | None) -> None:
    """Undo a refused run: with the directory claimed (it was empty then, so everything in it is
    this run's own), remove what is in it; then the directory and the parents Hydra made."""
    if lock is not None:
        for p in run_dir.iterdir():
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
        lock.close()
    elif run_dir.is_dir():
        fd = _try_lock(run_dir)
        if fd is None:
            return  # another process has just claimed it (still empty): leave it
        os.close(fd)  # (releases the lock taken here)
    remove_made(run_dir)
