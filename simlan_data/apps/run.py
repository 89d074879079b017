"""``python -m simlan_data.run``: simulate a scenario, record it, report it (a Hydra app).

    python -m simlan_data.run [GROUP=OPTION ...] [KEY=VALUE ...]      one run
    python -m simlan_data.run -m KEY=A,B ...                          a sweep

Run directory (``hydra.run.dir``): ``recording/`` (ROS 2 bag), ``metrics.json``, ``report.md``,
``.hydra/``; ``RUNNING`` exists while the run is in progress (pid, host, simulated time reached);
after a crash, ``python -m simlan_data.recover RUN_DIR`` repairs the recording.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from simlan_data.apps import run_dir as run_dirs
from simlan_data.apps import signals
from simlan_data.apps.cli import run_cli
from simlan_data.apps.help import print_help, wants_fast_help
from simlan_data.config.schema import Config, register_configs
from simlan_data.config.validation import to_config
from simlan_data.constants import CONF_DIR, METRICS_FILENAME, RECORDING_DIRNAME, RUNNING_MARKER
from simlan_data.errors import ConfigError, PluginError, RunError, SimlanError
from simlan_data.metrics_io import write_metrics
from simlan_data.recording.run_marker import RunMarker, write_running

if TYPE_CHECKING:
    from simlan_data.sim.simulation import RunStats
    from simlan_data.viz.foxglove_live import LiveView

# The simulator, the recorder's reader, OpenCV and the evaluation are imported where a run needs
# them, not here: `--help` and a config error then answer without loading them (issue 22).

# Messages go through logging: Hydra's job logging writes them to the console (as plain lines) and
# to the run's `run.log`; DEBUG records (start, progress, timings) to `run.log` only (conf/config.yaml).
log = logging.getLogger(__name__)
PROGRESS_LOG_STEP = 0.1  # run.log gets a progress line every tenth of the simulated time


def execute(
    cfg: Config,
    run_dir: Path,
    *,
    config_yaml: str,
    progress: bool = True,
    stop: Callable[[], bool] | None = None,
) -> dict[str, float]:
    """Check inputs, simulate and record into ``run_dir``; returns the metrics.

    ``stop()`` ends the simulation early at a step boundary (a signal): the recording, the
    metrics and the report of what ran are still written (``run.stopped_early`` in the metrics).

    Raises:
        ConfigError: bad inputs (before anything is written).
        RunError: the run failed.
    """
    from tqdm import tqdm

    from simlan_data.sim.scene import load_inputs
    from simlan_data.sim.simulation import Simulation

    inputs = load_inputs(cfg)
    bag = run_dir / RECORDING_DIRNAME
    if bag.exists():
        raise ConfigError(
            "recording exists",
            str(bag),
            "simlan_data never overwrites a recording",
            "choose another hydra.run.dir",
        )
    live = start_live_view(cfg, run_dir)  # (a taken port is refused here, before anything is written)
    run_dir.mkdir(parents=True, exist_ok=True)
    marker = run_dir / RUNNING_MARKER
    running = RunMarker.for_this_process(cfg.duration_s)
    write_running(run_dir, running)
    sim = Simulation(cfg, inputs, config_yaml=config_yaml)
    log.debug(
        "scenario '%s' starting: %g s simulated, cameras %s (%dx%d at %g Hz), agents %s, seed %d, run directory %s",
        cfg.scenario.name,
        cfg.duration_s,
        ", ".join(str(c) for c in cfg.cameras.ids),
        cfg.cameras.width,
        cfg.cameras.height,
        cfg.cameras.rate_hz,
        ", ".join(sorted(cfg.agents)),
        cfg.seed,
        run_dir,
    )
    logged = [0.0]  # simulated seconds of the last progress line in run.log
    wall0 = time.monotonic()
    bar = tqdm(
        total=round(cfg.duration_s, 3),
        unit="sim s",
        desc=cfg.scenario.name,
        disable=None if progress else True,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} sim s [{elapsed}<{remaining}]",
    )

    def on_progress(t_s: float) -> None:
        if live is not None:
            live.pace(t_s)
        bar.update(round(t_s - bar.n, 6))
        if t_s - logged[0] >= PROGRESS_LOG_STEP * cfg.duration_s - 1e-9 or t_s >= cfg.duration_s:
            logged[0] = t_s
            log.debug("simulated %.1f of %g s in %.1f s wall", t_s, cfg.duration_s, time.monotonic() - wall0)
        # how far the clock got: after a crash, recovery compares it with what the file holds
        write_running(run_dir, replace(running, simulated_s=round(t_s, 9)))

    def recover_hint() -> str:
        return f"`python -m simlan_data.recover {run_dir}` reads what was recorded" if bag.exists() else ""

    try:
        stats = sim.run(bag, progress=on_progress, stop=stop, listeners=[live.on_message] if live else [])
    except PluginError as err:  # the recording was finished: no recovery needed
        marker.unlink(missing_ok=True)
        kept = f"the recording up to then is kept in {bag}" if bag.exists() else ""
        raise RunError(err.what, err.where, err.why, "; ".join(x for x in (err.fix, kept) if x)) from err
    except SimlanError as err:
        if not bag.exists():  # refused before recording anything (a spawn pose in a shelf...)
            marker.unlink(missing_ok=True)
        if isinstance(err, ConfigError) or not recover_hint():
            raise
        raise RunError(
            err.what, err.where, err.why, "; ".join(x for x in (err.fix, recover_hint()) if x)
        ) from err
    except Exception as err:
        hint = recover_hint()
        raise RunError(
            "simulation failed",
            str(run_dir),
            f"{type(err).__name__}: {err}",
            "rerun with --debug for the traceback" + (f"; {hint}" if hint else ""),
        ) from err
    finally:
        bar.close()
        if live is not None:
            live.close()
    metrics = stats.metrics()
    import cv2

    metrics["job.opencv_threads"] = float(cv2.getNumThreads())
    metrics["job.encode_threads"] = float(cfg.recording.encode_threads)
    metrics["job.gl_threads"] = float(os.environ.get("LP_NUM_THREADS", "-1") or -1)  # -1: Mesa's default
    metrics["run.stopped_early"] = float(stats.stopped_early)
    marker.unlink()  # the recording is finished: a failure from here on (a full disk) needs no recovery
    if cfg.recording.enabled:
        from simlan_data.evaluation.localization_replay import recording_metrics
        from simlan_data.evaluation.replay import ReplayContext
        from simlan_data.evaluation.report import write_report
        from simlan_data.evaluation.safety_metrics import recording_safety_metrics
        from simlan_data.recording.reader import RecordingReader

        with RecordingReader(bag) as reader:
            ctx = ReplayContext(reader, run_dir)
            metrics.update(recording_metrics(reader, ctx.config, ctx.cameras))
            metrics.update(recording_safety_metrics(reader, ctx.config, ctx.cameras))
            write_metrics(run_dir / METRICS_FILENAME, metrics)
            write_report(
                run_dir,
                cfg,
                stats,
                metrics,
                reader,
                config=ctx.config,
                cameras=ctx.cameras,
                floor=inputs.grid,
            )
    else:
        write_metrics(run_dir / METRICS_FILENAME, metrics)
    if not stats.stopped_early:  # (an interrupted run says so in its one error line)
        log_summary(cfg, stats, metrics, run_dir)
    return metrics


def start_live_view(cfg: Config, run_dir: Path) -> LiveView | None:
    """``live.foxglove=true``: start the Foxglove WebSocket server and say where it is, and
    where the layout for this run's cameras and agents will be (after a simulated second)."""
    if not cfg.live.foxglove:
        return None
    from simlan_data.viz.foxglove_layout import LAYOUT_FILENAME
    from simlan_data.viz.foxglove_live import LiveView

    layout = run_dir / LAYOUT_FILENAME
    live = LiveView(cfg.live, name=cfg.scenario.name, layout_path=layout)
    log.info(
        "simlan_data: live view on %s (Foxglove: Open connection > Foxglove WebSocket; layout: Import from file %s)",
        live.url,
        layout,
    )
    return live


