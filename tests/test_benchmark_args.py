"""Benchmark commands refuse bad arguments with one line, before writing anything."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_posemap_noise_refuses_a_zero_scale(tmp_path: Path) -> None:
    work = tmp_path / "work"
    proc = subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "posemap_noise.py"),
            "--scales",
            "1",
            "0",
            "--workdir",
            str(work),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert lines == [
        "invalid --scales 0: the fit weighs landmarks by 1/noise; give scales > 0, e.g. --scales 0.25 0.5 1 2"
    ]
    assert not work.exists()
