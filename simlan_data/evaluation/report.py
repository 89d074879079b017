"""Write a run's ``report.md``: what ran, what it measured, what the recording holds."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from simlan_data.constants import NS_PER_S, REPORT_FILENAME
from simlan_data.imaging.image_files import write_image
from simlan_data.recording.codecs import decode_compressed, decode_raw
from simlan_data.recording.reader import RecordingReader

if TYPE_CHECKING:
    from simlan_data.config.schema import Config
    from simlan_data.sim.simulation import RunStats

MOSAIC_FILENAME = "report_cameras.png"


COLOUR_TOPIC = re.compile(r"^/camera_[^/]+/image_raw(/compressed)?$")


def last_images(reader: RecordingReader) -> dict[str, np.ndarray]:
    """The last colour image of every camera (decoded), by camera name."""
    topics = [t for t in reader.topics if COLOUR_TOPIC.match(t)]
    if not topics:
        return {}
    start = max(reader.start_ns, reader.end_ns - NS_PER_S)
    out: dict[str, np.ndarray] = {}
    for m in reader.messages(topics, start_ns=start):
        name = m.topic.split("/")[1]
        if m.msgtype.endswith("CompressedImage"):
            out[name] = decode_compressed(m.msg.format, m.msg.data)
        else:
            out[name] = decode_raw(m.msg.encoding, m.msg.height, m.msg.width, m.msg.step, m.msg.data)
    return dict(sorted(out.items()))


def camera_mosaic(
    images: dict[str, np.ndarray], *, columns: int = 4, tile_width: int = 480
) -> np.ndarray | None:
    """Tile labelled camera images into one RGB image."""
    if not images:
        return None
    tiles = []
    for name, img in images.items():
        h, w = img.shape[:2]
        tile = cv2.resize(img, (tile_width, round(h * tile_width / w)), interpolation=cv2.INTER_AREA)
        tile = np.ascontiguousarray(tile)
        cv2.putText(tile, name, (8, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 40, 40), 2, cv2.LINE_AA)
        tiles.append(tile)
    th = max(t.shape[0] for t in tiles)
    blank = np.zeros((th, tile_width, 3), dtype=np.uint8)
    tiles += [blank] * ((-len(tiles)) % columns)
    rows = [np.hstack(tiles[i : i + columns]) for i in range(0, len(tiles), columns)]
    return np.vstack(rows)


def write_report(
    run_dir: Path, cfg: Config, stats: RunStats, metrics: dict[str, float], reader: RecordingReader
) -> Path:
    mosaic = camera_mosaic(last_images(reader))
    if mosaic is not None:
        write_image(run_dir / MOSAIC_FILENAME, cv2.cvtColor(mosaic, cv2.COLOR_RGB2BGR))  # OSError if not
    lines = [
        f"# Run report: {cfg.scenario.name}",
        "",
        cfg.scenario.description or "",
        "",
        *(
            [
                f"**Stopped early** at {metrics['sim.duration_s']:.2f} s of {cfg.duration_s:g} s simulated "
                "(a signal: see `INTERRUPTED`); everything below is what ran.",
                "",
            ]
            if metrics.get("run.stopped_early")
            else []
        ),
        "| | |",
        "| --- | --- |",
        f"| seed | {cfg.seed} |",
        f"| simulated | {metrics['sim.duration_s']:.2f} s |",
        f"| wall clock | {metrics['sim.wall_s']:.2f} s |",
        f"| real-time factor | {metrics['sim.rtf']:.2f} |",
        f"| cameras | {', '.join(str(c) for c in cfg.cameras.ids)} at {cfg.cameras.rate_hz:g} Hz, {cfg.cameras.width}x{cfg.cameras.height}, {'+'.join(cfg.cameras.streams)}, distortion {'on' if cfg.cameras.distortion else 'off'} |",
        f"| renderer | {stats.renderer} ({'layered' if cfg.render.layered else 'full'}) |",
        f"| world | {cfg.world.layout}, fidelity {cfg.world.fidelity}, physics {cfg.world.physics_hz} Hz |",
        f"| recording | `recording/` ({stats.recording_bytes / 2**20:.1f} MiB, {reader.message_count} messages) |",
        "",
        "## Agents",
        "",
        "| namespace | type | goals reached | collisions | distance (m) | ATE xy RMSE (m) | yaw RMSE (deg) | availability |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]

    def fmt(key: str, spec: str = ".3f") -> str:
        value = metrics.get(key)
        return "-" if value is None else format(value, spec)

    for ns in sorted(stats.collisions):
        goals = f"{fmt(f'navigation.{ns}.goals_reached', '.0f')}/{fmt(f'navigation.{ns}.goals_total', '.0f')}"
        lines.append(
            f"| {ns} | {cfg.agents[ns].type} | {goals} | {stats.collisions[ns]} | {stats.distance_m.get(ns, 0.0):.2f} | "
            f"{fmt(f'localization.{ns}.ate_xy_rmse_m', '.4f')} | {fmt(f'localization.{ns}.yaw_rmse_deg')} | {fmt(f'localization.{ns}.availability')} |"
        )
    lines += ["", "## Metrics", "", "| metric | value |", "| --- | --- |"]
    lines += [f"| `{k}` | {v:.6g} |" for k, v in sorted(metrics.items())]
    lines += ["", "## Recording", "", "```", reader.summary(), "```", ""]
    if mosaic is not None:
        lines += ["## Cameras (last frame)", "", f"![cameras]({MOSAIC_FILENAME})", ""]
    if stats.calibration_issues:
        lines += ["## Calibration notes", "", "Fields that disagree with K, R, t (K, R, t are used):", ""]
        lines += [f"- {issue}" for issue in stats.calibration_issues]
        lines.append("")
    if stats.layout_notes:
        lines += ["## Layout notes", "", "Where SIMLAN's layout and this twin's geometry disagree:", ""]
        lines += [f"- {note}" for note in stats.layout_notes]
        lines.append("")
    path = run_dir / REPORT_FILENAME
    path.write_text("\n".join(lines))
    return path
