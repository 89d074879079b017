"""Fleet metrics of a run (``fleet.*``): tasks, throughput, waits, makespan, clearance, deadlocks.

From the recording alone: ground-truth poses (``/ground_truth/poses``) and each robot's recorded
navigation status (``/<ns>/navigation_status``: goals reached and failed, when). Computed for
every run with at least one robot that has goals; ``scenario=fleet`` runs are what they are for.

Definitions (what a sweep compares):

- a robot has a *pending goal* from its first status until it has reached or failed its last;
- *task*: goals ``2k`` and ``2k+1`` of a robot (pickup, drop-off; charger, home as
  :mod:`simlan_data.config.missions` makes them); a last unpaired goal is the return home and no
  task. ``tasks_completed``: tasks whose two goals were reached; ``tasks_per_hour``: those over
  the makespan (over the run's length when missions were left unfinished);
- ``makespan_s``: from the first ground-truth stamp to the last goal reached, when every goal of
  every robot was reached; the run's length otherwise (``missions_done`` says which);
- *waiting*: a robot with a pending goal that stands still (below ``STILL_MPS`` and
  ``STILL_RPS``, over ``SAMPLE_S`` steps); ``wait_s_mean`` / ``wait_s_max``: length of such
  stretches of at least ``MIN_WAIT_S``; ``wait_share``: standing share of pending robot-time;
- ``min_clearance_m``: the smallest footprint-to-footprint distance (shapely polygons of
  :attr:`AgentType.footprint_m` at the true poses) between two robots; 0 when they touch;
- *deadlock*: two or more robots with pending goals, each of which has not left a disc of
  ``DEADLOCK_MOVE_M`` for ``DEADLOCK_S`` seconds, linked to each other (each waits for another of
  the group on its navigation status, or their footprints are within ``DEADLOCK_NEAR_M``).
  ``deadlocks``: how many times such a group formed; ``deadlock_s``: time with one.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import polars as pl
import shapely
from numpy.typing import NDArray

from simlan_data.constants import NS_PER_S
from simlan_data.world.agent_types import AgentType

__all__ = ["DEADLOCK_MOVE_M", "DEADLOCK_S", "GOALS_PER_TASK", "MIN_WAIT_S", "Status", "fleet_metrics"]

GOALS_PER_TASK = 2
SAMPLE_S = 0.1  # the ground truth is resampled to this step
STILL_MPS = 0.05
STILL_RPS = 0.05
MIN_WAIT_S = 0.5  # shorter stands (a stop at a goal, a turn's start) are no wait
DEADLOCK_MOVE_M = 0.1
DEADLOCK_S = 20.0
DEADLOCK_NEAR_M = 2.0

# one navigation status: stamp_ns, goals_total, goals_reached, goals_failed, blocked_by
Status = tuple[int, int, int, int, tuple[str, ...]]


def _resample(table: pl.DataFrame, times_ns: NDArray[np.int64]) -> NDArray[np.float64]:
    """(T, 3) x, y, yaw of a ground-truth table at ``times_ns`` (last pose at or before each)."""
    stamps = table["stamp_ns"].to_numpy()
    idx = np.clip(np.searchsorted(stamps, times_ns, side="right") - 1, 0, len(stamps) - 1)
    return np.column_stack([table[c].to_numpy()[idx] for c in ("x", "y", "yaw")])


def _status_at(
    history: list[Status], times_ns: NDArray[np.int64]
) -> tuple[NDArray[np.bool_], list[tuple[str, ...]]]:
    """Whether the robot has a pending goal at each time, and whom it waits for."""
    stamps = np.array([h[0] for h in history], dtype=np.int64)
    idx = np.searchsorted(stamps, times_ns, side="right") - 1
    pending = np.array([i >= 0 and history[i][2] + history[i][3] < history[i][1] for i in idx], dtype=bool)
    blocked = [history[i][4] if i >= 0 else () for i in idx]
    return pending, blocked


def _goal_outcomes(history: list[Status]) -> list[tuple[bool, int]]:
    """(reached, stamp_ns) of each goal finished, in goal order (goals are done one after another)."""
    out: list[tuple[bool, int]] = []
    reached = failed = 0
    for stamp, _, r, f, _ in history:
        out += [(False, stamp)] * max(0, f - failed)  # (one status rarely finishes two goals)
        out += [(True, stamp)] * max(0, r - reached)
        reached, failed = max(reached, r), max(failed, f)
    return out


def _footprints(kind: AgentType, poses: NDArray[np.float64]) -> NDArray[np.object_]:
    """Shapely polygons of ``kind``'s footprint at each (x, y, yaw) pose."""
    x0, x1, y0, y1 = kind.footprint_m
    local = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    wx = poses[:, 0:1] + c * local[:, 0] - s * local[:, 1]
    wy = poses[:, 1:2] + s * local[:, 0] + c * local[:, 1]
    return shapely.polygons(np.stack([wx, wy], axis=2))


