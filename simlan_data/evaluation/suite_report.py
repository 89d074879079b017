"""Suite results for people: the console table, report.md with PNG plots, the polars tables.

OUT/metrics.parquet|csv   every metric of every case, seed and source (long table)
OUT/summary.parquet|csv   one row per check: n, mean, 95 % interval, bound, baseline, verdict
OUT/report.md             summary table, pending checks, per case: checks over seeds,
                          trajectories over the floor plan, error over time, bird's-eye view,
                          pose-mapping error over time and per joint;
                          per grid family (a sweep slice): the grid of a metric
OUT/plots/*.png
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import matplotlib

matplotlib.use("Agg")  # files only: no display here or in CI
import matplotlib.pyplot as plt
import numpy as np
import polars as pl

from simlan_data.constants import RECORDING_DIRNAME
from simlan_data.evaluation.birdseye_replay import REPORT_PNG as BIRDSEYE_PNG
from simlan_data.evaluation.metrics import estimates_from_recording, ground_truth
from simlan_data.evaluation.suite import FAILING, Job
from simlan_data.evaluation.suite_spec import Case, Fault, Suite
from simlan_data.imaging.image_files import write_image
from simlan_data.recording.reader import RecordingReader

REPORT_NAME = "report.md"
PLOTS_DIR = "plots"
MARKS = {
    "pass": "PASS",
    "fail": "FAIL",
    "regression": "REGRESSED",
    "missing": "MISSING",
    "error": "ERROR",
    "pending": "pending",
}


def write_tables(out: Path, metrics: pl.DataFrame, summary: pl.DataFrame) -> None:
    for table, stem in ((metrics, "metrics"), (summary, "summary")):
        table.write_parquet(out / f"{stem}.parquet")
        table.write_csv(out / f"{stem}.csv", float_precision=9)


def _num(v: Any, spec: str = ".4g") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def _ci(row: dict[str, Any]) -> str:
    if row.get("mean") is None:
        return "-"
    if row.get("n", 0) < 2:
        return f"{_num(row['mean'])} (n=1)"
    return f"{_num(row['mean'])} [{_num(row['ci_low'])}, {_num(row['ci_high'])}]"


def _rows(summary: pl.DataFrame) -> tuple[list[dict[str, Any]], dict[str, str]]:
    """Checks to show, and the pending cases collapsed to one line each."""
    shown: list[dict[str, Any]] = []
    pending: dict[str, str] = {}
    cells: dict[str, set[str]] = {}
    for row in summary.iter_rows(named=True):
        if row["verdict"] == "pending":
            family = row["case"].split("[")[0]  # the grid cells of a sweep slice: one line
            pending.setdefault(family, row["note"])
            cells.setdefault(family, set()).add(row["case"])
        else:
            shown.append(row)
    for family, names in cells.items():
        if len(names) > 1:
            pending[f"{family} ({len(names)} grid cells)"] = pending.pop(family)
    return shown, pending


def counts(summary: pl.DataFrame) -> dict[str, int]:
    out = dict.fromkeys(MARKS, 0)
    for v in summary["verdict"].to_list():
        out[v] = out.get(v, 0) + 1
    return out


def print_table(summary: pl.DataFrame) -> None:
    shown, pending = _rows(summary)
    header = f"{'verdict':<10} {'case':<22} {'metric':<48} {'mean [95% CI] over seeds':<34} {'bound':<10} {'baseline':<10}"
    print(header)
    print("-" * len(header))
    for r in shown:
        metric = f"{r['source']}:{r['metric']}"
        print(
            f"{MARKS.get(r['verdict'], r['verdict']):<10} {r['case'][:22]:<22} {metric[:48]:<48} {_ci(r)[:34]:<34} "
            f"{r['bound'][:10]:<10} {_num(r['baseline_mean'])[:10]:<10}"
        )
        if r["verdict"] in FAILING and r["note"]:
            print(f"{'':<10} {'':<22} -> {r['note']}")
    for case, note in pending.items():
        family = case.split(" (")[0]
        n = summary.filter(pl.col("case").str.split("[").list.first() == family).height
        print(f"{'pending':<10} {case:<22} {n} checks not run; {note}")
    c = counts(summary)
    failed = sum(c.get(v, 0) for v in FAILING)
    print(
        f"\n{c['pass']} passed, {failed} failed ({c['fail']} out of bounds, {c['regression']} regressed, "
        f"{c['missing']} missing, {c['error']} errors), {c['pending']} pending (not run, not counted as passed)"
    )
    print("verdict: " + ("RED: the suite failed" if failed else "GREEN: every check that ran holds"))


# ---------------------------------------------------------------------------------- plots
def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")


def plot_checks(path: Path, case: Case, metrics: pl.DataFrame, summary: pl.DataFrame) -> Path | None:
    """Small multiples: every checked metric over seeds, its mean and interval, bound, baseline."""
    rows = [r for r in summary.filter(pl.col("case") == case.name).iter_rows(named=True) if r["n"]]
    if not rows:
        return None
    cols = min(4, len(rows))
    nrows = math.ceil(len(rows) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(3.4 * cols, 2.6 * nrows), squeeze=False)
    for ax, r in zip(axes.flat, rows):
        sel = metrics.filter(
            (pl.col("case") == case.name)
            & (pl.col("source") == r["source"])
            & (pl.col("metric") == r["metric"])
        )
        seeds, values = sel["seed"].to_numpy(), sel["value"].to_numpy()
        ax.scatter(seeds, values, s=14, color="tab:blue", zorder=3, label="seeds")
        if r["mean"] is not None:
            x = seeds.max() + 1 if len(seeds) else 0
            ax.errorbar(
                [x],
                [r["mean"]],
                yerr=[[r["mean"] - r["ci_low"]], [r["ci_high"] - r["mean"]]],
                fmt="o",
                color="k",
                capsize=4,
                label="mean, 95 % CI",
            )
        for key, style in ((case_bound(case, r, "max"), "--"), (case_bound(case, r, "min"), "--")):
            if key is not None:
                ax.axhline(key, color="tab:red", ls=style, lw=1)
        if r["baseline_mean"] is not None:
            ax.axhline(r["baseline_mean"], color="grey", ls=":", lw=1)
        colour = "tab:red" if r["verdict"] in FAILING else "black"
        ax.set_title(
            f"{r['metric']}\n({r['source']}) {MARKS.get(r['verdict'], r['verdict'])}",
            fontsize=8,
            color=colour,
        )
        ticks = [int(v) for v in seeds]
        ax.set_xticks([*ticks, max(ticks, default=-1) + 1], [*map(str, ticks), "mean"])
        ax.tick_params(labelsize=7)
        ax.set_xlabel("seed", fontsize=7)
    for ax in list(axes.flat)[len(rows) :]:
        ax.axis("off")
    fig.suptitle(
        f"{case.name}: checks over seeds (red dashed: bound, grey dotted: baseline mean)", fontsize=9
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def case_bound(case: Case, row: dict[str, Any], which: str) -> float | None:
    for check in case.checks:
        if check.source == row["source"] and check.metric == row["metric"]:
            return getattr(check.bound, which)
    return None


def _estimates(
    job: Job, out: Path, reader: RecordingReader, namespaces: Sequence[str]
) -> dict[str, pl.DataFrame]:
    replayed = out / "replays" / job.name / "localization" / "estimates.parquet"
    if replayed.is_file():
        table = pl.read_parquet(replayed)
        return {ns: table.filter(pl.col("namespace") == ns) for ns in namespaces}
    return estimates_from_recording(reader, namespaces)


def _draw_floor_plan(ax: Any, config: dict[str, Any], cameras: dict[str, Any]) -> None:
    """Draw the occupancy grid of the run's layout and the cameras (^) under the trajectories."""
    from simlan_data.algorithms.occupancy import grid_from_world
    from simlan_data.world.layout import load_layout

    world = config.get("world") or {}
    grid = grid_from_world(
        load_layout(world.get("layout", "warehouse_layout.csv"), world.get("fidelity", "default")),
        resolution_m=0.1,
    )
    x0, y0 = grid.origin_xy_m
    h, w = grid.shape
    ax.imshow(
        grid.occupied,
        origin="lower",
        cmap="Greys",
        alpha=0.45,
        extent=(x0, x0 + w * 0.1, y0, y0 + h * 0.1),
    )
    for cid, cam in cameras.items():
        ax.plot(*cam.position[:2], marker="^", color="tab:purple", ms=5)
        ax.annotate(cid, (float(cam.position[0]), float(cam.position[1])), fontsize=6, color="tab:purple")


