"""A user's bird's-eye stitcher behind the plug-in seam: a nearest-camera stitcher (no blending,
OpenCV remap) in a module of its own, selected by import path, run live (/birdseye/image, read back
with the independent reader mcap + mcap_ros2) and replayed to the same canvas; and the built-in's
config refusing a bad value with one line. Real processes, real PyBullet, no mocks.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from simlan_data.algorithms import registry
from simlan_data.algorithms.birdseye_stitcher import GpssStitcherConfig
from simlan_data.errors import ConfigError
from simlan_data.recording.codecs import encode_rgb

NEAREST = '''
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class NearestConfig:
    interpolation: str = "linear"  # linear | nearest

    def __post_init__(self):
        if self.interpolation not in ("linear", "nearest"):
            raise ValueError(f"interpolation must be linear or nearest, got {self.interpolation!r}")


class NearestStitcher:
    """Each canvas pixel from the camera whose centre is closest to it (no blending)."""

    role = "stitcher"
    config_class = NearestConfig

    def __init__(self, config, context):
        canvas = context.canvas
        self.shape = (canvas.height, canvas.width, 3)
        self.interp = cv2.INTER_LINEAR if config.interpolation == "linear" else cv2.INTER_NEAREST
        points = canvas.world_points(slice(0, canvas.height), slice(0, canvas.width)).reshape(-1, 3)
        best = np.full(len(points), np.inf)
        self.maps = []
        for cam in context.cameras:
            uv, ok = cam.project(points)
            ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height - 1)
            dist = np.hypot(*(points[:, :2] - cam.position[:2]).T)
            mine = ok & (dist < best)
            best[mine] = dist[mine]
            self.maps.append((uv, mine))
        self.owner = np.full(len(points), -1)
        for k, (_, mine) in enumerate(self.maps):
            self.owner[mine] = k  # a later camera that is closer took the pixel from an earlier one
        self.tables = []
        for k, (uv, _) in enumerate(self.maps):
            mine = (self.owner == k).reshape(canvas.height, canvas.width)
            map_x = np.where(self.owner == k, uv[:, 0], -1.0).reshape(mine.shape).astype(np.float32)
            map_y = np.where(self.owner == k, uv[:, 1], -1.0).reshape(mine.shape).astype(np.float32)
            self.tables.append((map_x, map_y, mine))

    def stitch(self, frames):
        canvas = np.zeros(self.shape, np.uint8)
        for frame, (map_x, map_y, mine) in zip(frames, self.tables):
            image = cv2.remap(frame, map_x, map_y, self.interp, borderMode=cv2.BORDER_CONSTANT)
            canvas[mine] = image[mine]
        return canvas
'''
STITCHER = "nearest_stitcher:NearestStitcher"
REPO = Path(__file__).resolve().parents[1]
# two cameras over the truck's start, a coarse canvas around them, lossless colour: the replay
# must reproduce the live canvas from the recorded images bit for bit
LIVE = [
    "duration_s=2",
    "cameras.ids=[163,164]",
    "world.fidelity=light",
    "recording.rgb_encoding=png",
    "birdseye.rate_hz=5",
    "birdseye.x_m=[-4,16]",
    "birdseye.y_m=[-6,6]",
    "birdseye.px_per_m=20",
    "progress=false",
]


def _run(args: list[str], module: str, pythonpath: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.run(
        [sys.executable, "-m", module, *args], cwd=REPO, env=env, capture_output=True, text=True, timeout=600
    )


def _messages(bag: Path, topic: str) -> list:
    with open(bag / "recording.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [msg for _, _, _, msg in reader.iter_decoded_messages(topics=[topic])]


def _error_line(stderr: str) -> str:
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one error line, got:\n{stderr}"
    assert lines[0].startswith("error: "), lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("stitcher_plugin")
    (path / "nearest_stitcher.py").write_text(NEAREST)
    return path


@pytest.fixture(scope="module")
def nearest_run(plugin_dir: Path) -> Path:
    run_dir = plugin_dir / "run"
    args = [*LIVE, f"algorithms/stitcher={STITCHER}", "algorithms.stitcher.interpolation=nearest"]
    done = _run([*args, f"hydra.run.dir={run_dir}"], "simlan_data.run", plugin_dir)
    assert done.returncode == 0, done.stderr
    return run_dir


def test_a_users_stitcher_runs_live_and_replays_to_the_same_canvas(
    nearest_run: Path, plugin_dir: Path
) -> None:
    bag = nearest_run / "recording"
    live = _messages(bag, "/birdseye/image")
    assert len(live) == 11  # t = 0, 0.2, ..., 2.0 s
    (config_msg,) = _messages(bag, "/simlan/config")
    config = yaml.safe_load(config_msg.data)
    assert config["algorithms"]["stitcher"] == {"name": STITCHER, "interpolation": "nearest"}
    assert "feather_m" not in config["birdseye"]
    last = cv2.imdecode(np.frombuffer(bytes(live[-1].data), np.uint8), cv2.IMREAD_COLOR)
    assert last.shape == (240, 400, 3)
    assert 0.2 < (last.max(axis=2) > 0).mean() < 1.0  # two cameras see part of the canvas

    # replayed: selected by --set (PYTHONPATH has the module), and as recorded (no --set)
    for name, sets in [
        ("selected", ["--set", f"stitcher={STITCHER}", "--set", "interpolation=nearest"]),
        ("recorded", []),
    ]:
        out = plugin_dir / f"replay_{name}"
        args = [str(bag), "--algorithms", "birdseye", "--out", str(out), "--set", "ground_truth=false", *sets]
        done = _run(args, "simlan_data.replay", plugin_dir)
        assert done.returncode == 0, done.stderr
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["birdseye.canvases"] == len(live)
        assert "birdseye.seam_fraction" not in metrics  # it does not blend
        assert (
            "stitcher nearest_stitcher:NearestStitcher (interpolation=nearest)"
            in (out / "birdseye_report.md").read_text()
        )
        replayed = cv2.cvtColor(cv2.imread(str(out / "birdseye_last.png")), cv2.COLOR_BGR2RGB)
        _, data = encode_rgb(replayed, "jpeg", jpeg_quality=config["birdseye"]["jpeg_quality"])
        assert data == bytes(live[-1].data), name

    # the built-in on the same recording stitches another canvas (it blends; linear, not nearest)
    out = plugin_dir / "replay_gpss"
    args = [str(bag), "--algorithms", "birdseye", "--out", str(out), "--set", "ground_truth=false"]
    done = _run([*args, "--set", "stitcher=gpss", "--set", "feather_m=0.5"], "simlan_data.replay", plugin_dir)
    assert done.returncode == 0, done.stderr
    assert "stitcher gpss (feather_m=0.5, distort=True)" in (out / "birdseye_report.md").read_text()
    gpss = cv2.imread(str(out / "birdseye_last.png"))
    assert gpss.shape == replayed.shape and not np.array_equal(
        gpss, cv2.cvtColor(replayed, cv2.COLOR_RGB2BGR)
    )


def test_a_replay_option_the_selected_stitcher_does_not_have_is_one_line(
    nearest_run: Path, plugin_dir: Path
) -> None:
    out = plugin_dir / "replay_bad"
    args = [
        str(nearest_run / "recording"),
        "--algorithms",
        "birdseye",
        "--out",
        str(out),
        "--set",
        "feather_m=0.3",
    ]
    done = _run(args, "simlan_data.replay", plugin_dir)  # recorded: the nearest stitcher, no feather
    assert done.returncode == 2, done.stderr
    line = _error_line(done.stderr)
    assert line.startswith("error: unknown birdseye option 'feather_m' in replay --set: known: x_m, y_m"), (
        line
    )
    assert line.split("; ")[0].endswith("interpolation"), line


def test_a_bad_value_of_the_builtins_config_is_refused_with_one_line(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    done = _run(
        ["algorithms.stitcher.feather_m=0", f"hydra.run.dir={run_dir}", "progress=false"],
        "simlan_data.run",
        tmp_path,
    )
    assert done.returncode == 2, done.stderr
    line = _error_line(done.stderr)
    assert line.startswith("error: invalid algorithms.stitcher.feather_m=0.0 in "), line
    assert "must be within (0, 5] m" in line, line
    assert not (run_dir / "recording").exists()


def test_the_moved_key_is_refused_where_it_was(tmp_path: Path) -> None:
    done = _run(["birdseye.feather_m=0.3", f"hydra.run.dir={tmp_path / 'run'}"], "simlan_data.run", tmp_path)
    assert done.returncode == 2, done.stderr
    assert "birdseye.feather_m" in _error_line(done.stderr)


@pytest.mark.parametrize(
    ("values", "match"),
    [
        (
            {"feather_m": 0.0},
            r"invalid algorithms.stitcher.feather_m=0.0 in config: must be within \(0, 5\] m",
        ),
        ({"feather_m": "wide"}, r"invalid algorithms.stitcher.feather_m='wide' .*expected a number"),
        ({"distort": "yes"}, r"invalid algorithms.stitcher.distort='yes' .*expected true or false"),
        (
            {"blend": 1},
            r"unknown key 'blend' for stitcher 'gpss' .*GpssStitcherConfig has distort, feather_m",
        ),
    ],
)
def test_the_builtin_is_registered_and_checks_its_config(values: dict, match: str) -> None:
    spec = registry.resolve("stitcher", registry.DEFAULTS["stitcher"])
    assert spec.config_class is GpssStitcherConfig and "birdseye_stitcher:GpssStitcher" in spec.origin
    assert spec.make_config({}, where="config") == GpssStitcherConfig(feather_m=0.2, distort=True)
    with pytest.raises(ConfigError, match=match):
        spec.make_config(values, where="config")
