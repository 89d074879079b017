"""Benchmark of issue 20 (open platform): the built-ins unchanged by the plug-in seam, old against new.

    python benchmarks/plugin_seam.py [--old COMMIT] [--duration-s S] [--pairs N] [--json FILE]

With the code of an old commit (a ``git worktree`` put first on PYTHONPATH) and with this checkout:

1. behaviour: each scenario of ``SCENARIOS`` (every role's built-in at work: localizer,
   coordinator, safety trees, person detection, the live bird's-eye stitcher) is run once with
   each code, same seed, and the two recordings are compared message by message with the
   independent ``mcap`` reader: same topics, same log times, same bytes. ``/simlan/config`` is
   left out (the new one has the ``algorithms`` section); a compressedDepth image whose deflate
   bytes differ is decoded and compared by pixels (issue 21's open encoder nondeterminism);
2. speed: the default scenario, alternately old, new, new, old, ... (a steady drift of the
   host's speed cancels out): the real-time factor of each run, the medians and their ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from collections import Counter
from datetime import datetime, timezone
from pathlib import Path

import cv2
import numpy as np
from mcap.reader import make_reader

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = {  # name -> overrides (the same for old and new code)
    "default": ["birdseye.rate_hz=1"],
    "multi_robot": [],
    "restricted_zone": [],
    "humanoid_crossing": [],
}
SKIP_TOPICS = {"/simlan/config"}


def run_once(code_dir: Path, out_dir: Path, duration_s: float, overrides: list[str]) -> dict[str, float]:
    """One run with the package at ``code_dir``; its metrics.json."""
    env = {**os.environ, "PYTHONPATH": str(code_dir)}
    cmd = [
        sys.executable,
        "-m",
        "simlan_data.run",
        f"duration_s={duration_s}",
        "progress=false",
        f"hydra.run.dir={out_dir}",
        *overrides,
    ]
    done = subprocess.run(cmd, cwd=code_dir, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"run failed ({code_dir}): {done.stderr[-2000:]}")
    return json.loads((out_dir / "metrics.json").read_text())


def _messages(bag: Path) -> list[tuple[str, int, bytes]]:
    with open(next(bag.glob("*.mcap")), "rb") as f:
        return [
            (channel.topic, message.log_time, bytes(message.data))
            for _, channel, message in make_reader(f).iter_messages(log_time_order=True)
            if channel.topic not in SKIP_TOPICS
        ]


def _same_depth_pixels(a: bytes, b: bytes) -> bool:
    """compressedDepth: CDR header + format + 12-byte depth header + PNG; compare the PNGs' pixels."""
    ia, ib = a.find(b"\x89PNG"), b.find(b"\x89PNG")
    if (
        ia < 0 or ib < 0 or a[: ia - 16] != b[: ib - 16]
    ):  # (the CDR byte count before the depth header differs)
        return False
    da = cv2.imdecode(np.frombuffer(a[ia:], np.uint8), cv2.IMREAD_UNCHANGED)
    db = cv2.imdecode(np.frombuffer(b[ib:], np.uint8), cv2.IMREAD_UNCHANGED)
    return da is not None and db is not None and np.array_equal(da, db)


def compare_recordings(old: Path, new: Path) -> dict[str, object]:
    """Message-by-message comparison of two recordings (all topics but SKIP_TOPICS)."""
    a, b = _messages(old), _messages(new)
    differing: Counter[str] = Counter()
    same_pixels = 0
    if [(t, s) for t, s, _ in a] != [(t, s) for t, s, _ in b]:
        return {"messages": [len(a), len(b)], "same_topics_and_stamps": False}
    for (topic, _, da), (_, _, db) in zip(a, b):
        if da == db:
            continue
        if topic.endswith("compressedDepth") and _same_depth_pixels(da, db):
            same_pixels += 1
            continue
        differing[topic] += 1
    return {
        "messages": len(a),
        "topics": len({t for t, _, _ in a}),
        "same_topics_and_stamps": True,
        "differing_messages": dict(differing),
        "depth_same_pixels_other_deflate_bytes": same_pixels,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="67820fb", help="the commit before the plug-in seam (default 67820fb)")
    ap.add_argument("--duration-s", type=float, default=20.0)
    ap.add_argument(
        "--pairs", type=int, default=2, help="ABBA blocks of the speed part (each: old, new, new, old)"
    )
    ap.add_argument("--json", type=Path, help="write the figures here")
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), help="behaviour part: these scenarios")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="plugin_seam_") as tmp:
        old_dir = Path(tmp) / "old"
        subprocess.run(["git", "worktree", "add", "--detach", str(old_dir), args.old], cwd=REPO, check=True)
        try:
            behaviour = {}
            for name in args.scenarios:
                extra = SCENARIOS.get(name, [])
                overrides = [f"scenario={name}", *extra]
                runs = {}
                for which, code in (("old", old_dir), ("new", REPO)):
                    runs[which] = Path(tmp) / f"{name}_{which}"
                    run_once(code, runs[which], args.duration_s, overrides)
                behaviour[name] = compare_recordings(runs["old"] / "recording", runs["new"] / "recording")
                print(f"{name}: {behaviour[name]}", flush=True)
            rtf: dict[str, list[float]] = {"old": [], "new": []}
            for i, which in enumerate(["old", "new", "new", "old"] * args.pairs):
                code = old_dir if which == "old" else REPO
                metrics = run_once(code, Path(tmp) / f"rtf{i}_{which}", args.duration_s, [])
                rtf[which].append(metrics["sim.rtf"])
                print(f"{which}: RTF {metrics['sim.rtf']:.3f}", flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old_dir)], cwd=REPO, check=False)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    result = {
        "command": " ".join(sys.argv),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": f"{platform.node()}, {os.cpu_count()} cores",
        "old": args.old,
        "new": head.stdout.strip(),
        "duration_s": args.duration_s,
        "behaviour": behaviour,
        "rtf_order": ["old", "new", "new", "old"] * args.pairs,
        "rtf": rtf,
        "rtf_median": {k: statistics.median(v) for k, v in rtf.items() if v},
        "rtf_ratio_new_over_old": statistics.median(rtf["new"]) / statistics.median(rtf["old"])
        if rtf["old"]
        else None,
        "load_average_1min": [load0, os.getloadavg()[0]],
    }
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    same = all(
        b.get("same_topics_and_stamps") and not b.get("differing_messages") for b in behaviour.values()
    )
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
