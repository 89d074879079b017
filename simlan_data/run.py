"""``python -m simlan_data.run``: simulate a scenario, record it, report it (a Hydra app).

    python -m simlan_data.run [GROUP=OPTION ...] [KEY=VALUE ...]      one run
    python -m simlan_data.run -m KEY=A,B ...                          a sweep

Run directory (``hydra.run.dir``): ``recording/`` (ROS 2 bag), ``metrics.json``, ``report.md``,
``.hydra/``; ``RUNNING`` exists while the run is in progress.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import Any

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from .cli import run_cli
from .config import Config, register_configs
from .constants import CONF_DIR, METRICS_FILENAME, RECORDING_DIRNAME, RUNNING_MARKER
from .errors import ConfigError, RunError, SimlanError
from .evaluation import safety_sweep  # noqa: F401 - registers the collision sweep report
from .evaluation.localization_replay import recording_metrics
from .evaluation.replay import ReplayContext
from .evaluation.report import write_report
from .evaluation.safety_metrics import recording_safety_metrics
from .recording.reader import RecordingReader
from .sim.scene import load_inputs
from .sim.simulation import RunStats, Simulation

log = logging.getLogger("simlan_data.run")

register_configs()


def to_config(cfg: DictConfig) -> Config:
    """Build the typed config; range and reference checks raise ConfigError."""
    try:
        obj = OmegaConf.to_object(cfg)
    except SimlanError:
        raise
    except Exception as err:
        cur: BaseException | None = err
        while cur is not None:
            if isinstance(cur, SimlanError):
                raise cur from None
            cur = cur.__cause__ or cur.__context__
        raise
    assert isinstance(obj, Config)
    return obj


def execute(cfg: Config, run_dir: Path, *, config_yaml: str, progress: bool = True) -> dict[str, float]:
    """Check inputs, simulate and record into ``run_dir``; returns the metrics.

    Raises:
        ConfigError: bad inputs (before anything is written).
        RunError: the run failed.
    """
    inputs = load_inputs(cfg)
    bag = run_dir / RECORDING_DIRNAME
    if bag.exists():
        raise ConfigError(
            "recording exists",
            str(bag),
            "simlan_data never overwrites a recording",
            "choose another hydra.run.dir",
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    marker = run_dir / RUNNING_MARKER
    marker.write_text("this run has not finished; if no process writes here any more, it crashed\n")
    sim = Simulation(cfg, inputs, config_yaml=config_yaml)
    bar = tqdm(
        total=round(cfg.duration_s, 3),
        unit="sim s",
        desc=cfg.scenario.name,
        disable=None if progress else True,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} sim s [{elapsed}<{remaining}]",
    )

    def on_progress(t_s: float) -> None:
        bar.update(round(t_s - bar.n, 6))

    try:
        stats = sim.run(bag, progress=on_progress)
    except SimlanError:
        raise
    except Exception as err:
        raise RunError(
            "simulation failed",
            str(run_dir),
            f"{type(err).__name__}: {err}",
            "rerun with --debug for the traceback",
        ) from err
    finally:
        bar.close()
    metrics = stats.metrics()
    if cfg.recording.enabled:
        with RecordingReader(bag) as reader:
            ctx = ReplayContext(reader, run_dir)
            metrics.update(recording_metrics(reader, ctx.config, ctx.cameras))
            metrics.update(recording_safety_metrics(reader, ctx.config, ctx.cameras))
            (run_dir / METRICS_FILENAME).write_text(json.dumps(metrics, indent=2, sort_keys=True) + "\n")
            write_report(run_dir, cfg, stats, metrics, reader)
    else:
        (run_dir / METRICS_FILENAME).write_text(json.dumps(metrics, indent=2, sort_keys=True) + "\n")
    marker.unlink()
    print_summary(cfg, stats, metrics, run_dir)
    return metrics


def print_summary(cfg: Config, stats: RunStats, metrics: dict[str, float], run_dir: Path) -> None:
    bag = run_dir / RECORDING_DIRNAME
    mib = stats.recording_bytes / 2**20
    streams = "+".join(cfg.cameras.streams)
    lines = [
        f"simlan_data: scenario '{cfg.scenario.name}' finished",
        f"  run directory  {run_dir}",
        f"  recording      {bag}  ({mib:.1f} MiB, {int(metrics['recording.messages'])} messages, {len(stats.message_counts)} topics)"
        if cfg.recording.enabled
        else "  recording      off (recording.enabled=false)",
        f"  simulated      {metrics['sim.duration_s']:.1f} s in {metrics['sim.wall_s']:.1f} s wall: real-time factor {metrics['sim.rtf']:.2f}",
        f"  cameras        {len(cfg.cameras.ids)} x {cfg.cameras.rate_hz:g} Hz {cfg.cameras.width}x{cfg.cameras.height} {streams}, {int(stats.camera_frames)} frames ({stats.renderer} renderer, {'layered' if cfg.render.layered else 'full'})",
    ]
    for ns in sorted(stats.collisions):
        nav = ""
        if f"navigation.{ns}.goals_total" in metrics:
            nav = f"{int(metrics[f'navigation.{ns}.goals_reached'])}/{int(metrics[f'navigation.{ns}.goals_total'])} goals, "
        loc = ""
        if f"localization.{ns}.ate_xy_rmse_m" in metrics:
            loc = f", ATE {metrics[f'localization.{ns}.ate_xy_rmse_m'] * 100:.1f} cm, availability {metrics[f'localization.{ns}.availability']:.3f}"
        lines.append(
            f"  {ns:<14} {nav}{stats.collisions[ns]} collisions, {stats.distance_m.get(ns, 0.0):.1f} m driven{loc}"
        )
    if stats.calibration_issues:
        lines.append(
            f"  note           {len(stats.calibration_issues)} calibration fields disagree with K, R, t (listed in report.md)"
        )
    lines.append(f"  next           python -m simlan_data.replay {bag} --info")
    print("\n".join(lines), flush=True)


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def _app(cfg: DictConfig) -> Any:
    typed = to_config(cfg)
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    config_yaml = OmegaConf.to_yaml(cfg, resolve=True)
    metrics = execute(typed, run_dir, config_yaml=config_yaml, progress=typed.progress)
    return metrics.get("sim.rtf")


def main() -> None:
    run_cli(_app)


if __name__ == "__main__":
    sys.exit(main())
