"""The report's figures: trajectories on the map, localization error and speed over time.

Drawn with matplotlib's object API on its Agg canvas (no pyplot, no display), imported here only:
``--help`` and config errors never load it. Sizes are fixed (``FIGURE_SIZES``), so a report
looks the same for every run. Colours: one per agent (``AGENT_COLOURS``, truth and estimate
alike); events in ``EVENT_COLOURS``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from simlan_data.evaluation.report_series import AgentSeries, RunSeries

TRAJECTORIES_FILENAME = "report_trajectories.png"
ERROR_FILENAME = "report_error.png"
TIMELINE_FILENAME = "report_timeline.png"
DPI = 100
FIGURE_SIZES = {  # inches at DPI (the timeline grows by TIMELINE_ROW_IN per agent)
    TRAJECTORIES_FILENAME: (10.0, 6.0),
    ERROR_FILENAME: (10.0, 4.5),
    TIMELINE_FILENAME: (10.0, 1.0),
}
TIMELINE_ROW_IN = 2.0
MAX_TIMELINE_AGENTS = 8
MAP_MARGIN_M = 3.0
LAYOUT = None
PNG_OPTIONS = {"compress_level": 1}  # zlib's fastest: 6 (the default) took x ms a figure
AGENT_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
EVENT_COLOURS = {"stop": "#d62728", "slow": "#ffbf00", "resume": "#2ca02c"}
ZONE_COLOUR = "#d62728"
CAMERA_COLOUR = "#7f7f7f"


def agent_colour(index: int) -> str:
    return AGENT_COLOURS[index % len(AGENT_COLOURS)]


def write_figures(run_dir: Path, series: RunSeries, floor: Any | None) -> dict[str, float]:
    """Draw every figure that has data into ``run_dir``; returns {file name: seconds it took}
    (matplotlib's import counted in the first)."""
    t0 = time.perf_counter()
    import matplotlib

    matplotlib.use("Agg")  # files only: no display here or in CI
    from matplotlib.figure import Figure

    timings: dict[str, float] = {}
    drawers: list[tuple[str, Callable[[Any, RunSeries, Any], bool]]] = [
        (TRAJECTORIES_FILENAME, draw_trajectories),
        (ERROR_FILENAME, draw_errors),
        (TIMELINE_FILENAME, draw_timeline),
    ]
    for name, draw in drawers:
        width, height = FIGURE_SIZES[name]
        if name == TIMELINE_FILENAME:
            height += TIMELINE_ROW_IN * max(1, len(_moving(series)))
        fig = Figure(figsize=(width, height), dpi=DPI, layout=LAYOUT)
        if draw(fig, series, floor):
            fig.savefig(run_dir / name, dpi=DPI, pil_kwargs=PNG_OPTIONS)
        timings[name] = time.perf_counter() - t0
        t0 = time.perf_counter()
    return timings


def _margins(
    fig: Any, *, left: float = 0.9, right: float = 0.2, top: float = 0.45, bottom: float = 0.6
) -> None:
    """Fixed margins in inches (a layout engine measures every label first: 0.1-0.3 s a figure)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1 - right / w, top=1 - top / h, bottom=bottom / h, hspace=0.35)


def _moving(series: RunSeries) -> list[AgentSeries]:
    """Agents that drive or walk (commands or goals), at most MAX_TIMELINE_AGENTS."""
    out = [a for a in series.agents.values() if len(a.commanded) or len(a.goals)]
    return out[:MAX_TIMELINE_AGENTS]


# ------------------------------------------------------------------------------- the map
def draw_trajectories(fig: Any, series: RunSeries, floor: Any | None) -> bool:
    """Ground truth (lines), camera estimates (dots), goals (x), zones and cameras on the floor plan."""
    ax = fig.add_subplot()
    _margins(fig, left=0.7)
    points = [a.truth[:, 1:3] for a in series.agents.values() if len(a.truth)]
    points += [a.goals for a in series.agents.values() if len(a.goals)]
    points += [poly for _, poly in series.zones]
    if not points:
        return False
    pts = np.concatenate(points)
    x0, y0 = pts.min(axis=0) - MAP_MARGIN_M
    x1, y1 = pts.max(axis=0) + MAP_MARGIN_M
    for cid, (position, footprint) in sorted(series.cameras.items()):
        if footprint is not None:
            ax.fill(*footprint.T, color=CAMERA_COLOUR, alpha=0.06, lw=0)
        if x0 <= position[0] <= x1 and y0 <= position[1] <= y1:
            ax.plot(position[0], position[1], marker="^", color=CAMERA_COLOUR, ms=6, ls="none")
            ax.annotate(
                cid,
                (position[0], position[1]),
                fontsize=7,
                color=CAMERA_COLOUR,
                xytext=(3, 3),
                textcoords="offset points",
            )
    for name, poly in series.zones:
        ax.fill(*poly.T, color=ZONE_COLOUR, alpha=0.15, lw=0)
        ax.plot(*poly.T, color=ZONE_COLOUR, lw=1.2)
        ax.annotate(name, tuple(poly.mean(axis=0)), color=ZONE_COLOUR, fontsize=8, ha="center")
    for k, a in enumerate(series.agents.values()):
        colour = agent_colour(k)
        if len(a.truth):
            ax.plot(a.truth[:, 1], a.truth[:, 2], color=colour, lw=1.6, label=f"{a.namespace} truth")
            ax.plot(a.truth[0, 1], a.truth[0, 2], marker="o", color=colour, ms=6, ls="none")
        valid = a.estimate[a.estimate[:, 4] > 0] if len(a.estimate) else a.estimate
        if len(valid):
            ax.plot(
                valid[:, 1],
                valid[:, 2],
                ".",
                color=colour,
                ms=2.5,
                alpha=0.6,
                label=f"{a.namespace} estimate",
            )
        if len(a.goals):
            ax.plot(a.goals[:, 0], a.goals[:, 1], marker="x", color=colour, ms=9, mew=2, ls="none")
            for i, (gx, gy) in enumerate(a.goals):
                ax.annotate(
                    str(i + 1),
                    (gx, gy),
                    fontsize=7,
                    color=colour,
                    xytext=(4, -10),
                    textcoords="offset points",
                )
    x0, x1, y0, y1 = _frame_equal(fig, ax, (x0, x1, y0, y1))
    if floor is not None:
        _draw_floor(ax, floor, (x0, x1, y0, y1))
    ax.set_xlabel("x (m, map frame)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        "Trajectories: truth (line, o = start), camera estimate (dots), goals (x), zones (red), cameras (^)",
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="best", ncols=2)
    ax.grid(alpha=0.25)
    return True


def _frame_equal(
    fig: Any, ax: Any, box: tuple[float, float, float, float]
) -> tuple[float, float, float, float]:
    """Show ``box`` (x0, x1, y0, y1) at one scale on both axes, grown to the axes' shape."""
    x0, x1, y0, y1 = box
    pos = ax.get_position()
    w_in, h_in = fig.get_size_inches()
    shape = (pos.width * w_in) / (pos.height * h_in)
    if (x1 - x0) / (y1 - y0) < shape:
        half = (y1 - y0) * shape / 2
        x0, x1 = (x0 + x1) / 2 - half, (x0 + x1) / 2 + half
    else:
        half = (x1 - x0) / shape / 2
        y0, y1 = (y0 + y1) / 2 - half, (y0 + y1) / 2 + half
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    return x0, x1, y0, y1


def _draw_floor(ax: Any, floor: Any, box: tuple[float, float, float, float]) -> None:
    """The occupancy grid's cells inside ``box``, under everything else (obstacles grey)."""
    fx, fy = floor.origin_xy_m
    res = floor.resolution_m
    rows, cols = floor.shape
    c0, c1 = (int(np.clip(np.floor((v - fx) / res), 0, cols)) for v in box[:2])
    r0, r1 = (int(np.clip(np.floor((v - fy) / res), 0, rows)) for v in box[2:])
    c1, r1 = min(cols, c1 + 1), min(rows, r1 + 1)
    if c1 <= c0 or r1 <= r0:
        return
    ax.imshow(
        floor.occupied[r0:r1, c0:c1],
        origin="lower",
        cmap="Greys",
        vmin=0,
        vmax=2.2,  # obstacles mid grey: the lines over them stay readable
        extent=(fx + c0 * res, fx + c1 * res, fy + r0 * res, fy + r1 * res),
        interpolation="nearest",
        zorder=0,
    )


# ------------------------------------------------------------------------------ the error
def draw_errors(fig: Any, series: RunSeries, _floor: Any | None = None) -> bool:
    """Position error (cm) and heading error (deg) of the camera estimates over time, per agent."""
    errors = {k: (a, a.errors()) for k, a in enumerate(series.agents.values())}
    errors = {k: v for k, v in errors.items() if len(v[1])}
    if not errors:
        return False
    ax_xy, ax_yaw = fig.subplots(2, 1, sharex=True)
    for k, (a, err) in errors.items():
        t = _with_gaps(err[:, 0])
        ax_xy.plot(t, _gaps_like(t, err[:, 1] * 100), color=agent_colour(k), lw=1.0, label=a.namespace)
        ax_yaw.plot(t, _gaps_like(t, err[:, 2]), color=agent_colour(k), lw=1.0)
    ax_xy.set_ylabel("xy error (cm)")
    ax_yaw.set_ylabel("yaw error (deg)")
    ax_yaw.set_xlabel("simulated time (s)")
    ax_xy.set_xlim(0, max(series.duration_s, 1e-3))
    ax_xy.set_title("Localization error of the camera estimates (gaps: no valid estimate)", fontsize=9)
    ax_xy.legend(fontsize=7, loc="upper right")
    for ax in (ax_xy, ax_yaw):
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.25)
    _margins(fig)
    return True


