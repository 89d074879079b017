"""Benchmark of repeated-run identity (issue 21): same config and seed, same bytes, N of N.

    python benchmarks/determinism.py [--runs 100] [--duration 2] [--seed 0] [--src DIR]
                                     [--json FILE] [--keep DIR]

Runs the default scenario (its default cameras and streams; ``progress=false``) ``--runs``
times for ``--duration`` simulated seconds with one seed: the first half one after another, the
second half as pairs started side by side (two processes at once on the machine's cores, as a
sweep runs them). Each run's ``recording/recording.mcap`` and ``recording/metadata.yaml`` are
hashed (sha256) and compared with the first run's. A run whose bag differs is compared with the
first message by message (``mcap`` reader): its differing topics are reported, and for
compressedDepth/PNG messages whether the images inflate to the same bytes (an encoder's choice of
deflate bytes, not different pixels).

``--src DIR`` runs another checkout (e.g. a ``git worktree`` of an older commit) with this venv
(``PYTHONPATH=DIR``), for the before/after comparison in docs/benchmarks/determinism.md.

Prints markdown for docs/benchmarks/determinism.md; writes the raw numbers as JSON (default
``benchmarks/results/determinism_<date>.json``, ``_<date>_2.json``... when that exists: a run never
overwrites an earlier one). A quick check of fewer than ``FIGURE_RUNS`` runs is no figure of
BENCHMARKS.md: its JSON goes beside its run directories (``determinism.json``), not into results.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, machine

FILES = ("recording/recording.mcap", "recording/metadata.yaml")
RESULTS = REPO / "benchmarks" / "results"
FIGURE_RUNS = 100  # the repeated-run figure of BENCHMARKS.md (issue 21)


def default_json(runs: int, root: Path, today: datetime.date, results: Path = RESULTS) -> Path:
    """Where a run without ``--json`` writes its raw numbers: a quick check (fewer than
    FIGURE_RUNS runs) beside its run directories; a full run into ``results`` under a name no
    earlier file has (``--runs 2`` overwrote the day's 100-run file, the figure of BENCHMARKS.md)."""
    if runs < FIGURE_RUNS:
        return root / "determinism.json"
    out, n = results / f"determinism_{today}.json", 2
    while out.exists():
        out, n = results / f"determinism_{today}_{n}.json", n + 1
    return out


def _start(src: Path, run_dir: Path, duration: float, seed: int) -> subprocess.Popen[bytes]:
    env = {**os.environ, "PYTHONPATH": str(src)}
    env.pop("HYDRA_FULL_ERROR", None)
    args = [f"duration_s={duration}", f"seed={seed}", f"hydra.run.dir={run_dir}", "progress=false"]
    return subprocess.Popen(
        [sys.executable, "-m", "simlan_data.run", *args],
        cwd=src,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )


def _finish(proc: subprocess.Popen[bytes], run_dir: Path) -> dict[str, str]:
    _, err = proc.communicate(timeout=600)
    if proc.returncode != 0:
        raise SystemExit(f"run {run_dir} failed (exit {proc.returncode}):\n{err.decode()[-2000:]}")
    return {f: hashlib.sha256((run_dir / f).read_bytes()).hexdigest() for f in FILES}


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    from mcap.reader import make_reader

    with path.open("rb") as f:
        return [
            (c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages(log_time_order=False)
        ]


def _idat(cdr: bytes) -> bytes | None:
    """The inflated IDAT of the PNG inside a serialized CompressedImage, if there is one."""
    start = cdr.find(b"\x89PNG\r\n\x1a\n")
    if start < 0:
        return None
    png, pos, idat = cdr[start:], 8, b""
    while pos + 8 <= len(png):
        n = int.from_bytes(png[pos : pos + 4], "big")
        kind = png[pos + 4 : pos + 8]
        if kind == b"IDAT":
            idat += png[pos + 8 : pos + 8 + n]
        if kind == b"IEND":
            break
        pos += 12 + n
    try:
        return zlib.decompress(idat)
    except zlib.error:
        return None


def differences(a: Path, b: Path) -> dict[str, object]:
    """The topics whose messages differ between two bags (same order expected)."""
    ma, mb = _messages(a), _messages(b)
    topics: dict[str, dict[str, int]] = {}
    for x, y in zip(ma, mb):
        if x == y:
            continue
        d = topics.setdefault(
            x[0] if x[0] == y[0] else f"{x[0]} / {y[0]}", {"messages": 0, "same_inflated": 0}
        )
        d["messages"] += 1
        ia, ib = _idat(x[2]), _idat(y[2])
        d["same_inflated"] += int(ia is not None and ia == ib)
    return {"message_counts": [len(ma), len(mb)], "topics": topics}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100, help="runs in all (half serial, half in pairs)")
    ap.add_argument("--duration", type=float, default=2.0, help="simulated seconds per run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--src", type=Path, default=REPO, help="checkout to run (PYTHONPATH)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--keep", type=Path, help="keep the run directories here (default: a temp dir)")
    args = ap.parse_args()
    src = args.src.resolve()
    rev = subprocess.run(
        ["git", "-C", str(src), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    dirty = subprocess.run(
        ["git", "-C", str(src), "status", "--porcelain", "--untracked-files=no"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    raw: dict[str, object] = {
        "machine": machine(),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(
            timespec="seconds"
        ),  # audit-ok: report date
        "src": str(src),
        "commit": rev + ("+local changes" if dirty else ""),
        "runs": args.runs,
        "duration_s": args.duration,
        "seed": args.seed,
        "load_average_start": os.getloadavg()[0],
    }
    print(f"Machine: {raw['machine']}; load average at start {raw['load_average_start']:.1f}")
    print(f"Code: {src} at {raw['commit']}\n")
    root = args.keep or Path(tempfile.mkdtemp(prefix="determinism_"))
    root.mkdir(parents=True, exist_ok=True)
    serial = args.runs - args.runs // 2
    results: list[dict[str, object]] = []
    t0 = time.perf_counter()
    for i in range(serial):
        run_dir = root / f"serial_{i:03d}"
        results.append(
            {
                "run": run_dir.name,
                "mode": "serial",
                **_finish(_start(src, run_dir, args.duration, args.seed), run_dir),
            }
        )
    for i in range(0, args.runs - serial, 2):
        dirs = [root / f"pair_{i + j:03d}" for j in range(min(2, args.runs - serial - i))]
        procs = [_start(src, d, args.duration, args.seed) for d in dirs]
        for p, d in zip(procs, dirs):
            results.append({"run": d.name, "mode": "side by side", **_finish(p, d)})
    raw["wall_s"] = round(time.perf_counter() - t0, 1)
    first = results[0]
    rows = []
    for mode in ("serial", "side by side"):
        group = [r for r in results if r["mode"] == mode]
        rows.append((mode, sum(all(r[f] == first[f] for f in FILES) for r in group), len(group)))
    differing = [r for r in results if any(r[f] != first[f] for f in FILES)]
    for r in differing:
        r["differences"] = differences(root / str(first["run"]) / FILES[0], root / str(r["run"]) / FILES[0])
    n_same, n_all = sum(same for _, same, _ in rows), len(results)
    raw["identical"] = {mode: [same, count] for mode, same, count in rows}
    raw["identical_total"] = [n_same, n_all]
    raw["sha256_first"] = {f: first[f] for f in FILES}
    raw["differing"] = differing
    raw["results"] = results
    print(f"### Repeated default runs: duration_s={args.duration} seed={args.seed}\n")
    print("| runs | byte-identical to the first (recording.mcap and metadata.yaml) |")
    print("| --- | --- |")
    for mode, same, count in rows:
        print(f"| {mode} | {same} of {count} |")
    print(f"| all | **{n_same} of {n_all}** |\n")
    print(f"wall time {raw['wall_s']} s")
    for r in differing:
        print(f"- {r['run']} ({r['mode']}) differs: {json.dumps(r['differences'])}")
    out = args.json or default_json(args.runs, root, datetime.date.today())  # audit-ok: file name
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(raw, indent=1) + "\n")
    print(f"raw numbers: {out}")


if __name__ == "__main__":
    main()
