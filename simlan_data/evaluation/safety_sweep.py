"""Sweep report ``collision``: SIMLAN's collision families, collisions avoided per case.

An experiment (``conf/experiment/collision_case1.yaml``, ``collision_case2.yaml``) sweeps
``collision.angle``, ``collision.truck_speed_mps``, ``collision.collision_type`` and
``collision.guarded`` (which robots run a safety tree: none, SIMLAN's setup with only the Jackal,
both). After the sweep, the aggregation callback hands the table of every job's metrics here;
this writes ``collision_sweep.md`` (one row per case: collided or not and the smallest gap per
guard setup; totals; collisions avoided against the unguarded run of the same case) and
``collision_sweep.png`` (the same as coloured grids).
"""

from __future__ import annotations

from pathlib import Path

import polars as pl

REPORT_MD = "collision_sweep.md"
REPORT_PNG = "collision_sweep.png"
TYPES = {0: "head-on", 1: "pallet-truck side", 2: "Jackal side"}
GUARDS = ("none", "jackal", "both")
KEYS = ("angle", "truck_speed_mps", "collision_type")


def _col(table: pl.DataFrame, name: str, default: object) -> pl.Expr:
    return pl.col(name) if name in table.columns else pl.lit(default)


def collision_table(table: pl.DataFrame) -> pl.DataFrame:
    """One row per (case, guard setup): collided, collisions, smallest gap, stops."""
    return (
        table.select(
            _col(table, "override.collision.angle", 90.0).cast(pl.Float64).alias("angle"),
            _col(table, "override.collision.truck_speed_mps", 1.0).cast(pl.Float64).alias("truck_speed_mps"),
            _col(table, "override.collision.collision_type", 0).cast(pl.Int64).alias("collision_type"),
            _col(table, "override.collision.guarded", "both").cast(pl.String).alias("guarded"),
            pl.col("status"),
            _col(table, "safety.violations.collisions", None).cast(pl.Float64).alias("collisions"),
            _col(table, "safety.min_clearance_agents_m", None).cast(pl.Float64).alias("min_gap_m"),
            _col(table, "safety.stops", None).cast(pl.Float64).alias("stops"),
            _col(table, "safety.missed", None).cast(pl.Float64).alias("missed"),
            _col(table, "safety.slows", None).cast(pl.Float64).alias("slows"),
            _col(table, "safety.false_stops", None).cast(pl.Float64).alias("false_stops"),
            _col(table, "safety.max_latency_s", None).cast(pl.Float64).alias("max_latency_s"),
            _col(table, "localization.ate_xy_rmse_m", None).cast(pl.Float64).alias("ate_m"),
            pl.min_horizontal(
                _col(table, "localization.robot_agent_1.ticks_valid", None),
                _col(table, "localization.robot_agent_2.ticks_valid", None),
            )
            .cast(pl.Float64)
            .alias("localized_ticks"),
        )
        .with_columns((pl.col("collisions") > 0).alias("collided"))
        .sort(["collision_type", "angle", "truck_speed_mps", "guarded"])
    )


def summarize(cases: pl.DataFrame) -> list[str]:
    """Markdown lines: per-case table and totals."""
    guards = [g for g in GUARDS if g in set(cases["guarded"].to_list())]
    header = "| type | angle (deg) | truck m/s | " + " | ".join(f"guarded: {g}" for g in guards) + " |"
    lines = [header, "|" + " --- |" * (3 + len(guards))]
    for key, group in cases.group_by(list(KEYS), maintain_order=True):
        angle, speed, ctype = key
        cells = []
        for g in guards:
            row = group.filter(pl.col("guarded") == g)
            if row.height == 0:
                cells.append("-")
            elif row["status"][0] != "ok" or row["collisions"][0] is None:
                cells.append("failed")
            elif row["localized_ticks"][0] is not None and row["localized_ticks"][0] == 0:
                cells.append("not localized")  # a robot never seen by the cameras: no valid case
            else:
                gap = row["min_gap_m"][0]
                cells.append(("**collision**" if row["collided"][0] else "no contact") + f" ({gap:.2f} m)")
        lines.append(
            f"| {TYPES.get(int(ctype), ctype)} | {angle:g} | {speed:g} | " + " | ".join(cells) + " |"
        )
    lines += [
        "",
        "Totals (cells above: outcome and the smallest gap between the two footprints; 'not localized': "
        "a robot the cameras never found, the case says nothing about the safety layer):",
        "",
    ]
    base = cases.filter(pl.col("guarded") == "none").select([*KEYS, pl.col("collided").alias("base")])
    for g in guards:
        sub = cases.filter((pl.col("guarded") == g) & (pl.col("status") == "ok"))
        lost = sub.filter(pl.col("localized_ticks") == 0).height
        sub = sub.filter(pl.col("localized_ticks").is_null() | (pl.col("localized_ticks") > 0))
        n, hit = sub.height, int(sub["collided"].sum() or 0)
        line = f"- guarded {g}: {hit} of {n} runs collided" + (
            f" ({lost} not localized, left out)" if lost else ""
        )
        if g != "none" and base.height:
            joined = sub.join(base, on=list(KEYS), how="inner")
            would = int(joined["base"].sum() or 0)
            avoided = int((joined["base"] & ~joined["collided"]).sum() or 0)
            line += f"; of the {would} cases that collide unguarded, {avoided} avoided"
        if g != "none" and n:
            lat = sub["max_latency_s"].drop_nans().drop_nulls().to_list()
            line += (
                f"; {int(sub['stops'].sum() or 0)} stops, {int(sub['slows'].sum() or 0)} slow-downs, "
                f"{int(sub['false_stops'].sum() or 0)} false stops, "
                f"max latency {max(lat) if lat else float('nan'):.2f} s"
            )
        ate = sub["ate_m"].drop_nans().drop_nulls().to_list()
        if ate:
            line += f"; localization ATE at most {max(ate) * 100:.1f} cm"
        lines.append(line)
    return lines


