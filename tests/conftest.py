"""Shared fixtures: real PyBullet clients, one short real run read back by several tests."""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from importlib.metadata import entry_points
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from simlan_data.config.schema import register_configs
from simlan_data.constants import CONF_DIR

REPO = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------- parallel runs (pytest-xdist)
# The suite runs its test files in parallel (pyproject.toml: -n auto --dist loadfile), and other
# pytest sessions may share this environment: what tests share outside tmp_path is isolated here.
@pytest.fixture(scope="session", autouse=True)
def own_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """SIMLAN_DATA_CACHE_DIR (the --help cache) of this test process, inherited by the processes it
    starts: the tests neither read the user's cache nor leave entries in it."""
    cache = tmp_path_factory.mktemp("cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SIMLAN_DATA_CACHE_DIR", str(cache))
        yield cache


@contextmanager
def _exclusive(lock: Path) -> Iterator[None]:
    """An inter-process lock (flock on ``lock``), released when the file closes or the process dies."""
    with open(lock, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        yield


@contextmanager
def installed_packages_held() -> Iterator[None]:
    """An inter-process lock on this environment's installed packages: held while a test installs
    into it (tests/test_plugins.py) and while a test needs the installed plug-ins to stay as they
    are (the --help cache's key includes them), whichever pytest process or worker runs them."""
    digest = hashlib.sha256(sys.prefix.encode()).hexdigest()[:16]
    with _exclusive(Path(tempfile.gettempdir()) / f"simlan_data-tests-{digest}.lock"):
        yield


def made_once(tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[Path], None]) -> Path:
    """The directory ``name`` that ``make(directory)`` fills, once per test session however many
    xdist workers need it: the first makes it while the others wait, then all read it. For
    session fixtures whose tests only read what was made (they run at the same time)."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's directory, which holds each worker's
    directory, made = root / name, root / f"{name}.made"
    with _exclusive(root / f"{name}.lock"):
        if not made.exists():
            shutil.rmtree(directory, ignore_errors=True)  # (what a worker that failed left)
            directory.mkdir()
            make(directory)
            made.touch()
    return directory


@pytest.fixture
def installed_packages_unchanged() -> Iterator[None]:
    """No install into this environment while the test runs (installed_packages_held)."""
    with installed_packages_held():
        yield


def run_cli(
    *args: str, module: str = "simlan_data.run", timeout: float = 600, env: dict | None = None
) -> subprocess.CompletedProcess[str]:
    """Run an entry point as users do; returns the completed process (text output)."""
    full_env = {**os.environ, **(env or {})}
    full_env.pop("HYDRA_FULL_ERROR", None)
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=full_env,
        cwd=REPO,
    )


def export_cli(run: Path, fmt: str, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    """``python -m simlan_data.export RUN --format FMT [EXTRA ...] --out OUT``, as users run it."""
    return run_cli(str(run), "--format", fmt, *extra, "--out", str(out), module="simlan_data.export")


def compose_config(*overrides: str):
    """Compose the Hydra config as the app does, without a process (DictConfig)."""
    register_configs(list(overrides))  # the schema and every algorithm, as the app does first
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose("config", overrides=list(overrides))


@pytest.fixture(scope="session")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One real run of the default scenario, 3 s, all 11 cameras at 960x540, depth and semantic
    every frame (so every stream is checked); one for all workers."""

    def make(runs: Path) -> None:
        proc = run_cli(
            "duration_s=3",
            f"hydra.run.dir={runs / 'default_short'}",
            "progress=false",
            "recording.depth_rate_hz=5",
            "recording.semantic_rate_hz=5",
        )
        assert proc.returncode == 0, proc.stderr
        (runs / "default_short.stdout").write_text(proc.stdout)  # (what the console showed)

    return made_once(tmp_path_factory, "runs", make) / "default_short"


# ---------------------------------------------------------------------------------- pose mapping
DATASET_ARGS = (
    "experiment=posemap_dataset",
    "world.fidelity=empty",
    "cameras.width=480",
    "cameras.height=270",
    "progress=false",
)


@pytest.fixture(scope="session")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A 600-sample ray-occlusion dataset and a fusion model trained on it (seconds); one for all
    workers."""

    def make(root: Path) -> None:
        ds = root / "dataset"
        proc = run_cli(*DATASET_ARGS, "posemap.samples=600", "posemap.occlusion=rays", f"hydra.run.dir={ds}")
        assert proc.returncode == 0, proc.stderr
        proc = run_cli(
            "experiment=posemap_train",
            f"posemap.dataset={ds}",
            "posemap.epochs=40",
            "posemap.width=128",
            "posemap.layers=2",
            "posemap.dropout=0.0",
            "posemap.lr=0.003",
            f"hydra.run.dir={root / 'train'}",
        )
        assert proc.returncode == 0, proc.stderr
        assert "trained" in proc.stdout

    root = made_once(tmp_path_factory, "posemap", make)
    return root / "dataset", root / "train"


@pytest.fixture(scope="session")
def plugin_installed() -> None:
    """The example plug-in package (examples/simlan_centroid_localizer), installed editable into
    this interpreter's environment (loudly): its ``centroid`` localizer is then a registered name."""
    example = REPO / "examples" / "simlan_centroid_localizer"
    cmd = [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "-e", str(example)]
    with installed_packages_held():  # (tests in other processes may need the installed plug-ins unchanged)
        done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"installing the example plug-in failed:\n{done.stdout}\n{done.stderr}"
    found = {ep.name: ep.value for ep in entry_points(group="simlan_data.algorithms")}
    assert found.get("centroid") == "simlan_centroid_localizer:CentroidLocalizer", found
    # the built-in registers as "localizer.aruco" (ROLE.NAME) or "aruco"
    assert any(v.endswith(":ArucoLocalizer") for v in found.values()), found
