"""Bird's-eye view end to end: the live topic, its replay (bit for bit), the quality report,
the orthographic ground truth, and bad replay options."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from simlan_data.algorithms.birdseye import CanvasSpec
from simlan_data.algorithms.roles import StitcherContext
from simlan_data.config.schema import WorldConfig
from simlan_data.errors import ConfigError, RecordingInputError
from simlan_data.evaluation.birdseye_metrics import GCP_HALF_PX, ground_control_points, locate_gcps
from simlan_data.evaluation.birdseye_replay import birdseye, birdseye_settings
from simlan_data.evaluation.replay import ReplayContext
from simlan_data.recording import schema
from simlan_data.recording.codecs import decode_compressed, encode_rgb
from simlan_data.recording.reader import RecordingReader
from simlan_data.sim.orthographic import render_orthographic, static_world
from simlan_data.world.layout import load_layout


@pytest.fixture(scope="module")
def birdseye_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """0.4 s, cameras 163 and 164, the light world, lossless colour, bird's-eye view at 5 Hz."""
    run_dir = tmp_path_factory.mktemp("birdseye") / "run"
    proc = run_cli(
        "duration_s=0.4",
        "cameras.ids=[163,164]",
        "world.fidelity=light",
        "birdseye.rate_hz=5",
        "recording.rgb_encoding=png",
        "recording.semantic_rate_hz=5",
        "recording.depth_rate_hz=1",
        f"hydra.run.dir={run_dir}",
        "progress=false",
    )
    assert proc.returncode == 0, proc.stderr
    return run_dir


def test_live_topic_is_reproduced_bit_for_bit_by_replay(birdseye_run: Path) -> None:
    with RecordingReader(birdseye_run) as reader:
        ctx = ReplayContext(reader, birdseye_run)
        live = list(reader.messages([schema.BIRDSEYE_IMAGE]))
        assert len(live) == 3  # t = 0, 0.2, 0.4 s
        assert live[0].msg.header.frame_id == schema.MAP_FRAME
        settings = birdseye_settings(ctx)
        cfg = settings.birdseye
        cams = [ctx.cameras[c] for c in ("163", "164")]
        stitcher = settings.stitcher.build(settings.stitcher_config, StitcherContext(cams, cfg.canvas()))
        frames: dict[int, dict[str, np.ndarray]] = {}
        topics = [f"/camera_{c}/image_raw/compressed" for c in ("163", "164")]
        for m in reader.messages(topics):
            frames.setdefault(m.stamp_ns, {})[m.topic] = decode_compressed(m.msg.format, m.msg.data)
        for m in live:
            canvas = stitcher.stitch([frames[m.stamp_ns][t] for t in topics])
            assert canvas.shape == (1000, 2100, 3)
            _, data = encode_rgb(canvas, "jpeg", jpeg_quality=cfg.jpeg_quality)
            assert bytes(m.msg.data) == data