def _with_gaps(t: np.ndarray) -> np.ndarray:
    """``t`` with a NaN after every jump longer than three typical steps (a line break there)."""
    if len(t) < 3:
        return t
    dt = np.diff(t)
    jumps = np.flatnonzero(dt > 3 * np.median(dt))
    return np.insert(t.astype(float), jumps + 1, np.nan)


def _gaps_like(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` with a NaN wherever :func:`_with_gaps` put one into ``t``."""
    out = np.full(len(t), np.nan)
    out[~np.isnan(t)] = values
    return out


# ---------------------------------------------------------------------------- the timeline
def draw_timeline(fig: Any, series: RunSeries, _floor: Any | None = None) -> bool:
    """Per agent: speed commanded, true and estimated, with safety stops and slow-downs (shaded),
    goals reached or failed and collisions marked."""
    agents = _moving(series)
    if not agents:
        return False
    axes = np.atleast_1d(fig.subplots(len(agents), 1, sharex=True, squeeze=False)[:, 0])
    index = {ns: k for k, ns in enumerate(series.agents)}
    for ax, a in zip(axes, agents, strict=True):
        colour = agent_colour(index[a.namespace])
        truth = a.true_speed()
        if len(truth):
            ax.plot(truth[:, 0], truth[:, 1], color=colour, lw=1.4, label="true")
        if len(a.commanded):
            ax.step(
                a.commanded[:, 0],
                a.commanded[:, 1],
                where="post",
                color="black",
                lw=0.9,
                ls="--",
                label="commanded",
            )
        if len(a.estimated_speed):
            ax.plot(
                a.estimated_speed[:, 0],
                a.estimated_speed[:, 1],
                ".",
                color=colour,
                ms=2,
                alpha=0.5,
                label="estimated",
            )
        _shade_safety(ax, [e for e in series.events if e.namespace == a.namespace], series.duration_s)
        _mark_times(ax, a.goals_reached_s, "goal", "#2ca02c", "-")
        _mark_times(ax, a.goals_failed_s, "goal failed", "#d62728", ":")
        for t in a.collisions_s:
            ax.plot(t, 0.0, marker="X", color="black", ms=9, ls="none")
        ax.set_ylabel(f"{a.namespace}\nspeed (m/s)", fontsize=8)
        ax.grid(alpha=0.25)
    axes[-1].set_xlabel("simulated time (s)")
    axes[0].set_xlim(0, max(series.duration_s, 1e-3))
    axes[0].set_title(
        "Speed and events: safety stops (red) and slow-downs (yellow), goals reached (green), collisions (X)",
        fontsize=9,
        loc="left",
    )
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="upper right", ncols=3, frameon=False)
    _margins(fig, top=0.55)
    return True


def _mark_times(ax: Any, times: Sequence[float], text: str, colour: str, style: str) -> None:
    """A labelled vertical line at each time (goals reached, goals failed)."""
    for t in times:
        ax.axvline(t, color=colour, lw=1.2, ls=style)
        ax.annotate(
            text,
            (t, 1.0),
            xycoords=("data", "axes fraction"),
            fontsize=7,
            color=colour,
            xytext=(2, -10),
            textcoords="offset points",
        )


def _shade_safety(ax: Any, events: list[Any], end_s: float) -> None:
    """Shade each stop or slow-down from its event to the next event of that robot (or the end)."""
    for k, e in enumerate(events):
        if e.action not in ("stop", "slow"):
            continue
        until = events[k + 1].t_s if k + 1 < len(events) else end_s
        ax.axvspan(e.t_s, max(until, e.t_s + 0.05), color=EVENT_COLOURS[e.action], alpha=0.25, lw=0)
        ax.annotate(
            e.cause,
            (e.t_s, 0.0),
            xycoords=("data", "axes fraction"),
            fontsize=7,
            color=EVENT_COLOURS[e.action],
            xytext=(2, 3),
            textcoords="offset points",
        )
