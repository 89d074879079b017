"""The ``rtf`` sweep report: real-time factor against camera count and streams, beside SIMLAN.

    python -m simlan_data.run -m experiment=rtf
        -> <sweep dir>/sweep_metrics.parquet (one row per job, evaluation/sweep.py)
        -> rtf_table.md   RTF per camera count x stream set, SIMLAN's published numbers beside
        -> rtf.png        RTF against cameras (log scale), ours and SIMLAN's, both stream sets

SIMLAN's numbers are its published real-time factors (Gazebo on an Intel i9 with an RTX 2070,
an empty world), as quoted in issue 8.
"""

from __future__ import annotations

import os
from pathlib import Path

import polars as pl

# cameras -> real-time factor, SIMLAN (Gazebo, i9 + RTX 2070, empty world)
SIMLAN_RTF: dict[str, dict[int, float]] = {
    "image only": {1: 0.99, 2: 0.56, 4: 0.34, 6: 0.23, 9: 0.17, 12: 0.07},
    "image + depth + semantic": {1: 0.44, 2: 0.22, 4: 0.09, 6: 0.07, 9: 0.05, 12: 0.02},
}
# our stream sets (conf/streams) and what they are, in table order
STREAM_SETS: dict[str, str] = {
    "rgb": "RGB",
    "rgbds": "RGB + depth + semantic (depth, labels recorded at 1 Hz)",
    "rgbds_full": "RGB + depth + semantic (all recorded at 5 Hz)",
}
TABLE_FILENAME = "rtf_table.md"
PLOT_FILENAME = "rtf.png"


def rtf_rows(table: pl.DataFrame) -> pl.DataFrame:
    """One row per finished job: cameras, stream set, RTF and what it cost."""
    ok = table.filter(pl.col("status") == "ok")
    cameras = (
        pl.col("override.cameras.count").cast(pl.Int64)
        if "override.cameras.count" in ok.columns
        else pl.col("sim.cameras").cast(pl.Int64)
    )
    streams = (
        pl.col("override.streams").cast(pl.String) if "override.streams" in ok.columns else pl.lit("as run")
    )
    optional = [
        c
        for c in ("sim.camera_frames_changed", "sim.camera_frames", "sim.cpu_s", "recording.bytes")
        if c in ok.columns
    ]
    return ok.select(
        cameras.alias("cameras"),
        streams.alias("streams"),
        pl.col("sim.rtf").alias("rtf"),
        pl.col("sim.wall_s").alias("wall_s"),
        *[pl.col(c) for c in optional],
    ).sort("cameras", "streams")


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def markdown(rows: pl.DataFrame) -> str:
    """The RTF table (ours per stream set, SIMLAN's beside) and the per-job details."""
    sets = [s for s in STREAM_SETS if s in set(rows["streams"])] + sorted(
        set(rows["streams"]) - set(STREAM_SETS)
    )
    counts = sorted(set(rows["cameras"]) | {c for v in SIMLAN_RTF.values() for c in v})
    rtf = {(r["cameras"], r["streams"]): r["rtf"] for r in rows.iter_rows(named=True)}
    header = [
        "cameras",
        *[f"ours: {STREAM_SETS.get(s, s)}" for s in sets],
        *[f"SIMLAN: {k}" for k in SIMLAN_RTF],
    ]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    for n in counts:
        cells = [
            str(n),
            *[_fmt(rtf.get((n, s))) for s in sets],
            *[_fmt(v.get(n)) for v in SIMLAN_RTF.values()],
        ]
        lines.append("| " + " | ".join(cells) + " |")
    details = [
        "",
        "| cameras | streams | RTF | loop wall s | frames changed / all | process CPU s | recording MiB |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows.iter_rows(named=True):
        changed = (
            f"{int(r['sim.camera_frames_changed'])} / {int(r['sim.camera_frames'])}"
            if r.get("sim.camera_frames") is not None
            else "-"
        )
        cpu = _fmt(r.get("sim.cpu_s"))
        mib = f"{r['recording.bytes'] / 2**20:.0f}" if r.get("recording.bytes") else "-"
        details.append(
            f"| {r['cameras']} | {r['streams']} | {r['rtf']:.2f} | {r['wall_s']:.1f} | {changed} | {cpu} | {mib} |"
        )
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    note = [
        "",
        "SIMLAN: its published real-time factors (Gazebo, Intel i9 + RTX 2070, empty world).",
        f"Load average when the sweep finished: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores"
        " (timed figures depend on what else runs)."
        if load is not None
        else "",
    ]
    return "\n".join(lines + details + note) + "\n"


def plot(rows: pl.DataFrame, path: Path) -> None:
    """RTF against cameras: ours per stream set, SIMLAN's two series, real time marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=120)
    for (name, series), style in zip(SIMLAN_RTF.items(), ("--", ":")):
        xs = sorted(series)
        ax.plot(xs, [series[x] for x in xs], style, color="grey", marker="x", label=f"SIMLAN: {name}")
    for s in [s for s in STREAM_SETS if s in set(rows["streams"])] + sorted(
        set(rows["streams"]) - set(STREAM_SETS)
    ):
        sub = rows.filter(pl.col("streams") == s).sort("cameras")
        ax.plot(sub["cameras"].to_list(), sub["rtf"].to_list(), "-o", label=f"ours: {STREAM_SETS.get(s, s)}")
    ax.axhline(1.0, color="black", linewidth=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("cameras (the first N of 160-171)")
    ax.set_ylabel("real-time factor")
    ax.set_title("Real-time factor against cameras (four moving robots, recording on)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def rtf_report(table: pl.DataFrame, sweep_dir: Path) -> None:
    """Write rtf_table.md and rtf.png into the sweep directory; print the table."""
    rows = rtf_rows(table)
    if rows.is_empty():
        print("rtf report: no finished job", flush=True)
        return
    text = markdown(rows)
    (sweep_dir / TABLE_FILENAME).write_text(text)
    plot(rows, sweep_dir / PLOT_FILENAME)
    print(text, flush=True)
    print(f"rtf report -> {sweep_dir / TABLE_FILENAME}, {sweep_dir / PLOT_FILENAME}", flush=True)
