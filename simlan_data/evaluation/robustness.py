"""Robustness sweeps (issue 24): one scene run under camera effects of growing strength.

A sweep lives in the suite file (``evals/base.yaml``) next to the suites, under ``robustness:``::

    robustness:
      NAME:                        # python -m simlan_data.evals NAME
        description: ...
        seeds: 2                   # seeds 0..N-1 of every strength (--seeds N)
        overrides: [KEY=VALUE]     # of every run of the sweep
        case:                      # the scene: a suite case (overrides, replay, metrics; no grid)
          overrides: [scenario=single_truck, duration_s=30]
          replay: {ALGORITHM: {OPTION: VALUE}}          # optional
          metrics: {SOURCE: {METRIC: {max: B} or {min: B}}}   # the promises
        effects:
          EFFECT:                  # one curve
            key: sensors.timing.drop_rate               # the swept key of the typed config
            values: [0, 0.1, 0.3]  # the strengths, weakest first (the first is the reference)
            set: [sensors.timing.enabled=true]          # optional: overrides that turn it on
            also: {KEY: P}         # optional: KEY = value ** P as well (e.g. exposure_scale: -1
                                   # with gain keeps the brightness)

Each (effect, strength) becomes one ordinary suite case, ``EFFECT[KEY=VALUE]``: the suite's job
planning, Hydra launcher, replays and metrics table run it (:mod:`simlan_data.evaluation.suite`).
:func:`breaking_points` says per effect and promised metric where the mean over seeds first
leaves its promise; :mod:`simlan_data.evaluation.robustness_report` writes the CSV, plots and
summary.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import polars as pl

from simlan_data.config.safe_yaml import load_yaml
from simlan_data.errors import ConfigError
from simlan_data.evaluation.stats import Bound
from simlan_data.evaluation.suite_spec import (
    Case,
    Check,
    Suite,
    _cases,
    _config_has,
    _known_keys,
    _mapping,
    _override_value,
    _strings,
)

SECTION = "robustness"
CASE_KEYS = ("description", "overrides", "replay", "metrics", "requires", "pending_note")


@dataclass(frozen=True)
class Effect:
    """One swept key and its strengths."""

    name: str
    key: str
    values: tuple[float, ...]
    set: tuple[str, ...] = ()
    also: tuple[tuple[str, float], ...] = ()  # (KEY, power): KEY = value ** power

    def overrides(self, value: float) -> tuple[str, ...]:
        derived = tuple(f"{k}={_override_value(_power(value, p))}" for k, p in self.also)
        return (*self.set, f"{self.key}={_override_value(value)}", *derived)

    def case_name(self, value: float) -> str:
        return f"{self.name}[{self.key}={_override_value(value)}]"


@dataclass(frozen=True)
class Robustness:
    """A sweep: the suite of its (effect, strength) cases and where each case sits."""

    name: str
    description: str
    suite: Suite
    effects: tuple[Effect, ...]
    cells: dict[str, tuple[Effect, float]]  # case name -> (effect, strength)
    checks: tuple[Check, ...]

    def cases_of(self, effect: Effect) -> list[Case]:
        return [c for c in self.suite.cases if self.cells[c.name][0].name == effect.name]


def _power(value: float, power: float) -> float:
    return float(float(value) ** power)  # (0 with a power <= 0 is refused on load)


def _err(where: str, what: str, why: str, fix: str) -> ConfigError:
    return ConfigError(what, where, why, fix)


def sweep_names(path: Path) -> list[str]:
    """The robustness sweeps of the suite file (none if it has no ``robustness:`` section)."""
    if not path.is_file():
        return []
    doc = load_yaml(path, what="suite file") or {}
    return list(_mapping(doc.get(SECTION), f"{path}: {SECTION}")) if isinstance(doc, Mapping) else []


def _number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(float(v))


def _key(value: Any, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise _err(
            where, "invalid effect key", "expected a dotted config key", "e.g. key: sensors.timing.drop_rate"
        )
    if not _config_has(value):
        raise _err(
            where,
            f"unknown effect key {value!r}",
            "no such key in the typed config",
            "python -m simlan_data.run --cfg job sensors=realistic lists the keys",
        )
    return value


def _effect(name: str, entry: Any, where: str) -> Effect:
    e = _mapping(entry, where)
    _known_keys(e, ("description", "key", "values", "set", "also"), where)
    key = _key(e.get("key"), f"{where}.key")
    values = e.get("values")
    if not isinstance(values, list) or not values:
        raise _err(
            f"{where}.values", "no strengths", "expected a non-empty list of numbers", "e.g. [0, 0.1, 0.3]"
        )
    if not all(_number(v) for v in values):
        raise _err(f"{where}.values", "invalid strength", "expected numbers", "e.g. [0, 0.1, 0.3]")
    if len(set(values)) != len(values):
        raise _err(f"{where}.values", "repeated strength", "each strength once", "drop the repeat")
    also = _mapping(e.get("also"), f"{where}.also")
    for k, p in also.items():
        _key(k, f"{where}.also")
        if not _number(p):
            raise _err(
                f"{where}.also.{k}", f"invalid power {p!r}", "expected a number", "e.g. -1 (1 / value)"
            )
        if p <= 0 and 0 in values:
            raise _err(
                f"{where}.also.{k}", "0 to a power <= 0", "a strength is 0", "start the strengths above 0"
            )
    return Effect(
        name,
        key,
        tuple(values),
        _strings(e.get("set"), f"{where}.set"),
        tuple((str(k), float(p)) for k, p in also.items()),
    )


def _promises(checks: tuple[Check, ...], where: str) -> None:
    for c in checks:
        if c.bound.max is None and c.bound.min is None:
            raise _err(
                f"{where}.{c.source}.{c.metric}",
                "no promise",
                "a robustness metric needs max or min (where the curve breaks)",
                "e.g. {max: 0.02}",
            )


def load_robustness(
    path: Path, name: str, *, seeds: int | None = None, only: list[str] | None = None
) -> Robustness:
    """Read sweep ``name``; every (effect, strength) becomes a suite case.

    Raises:
        ConfigError: an unknown sweep, effect or key, an empty list of strengths (named in the message).
    """
    where = f"{path}: {SECTION}.{name}"
    doc = _mapping(load_yaml(path, what="suite file"), str(path))
    sweeps = _mapping(doc.get(SECTION), f"{path}: {SECTION}")
    if name not in sweeps:
        raise _err(
            str(path),
            f"unknown robustness sweep {name!r}",
            f"sweeps: {', '.join(sweeps) or '(none)'}",
            "pick one",
        )
    s = _mapping(sweeps[name], where)
    _known_keys(s, ("description", "seeds", "confidence", "overrides", "case", "effects"), where)
    if seeds is not None:
        s["seeds"] = seeds
    case = _mapping(s.get("case"), f"{where}.case")
    _known_keys(case, CASE_KEYS, f"{where}.case")
    effects_doc = _mapping(s.get("effects"), f"{where}.effects")
    if not effects_doc:
        raise _err(
            f"{where}.effects", "no effects", "a sweep needs at least one effect", "add effects: {...}"
        )
    effects = [_effect(str(n), e, f"{where}.effects.{n}") for n, e in effects_doc.items()]
    if only:
        unknown = [o for o in only if o not in effects_doc]
        if unknown:
            raise _err(
                "--only", f"unknown effect {unknown[0]!r}", f"effects: {', '.join(effects_doc)}", "pick one"
            )
        effects = [e for e in effects if e.name in only]
    cases: list[Case] = []
    cells: dict[str, tuple[Effect, float]] = {}
    base_overrides = list(_strings(case.get("overrides"), f"{where}.case.overrides"))
    for effect in effects:
        for value in effect.values:
            entry = {**case, "overrides": [*base_overrides, *effect.overrides(value)], "faults": []}
            (made,) = _cases(
                effect.case_name(value), entry, s, path.parent, f"{where}.effects.{effect.name}", []
            )
            cases.append(made)
            cells[made.name] = (effect, value)
    checks = cases[0].checks
    _promises(checks, f"{where}.case.metrics")
    confidence = s.get("confidence", 0.95)
    if not isinstance(confidence, float) or not 0.5 <= confidence < 1:
        raise _err(where, f"invalid confidence={confidence!r}", "expected 0.5..0.999", "use 0.95")
    suite = Suite(
        name,
        path,
        (path.parent / "baselines" / f"{name}.parquet").resolve(),  # unused: a sweep has no baseline
        float(confidence),
        _strings(s.get("overrides"), f"{where}.overrides"),
        tuple(cases),
        {},
    )
    return Robustness(name, str(s.get("description", "")), suite, tuple(effects), cells, checks)


# ------------------------------------------------------------------------------- the results
ROBUSTNESS_SCHEMA = {
    "effect": pl.String,
    "key": pl.String,
    "strength": pl.Float64,
    "seed": pl.Int64,
    "source": pl.String,
    "metric": pl.String,
    "value": pl.Float64,
}


def robustness_table(sweep: Robustness, metrics: pl.DataFrame) -> pl.DataFrame:
    """One row per effect, strength, seed and promised metric (value null where none came back)."""
    got = {
        (r["case"], r["seed"], r["source"], r["metric"]): r["value"] for r in metrics.iter_rows(named=True)
    }
    rows = [
        (
            effect.name,
            effect.key,
            float(value),
            seed,
            c.source,
            c.metric,
            got.get((case.name, seed, c.source, c.metric)),
        )
        for case in sweep.suite.cases
        for effect, value in [sweep.cells[case.name]]
        for seed in case.seeds
        for c in sweep.checks
    ]
    return pl.DataFrame(rows, schema=ROBUSTNESS_SCHEMA, orient="row")


def holds(bound: Bound, mean: float) -> bool:
    """The mean keeps the promise (a missing value keeps none)."""
    if mean is None or math.isnan(mean):
        return False
    return (bound.max is None or mean <= bound.max) and (bound.min is None or mean >= bound.min)


@dataclass(frozen=True)
class Verdict:
    """Where one effect's curve of one metric leaves its promise."""

    effect: str
    key: str
    source: str
    metric: str
    promise: str
    means: tuple[tuple[float, float], ...]  # (strength, mean over seeds)
    holds_up_to: float | None  # the last strength before the first break (None: none held)
    breaks_at: float | None  # the first strength whose mean leaves the promise (None: never)

    def text(self) -> str:
        if self.breaks_at is None:
            return "holds over the whole range"
        broke = f"breaks at {self.breaks_at:g}"
        if self.holds_up_to is None:
            return f"{broke} (already at the first strength)"
        return f"holds up to {self.holds_up_to:g}, {broke}"


def breaking_points(sweep: Robustness, table: pl.DataFrame) -> list[Verdict]:
    """Per effect and promised metric: the mean over seeds at each strength and the first break."""
    out = []
    for effect in sweep.effects:
        for c in sweep.checks:
            sel = table.filter(
                (pl.col("effect") == effect.name)
                & (pl.col("source") == c.source)
                & (pl.col("metric") == c.metric)
            )
            means = []
            for value in effect.values:
                vals = sel.filter(pl.col("strength") == float(value))["value"].to_list()
                finite = [v for v in vals if v is not None and not math.isnan(v)]
                means.append(
                    (
                        float(value),
                        sum(finite) / len(finite) if finite and len(finite) == len(vals) else math.nan,
                    )
                )
            first = next((i for i, (_, m) in enumerate(means) if not holds(c.bound, m)), None)
            out.append(
                Verdict(
                    effect.name,
                    effect.key,
                    c.source,
                    c.metric,
                    c.bound.describe(),
                    tuple(means),
                    None if first == 0 else means[(first if first is not None else len(means)) - 1][0],
                    None if first is None else means[first][0],
                )
            )
    return out