def _draw_agent(
    ax: Any, ax_e: Any, k: int, ns: str, colour: Any, gt: pl.DataFrame, agent: dict[str, Any], e: Any
) -> np.ndarray:
    """Draw one agent of seed ``k``: truth, goals (seed 0), estimates and the xy error; return the truth's xy."""
    xy = gt.select("x", "y").to_numpy()
    ax.plot(
        xy[:, 0],
        xy[:, 1],
        color=colour,
        lw=1.2,
        alpha=0.9 if k == 0 else 0.35,
        label=f"{ns} truth" if k == 0 else None,
    )
    goals = np.asarray(agent.get("goals") or [], dtype=float).reshape(-1, 2)
    if k == 0 and len(goals):
        ax.scatter(goals[:, 0], goals[:, 1], marker="x", color=colour, s=40, zorder=4)
    if e is None or e.height == 0:
        return xy
    e = e.filter(pl.col("x").is_not_null())
    ax.scatter(
        e["x"].to_numpy(),
        e["y"].to_numpy(),
        s=1.5,
        color=colour,
        alpha=0.6 if k == 0 else 0.2,
        label=f"{ns} estimate" if k == 0 else None,
    )
    joined = e.join(gt.rename({"x": "gx", "y": "gy", "yaw": "gyaw"}), on="stamp_ns", how="inner")
    if joined.height:
        err = np.hypot((joined["x"] - joined["gx"]).to_numpy(), (joined["y"] - joined["gy"]).to_numpy())
        ax_e.plot(
            joined["stamp_ns"].to_numpy() / 1e9,
            err * 100,
            color=colour,
            lw=0.8,
            alpha=0.9 if k == 0 else 0.35,
            label=f"{ns}" if k == 0 else None,
        )
    return xy


