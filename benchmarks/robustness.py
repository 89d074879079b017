"""Where each built-in algorithm leaves its promise under camera effects (issue 24): BENCHMARKS rows.

Reads the outputs of robustness sweeps (``python -m simlan_data.evals SWEEP --out DIR``; each DIR
holds ``robustness.csv``), recomputes the verdicts with the sweep's own promises
(``simlan_data.evaluation.robustness.breaking_points``) and writes one figure per effect: the
first strength at which the mean over seeds leaves a promise (or "holds" over the whole range),
which metric breaks there, and the last strength that holds::

    python -m simlan_data.evals robustness --out /tmp/rob/loc
    python benchmarks/robustness.py --sweep robustness --from /tmp/rob/loc --json FILE

Several ``--from`` directories of one sweep are merged (a later one's effects replace an earlier
one's): sweeps are long and are often run effect by effect (``--only``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
from pathlib import Path

import polars as pl

from simlan_data.evaluation.robustness import Verdict, breaking_points, load_robustness
from simlan_data.evaluation.robustness_report import CSV_NAME

REPO = Path(__file__).resolve().parents[1]
HISTORY = "docs/benchmarks/sensors.md"
ALGORITHM = {"robustness": "localizer", "robustness_birdseye": "stitcher", "robustness_safety": "safety"}


def merged_table(dirs: list[Path]) -> pl.DataFrame:
    """Every row of the sweeps' CSVs, each effect from the last directory that has it."""
    tables: dict[str, pl.DataFrame] = {}
    for d in dirs:
        table = pl.read_csv(d / CSV_NAME)
        for effect in table["effect"].unique().to_list():
            tables[effect] = table.filter(pl.col("effect") == effect)
    return pl.concat(list(tables.values()))


def figure(sweep: str, effect: str, key: str, verdicts: list[Verdict]) -> dict[str, object]:
    """One row: the first breaking strength over the effect's promises, and what breaks there."""
    broken = [v for v in verdicts if v.breaks_at is not None]
    name = f"{ALGORITHM.get(sweep, sweep)} under {effect} (`{key}`): first strength that breaks a promise"
    if not broken:
        top = max(s for v in verdicts for s, _ in v.means)
        return {"id": f"{sweep}_{effect}", "figure": name, "value": "none", "unit": f"(holds up to {top:g})",
                "note": "; ".join(f"{v.metric} {v.promise}" for v in verdicts)}  # fmt: skip
    first = min(v.breaks_at for v in broken if v.breaks_at is not None)
    at = [v for v in broken if v.breaks_at == first]
    means = {v.metric: dict(v.means) for v in at}
    what = ", ".join(f"{v.metric} {means[v.metric].get(first, float('nan')):.3g} ({v.promise})" for v in at)
    holds = [v.holds_up_to for v in at if v.holds_up_to is not None]
    return {
        "id": f"{sweep}_{effect}",
        "figure": name,
        "value": f"{first:g}",
        "unit": "",
        "note": f"there {what}; holds up to {min(holds):g}" if holds else f"there {what}",
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sweep", required=True, help="the sweep in evals/base.yaml (robustness, ...)")
    ap.add_argument("--from", dest="dirs", nargs="+", type=Path, required=True, help="sweep output dirs")
    ap.add_argument("--json", type=Path, help="write the figures here")
    args = ap.parse_args(argv)
    table = merged_table(args.dirs)
    effects = sorted(set(table["effect"].to_list()))
    sweep = load_robustness(REPO / "evals" / "base.yaml", args.sweep, only=effects)
    verdicts = breaking_points(sweep, table)
    figures = []
    for effect in sweep.effects:
        mine = [v for v in verdicts if v.effect == effect.name]
        figures.append(figure(args.sweep, effect.name, effect.key, mine))
    seeds = table["seed"].n_unique()
    command = f"python benchmarks/robustness.py --sweep {args.sweep} --from DIR --json FILE"
    out = {
        "command": command,
        "sweep_command": f"python -m simlan_data.evals {args.sweep} --out DIR",
        "machine": "AMD EPYC, 2 cores, 24 GiB RAM, no GPU (Mesa llvmpipe for EGL); other work running beside it",
        "date": dt.date.today().isoformat(),
        "history": HISTORY,
        "seeds": seeds,
        "figures": figures,
    }
    for f in figures:
        print(f"{f['id']:<40} {f['value']:>8} {f['unit']}  {f.get('note', '')}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
