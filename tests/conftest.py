"""Shared fixtures: real PyBullet clients, one short real run read back by several tests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from simlan_data.config.schema import register_configs
from simlan_data.constants import CONF_DIR

REPO = Path(__file__).resolve().parents[1]


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


def compose_config(*overrides: str):
    """Compose the Hydra config as the app does, without a process (DictConfig)."""
    register_configs(list(overrides))  # the schema and every algorithm, as the app does first
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose("config", overrides=list(overrides))


@pytest.fixture(scope="session")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One real run of the default scenario, 3 s, all 11 cameras at 960x540, depth and semantic
    every frame (so every stream is checked)."""
    run_dir = tmp_path_factory.mktemp("runs") / "default_short"
    proc = run_cli(
        "duration_s=3",
        f"hydra.run.dir={run_dir}",
        "progress=false",
        "recording.depth_rate_hz=5",
        "recording.semantic_rate_hz=5",
    )
    assert proc.returncode == 0, proc.stderr
    (run_dir.parent / "default_short.stdout").write_text(proc.stdout)  # (what the console showed)
    return run_dir


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
    """A 600-sample ray-occlusion dataset and a fusion model trained on it (seconds)."""
    root = tmp_path_factory.mktemp("posemap")
    ds = root / "dataset"
    proc = run_cli(*DATASET_ARGS, "posemap.samples=600", "posemap.occlusion=rays", f"hydra.run.dir={ds}")
    assert proc.returncode == 0, proc.stderr
    run = root / "train"
    proc = run_cli(
        "experiment=posemap_train",
        f"posemap.dataset={ds}",
        "posemap.epochs=40",
        "posemap.width=128",
        "posemap.layers=2",
        "posemap.dropout=0.0",
        "posemap.lr=0.003",
        f"hydra.run.dir={run}",
    )
    assert proc.returncode == 0, proc.stderr
    assert "trained" in proc.stdout
    return ds, run