def test_replay_writes_metrics_and_report(birdseye_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "replay"
    proc = run_cli(
        str(birdseye_run), "--out", str(out), "--algorithms", "birdseye", "--set", "eval_frames=1",
        module="simlan_data.replay",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["birdseye.canvases"] == 3 and metrics["birdseye.eval_frames"] == 1
    assert (
        metrics["birdseye.gcp_count"] >= 5 and metrics["birdseye.gcp_found"] == metrics["birdseye.gcp_count"]
    )
    assert metrics["birdseye.gcp_median_cm"] < 2.0
    assert metrics["birdseye.psnr_db"] > 25 and metrics["birdseye.psnr_gain_db"] > 6
    assert 0 < metrics["birdseye.ssim"] <= 1 and metrics["birdseye.simlan.ssim"] < metrics["birdseye.ssim"]
    report = (out / "birdseye_report.md").read_text()
    assert "PSNR on floor pixels" in report and "birdseye_report.png" in report
    assert (out / "birdseye_report.png").stat().st_size > 10_000
    assert (out / "birdseye_last.png").is_file()


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        (["--set", "px_per_m=0"], "invalid birdseye.px_per_m=0.0 in replay --set: must be within"),
        (["--set", "x_m=[3,3]"], "invalid birdseye.x_m=[3.0, 3.0] in replay --set: empty region"),
        (["--set", "colour=false"], "unknown birdseye option 'colour' in replay --set"),
    ],
)
def test_bad_replay_options_give_one_line_and_exit_2(
    birdseye_run: Path, tmp_path: Path, options: list[str], expected: str
) -> None:
    proc = run_cli(
        str(birdseye_run), "--out", str(tmp_path / "o"), "--algorithms", "birdseye", *options,
        module="simlan_data.replay",
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert expected in lines[0]


def test_replay_option_errors(birdseye_run: Path) -> None:
    with RecordingReader(birdseye_run) as reader:
        for options, match in [
            ({"eval_frames": -1}, r"invalid eval_frames=-1 in replay --set"),
            ({"colour": False}, r"unknown birdseye option 'colour' in replay --set: known: x_m, y_m"),
            ({"x_m": "abc"}, r"invalid birdseye.x_m='abc' in replay --set: expected \[min, max\]"),
            ({"px_per_m": [1, 2]}, r"invalid birdseye.px_per_m=\[1, 2\] in replay --set: expected a number"),
            ({"feather_m": 0}, r"invalid algorithms.stitcher.feather_m=0 in replay --set: must be within"),
            (
                {"feather_m": "wide"},
                r"invalid algorithms.stitcher.feather_m='wide' in replay --set: expected a number",
            ),
        ]:
            with pytest.raises(ConfigError, match=match):
                birdseye_settings(ReplayContext(reader, birdseye_run, options))
        ctx = ReplayContext(reader, birdseye_run, {"eval_frames": 1})
        ctx.__dict__["cameras"] = {}
        with pytest.raises(RecordingInputError, match="recording has no cameras"):
            birdseye(ctx)
        ctx = ReplayContext(reader, birdseye_run, {"eval_frames": 1})
        ctx.__dict__["config"] = {**ctx.config, "world": {"fidelity": "ultra"}}
        with pytest.raises(RecordingInputError, match="recorded world config unusable"):
            birdseye(ctx)


def test_orthographic_ground_truth_is_aligned_with_the_world() -> None:
    """A floor-slab joint crossing lies where the layout puts it, to a quarter pixel."""
    spec = CanvasSpec((-2.0, 4.4), (-2.0, 3.0), 50.0)
    world = static_world(WorldConfig(fidelity="light", settle_s=0.0))
    try:
        rgb, labels = render_orthographic(world.client, spec, world.labels)
    finally:
        world.close()
    gcps = ground_control_points(load_layout("warehouse_layout.csv", "light"), spec)
    assert len(gcps) == 1 and np.allclose(gcps[0], [1.2, 0.5])  # slab joints moved by the layout
    assert (labels == 1).mean() > 0.95
    col, row = spec.world_to_pixel(gcps[:, 0], gcps[:, 1])
    grey = rgb.mean(axis=2)
    c, r = round(col[0]), round(row[0])
    # the dark joints: 3 cm wide, centred on the crossing (1.5 px at 50 px/m)
    for axis, centre, profile in [
        ("x", col[0], grey[r + 5 : r + 30, c - 6 : c + 7].mean(axis=0)),
        ("y", row[0], grey[r - 6 : r + 7, c + 5 : c + 30].mean(axis=1)),
    ]:
        dark = np.clip(np.median(profile) - profile, 0, None)
        dark[dark < 10] = 0
        found = (dark * np.arange(-6, 7)).sum() / dark.sum() + (c if axis == "x" else r)
        assert abs(found - centre) < 0.25, axis
    # and the point locator finds the crossing of a shifted copy where it was shifted to
    shifted = np.roll(rgb.mean(axis=2).astype(np.uint8), (2, -3), axis=(0, 1))
    found = locate_gcps(shifted, grey.astype(np.uint8), np.stack([col, row], 1), search_px=GCP_HALF_PX)
    assert np.allclose(found.offsets_px[0], [-3, 2], atol=0.05)