def _stretches(flags: NDArray[np.bool_]) -> list[int]:
    """Lengths (in samples) of the runs of True in ``flags``."""
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [int(b - a) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _stuck(poses: NDArray[np.float64], pending: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Pending and within DEADLOCK_MOVE_M of every pose of the last DEADLOCK_S seconds."""
    window = round(DEADLOCK_S / SAMPLE_S)
    out = np.zeros(len(poses), dtype=bool)
    for t in range(window, len(poses)):
        if pending[t - window : t + 1].all():
            span = poses[t - window : t + 1, :2]
            out[t] = bool(np.hypot(*(span - poses[t, :2]).T).max() < DEADLOCK_MOVE_M)
    return out


def _deadlocked(
    names: list[str],
    stuck: dict[str, NDArray[np.bool_]],
    blocked: dict[str, list[tuple[str, ...]]],
    gaps: dict[tuple[str, str], NDArray[np.float64]],
    t: int,
) -> bool:
    """Whether two or more stuck robots at sample ``t`` form a linked group (see the module)."""
    now = [ns for ns in names if stuck[ns][t]]
    for ns in now:
        for other in now:
            if other == ns:
                continue
            key = (ns, other) if (ns, other) in gaps else (other, ns)
            if other in blocked[ns][t] or gaps[key][t] <= DEADLOCK_NEAR_M:
                return True
    return False


def fleet_metrics(
    truth: Mapping[str, pl.DataFrame], status: Mapping[str, list[Status]], kinds: Mapping[str, AgentType]
) -> dict[str, float]:
    """``fleet.*`` of the robots in ``status`` (their navigation status history) that have goals."""
    names = [
        ns for ns, h in status.items() if h and max(s[1] for s in h) > 0 and ns in truth and truth[ns].height
    ]
    if not names:
        return {}
    start = min(int(truth[ns]["stamp_ns"][0]) for ns in names)
    end = max(int(truth[ns]["stamp_ns"][-1]) for ns in names)
    step = round(SAMPLE_S * NS_PER_S)
    times = np.arange(start, end + 1, step, dtype=np.int64)
    poses = {ns: _resample(truth[ns], times) for ns in names}
    pend_block = {ns: _status_at(status[ns], times) for ns in names}
    out: dict[str, float] = {}
    # tasks and makespan
    tasks = goals = reached_all = 0
    last_reach = start
    for ns in names:
        outcomes = _goal_outcomes(status[ns])
        total = max(s[1] for s in status[ns])
        goals += total
        reached_all += sum(ok for ok, _ in outcomes)
        tasks += sum(
            1 for k in range(0, len(outcomes) - 1, GOALS_PER_TASK) if outcomes[k][0] and outcomes[k + 1][0]
        )
        last_reach = max([last_reach, *(stamp for ok, stamp in outcomes if ok)])
    done = reached_all == goals
    makespan = (last_reach if done else end) - start
    out["fleet.robots"] = float(len(names))
    out["fleet.tasks_total"] = float(sum(max(s[1] for s in status[ns]) // GOALS_PER_TASK for ns in names))
    out["fleet.tasks_completed"] = float(tasks)
    out["fleet.missions_done"] = float(done)
    out["fleet.makespan_s"] = makespan / NS_PER_S
    out["fleet.tasks_per_hour"] = tasks * 3600.0 / (makespan / NS_PER_S) if makespan > 0 else float("nan")
    # waits
    waits: list[float] = []
    standing = pending_total = 0
    for ns in names:
        p, pending = poses[ns], pend_block[ns][0]
        speed = np.hypot(*np.diff(p[:, :2], axis=0).T) / SAMPLE_S
        turn = np.abs(np.angle(np.exp(1j * np.diff(p[:, 2])))) / SAMPLE_S
        still = np.concatenate([[True], (speed < STILL_MPS) & (turn < STILL_RPS)]) & pending
        standing += int(still.sum())
        pending_total += int(pending.sum())
        waits += [n * SAMPLE_S for n in _stretches(still) if n * SAMPLE_S >= MIN_WAIT_S]
    out["fleet.wait_s_mean"] = float(np.mean(waits)) if waits else 0.0
    out["fleet.wait_s_max"] = float(np.max(waits)) if waits else 0.0
    out["fleet.wait_share"] = standing / pending_total if pending_total else 0.0
    # clearance between footprints
    shapes = {ns: _footprints(kinds[ns], poses[ns]) for ns in names}
    gaps = {
        (a, b): shapely.distance(shapes[a], shapes[b]) for i, a in enumerate(names) for b in names[i + 1 :]
    }
    out["fleet.min_clearance_m"] = float(min((g.min() for g in gaps.values()), default=float("inf")))
    # deadlocks
    stuck = {ns: _stuck(poses[ns], pend_block[ns][0]) for ns in names}
    blocked = {ns: pend_block[ns][1] for ns in names}
    any_stuck = np.sum([stuck[ns] for ns in names], axis=0) >= 2
    locked = np.array(
        [bool(any_stuck[t]) and _deadlocked(names, stuck, blocked, gaps, t) for t in range(len(times))],
        dtype=bool,
    )
    out["fleet.deadlocks"] = float(len(_stretches(locked)))
    out["fleet.deadlock_s"] = float(locked.sum() * SAMPLE_S)
    return out
