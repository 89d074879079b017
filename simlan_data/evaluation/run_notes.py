"""Notes on a run: what went wrong, in one line each, for the summary a run prints and report.md.

A note appears only when something is wrong (a robot no camera saw, goals not reached,
collisions, safety violations, a realtime run that fell behind), never on every run: what is
known and always so (the packaged calibrations' stale derived fields) is explained once in the
docs. Notes marked ``in_summary`` are also lines of the run's printed summary; the report shows
them all.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from simlan_data.algorithms.navigation import BLOCKED_AFTER_S

REALTIME_SLACK = 0.95  # a realtime run (live.realtime) below this real-time factor fell behind

_FAILURE_WHY = {  # the reasons of simlan_data.algorithms.navigation.FAILURE_REASONS, for people
    "unreachable": "no path",
    "blocked": f"no progress for {BLOCKED_AFTER_S:g} s at the end",
    "timeout": "the run ended first",
}

__all__ = ["Note", "run_notes"]


@dataclass(frozen=True)
class Note:
    text: str
    in_summary: bool = False  # also printed in the run's summary (else report.md only)


def _never_seen(metrics: Mapping[str, float], ns: str) -> bool:
    """No camera saw ``ns``: no fix while in view, or (never in view) no valid estimate at all."""
    if metrics.get(f"localization.{ns}.availability") == 0.0:
        return True
    return metrics.get(f"localization.{ns}.ticks_valid") == 0.0  # availability is NaN then


def _goals_note(metrics: Mapping[str, float], ns: str, failed_recorded: int) -> Note | None:
    """``ns`` did not reach every goal: how many, and why each failed (in the summary too: a
    failed goal is a result of the run, which still exits 0, and must not go unseen)."""
    reached = metrics.get(f"navigation.{ns}.goals_reached")
    total = metrics.get(f"navigation.{ns}.goals_total")
    if not total or reached is None or reached >= total:
        return None
    text = f"{ns} reached {reached:.0f} of {total:.0f} goals in {metrics.get('sim.duration_s', 0.0):.3g} s simulated"
    failed = metrics.get(f"navigation.{ns}.goals_failed")
    if failed is None:  # metrics of an older version: only the given-up count, from the recording
        return Note(text + (f", {failed_recorded} given up (no path)" if failed_recorded else ""))
    why = ", ".join(
        f"{n:.0f} {reason} ({what})"
        for reason, what in _FAILURE_WHY.items()
        if (n := metrics.get(f"navigation.{ns}.goals_failed.{reason}", 0.0))
    )
    return Note(f"{text}; {failed:.0f} failed: {why}{_held(metrics, ns)}", in_summary=True)


def _held(metrics: Mapping[str, float], ns: str) -> str:
    """``"; a safety stop held it at the end (cause; ...)"`` when a stop still held ``ns``, else ``""``."""
    if not metrics.get(f"safety.{ns}.stopped_at_end"):
        return ""
    prefix = f"safety.{ns}.stopped_at_end."
    causes = [k[len(prefix) :] for k, v in metrics.items() if k.startswith(prefix) and v]
    return f"; a safety stop held it at the end ({', '.join(causes) or 'cause not recorded'}; see the safety events)"


def run_notes(
    metrics: Mapping[str, float],
    namespaces: Iterable[str],
    *,
    config: Mapping[str, Any] | None = None,
    calibration_issues: int = 0,
    user_calibration: bool = False,
    goals_failed: Mapping[str, int] | None = None,
) -> list[Note]:
    """The notes of a run from its metrics (and its resolved ``config`` as a plain dict)."""
    namespaces = sorted(namespaces)
    config = config or {}
    notes: list[Note] = []
    unseen = [ns for ns in namespaces if _never_seen(metrics, ns)]
    if unseen:  # a camera-steered run whose robot no camera saw: its results mean little
        notes.append(
            Note(
                f"never seen by a camera: {', '.join(unseen)} (no marker detection in the whole run; "
                "check cameras.ids against where the robot drives)",
                in_summary=True,
            )
        )
    # the packaged calibrations' stale derived fields are known (docs/twin.md): a user's files only
    if calibration_issues and user_calibration:
        notes.append(
            Note(
                f"{calibration_issues} calibration fields disagree with K, R, t (listed in report.md)",
                in_summary=True,
            )
        )
    for ns in namespaces:
        note = _goals_note(metrics, ns, (goals_failed or {}).get(ns, 0))
        if note is not None:
            notes.append(note)
        hits = metrics.get(f"agents.{ns}.collisions", 0.0)
        if hits:
            notes.append(Note(f"{ns} collided {hits:.0f} time{'s' if hits != 1 else ''} (collision sensor)"))
    violations = metrics.get("safety.violations", 0.0)
    if violations:
        kinds = ", ".join(
            f"{metrics.get(f'safety.violations.{k}', 0.0):.0f} {k.replace('_', ' ')}"
            for k in ("zone_entries", "collisions", "unobserved")
        )
        notes.append(Note(f"safety: {violations:.0f} violations ({kinds}); see the timeline"))
    if metrics.get("safety.hazards_unanswered", 0.0):
        notes.append(
            Note(f"safety: {metrics['safety.hazards_unanswered']:.0f} hazards not answered within the budget")
        )
    rtf = metrics.get("sim.rtf")
    if (config.get("live") or {}).get("realtime") and rtf is not None and rtf < REALTIME_SLACK:
        notes.append(Note(f"realtime run fell behind the wall clock: real-time factor {rtf:.2f}"))
    return notes
