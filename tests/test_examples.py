"""Every runnable example in examples/*.py runs as its docstring says, on a committed recording.

Real processes on the real golden recording (recordings/golden/single_truck, 14 s, 2 cameras):
exit 0 and the output the example promises. A new example must get an entry in CASES.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
GOLDEN = REPO / "recordings" / "golden" / "single_truck"

# example -> (arguments after the recording, regexes its stdout must match)
CASES: dict[str, tuple[list[str], list[str]]] = {
    "read_recording.py": (
        ["--camera", "163"],
        [
            r"^3521 messages on 22 topics, 14\.0 s simulated$",
            r"^/camera_163/image_raw/compressed at 0\.000 s: 480x270 uint8",
        ],
    ),
    "read_with_mcap.py": (
        [],
        [
            r"^\s+841  /ground_truth/poses$",
            r"^first ground truth of robot_agent_1/base_link: x=-4\.00 y=0\.40",
        ],
    ),
    "plot_trajectory.py": (
        ["--save", "{tmp}/trajectory.png"],
        [r"^robot_agent_1: 281 estimates, ATE xy RMSE 1\.\d\d cm; wrote "],
    ),
}


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, timeout=120, cwd=REPO, check=False
    )


def test_every_example_has_a_case() -> None:
    examples = sorted(p.name for p in (REPO / "examples").glob("*.py"))
    assert examples == sorted(CASES), "add the new example to CASES (arguments and expected output)"


@pytest.mark.parametrize("name", sorted(CASES))
def test_example_runs(name: str, tmp_path: Path) -> None:
    extra, expected = CASES[name]
    proc = _run(f"examples/{name}", str(GOLDEN), *(a.format(tmp=tmp_path) for a in extra))
    assert proc.returncode == 0, proc.stderr
    for pattern in expected:
        assert re.search(pattern, proc.stdout, flags=re.MULTILINE), f"{pattern!r} not in:\n{proc.stdout}"
    if name == "plot_trajectory.py":
        png = (tmp_path / "trajectory.png").read_bytes()
        assert png.startswith(b"\x89PNG") and len(png) > 10_000


@pytest.mark.parametrize("name", sorted(CASES))
def test_example_says_what_is_wrong_with_a_bad_path(name: str, tmp_path: Path) -> None:
    extra, _ = CASES[name]
    proc = _run(f"examples/{name}", str(tmp_path / "missing"), *(a.format(tmp=tmp_path) for a in extra))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
