"""Benchmark: the cost of the photometric sensor model per 960x540 frame (issue 24).

    python benchmarks/sensor_model.py [--repeats 50] [--json FILE]

``simlan_data.imaging.sensor_model.SensorModel`` with ``realistic_defaults()`` (noise, vignetting,
12-bit ADC, 8 noise phases) on SIMLAN camera 160 at 960x540, on a synthetic frame (a smooth
gradient with texture; the model's cost does not depend on the content). Median of ``--repeats``
calls (after warm-up) of:

- a full recompute (the exposure alternates between two values, so no pixel is reused);
- an unchanged frame (the same frame again in a warmed phase: a block compare, the cached image
  handed out), and the same when the caller says so (``changed=False``: not even compared);
- a frame with 20 % of its rows changed over the whole width (four bands of 27 rows; the same
  phase, alternating between two frames that differ in those rows);
- a robot-sized patch (60 x 60 pixels) moving 6 pixels a frame through the 8 phases, as a
  ceiling camera sees a robot: each frame recomputes the blocks the patch touched since that
  phase's last frame;
- for reference, fresh noise every frame (``noise_phases = 0``: drawing the Gaussian field each
  frame, no caching).

Prints the figures; writes JSON with a ``figures`` list for benchmarks/summary.py.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine
from simlan_data.geometry.calibration import load_calibration
from simlan_data.imaging.sensor_model import SensorModel, realistic_defaults
from simlan_data.seeding import run_rng

WIDTH, HEIGHT = 960, 540
CAMERA = 160
BANDS = ((60, 87), (180, 207), (300, 327), (420, 447))  # 4 x 27 rows = 20 % of 540


def frames() -> tuple[np.ndarray, np.ndarray]:
    """A textured gradient and a copy whose rows in ``BANDS`` differ."""
    rng = np.random.default_rng(0)
    ramp = np.linspace(20, 230, WIDTH, dtype=np.float32)[None, :, None]
    texture = rng.normal(0, 8, (HEIGHT, WIDTH, 3)).astype(np.float32)
    base = np.clip(ramp + texture, 0, 255).astype(np.uint8)
    moved = base.copy()
    for lo, hi in BANDS:
        moved[lo:hi] = 255 - moved[lo:hi]
    return base, moved


def moving_patch(base: np.ndarray, frames: int) -> list[np.ndarray]:
    """``base`` with a 60 x 60 patch 6 pixels further right in each frame."""
    out = []
    for i in range(frames):
        f = base.copy()
        f[240:300, 200 + 6 * i : 260 + 6 * i] = (200, 60, 40)
        out.append(f)
    return out


def median_ms(step: Callable[[int], object], repeats: int) -> float:
    for i in range(5):
        step(i)
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        step(i)
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def measure(repeats: int) -> dict[str, float]:
    camera = load_calibration(CAMERA).camera.scaled(WIDTH, HEIGHT)
    params = realistic_defaults()
    base, moved = frames()

    def sensor(p=params) -> SensorModel:
        return SensorModel(p, camera, run_rng(0, "camera_noise", str(CAMERA)))

    full = sensor()
    unchanged = sensor()
    for k in range(params.noise_phases):  # warm every phase
        unchanged.apply(base, k)
    said = sensor()
    for k in range(params.noise_phases):
        said.apply(base, k)
    partial = sensor()
    patch, patches = sensor(), moving_patch(base, repeats + 13)
    for k in range(params.noise_phases):
        patch.apply(patches[k], k)
    fresh = sensor(replace(params, noise_phases=0))
    return {
        "full_ms": median_ms(lambda i: full.apply(base, 0, exposure_scale=1.0 if i % 2 else 0.999), repeats),
        "unchanged_ms": median_ms(lambda i: unchanged.apply(base, i), repeats),
        "unchanged_said_ms": median_ms(lambda i: said.apply(base, i + 8, changed=False), repeats),
        "rows20_ms": median_ms(lambda i: partial.apply(moved if i % 2 else base, 0), repeats),
        "patch_ms": median_ms(lambda i: patch.apply(patches[i + 8], i + 8), repeats),
        "fresh_noise_ms": median_ms(lambda i: fresh.apply(base, i), repeats),
    }


def figures(r: dict[str, float], repeats: int) -> list[dict]:
    common = {"unit": "ms", "history": "docs/benchmarks/sensors.md"}
    note = f"960x540, realistic_defaults(), 8 noise phases, median of {repeats}"
    return [
        {"id": "sensor_full", "figure": "sensor model: full recompute of a frame", "value": round(r["full_ms"], 2),
         "note": note + f"; fresh noise every frame (noise_phases=0): {r['fresh_noise_ms']:.1f} ms", **common},
        {"id": "sensor_unchanged", "figure": "sensor model: unchanged frame (block compare, cached image)",
         "value": round(r["unchanged_ms"], 3),
         "note": note + f"; said unchanged (changed=False, no compare): {r['unchanged_said_ms']:.3f} ms", **common},
        {"id": "sensor_rows20", "figure": "sensor model: frame with 20 % of its rows changed",
         "value": round(r["rows20_ms"], 2), "note": note, **common},
        {"id": "sensor_patch", "figure": "sensor model: a 60x60 patch moving 6 px a frame (a robot)",
         "value": round(r["patch_ms"], 2), "note": note, **common},
    ]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument(
        "--json",
        type=Path,
        default=REPO / "benchmarks" / "results" / f"sensor_model_{datetime.date.today().isoformat()}.json",
    )
    args = ap.parse_args()
    load_before = os.getloadavg()[0]
    r = measure(args.repeats)
    for key, value in r.items():
        print(f"{key:16s} {value:8.3f}")
    result = {
        "command": f"python benchmarks/sensor_model.py --repeats {args.repeats}",
        "machine": machine(),
        "date": datetime.datetime.now().isoformat(timespec="minutes"),  # (a rerun the same day wins)
        "conditions": f"load average {load_before:.1f} at the start, {os.getloadavg()[0]:.1f} at the end",
        "history": "docs/benchmarks/sensors.md",
        "ms_per_frame": r,
        "figures": figures(r, args.repeats),
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=1) + "\n")
    print(f"-> {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
