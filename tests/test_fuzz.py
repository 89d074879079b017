"""Property tests: no input makes the calibration loader, the config checks or the recording
reader (and recovery) raise anything but their own one-line errors, or hang.

Default budget: ``SIMLAN_FUZZ_EXAMPLES`` examples per target (60; half for the config checks,
which compose a whole config each); the ``slow`` variants run
``SIMLAN_FUZZ_EXAMPLES_SLOW`` (1000) in CI. Deadlines catch hangs (sizes read from untrusted
files are bounded before anything is allocated).
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest
from fuzz_targets import (
    calibration_inputs,
    check_calibration,
    check_config,
    check_hostile,
    check_recording,
    config_overrides,
    hostile_inputs,
    recording_inputs,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from reliability_cases import small_recording

EXAMPLES = int(os.environ.get("SIMLAN_FUZZ_EXAMPLES", "60"))
EXAMPLES_SLOW = int(os.environ.get("SIMLAN_FUZZ_EXAMPLES_SLOW", "1000"))


@pytest.fixture(scope="module")
def bag_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    bag = small_recording(tmp_path_factory.mktemp("fuzz") / "recording")
    return {p.name: p.read_bytes() for p in bag.iterdir()}


def _fuzz(
    strategy: st.SearchStrategy, check: Callable[[object], str], examples: int, deadline_ms: int
) -> Counter:
    outcomes: Counter = Counter()

    @settings(
        max_examples=examples,
        deadline=deadline_ms,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(strategy)
    def run(value: object) -> None:
        outcomes[check(value)] += 1

    run()
    assert sum(outcomes.values()) >= examples // 2, outcomes  # the budget was really spent
    return outcomes


def test_fuzz_calibration_loader() -> None:
    outcomes = _fuzz(calibration_inputs(), check_calibration, EXAMPLES, 2000)
    assert set(outcomes) - {"ok"} <= {"CalibrationError"}, outcomes


def test_fuzz_config_validation() -> None:
    outcomes = _fuzz(config_overrides(), check_config, max(EXAMPLES // 2, 20), 5000)  # (0.4 s each)
    assert set(outcomes) - {"ok"} <= {"ConfigError", "CalibrationError", "AssetError"}, outcomes


def test_fuzz_recording_reader_and_recovery(bag_files: dict[str, bytes]) -> None:
    outcomes = _fuzz(recording_inputs(bag_files), check_recording, EXAMPLES, 5000)
    assert any(k.startswith("RecordingInputError") for k in outcomes), outcomes


def test_fuzz_hostile_inputs() -> None:
    """Issue 21's shapes (FIFOs and directories for files, alias bombs, oversized metadata.yaml,
    counts that disagree with the MCAP file, topics of the wrong type, ``--set`` values of the
    wrong type): every one a one-line exit-2 error within 5 s, nothing left behind."""
    outcomes = _fuzz(hostile_inputs(), check_hostile, max(EXAMPLES // 2, 20), 5000)
    assert set(outcomes) <= {"RecordingInputError", "ConfigError"}, outcomes


@pytest.mark.slow
@pytest.mark.parametrize(
    ("target", "share"), [("calibration", 1), ("config", 4), ("recording", 1), ("hostile", 4)]
)
def test_fuzz_large_budget_with_heap_checks(target: str, share: int) -> None:
    """The large budget, in a process with glibc's heap checks on (MALLOC_CHECK_=3)."""
    proc = subprocess.run(
        [
            sys.executable,
            str(Path(__file__).with_name("fuzz_targets.py")),
            target,
            str(EXAMPLES_SLOW // share),
        ],
        capture_output=True,
        text=True,
        env={**os.environ, "MALLOC_CHECK_": "3"},
        timeout=3600,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    outcomes = ast.literal_eval(proc.stdout.strip().splitlines()[-1])
    assert sum(outcomes.values()) >= EXAMPLES_SLOW // share // 2, outcomes
