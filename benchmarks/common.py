"""Helpers for benchmark scripts: machine description, timing, markdown tables."""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        kb = int(
            next(
                ln for ln in Path("/proc/meminfo").read_text().splitlines() if ln.startswith("MemTotal")
            ).split()[1]
        )
        mem = f", {kb / 2**20:.0f} GiB RAM"
    except (OSError, StopIteration):
        pass
    libs = ", ".join(f"{p} {version(p)}" for p in ("pybullet", "opencv-python-headless", "numpy", "rosbags"))
    return f"{cpu}, {os.cpu_count()} cores{mem}, no GPU (Mesa llvmpipe for EGL); Python {platform.python_version()}; {libs}"


def best_of(fn: Callable[[], object], repeat: int = 3) -> float:
    """Fastest wall time of ``repeat`` calls (seconds)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def run_cli(
    *args: str,
    timeout: float = 3600,
    module: str = "simlan_data.run",
    prefix: Sequence[str] = (),
    env_extra: dict[str, str] | None = None,
) -> subprocess.CompletedProcess[str]:
    """``python -m module args`` from the repository (``prefix``: e.g. a taskset command;
    ``env_extra``: variables added to this process's environment)."""
    env = {**os.environ, **(env_extra or {})}
    env.pop("HYDRA_FULL_ERROR", None)
    return subprocess.run(
        [*prefix, sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=timeout,
        env=env,
        check=False,
    )


def write_result(
    command: str, history: str, load: tuple[str, str], body: dict[str, Any], path: Path | None
) -> int:
    """Print a benchmark's results JSON (its command, the machine, the date, the docs page of its
    history, the load before and after, then ``body``) and write it to ``path``; returns 0."""
    raw = {
        "command": command,
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
        "history": history,
        "load_before": load[0],
        "load_after": load[1],
        **body,
    }
    text = json.dumps(raw, indent=1)
    print(text)
    if path is not None:
        path.write_text(text + "\n")
    return 0