def _save_trajectory_plots(
    path: Path, case: Case, fig: Any, ax: Any, fig_e: Any, ax_e: Any, pts: np.ndarray
) -> tuple[Path, Path | None]:
    """Frame the floor plan around the trajectories, label both figures and write them."""
    ax.set_xlim(pts[:, 0].min() - 4, pts[:, 0].max() + 4)
    ax.set_ylim(pts[:, 1].min() - 4, pts[:, 1].max() + 4)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, map)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=7, loc="upper right", ncols=2)
    ax.set_title(
        f"{case.name}: trajectories over the floor plan (truth lines, estimate dots, goals x, cameras ^; seed 0 bold, other seeds faint)",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    err_path = path.with_name(path.name.replace("_trajectories", "_error"))
    ax_e.set_xlabel("simulated time (s)")
    ax_e.set_ylabel("xy error (cm)")
    ax_e.set_title(f"{case.name}: localization error over time (seed 0 bold, other seeds faint)", fontsize=9)
    if ax_e.lines:
        ax_e.legend(fontsize=7, loc="upper right")
    fig_e.tight_layout()
    fig_e.savefig(err_path, dpi=90)
    plt.close(fig_e)
    return path, err_path if ax_e.lines else None


def plot_trajectories(path: Path, case: Case, jobs: list[Job], out: Path) -> tuple[Path | None, Path | None]:
    """Ground truth and estimates over the floor plan, and the xy error over time, for every seed."""
    from simlan_data.evaluation.replay import ReplayContext

    fig, ax = plt.subplots(figsize=(11, 5.5))
    fig_e, ax_e = plt.subplots(figsize=(11, 3.2))
    extent_pts: list[np.ndarray] = []
    colours = plt.get_cmap("tab10")
    drawn_map = False
    for k, job in enumerate(jobs):
        bag = job.run_dir / RECORDING_DIRNAME
        if job.error or not bag.is_dir():
            continue
        with RecordingReader(bag) as reader:
            ctx = ReplayContext(reader, out)
            config = ctx.config
            truth = ground_truth(reader)
            agents = config.get("agents") or {}
            namespaces = [ns for ns in agents if ns in truth]
            est = _estimates(job, out, reader, namespaces)
            if not drawn_map:
                _draw_floor_plan(ax, config, ctx.cameras)
                drawn_map = True
        for i, ns in enumerate(namespaces):
            xy = _draw_agent(ax, ax_e, k, ns, colours(i % 10), truth[ns], agents[ns] or {}, est.get(ns))
            extent_pts.append(xy)
    if not extent_pts:
        plt.close(fig)
        plt.close(fig_e)
        return None, None
    return _save_trajectory_plots(path, case, fig, ax, fig_e, ax_e, np.vstack(extent_pts))


def copy_birdseye(path: Path, jobs: list[Job], out: Path) -> Path | None:
    for job in jobs:
        src = out / "replays" / job.name / "birdseye" / BIRDSEYE_PNG
        if src.is_file():
            img = cv2.imread(str(src))
            if img is None:
                continue
            scale = 900 / img.shape[1]
            write_image(path, cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA))
            return path
    return None