def plot(cases: pl.DataFrame, path: Path) -> None:
    """Grids angle x truck speed per collision type and guard setup: red collided, green not."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    guards = [g for g in GUARDS if g in set(cases["guarded"].to_list())]
    types = sorted(set(cases["collision_type"].to_list()))
    angles = sorted(set(cases["angle"].to_list()))
    speeds = sorted(set(cases["truck_speed_mps"].to_list()))
    fig, axes = plt.subplots(
        len(types), len(guards), figsize=(3.2 * len(guards), 2.6 * len(types)), squeeze=False
    )
    cmap = ListedColormap(["#4caf50", "#e53935", "#bdbdbd"])
    for r, ctype in enumerate(types):
        for c, g in enumerate(guards):
            ax = axes[r][c]
            grid = [[2.0] * len(speeds) for _ in angles]
            labels = [[""] * len(speeds) for _ in angles]
            for row in cases.filter((pl.col("collision_type") == ctype) & (pl.col("guarded") == g)).iter_rows(
                named=True
            ):
                i, j = angles.index(row["angle"]), speeds.index(row["truck_speed_mps"])
                if row["collisions"] is not None:
                    grid[i][j] = 1.0 if row["collided"] else 0.0
                    labels[i][j] = f"{row['min_gap_m']:.2f}"
            ax.imshow(grid, cmap=cmap, vmin=0, vmax=2, aspect="auto")
            for i in range(len(angles)):
                for j in range(len(speeds)):
                    ax.text(j, i, labels[i][j], ha="center", va="center", fontsize=8)
            ax.set_xticks(range(len(speeds)), [f"{s:g}" for s in speeds])
            ax.set_yticks(range(len(angles)), [f"{a:g}" for a in angles])
            ax.set_title(f"{TYPES.get(int(ctype), ctype)}, guarded: {g}", fontsize=9)
            if r == len(types) - 1:
                ax.set_xlabel("truck speed (m/s)")
            if c == 0:
                ax.set_ylabel("angle (deg)")
    fig.suptitle("Collisions (red) per case; numbers: smallest gap between footprints (m)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def collision_report(table: pl.DataFrame, sweep_dir: Path) -> None:
    cases = collision_table(table)
    cases.write_csv(sweep_dir / "collision_cases.csv")
    lines = [
        "# SIMLAN's collision families: collisions with and without the safety layer",
        "",
        f"Sweep: `{sweep_dir}`, {table.height} runs. `guarded`: robots with a safety tree (none; "
        "jackal: SIMLAN's setup, only the Jackal has a safety stop; both). Types: head-on (fronts meet), "
        "pallet-truck side (the Jackal drives into the truck's side), Jackal side (the truck drives "
        "into the Jackal's side); angle: the Jackal's heading relative to the truck's (0: catch-up, "
        "180: head-on on one line).",
        "",
        *summarize(cases),
        "",
        f"![collisions per case]({REPORT_PNG})",
        "",
    ]
    (sweep_dir / REPORT_MD).write_text("\n".join(lines))
    plot(cases, sweep_dir / REPORT_PNG)
    print(f"collision report -> {sweep_dir / REPORT_MD}", flush=True)
