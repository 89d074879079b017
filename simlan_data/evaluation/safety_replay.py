"""Counterfactual replay of the safety layer: what another safety config would have done.

    python -m simlan_data.replay REC --out DIR --algorithms safety \\
        --set 'zones=[{"name": "dock", "polygon": [[2, -2], [6, -2], [6, 3], [2, 3]]}]' \\
        --set observability.timeout_s=1.0
    python -m simlan_data.replay REC --out DIR --algorithms safety --set safety=my_pkg.mod:MyMonitor

``--set safety=NAME`` selects another safety monitor (a registered name or module:Class); the
other ``--set`` keys are the selected monitor's config keys (dotted), over the recorded ones.
The monitor (the recorded trees by default) is ticked again on what the live trees read, as recorded: every robot's estimate
(``/<ns>/pose_estimate``, ``velocity_estimate``, ``localization_status``), its collision sensor,
its plans and navigation state, and the people detections (through the same tracker). With the
recorded config this reproduces the live events exactly (``replay.safety.events_diff_to_live`` =
0); with another one it tells when each robot would have stopped or slowed.

Limits: nothing is re-simulated. The robots' recorded motion is what they did under the live
safety layer; once a counterfactual decision differs from the live one (a stop the live run did
not make, or the other way round), the recording no longer shows what that robot would have
done next. Verdicts therefore judge each real violation (judged with the new config) by the
first counterfactual stop before it: *prevented* if the robot, braking at
``restricted_area.decel_mps2`` from its true speed at that stop, would have stood still before it
got there; verdicts that depend on motion after an earlier divergence are marked *uncertain*.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import polars as pl

from simlan_data.algorithms import registry
from simlan_data.algorithms.people import PeopleParams, PersonTracker
from simlan_data.algorithms.safety import (
    DRIVE,
    FREE,
    STOP,
    SafetyDecision,
    SafetyEvent,
    SafetyWorld,
    TreeParams,
    transition_events,
)
from simlan_data.config.legacy import with_algorithms
from simlan_data.constants import NS_PER_S
from simlan_data.errors import RecordingInputError
from simlan_data.evaluation.replay import ReplayContext, register
from simlan_data.evaluation.safety_inputs import (
    SafetyRecording,
    judging_params,
    read_safety_recording,
    safety_context,
    selected_safety,
)
from simlan_data.evaluation.safety_metrics import Violation, evaluate

VERDICTS_MD = "safety_counterfactual.md"


def people_params(config: dict) -> PeopleParams:
    """The recorded person detection (``people``; ``safety.people`` in older recordings)."""
    return PeopleParams(**(with_algorithms(config).get("people") or {}))


def replay_trees(
    rec: SafetyRecording, spec: registry.AlgorithmSpec, safety_config: object
) -> tuple[list[SafetyEvent], dict[str, list[str]]]:
    """Tick the safety monitor ``spec`` with ``safety_config`` on the recorded inputs; events and
    the state at every tick of every guarded robot (the built-in's trees; every robot otherwise)."""
    if not rec.estimates:
        raise RecordingInputError(
            "no camera estimates",
            "the recording",
            "the safety replay needs the localizer's output (localization.source=camera)",
            "replay a run steered by the cameras",
        )
    context = safety_context(rec.config, rec.specs, rec.spawn)
    monitor = registry.Guarded(spec.build(safety_config, context, where="replay"), spec)
    tracker = PersonTracker(people_params(rec.config))
    guarded = getattr(monitor, "trees", None)
    states: dict[str, list[str]] = {ns: [] for ns in (rec.robots if guarded is None else guarded)}
    own_events = getattr(monitor, "events", None)
    events: list[SafetyEvent] = [] if own_events is None else own_events
    last: dict[str, SafetyDecision] = {}
    navigating = {ns: rec.goals.get(ns, 0) > 0 for ns in rec.robots}
    k = 0
    for i, t in enumerate(rec.ticks):
        while k < len(rec.people) and rec.people[k][0] <= t:
            tracker.update(rec.people[k][0], rec.people[k][1])
            k += 1
        if i > 0:
            for ns in rec.robots:
                state = rec.nav_states[ns][i - 1]
                if state is not None:
                    navigating[ns] = state != "done"
        world = SafetyWorld(
            int(t),
            {ns: rec.estimates[ns][i] for ns in rec.robots if ns in rec.estimates},
            {ns: rec.contacts[ns][i] for ns in rec.robots},
            tracker.people(int(t)) if rec.people else [],
            {ns: (rec.plans[ns][i - 1] if i > 0 else None) for ns in rec.robots},
            dict(navigating),
        )
        decisions = monitor.step(world)
        if own_events is None:
            events.extend(transition_events(last, decisions, world))
            last.update(decisions)
        for ns in states:
            states[ns].append(decisions.get(ns, FREE).state)
    return events, states


@dataclass(frozen=True)
class Verdict:
    namespace: str
    kind: str
    t_s: float
    other: str
    as_recorded: str  # what the live safety layer did about it
    counterfactual: str  # prevented | too late | not stopped | stopped in time | standing | uncertain
    stop_t_s: float  # the counterfactual stop that counts (nan: none)
    travelled_m: float  # true distance from that stop to the violation
    stopping_m: float  # distance the robot needed to stand still from that stop


def _stop_start(states: list[str], i: int) -> int | None:
    """Index where the stop that holds at ``i`` began (None: not stopped at ``i``)."""
    if states[i] != STOP:
        return None
    while i > 0 and states[i - 1] == STOP:
        i -= 1
    return i


def verdicts(
    rec: SafetyRecording,
    params: TreeParams,
    violations: list[Violation],
    cf_states: dict[str, list[str]],
    diverged: dict[str, int | None],
) -> list[Verdict]:
    """Judge each real violation by the counterfactual stops (see the module docstring)."""
    budget = params.control_period_s + params.camera_period_s
    tol = int(np.ceil(budget / params.control_period_s - 1e-9))
    out = []
    for v in violations:
        i = rec.index(v.onset_ns)
        states = cf_states.get(v.namespace)
        as_recorded = (
            "entered" if v.kind == "zone_entry" else ("stopped in time" if v.stopped_in_time else "missed")
        )
        t_s = v.onset_ns / NS_PER_S
        if states is None:
            out.append(
                Verdict(v.namespace, v.kind, t_s, v.other, as_recorded, "no tree", np.nan, np.nan, np.nan)
            )
            continue
        tr = rec.truth[v.namespace]
        if v.kind == "unobserved":
            j = min(len(states) - 1, i + tol)
            start = _stop_start(states, j)
            verdict = "stopped in time" if start is not None else "not stopped"
            stop_t = rec.ticks[start] / NS_PER_S if start is not None else np.nan
            out.append(
                Verdict(v.namespace, v.kind, t_s, v.other, as_recorded, verdict, stop_t, np.nan, np.nan)
            )
            continue
        if v.kind == "collision" and not v.moving:
            out.append(Verdict(v.namespace, v.kind, t_s, v.other, as_recorded, "standing", np.nan, 0.0, 0.0))
            continue
        start = _stop_start(states, i)
        if start is None:
            out.append(
                Verdict(v.namespace, v.kind, t_s, v.other, as_recorded, "not stopped", np.nan, np.nan, np.nan)
            )
            continue
        travelled = (
            float(np.sum(np.hypot(*np.diff(tr.pose[start : i + 1, :2], axis=0).T))) if i > start else 0.0
        )
        speed = abs(float(tr.speed_mps[start]))
        needed = speed * speed / (2.0 * params.config.restricted_area.decel_mps2)
        verdict = "prevented" if needed < travelled else "too late"
        d = diverged.get(v.namespace)
        if d is not None and d < start:
            verdict = "uncertain"
        out.append(
            Verdict(
                v.namespace,
                v.kind,
                t_s,
                v.other,
                as_recorded,
                verdict,
                rec.ticks[start] / NS_PER_S,
                travelled,
                needed,
            )
        )
    return out


def _event_key(e: SafetyEvent) -> tuple[int, str, str, str]:
    return (e.stamp_ns, e.namespace, e.action, e.cause)


def _events_table(events: list[SafetyEvent]) -> pl.DataFrame:
    return pl.DataFrame(
        [
            (
                e.stamp_ns,
                e.namespace,
                e.cause,
                e.action,
                *(e.pose if e.pose is not None else (np.nan, np.nan, np.nan)),
                e.speed_mps,
                e.other,
                e.detail,
            )
            for e in events
        ],
        schema={
            "stamp_ns": pl.Int64,
            "namespace": pl.String,
            "cause": pl.String,
            "action": pl.String,
            "x_m": pl.Float64,
            "y_m": pl.Float64,
            "yaw_rad": pl.Float64,
            "speed_mps": pl.Float64,
            "other": pl.String,
            "detail": pl.String,
        },
        orient="row",
    )


@register("safety")
def safety(ctx: ReplayContext) -> dict[str, float]:
    """Re-run the safety monitor (``--set safety=NAME``, else the recorded one) with the recording's
    config plus ``--set`` overrides."""
    config = ctx.config
    spec, safety_config = selected_safety(config, dict(ctx.options), where="replay --set")
    rec = read_safety_recording(ctx.reader, config)
    events, states = replay_trees(rec, spec, safety_config)
    params = judging_params(config, safety_config, safety_context(config, rec.specs, rec.spawn))
    cameras = ctx.cameras
    metrics, _, _ = evaluate(rec, params, events, states, cameras, prefix="replay.safety")
    # what really happened, judged with the counterfactual config (its zones, timeouts)
    recorded, violations, _ = evaluate(
        rec, params, rec.events, rec.states, cameras, prefix="replay.safety.as_recorded"
    )
    diverged: dict[str, int | None] = {}
    for ns, st in states.items():
        live = rec.states.get(ns, [DRIVE] * len(st))
        diff = [i for i, (a, b) in enumerate(zip(st, live)) if a != b]
        diverged[ns] = diff[0] if diff else None
    judged = verdicts(rec, params, violations, states, diverged)
    live_keys = {_event_key(e) for e in rec.events}
    cf_keys = {_event_key(e) for e in events}
    metrics.update({k: v for k, v in recorded.items() if k.count(".") == 3})  # overall figures only
    metrics["replay.safety.events_diff_to_live"] = float(len(live_keys ^ cf_keys))
    metrics["replay.safety.prevented"] = float(sum(1 for v in judged if v.counterfactual == "prevented"))
    metrics["replay.safety.not_prevented"] = float(
        sum(1 for v in judged if v.counterfactual in ("too late", "not stopped"))
    )
    metrics["replay.safety.uncertain"] = float(sum(1 for v in judged if v.counterfactual == "uncertain"))
    first = [d for d in diverged.values() if d is not None]
    metrics["replay.safety.diverged_s"] = float(rec.ticks[min(first)] / NS_PER_S) if first else float("nan")
    _events_table(events).write_parquet(ctx.out_dir / "safety_events.parquet")
    table = pl.DataFrame([v.__dict__ for v in judged]) if judged else pl.DataFrame()
    if judged:
        table.write_parquet(ctx.out_dir / "safety_verdicts.parquet")
    write_counterfactual_report(ctx, params, events, rec.events, judged, metrics, diverged, rec)
    return metrics


def write_counterfactual_report(
    ctx: ReplayContext,
    params: TreeParams,
    events: list[SafetyEvent],
    live_events: list[SafetyEvent],
    judged: list[Verdict],
    metrics: dict[str, float],
    diverged: dict[str, int | None],
    rec: SafetyRecording,
) -> None:
    """``safety_counterfactual.md``: the counterfactual events beside the live ones, and verdicts."""

    def rows(evs: list[SafetyEvent]) -> list[str]:
        return [
            f"| {e.stamp_ns / NS_PER_S:.2f} | {e.namespace} | {e.action} | {e.cause} | {e.detail} |"
            for e in evs
        ] or ["| - | - | - | - | - |"]

    lines = [
        "# Safety layer: counterfactual replay",
        "",
        f"Recording: `{ctx.reader.path}`; overrides: `{dict(ctx.options)}`.",
        f"Zones: {', '.join(f'{z.name} {z.points}' for z in params.zones) or 'none'}; "
        f"observability timeout {params.config.observability.timeout_s:g} s; TTC stop at CPA <= {params.config.ttc.stop_cpa_m:g} m "
        f"and TTC <= {params.config.ttc.stop_ttc_s:g} s.",
        "",
        "Nothing is re-simulated: the robots' motion is the recorded one. After the first decision that "
        "differs from the live run the recording no longer shows what a robot would have done; verdicts "
        "that depend on it are marked uncertain.",
        "",
        "## Events, counterfactual",
        "",
        "| t (s) | robot | action | cause | detail |",
        "| --- | --- | --- | --- | --- |",
        *rows(events),
        "",
        "## Events, as recorded",
        "",
        "| t (s) | robot | action | cause | detail |",
        "| --- | --- | --- | --- | --- |",
        *rows(live_events),
        "",
        "## Real violations (judged with the counterfactual config)",
        "",
        "| robot | kind | t (s) | zone / agent | as recorded | counterfactual | stop at (s) | travelled from stop (m) | needed to stop (m) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *(
            f"| {v.namespace} | {v.kind} | {v.t_s:.2f} | {v.other} | {v.as_recorded} | **{v.counterfactual}** | "
            f"{v.stop_t_s:.2f} | {v.travelled_m:.2f} | {v.stopping_m:.2f} |"
            for v in judged
        ),
        *([] if judged else ["| - | - | - | - | - | - | - | - | - |"]),
        "",
        "Diverged from the live decisions: "
        + (
            ", ".join(
                f"{ns} at {rec.ticks[d] / NS_PER_S:.2f} s" if d is not None else f"{ns} never"
                for ns, d in sorted(diverged.items())
            )
            or "-"
        ),
        "",
        "## Figures",
        "",
        *(f"- `{k}`: {v:.4g}" for k, v in sorted(metrics.items()) if k.count(".") == 2),
        "",
    ]
    (ctx.out_dir / VERDICTS_MD).write_text("\n".join(lines))