def plot_posemap(path: Path, case: Case, jobs: list[Job], out: Path) -> Path | None:
    """Pose mapping replayed: joint MAE over time per seed, and the worst joints over all seeds."""
    from simlan_data.evaluation.posemap_replay import FRAMES_FILE, JOINTS_FILE

    found = [
        (j, out / "replays" / j.name / "posemap")
        for j in jobs
        if (out / "replays" / j.name / "posemap" / FRAMES_FILE).is_file()
    ]
    if not found:
        return None
    fig, (ax_t, ax_j) = plt.subplots(1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios": [3, 2]})
    joints = []
    for k, (job, d) in enumerate(found):
        frames = pl.read_parquet(d / FRAMES_FILE)
        ax_t.plot(
            frames["stamp_ns"].to_numpy() / 1e9,
            np.degrees(frames["mae_rad"].to_numpy()),
            lw=1.2 if k == 0 else 0.8,
            alpha=0.9 if k == 0 else 0.4,
            label=f"seed {job.seed}",
        )
        joints.append(pl.read_parquet(d / JOINTS_FILE))
    per_joint = pl.concat(joints).group_by("joint").agg(pl.col("mae_deg").mean()).sort("mae_deg").tail(12)
    ax_j.barh(per_joint["joint"].to_list(), per_joint["mae_deg"].to_list(), color="tab:red", alpha=0.7)
    ax_j.tick_params(axis="y", labelsize=6)
    ax_j.set_xlabel("MAE (deg), mean over seeds")
    ax_j.set_title("worst joints", fontsize=9)
    ax_t.set_xlabel("simulated time (s)")
    ax_t.set_ylabel("MAE over 47 joints (deg)")
    ax_t.set_title(f"{case.name}: predicted vs posed joints per landmark frame", fontsize=9)
    ax_t.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_grid(path: Path, family: str, cases: list[Case], summary: pl.DataFrame) -> Path | None:
    """A sweep slice: the first checked metric's mean over the grid (1-D bars, 2-D heat map)."""
    cells = [c for c in cases if c.family == family and c.grid and not c.pending]
    if not cells:
        return None
    check = cells[0].checks[0]
    keys = list(cells[0].grid)
    means = {}
    for c in cells:
        sel = summary.filter(
            (pl.col("case") == c.name)
            & (pl.col("metric") == check.metric)
            & (pl.col("source") == check.source)
        )
        means[tuple(c.grid[k] for k in keys)] = (
            sel["mean"][0] if sel.height and sel["mean"][0] is not None else np.nan
        )
    fig, ax = plt.subplots(figsize=(6, 4))
    if len(keys) == 1:
        xs = [str(k[0]) for k in means]
        ax.bar(xs, list(means.values()))
        ax.set_xlabel(keys[0])
    else:
        xs = sorted({k[0] for k in means}, key=str)
        ys = sorted({k[1] for k in means}, key=str)
        grid = np.array(
            [
                [np.nanmean([v for k, v in means.items() if k[0] == x and k[1] == y] or [np.nan]) for x in xs]
                for y in ys
            ]
        )
        im = ax.imshow(grid, origin="lower", cmap="viridis")
        ax.set_xticks(range(len(xs)), [str(x) for x in xs])
        ax.set_yticks(range(len(ys)), [str(y) for y in ys])
        ax.set_xlabel(keys[0])
        ax.set_ylabel(keys[1])
        for (j, i), v in np.ndenumerate(grid):
            ax.text(i, j, _num(float(v), ".3g"), ha="center", va="center", color="w", fontsize=8)
        fig.colorbar(im, ax=ax)
    ax.set_title(f"{family}: mean {check.metric} ({check.source})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


# ----------------------------------------------------------------------------------- report
def _header_lines(
    suite: Suite,
    summary: pl.DataFrame,
    faults: list[Fault],
    timings: dict[str, float],
    reused: Path | None,
) -> list[str]:
    """Write the verdict, the run's facts (recordings, faults, overrides, wall times) and how bounds are read."""
    c = counts(summary)
    failed = sum(c.get(v, 0) for v in FAILING)
    lines = [
        f"# V&V suite `{suite.name}`: {'RED' if failed else 'GREEN'}",
        "",
        f"{c['pass']} checks passed, **{failed} failed**, {c['pending']} pending (not run, never counted as passed). "
        f"Suite file `{suite.path}`, baseline `{suite.baseline}`, {100 * suite.confidence:g} % Student-t intervals over seeds.",
        "",
        "| | |",
        "| --- | --- |",
        f"| recordings | {'reused from `' + str(reused) + '`' if reused else 'simulated for this report'} |",
        f"| injected faults | {', '.join(f'`{f.name}` ({f.description})' for f in faults) or 'none'} |",
        f"| overrides of every run | {', '.join(f'`{o}`' for o in suite.overrides) or '-'} |",
    ]
    lines += [f"| {k.replace('_s', '')} wall time | {v:.1f} s |" for k, v in timings.items()]
    lines += [
        "",
        "A bound holds when the whole interval of the mean lies within it; a regression is a change for "
        "the worse beyond the tolerance that the interval of the difference to the baseline shows "
        "(paired over seeds). Tables: `summary.parquet|csv` (checks), `metrics.parquet|csv` (every metric).",
    ]
    return lines


def _checks_lines(summary: pl.DataFrame) -> list[str]:
    """Write the table of checks (failures marked) and the list of pending cases."""
    lines = [
        "",
        "## Checks",
        "",
        "| verdict | case | source | metric | n | mean [95 % CI] | bound | baseline mean | tolerance | note |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    shown, pending = _rows(summary)
    for r in shown:
        verdict = MARKS.get(r["verdict"], r["verdict"])
        verdict = f"**{verdict}**" if r["verdict"] in FAILING else verdict
        lines.append(
            f"| {verdict} | {r['case']} | {r['source']} | `{r['metric']}` | {r['n'] or '-'} | {_ci(r)} | {r['bound']} | "
            f"{_num(r['baseline_mean'])} | {_num(r['tolerance'])} | {r['note'] or ''} |"
        )
    if pending:
        lines += [
            "",
            "## Pending",
            "",
            "Written in the suite but waiting for a capability; not run, not counted as passed.",
            "",
        ]
        lines += [f"- `{case}`: {note}" for case, note in pending.items()]
    return lines


def _case_lines(
    case: Case, jobs: list[Job], out: Path, plots: Path, metrics: pl.DataFrame, summary: pl.DataFrame
) -> list[str]:
    """Write one case's section: description, overrides, and its plots (checks, trajectories, error, pose mapping, bird's-eye)."""
    case_jobs = [j for j in jobs if j.case.name == case.name]
    lines = ["", f"## {case.name}", "", case.description, ""]
    if case.overrides:
        lines += [
            f"Overrides: {', '.join(f'`{o}`' for o in case.overrides)}; seeds {', '.join(map(str, case.seeds))}.",
            "",
        ]
    checks_png = plot_checks(plots / f"{_slug(case.name)}_checks.png", case, metrics, summary)
    if checks_png is not None:
        lines += [f"![checks]({PLOTS_DIR}/{checks_png.name})", ""]
    traj, err = plot_trajectories(plots / f"{_slug(case.name)}_trajectories.png", case, case_jobs, out)
    for png, title in ((traj, "trajectories"), (err, "error over time")):
        if png is not None:
            lines += [f"![{title}]({PLOTS_DIR}/{png.name})", ""]
    pm = plot_posemap(plots / f"{_slug(case.name)}_posemap.png", case, case_jobs, out)
    if pm is not None:
        lines += [f"![pose mapping]({PLOTS_DIR}/{pm.name})", ""]
    be = copy_birdseye(plots / f"{_slug(case.name)}_birdseye.png", case_jobs, out)
    if be is not None:
        lines += [
            "Bird's-eye view (ours, SIMLAN's method, ground truth):",
            "",
            f"![bird's-eye]({PLOTS_DIR}/{be.name})",
            "",
        ]
    return lines


def _runs_lines(jobs: list[Job]) -> list[str]:
    """Write the table of runs: case, seed, run directory and which replays failed."""
    lines = ["", "## Runs", "", "| case | seed | run directory | replays |", "| --- | --- | --- | --- |"]
    for j in jobs:
        status = j.error or ", ".join(
            f"{k}: {'ok' if k in j.sources else 'FAILED ' + v}"
            for k, v in {**dict.fromkeys(j.case.replay, ""), **j.errors}.items()
            if k != "run"
        )
        lines.append(f"| {j.case.name} | {j.seed} | `{j.run_dir}` | {status or '-'} |")
    return lines


def write_report(
    out: Path,
    suite: Suite,
    cases: list[Case],
    jobs: list[Job],
    metrics: pl.DataFrame,
    summary: pl.DataFrame,
    *,
    faults: list[Fault],
    timings: dict[str, float],
    reused: Path | None,
) -> Path:
    """Write report.md: header, checks, one section per grid family or case (with plots), runs."""
    plots = out / PLOTS_DIR
    plots.mkdir(exist_ok=True)
    lines = _header_lines(suite, summary, faults, timings, reused)
    lines += _checks_lines(summary)
    families: dict[str, list[Case]] = {}
    for case in cases:
        if not case.pending:
            families.setdefault(case.family if case.grid else case.name, []).append(case)
    for family, members in families.items():
        if members[0].grid:
            lines += ["", f"## {family} (grid of {len(members)} cells)", ""]
            grid_png = plot_grid(plots / f"{_slug(family)}_grid.png", family, cases, summary)
            if grid_png is not None:
                lines += [f"![{family} grid]({PLOTS_DIR}/{grid_png.name})", ""]
            continue
        lines += _case_lines(members[0], jobs, out, plots, metrics, summary)
    lines += _runs_lines(jobs)
    path = out / REPORT_NAME
    path.write_text("\n".join(lines) + "\n")
    return path
