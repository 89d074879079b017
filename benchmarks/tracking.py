"""Multi-camera tracking scores of the marker localizer (issue 25, item 4): HOTA, MOTA and IDF1
(TrackEval) of its estimates against the instance ground truth, in world coordinates and per camera.

    python benchmarks/tracking.py --json benchmarks/results/tracking_DATE.json [--scenario multi_robot]
                                  [--duration 30] [--seeds 3] [--override KEY=VALUE ... --tag NAME]

Per seed: ``python -m simlan_data.run scenario=SCENARIO duration_s=D seed=S`` with the base
suite's spawn perturbation and ``cameras.streams=[rgb,semantic,instance]`` (the default GPSS
cameras, 960x540 at 5 Hz), then ``python -m simlan_data.replay RUN --algorithms tracking`` (the
localizer's recorded estimates; world similarity max(0, 1 - d / 2 m), matches within 1 m; per
camera its estimated 3D boxes projected, IoU against the amodal boxes). Figures: the mean over
seeds, the range beside it; ``--override`` (Hydra overrides of every run, e.g. ``sensors=realistic``)
needs a ``--tag`` that names the figures apart. History: docs/benchmarks/tracking.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import statistics
import tempfile
from pathlib import Path

from common import machine, run_cli

KEYS = ("hota", "mota", "idf1", "loca", "idsw", "gt_dets")


def one(root: Path, scenario: str, duration_s: float, seed: int, extra: list[str]) -> dict[str, float]:
    run = root / f"s{seed}"
    proc = run_cli(
        f"scenario={scenario}",
        f"duration_s={duration_s:g}",
        f"seed={seed}",
        "progress=false",
        "perturbation.spawn_xy_m=0.15",
        "perturbation.spawn_yaw_deg=3",
        "cameras.streams=[rgb,semantic,instance]",
        *extra,
        f"hydra.run.dir={run}",
    )
    if proc.returncode != 0:
        raise SystemExit(f"run failed: {proc.stderr[-2000:]}")
    proc = run_cli(
        str(run), "--out", str(root / f"r{seed}"), "--algorithms", "tracking", module="simlan_data.replay"
    )
    if proc.returncode != 0:
        raise SystemExit(f"replay failed: {proc.stderr[-2000:]}")
    metrics = json.loads((root / f"r{seed}" / "metrics.json").read_text())
    out = {f"world.{k}": metrics[f"tracking.{k}"] for k in KEYS}
    out.update({f"camera.{k}": metrics[f"tracking.camera.{k}"] for k in KEYS})
    return out


def _localizer(overrides: list[str]) -> str:
    """The localizer a run steers on: the ``algorithms/localizer=NAME`` override's, else the marker one."""
    chosen = [o.split("=", 1)[1] for o in overrides if o.startswith("algorithms/localizer=")]
    return (
        f"{chosen[-1]} (marker-free)" if chosen and chosen[-1] == "foreground" else (chosen or ["marker"])[-1]
    )


def _range(values: list[float]) -> str:
    return f"{min(values):.4f}-{max(values):.4f}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="multi_robot")
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument(
        "--override", nargs="*", default=[], metavar="KEY=VALUE", help="Hydra overrides of every run"
    )
    p.add_argument("--tag", default="", help="names the figures of a run with --override")
    p.add_argument("--json", type=Path, required=True)
    args = p.parse_args()
    if bool(args.override) != bool(args.tag):
        p.error("--override and --tag go together")
    with tempfile.TemporaryDirectory(prefix="bench_tracking_") as tmp:
        runs = [one(Path(tmp), args.scenario, args.duration, s, args.override) for s in range(args.seeds)]
    mean = {k: statistics.fmean(r[k] for r in runs) for k in runs[0]}
    setup = f"scenario={args.scenario}, {args.duration:g} s, seeds 0-{args.seeds - 1}, default GPSS cameras 960x540 at 5 Hz"
    setup += "".join(f", {o}" for o in args.override)
    suffix = f"_{args.tag}" if args.tag else ""
    history = "docs/benchmarks/tracking.md"
    figures = []
    for space, what, sim in (
        ("world", "world coordinates (3D box centre on the floor)", "match within 1 m"),
        ("camera", "per camera (estimated 3D boxes projected vs amodal boxes, all cameras combined)", "IoU"),
    ):
        values = {k: [r[f"{space}.{k}"] for r in runs] for k in ("hota", "mota", "idf1")}
        figures.append(
            {
                "id": f"tracking_{space}_hota{suffix}",
                "figure": f"{_localizer(args.override)} localizer's tracking, {what}: HOTA / MOTA / IDF1 ({setup})",
                "value": f"{mean[f'{space}.hota']:.4f} / {mean[f'{space}.mota']:.4f} / {mean[f'{space}.idf1']:.4f}",
                "unit": "",
                "note": f"mean of {args.seeds} seeds; HOTA {_range(values['hota'])}, MOTA {_range(values['mota'])}, "
                f"IDF1 {_range(values['idf1'])}; LocA {mean[f'{space}.loca']:.4f} ({sim}); "
                f"ID switches {sum(r[f'{space}.idsw'] for r in runs):g}; {mean[f'{space}.gt_dets']:.0f} ground-truth detections a seed",
                "history": history,
            }
        )
    doc = {
        "command": f"python benchmarks/tracking.py --scenario {args.scenario} --duration {args.duration:g} "
        f"--seeds {args.seeds}"
        + (f" --override {' '.join(args.override)} --tag {args.tag}" if args.tag else "")
        + " --json FILE",
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
        "history": history,
        "setup": setup,
        "runs": runs,
        "mean": mean,
        "figures": figures,
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(doc, indent=1) + "\n")
    for fig in figures:
        print(f"{fig['figure']}: {fig['value']} ({fig['note']})")


if __name__ == "__main__":
    main()