def log_summary(cfg: Config, stats: RunStats, metrics: dict[str, float], run_dir: Path) -> None:
    """The run's summary (console and run.log): where its files are, what it measured, notes."""
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
    if cfg.sensors.active:  # realistic cameras (docs/sensors.md): what the camera stage did
        on = [g for g in ("photometric", "timing", "drift", "shutter") if getattr(cfg.sensors, g).enabled]
        lines.append(
            f"  sensors        {cfg.sensors.name}: {', '.join(on)}; {int(stats.camera_frames_dropped)} frames lost,"
            f" {int(stats.camera_subframes)} renders per camera for {int(stats.camera_frames) // max(1, len(cfg.cameras.ids))} ticks"
            " (per-frame truth on /camera_<id>/effects)"
        )
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
    from simlan_data.evaluation.run_notes import run_notes

    notes = run_notes(
        metrics,
        stats.collisions,
        calibration_issues=len(stats.calibration_issues),
        user_calibration=bool(cfg.cameras.calibration_dir),
    )
    lines += [f"  note           {n.text}" for n in notes if n.in_summary]  # (report.md has them all)
    lines.append(f"  next           python -m simlan_data.replay {bag} --info")
    log.info("\n".join(lines))


def job_cpu_share(hydra_cfg: Any, cpu_count: int | None = None) -> int:
    """Cores one job may use when a parallel launcher runs several at once (0: no limit).

    joblib runs ``n_jobs`` jobs at a time on this machine (-1: one per core); Ray gives every
    job ``hydra.launcher.ray.remote.num_cpus`` cores (1 unless set).
    """
    cores = cpu_count or os.cpu_count() or 1
    if hydra_cfg.mode != RunMode.MULTIRUN:
        return 0
    launcher = hydra_cfg.launcher
    target = str(launcher.get("_target_", ""))
    if "joblib" in target:
        n_jobs = int(launcher.get("n_jobs") or -1)
        parallel = n_jobs if n_jobs > 0 else max(1, cores + 1 + n_jobs)
        return max(1, cores // min(parallel, cores))
    if "ray" in target:
        remote = OmegaConf.select(launcher, "ray.remote") or {}
        return max(1, int(remote.get("num_cpus", 1) or 1))
    return 0


def limit_threads(cores: int) -> None:
    """Keep one job's thread pools to its share of the cores (parallel jobs must not oversubscribe).

    OpenCV's pool (remap, marker detection) spins while it waits: on shared cores that burns the
    other job's time. numpy's BLAS is limited by the launchers (joblib's loky, Ray's
    OMP_NUM_THREADS). A job with one core of its own (see :func:`single_core_job`) also runs
    Mesa's rasterizer and the image encoding on its own thread.
    """
    if cores > 0:
        import cv2

        cv2.setNumThreads(cores)


def single_core_job(cfg: DictConfig, cores: int, overrides: list[str]) -> bool:
    """A job that a parallel launcher gives one core: no helper threads of its own.

    Alone, a run spreads over both cores (Mesa's rasterizer thread, the encoder threads: 1.1 to
    1.3 cores); with every core already running a job, those threads only take turns with the
    other jobs and add their hand-overs (measured: the joblib sweep 6 % faster, 5 % less CPU).
    So Mesa rasterizes on the calling thread (``LP_NUM_THREADS=0``) and the recorder encodes on
    the simulation thread (``recording.encode_threads=0``), unless the user set either.
    """
    if cores != 1:
        return False
    keys = {o.split("=", 1)[0].lstrip("+~") for o in overrides}
    if "render.software_gl_threads" not in keys:
        os.environ.setdefault("LP_NUM_THREADS", "0")
    if "recording.encode_threads" not in keys:
        cfg.recording.encode_threads = 0
    return True


def execute_posemap(cfg: Config, run_dir: Path, *, config_yaml: str) -> float:
    """The pose-mapping tasks (``posemap.task``): a dataset, or a trained model; returns the
    sweep objective (the validation MAE of a training run, the samples/s of a dataset)."""
    task = cfg.posemap.task
    out = run_dir / ("dataset.parquet" if task == "dataset" else "model")
    if out.exists():
        raise ConfigError(
            f"{'dataset' if task == 'dataset' else 'model'} exists",
            str(out),
            "simlan_data never overwrites one",
            "choose another hydra.run.dir",
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    if task == "dataset":
        from simlan_data.sim.posemap_dataset import generate_dataset

        metrics = generate_dataset(cfg, run_dir, progress=cfg.progress)
        return metrics["posemap.dataset.samples_per_s"]
    from simlan_data.algorithms.posemap.training import train_from_config
    from simlan_data.sim.posemap_drive import trained_mapper_params

    fit = trained_mapper_params(cfg)  # the built-in mapper's refine and fit parameters
    metrics = train_from_config(cfg.posemap, fit, run_dir, seed=cfg.seed, config_yaml=config_yaml)
    return metrics["posemap.val.mae_rad"]


_STARTED: list[bool] = []  # set once Hydra has composed the config and called _app


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def _app(cfg: DictConfig) -> Any:
    _STARTED.append(True)
    hydra_cfg = HydraConfig.get()
    run_dir = Path(hydra_cfg.runtime.output_dir)
    cores = job_cpu_share(hydra_cfg)
    limit_threads(cores)
    single_core_job(cfg, cores, list(hydra_cfg.overrides.task))  # (before checking: it sets a field)
    lock: run_dirs.RunDirLock | None = None
    try:
        typed = to_config(cfg)
        lock = run_dirs.claim(run_dir)  # held until the process ends
        if typed.posemap.task == "none":  # names this process to a second run into the directory
            write_running(run_dir, RunMarker.for_this_process(typed.duration_s))
        run_dirs.write_provenance(run_dir, cfg, hydra_cfg, list(hydra_cfg.overrides.task))
        config_yaml = OmegaConf.to_yaml(cfg, resolve=True)
        if typed.posemap.task != "none":
            return execute_posemap(typed, run_dir, config_yaml=config_yaml)
        return run_until_signal(typed, run_dir, config_yaml)
    except run_dirs.RunDirTakenError:
        raise  # another run's directory: not ours to clean
    except ConfigError:
        if not (run_dir / RECORDING_DIRNAME).exists():
            run_dirs.clear_refused(run_dir, lock)  # bad input writes nothing
        raise


def run_until_signal(cfg: Config, run_dir: Path, config_yaml: str) -> float | None:
    """``execute``, stopped early by SIGTERM or SIGINT (``apps.signals``): what ran is
    finalized and reported, the run directory is marked ``INTERRUPTED``, exit 128 + signal."""
    second = signals.say_stopped_at_once(
        f"{{signal}} again during the shutdown: stopped at once; `python -m simlan_data.recover {run_dir}` "
        "reads what was recorded"
    )
    with signals.graceful_stop(on_second=second) as stop:
        wall0 = time.monotonic()
        metrics = execute(cfg, run_dir, config_yaml=config_yaml, progress=cfg.progress, stop=stop)
        if metrics.get("run.stopped_early") and stop.signum is not None:
            reached = metrics.get("sim.duration_s", 0.0)
            run_dirs.mark_interrupted(run_dir, stop.name, reached, cfg.duration_s, time.monotonic() - wall0)
            raise signals.RunInterruptedError(
                stop.signum,
                f"interrupted by {stop.name}",
                str(run_dir),
                f"stopped at {reached:.2f} s of {cfg.duration_s:g} s simulated; the recording, "
                "metrics.json and report.md of what ran are written",
                f"replay it with `python -m simlan_data.replay {run_dir / RECORDING_DIRNAME}`",
            )
    return metrics.get("sim.rtf")


def _registered_app() -> Any:
    if wants_fast_help(sys.argv[1:]):  # Hydra's own --help takes 2 s to list the groups
        return print_help(sys.argv[1:])
    register_configs()  # the schema and every algorithm (plug-ins load here: their errors are one line)
    return _app()


def main() -> None:
    """The command line: the Hydra app, errors turned into one line and an exit code."""
    signals.exit_on_early_signal()  # (simlan-run: the -m shims installed it already)
    run_cli(_registered_app, started=lambda: bool(_STARTED))


cli = main


if __name__ == "__main__":
    main()
