"""Helpers shared by the reliability tests and ``benchmarks/reliability.py``.

Everything here reads recordings with the independent ``mcap`` reader (CRC validation on), never
with simlan_data's own reader, so that a test of the writer or of recovery cannot pass by the two
sharing a bug.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mcap.reader import make_reader

REPO = Path(__file__).resolve().parents[1]

# a short, low-resolution run of the default scenario (3 cameras around the truck's start)
SMALL_RUN = (
    "cameras.ids=[160,161,162]",
    "cameras.width=480",
    "cameras.height=270",
    "progress=false",
)


@dataclass(frozen=True)
class Msg:
    topic: str
    log_time: int
    data: bytes


def mcap_file(bag: Path) -> Path:
    files = sorted(bag.glob("*.mcap"))
    assert len(files) == 1, files
    return files[0]


def messages_in_file_order(bag: Path) -> list[Msg]:
    """Every message of a finished bag in the order it was written, CRCs validated (mcap library)."""
    with mcap_file(bag).open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        return [
            Msg(channel.topic, message.log_time, bytes(message.data))
            for _, channel, message in reader.iter_messages(log_time_order=False)
        ]


def payload_digest(messages: list[Msg]) -> str:
    """SHA-256 over (topic, log time, data) of every message, in order."""
    h = hashlib.sha256()
    for m in messages:
        h.update(m.topic.encode())
        h.update(m.log_time.to_bytes(8, "little"))
        h.update(len(m.data).to_bytes(8, "little"))
        h.update(m.data)
    return h.hexdigest()


def read_running(run_dir: Path) -> dict[str, float]:
    """The RUNNING marker as a dict (parsed without simlan_data)."""
    import yaml

    return yaml.safe_load((run_dir / "RUNNING").read_text())


def start_run(run_dir: Path, *overrides: str) -> subprocess.Popen[str]:
    """Start ``python -m simlan_data.run`` as users do, in the background."""
    env = {**os.environ}
    env.pop("HYDRA_FULL_ERROR", None)
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    # stderr to a file beside the run (an unread pipe could fill up and block the child)
    with (run_dir.parent / f"{run_dir.name}.stderr").open("w") as log:
        return subprocess.Popen(
            [sys.executable, "-m", "simlan_data.run", *overrides, f"hydra.run.dir={run_dir}"],
            cwd=REPO,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=log,
            text=True,
        )


def kill_when(
    proc: subprocess.Popen[str], ready: Callable[[], bool], *, timeout_s: float = 300.0, poll_s: float = 0.05
) -> bool:
    """SIGSTOP then SIGKILL ``proc`` as soon as ``ready()``; False if it ended first.

    Stopping first freezes the process (all its threads) at an arbitrary point, so what its
    RUNNING marker and the file say at that instant is what the kill leaves behind.
    """
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        if ready():
            os.kill(proc.pid, signal.SIGSTOP)
            return True
        time.sleep(poll_s)
    proc.kill()
    raise TimeoutError("the run never reached the kill point")


def finish_kill(proc: subprocess.Popen[str]) -> None:
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


class LineWatcher:
    """Collect the stdout lines of a child process on a thread (the last one is its progress)."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        assert proc.stdout is not None
        self._thread = threading.Thread(target=self._pump, args=(proc.stdout,), daemon=True)
        self._thread.start()

    def _pump(self, stream: object) -> None:
        for line in stream:  # type: ignore[attr-defined]
            self.lines.append(line.strip())

    def last(self) -> str:
        return self.lines[-1] if self.lines else ""
