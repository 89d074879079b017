"""Sweeps: every job writes its own run directory; one step aggregates all metrics.json (polars)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import polars as pl
import pytest
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from conftest import compose_config, run_cli
from simlan_data.apps.run import job_cpu_share
from simlan_data.config.validation import to_config
from simlan_data.errors import ConfigError
from simlan_data.evaluation.sweep import aggregate, collect_sweep, register_sweep_report


def _job(root: Path, name: str, overrides: list[str], metrics: dict[str, float] | None) -> None:
    job = root / name
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    if metrics is not None:
        (job / "metrics.json").write_text(json.dumps(metrics))


def test_collect_reads_overrides_and_metrics_and_flags_failed_jobs(tmp_path: Path) -> None:
    _job(tmp_path, "0", ["seed=1", "cameras=single"], {"sim.rtf": 2.0})
    _job(tmp_path, "1", ["seed=2", "cameras=single"], {"sim.rtf": 3.0, "extra.metric": 1.0})
    _job(tmp_path, "2", ["seed=3", "cameras=single"], None)
    _job(tmp_path, "10", ["seed=4", "+cameras.rate_hz=2.5"], {"sim.rtf": 5.0})
    (tmp_path / "not_a_job").mkdir()
    table = collect_sweep(tmp_path)
    assert table["job"].to_list() == ["0", "1", "2", "10"]  # numeric order, not "10" < "2"
    assert table["status"].to_list() == ["ok", "ok", "failed", "ok"]
    assert table["override.seed"].to_list() == [1, 2, 3, 4]
    assert table["override.cameras.rate_hz"].to_list() == [None, None, None, 2.5]
    assert table["sim.rtf"].to_list() == [2.0, 3.0, None, 5.0]
    assert table["extra.metric"].to_list() == [None, 1.0, None, None]


def test_aggregate_writes_tables_and_runs_the_named_report(tmp_path: Path) -> None:
    _job(tmp_path, "0", ["seed=1"], {"sim.rtf": 2.0})
    seen: list[int] = []

    @register_sweep_report("test_only")
    def _report(table: pl.DataFrame, sweep_dir: Path) -> None:
        seen.append(table.height)
        (sweep_dir / "report.txt").write_text("ok")

    aggregate(tmp_path, "test_only")
    assert seen == [1]
    assert pl.read_parquet(tmp_path / "sweep_metrics.parquet")["sim.rtf"].to_list() == [2.0]
    assert (tmp_path / "sweep_metrics.csv").read_text().startswith("job,")
    with pytest.raises(ConfigError, match="unknown sweep report 'nope'"):
        aggregate(tmp_path, "nope")


def test_collect_refuses_what_is_not_a_sweep(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not a sweep directory"):
        collect_sweep(tmp_path / "missing")
    with pytest.raises(ConfigError, match="no sweep jobs"):
        collect_sweep(tmp_path)


def test_two_job_sweep_through_the_cli_is_aggregated(tmp_path: Path) -> None:
    sweep = tmp_path / "sweep"
    proc = run_cli(
        "-m",
        "seed=0,1",
        "duration_s=0.4",
        "cameras=single",
        "cameras.width=320",
        "cameras.height=180",
        "world.fidelity=empty",
        "world.settle_s=0",
        "recording.depth_rate_hz=5",
        "recording.semantic_rate_hz=5",
        "progress=false",
        f"hydra.sweep.dir={sweep}",
    )
    assert proc.returncode == 0, proc.stderr
    table = pl.read_parquet(sweep / "sweep_metrics.parquet")
    assert table["override.seed"].to_list() == [0, 1]
    assert table["status"].to_list() == ["ok", "ok"]
    assert all(d > 0 for d in table["sim.camera_frames"].to_list())
    for job in ("0", "1"):
        assert (sweep / job / "recording" / "metadata.yaml").is_file()


def test_rtf_report_writes_the_table_beside_simlan_and_a_plot(tmp_path: Path) -> None:
    rtf = {("1", "rgb"): 9.5, ("1", "rgbds"): 7.25, ("12", "rgb"): 1.5, ("12", "rgbds"): 1.125}
    for n, ((count, streams), value) in enumerate(rtf.items()):
        metrics = {"sim.rtf": value, "sim.wall_s": 20.0 / value, "sim.camera_frames": 100.0}
        metrics |= {"sim.camera_frames_changed": 60.0, "sim.cpu_s": 30.0, "recording.bytes": 2.0**20}
        _job(tmp_path, str(n), [f"cameras.count={count}", f"streams={streams}"], metrics)
    _job(tmp_path, "4", ["cameras.count=4", "streams=rgb"], None)  # a failed job is left out
    aggregate(tmp_path, "rtf")
    table = (tmp_path / "rtf_table.md").read_text()
    header = table.splitlines()[0]
    assert "ours: RGB |" in header and "SIMLAN: image only" in header
    assert "SIMLAN: image + depth + semantic" in header
    assert "| 12 | 1.50 | 1.12 | 0.07 | 0.02 |" in table  # ours beside SIMLAN's published 12-camera RTF
    assert "| 4 | - | - | 0.34 | 0.09 |" in table
    assert "| 12 | rgbds | 1.12 | 17.8 | 60 / 100 | 30.00 | 1 |" in table
    image = cv2.imread(str(tmp_path / "rtf.png"))
    assert image is not None and image.shape[0] > 200 and image.shape[1] > 300


def test_stream_sets_and_camera_count_compose_into_the_typed_config() -> None:
    cfg = to_config(compose_config("experiment=rtf", "cameras.count=4", "streams=rgbds_full"))
    assert cfg.cameras.ids == [160, 161, 162, 163]
    assert cfg.cameras.streams == ["rgb", "depth", "semantic"]
    assert cfg.recording.depth_rate_hz == cfg.recording.semantic_rate_hz == cfg.cameras.rate_hz == 5.0
    assert cfg.localization.source == "ground_truth" and len(cfg.agents) == 4
    cfg = to_config(compose_config("streams=rgb"))
    assert cfg.cameras.streams == ["rgb"] and len(cfg.cameras.ids) == 11
    cfg = to_config(compose_config("streams=rgbds"))
    assert cfg.recording.depth_rate_hz == 1.0
    with pytest.raises(ConfigError, match=r"invalid cameras.count=12 .*must be within 0..11"):
        to_config(compose_config("cameras.count=12"))


def _hydra_cfg(mode: RunMode, launcher: dict) -> DictConfig:
    return OmegaConf.create({"mode": mode, "launcher": launcher})


def test_parallel_launchers_give_each_job_its_share_of_the_cores() -> None:
    joblib = "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher"
    ray = "hydra_plugins.hydra_ray_launcher.ray_launcher.RayLauncher"
    basic = "hydra._internal.core_plugins.basic_launcher.BasicLauncher"
    share = job_cpu_share
    assert share(_hydra_cfg(RunMode.MULTIRUN, {"_target_": joblib, "n_jobs": -1}), cpu_count=2) == 1
    assert share(_hydra_cfg(RunMode.MULTIRUN, {"_target_": joblib, "n_jobs": 2}), cpu_count=8) == 4
    assert share(_hydra_cfg(RunMode.MULTIRUN, {"_target_": joblib, "n_jobs": -2}), cpu_count=8) == 1
    assert share(_hydra_cfg(RunMode.MULTIRUN, {"_target_": ray, "ray": {"remote": {}}}), cpu_count=8) == 1
    assert share(_hydra_cfg(RunMode.MULTIRUN, {"_target_": ray, "ray": {"remote": {"num_cpus": 3}}})) == 3
    assert share(_hydra_cfg(RunMode.MULTIRUN, {"_target_": basic}), cpu_count=2) == 0
    assert share(_hydra_cfg(RunMode.RUN, {"_target_": joblib, "n_jobs": -1}), cpu_count=2) == 0


def test_a_job_with_one_core_runs_no_helper_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    """One core per job (joblib on two cores, a Ray task): encoding on the simulation thread and
    Mesa rasterizing inline, unless the user set either; more cores or the basic launcher: as is."""
    from simlan_data.apps.run import single_core_job

    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    cfg = compose_config()
    assert not single_core_job(cfg, 0, []) and not single_core_job(cfg, 2, [])
    assert cfg.recording.encode_threads == 2 and "LP_NUM_THREADS" not in os.environ
    assert single_core_job(cfg, 1, ["cameras.count=3"])
    assert cfg.recording.encode_threads == 0 and os.environ["LP_NUM_THREADS"] == "0"
    monkeypatch.delenv("LP_NUM_THREADS")
    cfg = compose_config("recording.encode_threads=3")
    single_core_job(cfg, 1, ["recording.encode_threads=3", "render.software_gl_threads=2"])
    assert cfg.recording.encode_threads == 3 and "LP_NUM_THREADS" not in os.environ


@pytest.mark.slow
def test_rtf_experiment_through_the_joblib_launcher(tmp_path: Path) -> None:
    """The issue's sweep, tiny: two jobs at a time on both cores, one OpenCV thread each, each
    job in its own run directory, one aggregation with the rtf report."""
    sweep = tmp_path / "sweep"
    proc = run_cli(
        "-m",
        "experiment=rtf",
        "hydra/launcher=joblib",
        "cameras.count=1,2",
        "streams=rgb",
        "duration_s=0.4",
        "cameras.width=320",
        "cameras.height=180",
        "world.fidelity=empty",
        "world.settle_s=0",
        f"hydra.sweep.dir={sweep}",
    )
    assert proc.returncode == 0, proc.stderr
    table = pl.read_parquet(sweep / "sweep_metrics.parquet")
    assert table["status"].to_list() == ["ok", "ok"]
    assert table["override.cameras.count"].to_list() == [1, 2]
    assert table["sim.cameras"].to_list() == [1.0, 2.0]
    assert (
        table["job.opencv_threads"].to_list()
        == [max(1, (os.cpu_count() or 1) // min(2, os.cpu_count() or 1))] * 2
    )
    # on two cores each job has one: no rasterizer or encoder threads of its own
    single = max(1, (os.cpu_count() or 1) // min(2, os.cpu_count() or 1)) == 1
    assert table["job.encode_threads"].to_list() == ([0.0] * 2 if single else [2.0] * 2)
    if single and "LP_NUM_THREADS" not in os.environ:
        assert table["job.gl_threads"].to_list() == [0.0, 0.0]
    assert (sweep / "rtf_table.md").is_file() and (sweep / "rtf.png").is_file()
    for job in ("0", "1"):
        assert (sweep / job / "recording" / "metadata.yaml").is_file()
        assert not (sweep / job / "RUNNING").exists()
