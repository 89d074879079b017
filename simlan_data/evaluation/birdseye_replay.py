"""Replay algorithm ``birdseye``: stitch a recording's camera frames, measure, report.

    python -m simlan_data.replay RECORDING --out DIR --algorithms birdseye [--set KEY=VALUE ...]

Options (``--set``): the canvas ``x_m=[-8,34]``, ``y_m=[-10,10]``, ``px_per_m=50``, ``plane_z_m=0``
(default: the recording's ``birdseye`` config section, else these); ``stitcher=NAME`` (a registered
name or module:Class; default: the recorded ``algorithms.stitcher``, for recordings made before it
the built-in ``gpss`` with their ``birdseye.feather_m``) and the stitcher's own config keys, e.g.
``feather_m=0.2`` of the built-in (default: the recorded values of the recorded stitcher);
``eval_frames=5`` (frames scored against ground truth, spread over the recording; 0 = none);
``ground_truth=true`` (build the recorded world in PyBullet for the orthographic ground truth);
``drop_cameras=[163]``, ``yaw_error_deg=1 yaw_error_cameras=[163]`` (injected faults, see
:mod:`~simlan_data.config.faults`; default: the recording's ``faults`` section).

Data flow::

    colour (+ semantic) messages, grouped by stamp --decode--> frames of all cameras
        --the stitcher (registry, guarded)--> canvas (timed: canvases/s)
        labelled frames (eval_frames of them) --+ SimlanBirdseye (baseline, same frames)
                                                +--QualityEvaluator vs orthographic ground truth
    --> birdseye.* metrics, DIR/birdseye_report.md, DIR/birdseye_report.png, DIR/birdseye_last.png
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import NDArray
from omegaconf import OmegaConf

from simlan_data.algorithms import registry
from simlan_data.algorithms.birdseye import CanvasSpec
from simlan_data.algorithms.birdseye_simlan import SimlanBirdseye
from simlan_data.algorithms.birdseye_stitcher import GpssStitcher
from simlan_data.algorithms.roles import StitcherContext
from simlan_data.config.faults import CAMERA_FAULT_OPTIONS
from simlan_data.config.legacy import with_algorithms
from simlan_data.config.schema import BirdseyeConfig, WorldConfig
from simlan_data.errors import ConfigError, RecordingInputError, SimlanError
from simlan_data.evaluation.birdseye_metrics import (
    FULL,
    CameraViews,
    QualityEvaluator,
    ground_control_points,
    stitcher_projections,
)
from simlan_data.evaluation.replay import ReplayContext, check_options, register
from simlan_data.imaging.image_files import write_image
from simlan_data.recording import schema
from simlan_data.recording.codecs import decode_compressed, decode_raw
from simlan_data.recording.reader import Message
from simlan_data.world.layout import load_layout

REPORT_MD = "birdseye_report.md"
REPORT_PNG = "birdseye_report.png"
LAST_PNG = "birdseye_last.png"
CANVAS_OPTIONS = ("x_m", "y_m", "px_per_m", "plane_z_m")
# replay options that are not the stitcher's config: the canvas, what to score, which stitcher, faults
OPTIONS = (*CANVAS_OPTIONS, "eval_frames", "ground_truth", "stitcher", *CAMERA_FAULT_OPTIONS)
_TOPIC = re.compile(r"^/camera_([^/]+)/(image_raw|semantic/image_raw)(/compressed)?$")


def _decode(m: Message) -> NDArray[np.uint8]:
    if m.msgtype.endswith("CompressedImage"):
        image = decode_compressed(m.msg.format, m.msg.data)
    else:
        image = decode_raw(m.msg.encoding, m.msg.height, m.msg.width, m.msg.step, m.msg.data)
    return np.asarray(image, dtype=np.uint8)


@dataclass(frozen=True)
class BirdseyeSettings:
    """What the replay stitches with and how it scores."""

    birdseye: BirdseyeConfig  # the canvas (and the recorded jpeg_quality)
    stitcher: registry.AlgorithmSpec
    stitcher_config: Any
    eval_frames: int
    ground_truth: bool


def selected_stitcher(
    config: dict[str, Any], options: dict[str, Any] | None = None
) -> tuple[registry.AlgorithmSpec, Any]:
    """The stitcher and its config: the recording's, or ``options["stitcher"]`` (a registered name
    or module:Class), with the options that are not the replay's own as its config values.

    Raises:
        ConfigError: an unknown name or option, a value its config rejects.
    """
    options = dict(options or {})
    config = with_algorithms(config)  # (an older recording: the built-in, its keys from the old place)
    name = options.get("stitcher")
    name = registry.selection(config, "stitcher")[0] if name is None else str(name)
    spec = registry.resolve("stitcher", name, where="replay --set")
    own = [f.name for f in dataclasses.fields(spec.config_class) if f.init]
    check_options(options, (*OPTIONS, *own), "birdseye", "replay --set", "e.g. --set px_per_m=25")
    overrides = {k: v for k, v in options.items() if k not in OPTIONS}
    try:
        return registry.from_config(config, "stitcher", name=name, overrides=overrides, where="replay --set")
    except ConfigError as err:
        if err.where != "config":
            raise
        raise ConfigError(err.what, "replay --set", err.why, err.fix) from None


def birdseye_settings(ctx: ReplayContext) -> BirdseyeSettings:
    """The canvas config (recording's section, then --set options), the stitcher and its config
    (see :func:`selected_stitcher`) and the evaluation options."""
    stitcher, stitcher_config = selected_stitcher(ctx.config, ctx.options)
    recorded = dict(ctx.config.get("birdseye") or {})
    merged = {**{k: v for k, v in recorded.items() if k in BirdseyeConfig.__dataclass_fields__}}
    merged.update({k: ctx.options[k] for k in CANVAS_OPTIONS if k in ctx.options})
    try:
        cfg = BirdseyeConfig(**{**merged, "rate_hz": 0.0})
        cfg.canvas(where="replay --set")
    except ConfigError as err:
        raise ConfigError(err.what, "replay --set", err.why, err.fix.replace("birdseye.", "--set ")) from None
    except TypeError as err:
        raise ConfigError(
            "invalid birdseye option", "replay --set", str(err), "give numbers, e.g. --set x_m=[-8,34]"
        ) from None
    eval_frames = ctx.options.get("eval_frames", 5)
    if not isinstance(eval_frames, int) or not 0 <= eval_frames <= 1000:
        raise ConfigError(
            f"invalid eval_frames={eval_frames!r}",
            "replay --set",
            "must be an integer within 0..1000",
            "use e.g. 5",
        )
    return BirdseyeSettings(
        cfg, stitcher, stitcher_config, eval_frames, bool(ctx.options.get("ground_truth", True))
    )


def _ground_truth(ctx: ReplayContext, spec: CanvasSpec) -> tuple[NDArray[np.uint8], NDArray[np.uint8], Any]:
    """Orthographic render of the recorded world (settled, no agents) and its layout."""
    from simlan_data.sim.orthographic import render_orthographic, static_world  # the simulator, only here

    world_dict = ctx.config.get("world")
    try:
        world_cfg = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(WorldConfig), world_dict or {}))
    except Exception as err:  # ConfigError from the schema's checks, OmegaConf's type errors
        raise RecordingInputError(
            "recorded world config unusable",
            str(ctx.reader.path),
            err.line()
            if isinstance(err, SimlanError)
            else f"{type(err).__name__}: {str(err).splitlines()[0]}",
            "replay with --set ground_truth=false",
        ) from err
    assert isinstance(world_cfg, WorldConfig)
    backend = (ctx.config.get("render") or {}).get("backend", "auto")
    drawn = ctx.reader.first(schema.RANDOMIZATION)  # randomize: the run's moved, tinted and added bodies
    sw = static_world(world_cfg, backend=backend, randomization=json.loads(drawn.msg.data) if drawn else None)
    try:
        rgb, labels = render_orthographic(sw.client, spec, sw.labels)
    finally:
        sw.close()
    return rgb, labels, load_layout(world_cfg.layout, world_cfg.fidelity)


def _image_topics(ctx: ReplayContext, cams: dict[str, Any]) -> tuple[dict[str, str], dict[str, str]]:
    """Find the colour and the semantic image topic of each camera: topic -> camera id."""
    colour: dict[str, str] = {}
    semantic: dict[str, str] = {}
    for topic in ctx.reader.topics:
        found = _TOPIC.match(topic)
        if found and found.group(1) in cams:
            (colour if found.group(2) == "image_raw" else semantic)[topic] = found.group(1)
    return colour, semantic


def _score(
    ctx: ReplayContext,
    spec: CanvasSpec,
    cameras: list[Any],
    views: Any,  # the stitcher (maybe a guarded plug-in) or its CameraViews: .coverage, the floor masks
    evaluated: list[tuple[list[NDArray[np.uint8]], list[NDArray[np.uint8]], NDArray[np.uint8]]],
    metrics: dict[str, float],
) -> tuple[dict[str, dict[str, float]], NDArray[np.uint8]]:
    """Score our canvases and SIMLAN's method against the orthographic ground truth; add to ``metrics``.

    ``views``: where each camera sees the canvas (floor masks, seam error, coverage). Returns the
    summary per method and the ground-truth image.
    """
    truth_rgb, truth_labels, layout = _ground_truth(ctx, spec)
    simlan = SimlanBirdseye(cameras, spec)
    evaluator = QualityEvaluator(spec, truth_rgb, truth_labels, ground_control_points(layout, spec))
    for frames, labels, canvas in evaluated:
        evaluator.begin_frame(stitcher_projections(views, labels, nearest=True))
        evaluator.add("ours", canvas, views.coverage, stitcher_projections(views, frames))
        per_cam = [(FULL, img, inside) for img, inside in zip(simlan.project_each(frames), simlan.inside)]
        evaluator.add("simlan", simlan.stitch(frames), simlan.coverage, per_cam)
    summary = evaluator.summary()
    metrics["birdseye.eval_frames"] = float(len(evaluated))
    metrics["birdseye.floor_fraction"] = float(np.mean(evaluator.floor_fraction))
    for key, value in summary["ours"].items():
        if key != "coverage":
            metrics[f"birdseye.{key}"] = value
    for key, value in summary["simlan"].items():
        metrics[f"birdseye.simlan.{key}"] = value
    metrics["birdseye.psnr_gain_db"] = summary["ours"]["psnr_grey_db"] - summary["simlan"]["psnr_grey_db"]
    return summary, truth_rgb


Evaluated = list[tuple[list[NDArray[np.uint8]], list[NDArray[np.uint8]], NDArray[np.uint8]]]


@dataclass
class _Stitched:
    """What one pass over the recording's frame sets gave."""

    seconds: float = 0.0
    canvases: int = 0
    last: NDArray[np.uint8] | None = None
    evaluated: Evaluated = field(default_factory=list)  # (frames, labels, canvas) to score


def _stitch_recording(
    ctx: ReplayContext,
    stitcher: Any,
    ids: list[str],
    colour: dict[str, str],
    semantic: dict[str, str],
    wanted: set[int],
) -> _Stitched:
    """Stitch every complete frame set in time order; keep the ``wanted`` labelled ones."""
    out = _Stitched()
    labelled_seen = 0
    group: dict[tuple[str, str], Message] = {}
    stamp: int | None = None

    def flush() -> None:
        nonlocal labelled_seen
        rgb = [group.get(("rgb", c)) for c in ids]
        if any(f is None for f in rgb):
            return
        frames = [_decode(f) for f in rgb if f is not None]
        t0 = time.perf_counter()
        out.last = stitcher.stitch(frames)
        out.seconds += time.perf_counter() - t0
        out.canvases += 1
        labels = [group.get(("sem", c)) for c in ids]
        if all(lab is not None for lab in labels):
            if labelled_seen in wanted:
                out.evaluated.append((frames, [_decode(lab) for lab in labels if lab is not None], out.last))
            labelled_seen += 1

    for msg in ctx.reader.messages([*colour, *semantic]):
        if msg.stamp_ns != stamp:
            flush()
            group, stamp = {}, msg.stamp_ns
        slot = ("rgb", colour[msg.topic]) if msg.topic in colour else ("sem", semantic[msg.topic])
        group[slot] = msg
    flush()
    return out


def _frames_to_score(
    ctx: ReplayContext, semantic: dict[str, str], ids: list[str], eval_frames: int
) -> set[int]:
    """Indices of the labelled frame sets to score: ``eval_frames`` spread evenly over them."""
    labelled_count = min((ctx.reader.topics[t].count for t in semantic), default=0)
    if len(semantic) < len(ids):
        labelled_count = 0
    return set(
        np.linspace(0, labelled_count - 1, min(eval_frames, labelled_count)).round().astype(int).tolist()
    )


@register("birdseye")
def birdseye(ctx: ReplayContext) -> dict[str, float]:
    """Stitch every frame of the recording, score some against ground truth, write a report."""
    settings = birdseye_settings(ctx)
    cfg, with_truth = settings.birdseye, settings.ground_truth
    spec = cfg.canvas(where="replay --set")
    cams = dict(sorted(ctx.believed_cameras.items(), key=lambda kv: (len(kv[0]), kv[0])))
    if not cams:
        raise RecordingInputError(
            "recording has no cameras", str(ctx.reader.path), "no camera_info topics", "record with cameras"
        )
    colour, semantic = _image_topics(ctx, cams)
    ids = [c for c in cams if c in colour.values()]
    cameras = [cams[c] for c in ids]
    algorithm = settings.stitcher
    stitcher = registry.Guarded(
        algorithm.build(settings.stitcher_config, StitcherContext(cameras, spec), where="replay"), algorithm
    )
    # where each camera sees the canvas: the stitcher's own tables if it has them (the built-in)
    own = callable(getattr(stitcher, "project_each", None)) and hasattr(stitcher, "coverage")
    views = stitcher if own else CameraViews(cameras, spec)
    wanted = _frames_to_score(ctx, semantic, ids, settings.eval_frames)
    done = _stitch_recording(ctx, stitcher, ids, colour, semantic, wanted)
    evaluated, last = done.evaluated, done.last

    metrics: dict[str, float] = {
        "birdseye.canvases": float(done.canvases),
        "birdseye.canvases_per_s": done.canvases / done.seconds if done.seconds > 0 else 0.0,
        "birdseye.coverage": float(views.coverage.mean()),
        "birdseye.cameras": float(len(cameras)),
    }
    if isinstance(getattr(stitcher, "seam_fraction", None), float):  # a blending stitcher's
        metrics["birdseye.seam_fraction"] = stitcher.seam_fraction
    summary: dict[str, dict[str, float]] = {}
    truth = None
    if with_truth and evaluated and spec.plane_z_m == 0.0:
        summary, truth = _score(ctx, spec, cameras, views, evaluated, metrics)
    shown = evaluated[-1][2] if evaluated else last
    write_report(
        ctx.out_dir,
        spec,
        settings,
        metrics,
        summary,
        last,
        shown,
        truth,
        evaluated[-1][0] if evaluated else None,
        cameras,
    )
    # metrics.json holds numbers only: NaN (no colour PSNR for a grey method) and inf (GCPs lost
    # beyond the search radius) stay in the report
    return {k: v for k, v in metrics.items() if math.isfinite(v)}


def _panel(image: NDArray[np.uint8], title: str, width: int) -> NDArray[np.uint8]:
    rgb = image if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    h = round(rgb.shape[0] * width / rgb.shape[1])
    small = np.ascontiguousarray(cv2.resize(rgb, (width, h), interpolation=cv2.INTER_AREA))
    cv2.putText(small, title, (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (255, 40, 40), 2, cv2.LINE_AA)
    return cast(NDArray[np.uint8], small)


def write_report(
    out_dir: Path,
    spec: CanvasSpec,
    settings: BirdseyeSettings,
    metrics: dict[str, float],
    summary: dict[str, dict[str, float]],
    last: NDArray[np.uint8] | None,
    shown: NDArray[np.uint8] | None,
    truth: NDArray[np.uint8] | None,
    frames: list[NDArray[np.uint8]] | None,
    cameras: list[Any],
) -> Path:
    """Markdown report with a PNG of ours, SIMLAN's method and the ground truth (one frame)."""
    algorithm = settings.stitcher
    values = ", ".join(f"{k}={v}" for k, v in dataclasses.asdict(settings.stitcher_config).items())
    ours = (
        "ours (distortion-aware, colour, best-view blend)"
        if algorithm.cls is GpssStitcher and getattr(settings.stitcher_config, "distort", True)
        else f"ours ({algorithm.name})"
    )
    seams = metrics.get("birdseye.seam_fraction")
    lines = [
        "# Bird's-eye view report",
        "",
        f"Canvas x {spec.x_m[0]:g}..{spec.x_m[1]:g} m, y {spec.y_m[0]:g}..{spec.y_m[1]:g} m at "
        f"{spec.px_per_m:g} px/m ({spec.width}x{spec.height}), plane z = {spec.plane_z_m:g} m, "
        f"stitcher {algorithm.name} ({values or 'no options'}); "
        f"{len(cameras)} cameras ({', '.join(c.camera_id for c in cameras)}).",
        "",
        f"Stitched {int(metrics['birdseye.canvases'])} canvases at {metrics['birdseye.canvases_per_s']:.1f} canvases/s "
        f"(stitching only, decoded frames in memory); coverage {100 * metrics['birdseye.coverage']:.1f} %"
        + (f", {100 * seams:.1f} % of it blended from two or more cameras." if seams is not None else "."),
        "",
    ]
    if last is not None:
        write_image(out_dir / LAST_PNG, cv2.cvtColor(last, cv2.COLOR_RGB2BGR))
        lines += [f"Last canvas at full resolution: `{LAST_PNG}`.", ""]
    if not summary and spec.plane_z_m != 0.0:
        lines += ["Quality is scored on the floor only (plane_z_m = 0); this canvas lies above it.", ""]
    if summary:
        o, s = summary["ours"], summary["simlan"]
        lines += [
            f"## Quality against the orthographic ground truth ({int(metrics['birdseye.eval_frames'])} frames)",
            "",
            "Floor pixels: ground truth and every covering camera see the floor "
            f"({100 * metrics['birdseye.floor_fraction']:.1f} % of the canvas). Ground control points: "
            "floor-slab joint crossings and floor-line ends, located by correlation within +-2 m.",
            "",
            f"| | {ours} | SIMLAN's method (pinhole, grey, mean of all cameras) |",
            "| --- | --- | --- |",
            f"| PSNR on floor pixels, grey (dB) | {o['psnr_grey_db']:.2f} | {s['psnr_grey_db']:.2f} |",
            f"| PSNR on floor pixels, colour (dB) | {o['psnr_db']:.2f} | - (grey only) |",
            f"| SSIM on floor pixels | {o['ssim']:.3f} | {s['ssim']:.3f} |",
            f"| GCP error, median (cm) | {o['gcp_median_cm']:.2f} | {s['gcp_median_cm']:.1f} |",
            f"| GCP error, median (px) | {o['gcp_median_px']:.2f} | {s['gcp_median_px']:.1f} |",
            f"| GCP error, 90th percentile (cm) | {o['gcp_p90_cm']:.2f} | {s['gcp_p90_cm']:.1f} |",
            f"| GCPs found / used | {int(o['gcp_found'])}/{int(o['gcp_count'])} | {int(s['gcp_found'])}/{int(s['gcp_count'])} |",
            f"| coverage | {100 * o['coverage']:.1f} % | {100 * s['coverage']:.1f} % |",
            f"| seam error: RMS grey difference between overlapping cameras | {o['seam_rms']:.1f} | {s['seam_rms']:.1f} |",
            "",
            "GCPs not found within the search radius count as that far off (inf in the medians if most are lost).",
            "",
        ]
    panels = []
    if shown is not None:
        panels.append(_panel(shown, "ours", 1050))
    if frames is not None and cameras:
        panels.append(_panel(SimlanBirdseye(cameras, spec).stitch(frames), "SIMLAN's method", 1050))
    if truth is not None:
        panels.append(_panel(truth, "ground truth (orthographic render)", 1050))
    if panels:
        write_image(out_dir / REPORT_PNG, cv2.cvtColor(np.vstack(panels), cv2.COLOR_RGB2BGR))
        lines += [f"![ours, SIMLAN's method, ground truth]({REPORT_PNG})", ""]
    lines += ["## Metrics", "", "| metric | value |", "| --- | --- |"]
    lines += [f"| `{k}` | {v:.6g} |" for k, v in sorted(metrics.items())]
    path = out_dir / REPORT_MD
    path.write_text("\n".join(lines) + "\n")
    return path
