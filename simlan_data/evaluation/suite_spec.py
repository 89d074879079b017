"""The V&V suite file (``evals/base.yaml``): faults, suites, cases, metric bounds; checked on load.

Layout (every key is checked; a bad one is one error line naming the place)::

    faults:                      # --inject NAME
      NAME:
        description: ...
        run: [KEY=VALUE, ...]    # Hydra overrides of every simulated run (closed loop)
        replay: {ALGORITHM: {OPTION: VALUE}, "*": {...}}   # options of the replays ("*": all)
        requires: [...]          # see below; unmet = pending (cannot be injected yet)
        expect: [METRIC, ...]    # metrics it must turn red (the fault tests check this)
    suites:
      NAME:                      # python -m simlan_data.evals NAME
        baseline: PATH           # accepted results (parquet or csv), relative to this file
        seeds: 3                 # seeds 0..N-1 of every case (--seeds N)
        confidence: 0.95
        overrides: [KEY=VALUE]   # of every run of the suite
        cases:
          NAME:
            description: ...
            overrides: [scenario=single_truck, ...]   # a simulated case, or
            recording: PATH      # or a fixed run directory (relative to this file), made by the
                                 # overrides when regenerated (--regenerate)
            seeds: N             # optional, else the suite's
            grid: {KEY: [V1, V2]}   # optional: one case per combination, NAME[KEY=V1]
            requires: [...]      # optional; unmet = every check of the case is pending
            pending_note: ...    # what the case waits for (shown with "pending:")
            replay: {ALGORITHM: {OPTION: VALUE}}      # replays of every recording (options that
                                 # name files, e.g. posemap's model, are relative to this file)
            faults: [NAME, ...]  # optional: the faults that act on it (default: all; [] = none,
                                 # e.g. a case without the cameras a fault names)
            metrics: {SOURCE: {METRIC: {max, min, tolerance, rel_tolerance, better}}}

    robustness:                  # robustness sweeps: simlan_data/evaluation/robustness.py

SOURCE is ``run`` (the run's metrics.json) or a replay algorithm of the case. A requirement is
``replay:NAME`` (a registered replay algorithm), ``conf:GROUP/OPTION`` (a config file),
``config:KEY.PATH`` (a key of the typed config) or ``module:NAME[=EXTRA]`` (an importable Python
module, from the package's extra EXTRA: ``module:torch=posemap``); the case's replay algorithms and its
``GROUP=OPTION`` overrides are required implicitly.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, get_type_hints

import yaml

from simlan_data.config.safe_yaml import load_yaml
from simlan_data.config.schema import Config
from simlan_data.constants import CONF_DIR
from simlan_data.errors import ConfigError
from simlan_data.evaluation.replay import PATH_OPTIONS, REPLAY_ALGORITHMS
from simlan_data.evaluation.stats import Bound

RUN_SOURCE = "run"
ALL_ALGORITHMS = "*"
MAX_SUITE_BYTES = 1 << 20


@dataclass(frozen=True)
class Check:
    """One metric of one source that a case must meet."""

    source: str
    metric: str
    bound: Bound


@dataclass(frozen=True)
class Case:
    name: str
    description: str
    overrides: tuple[str, ...]
    recording: Path | None
    seeds: tuple[int, ...]
    replay: dict[str, dict[str, Any]]
    checks: tuple[Check, ...]
    pending: str = ""  # why it cannot run yet ("" = it can)
    grid: dict[str, Any] = field(default_factory=dict)  # the grid cell this case is (key -> value)
    family: str = ""  # the case name before grid expansion
    faults: tuple[str, ...] | None = None  # the faults that act on it (None: every one)

    def subject_to(self, faults: list[Fault]) -> list[Fault]:
        """The injected faults that act on this case."""
        return [f for f in faults if self.faults is None or f.name in self.faults]


@dataclass(frozen=True)
class Fault:
    name: str
    description: str
    run: tuple[str, ...]
    replay: dict[str, dict[str, Any]]
    expect: tuple[str, ...]
    pending: str = ""

    def replay_options(self, algorithm: str) -> dict[str, Any]:
        return {**self.replay.get(ALL_ALGORITHMS, {}), **self.replay.get(algorithm, {})}


@dataclass(frozen=True)
class Suite:
    name: str
    path: Path
    baseline: Path
    confidence: float
    overrides: tuple[str, ...]
    cases: tuple[Case, ...]
    faults: dict[str, Fault]


def _err(where: str, what: str, why: str, fix: str) -> ConfigError:
    return ConfigError(what, where, why, fix)


def _mapping(value: Any, where: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise _err(
            where, "invalid entry", f"expected a mapping, got {type(value).__name__}", "see evals/base.yaml"
        )
    return dict(value)


def _strings(value: Any, where: str) -> tuple[str, ...]:
    if value is None:
        return ()
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise _err(where, "invalid entry", "expected a list of strings", "e.g. [scenario=single_truck]")
    return tuple(value)


def _known_keys(entry: Mapping[str, Any], allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(entry) - set(allowed))
    if unknown:
        raise _err(where, f"unknown key {unknown[0]!r}", f"known: {', '.join(allowed)}", "fix the spelling")


def _config_has(path: str) -> bool:
    """True if the dotted path names a key of the typed config (dict-valued keys end the walk)."""
    cls: Any = Config
    for part in path.split("."):
        if not dataclasses.is_dataclass(cls):
            return True  # inside a dict field: any key may exist
        hints = get_type_hints(cls)
        if part not in hints:
            return False
        cls = hints[part]
    return True


def unmet(requirement: str) -> str:
    """Why ``requirement`` is not met here ("" if it is)."""
    kind, _, name = requirement.partition(":")
    if kind == "replay":
        return "" if name in REPLAY_ALGORITHMS else f"replay algorithm '{name}'"
    if kind == "conf":
        return "" if (CONF_DIR / f"{name}.yaml").is_file() else f"config file conf/{name}.yaml"
    if kind == "config":
        return "" if _config_has(name) else f"config key '{name}'"
    if kind == "module" and name:
        module, _, extra = name.partition("=")
        if importlib.util.find_spec(module) is not None:  # finds, does not import (torch takes seconds)
            return ""
        return f"Python module '{module}'" + (f' (pip install -e ".[{extra}]")' if extra else "")
    raise _err(
        "requires",
        f"invalid requirement {requirement!r}",
        "expected replay:NAME, conf:GROUP/OPTION, config:KEY.PATH or module:NAME[=EXTRA]",
        "e.g. replay:safety",
    )


def _implied(overrides: tuple[str, ...], replay: Mapping[str, Any]) -> list[str]:
    out = [f"replay:{name}" for name in replay]
    for item in overrides:
        key, sep, value = item.partition("=")
        key = key.lstrip("+~")
        if sep and (CONF_DIR / key).is_dir() and "," not in value:
            out.append(f"conf:{key}/{value}")
    return out


def _pending(requires: list[str], note: str) -> str:
    missing = [m for m in (unmet(r) for r in dict.fromkeys(requires)) if m]
    if not missing:
        return ""
    text = "needs " + ", ".join(missing)
    return f"{text}; waiting for the {note}" if note else text


def _bound(spec: Any, where: str) -> Bound:
    entry = _mapping(spec, where)
    _known_keys(entry, ("max", "min", "tolerance", "rel_tolerance", "better"), where)
    values: dict[str, Any] = {}
    for key in ("max", "min", "tolerance", "rel_tolerance"):
        if key in entry:
            v = entry[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(float(v)):
                raise _err(where, f"invalid {key}={v!r}", "expected a number", f"e.g. {key}: 0.02")
            values[key] = float(v)
    if values.get("tolerance", 0.0) < 0 or values.get("rel_tolerance", 0.0) < 0:
        raise _err(where, "invalid tolerance", "must be >= 0", "use e.g. tolerance: 0.005")
    if not values:
        raise _err(where, "empty bound", "no max, min or tolerance", "give e.g. {max: 0.02}")
    better = entry.get("better")
    if better is None:
        better = "higher" if ("min" in values and "max" not in values) else "lower"
    if better not in ("lower", "higher"):
        raise _err(where, f"invalid better={better!r}", "expected lower or higher", "e.g. better: higher")
    return Bound(**values, better=better)


def _checks(metrics: Any, sources: set[str], where: str) -> tuple[Check, ...]:
    out = []
    for source, entries in _mapping(metrics, where).items():
        if source not in sources:
            raise _err(
                f"{where}.{source}",
                f"unknown metrics source {source!r}",
                f"a source is 'run' or one of the case's replays ({', '.join(sorted(sources - {RUN_SOURCE})) or 'none'})",
                "add the algorithm under replay: or fix the name",
            )
        for metric, spec in _mapping(entries, f"{where}.{source}").items():
            out.append(Check(source, str(metric), _bound(spec, f"{where}.{source}.{metric}")))
    if not out:
        raise _err(where, "no metrics", "a case must check at least one metric", "add metrics: {run: {...}}")
    return tuple(out)


def _replay(value: Any, where: str, base: Path) -> dict[str, dict[str, Any]]:
    """Replay options per algorithm; options that name files are resolved relative to ``base``
    (the suite file's directory), as the cases' recordings are."""
    out = {str(k): _mapping(v, f"{where}.{k}") for k, v in _mapping(value, where).items()}
    for algorithm, options in out.items():
        for key in PATH_OPTIONS.get(algorithm, ()):
            if isinstance(options.get(key), str) and options[key]:
                options[key] = str((base / options[key]).resolve())
    return out


def _fault(name: str, entry: Any, where: str, base: Path) -> Fault:
    e = _mapping(entry, where)
    _known_keys(e, ("description", "run", "replay", "requires", "expect", "pending_note"), where)
    replay = _replay(e.get("replay"), f"{where}.replay", base)
    if not e.get("run") and not replay:
        raise _err(where, "empty fault", "neither run overrides nor replay options", "give run: or replay:")
    requires = list(_strings(e.get("requires"), f"{where}.requires"))
    requires += [f"replay:{a}" for a in replay if a != ALL_ALGORITHMS]
    return Fault(
        name,
        str(e.get("description", "")),
        _strings(e.get("run"), f"{where}.run"),
        replay,
        _strings(e.get("expect"), f"{where}.expect"),
        _pending(requires, str(e.get("pending_note", ""))),
    )


def _grid_cells(grid: Mapping[str, Any], where: str) -> list[dict[str, Any]]:
    keys = list(grid)
    for k in keys:
        if not isinstance(grid[k], list) or not grid[k]:
            raise _err(f"{where}.{k}", "invalid grid", "expected a non-empty list of values", "e.g. [45, 90]")
    return [dict(zip(keys, combo)) for combo in itertools.product(*(grid[k] for k in keys))]


def _override_value(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()


def _cases(
    name: str, entry: Any, suite: Mapping[str, Any], base: Path, where: str, fault_names: list[str]
) -> list[Case]:
    e = _mapping(entry, where)
    _known_keys(
        e,
        (
            "description",
            "overrides",
            "recording",
            "seeds",
            "grid",
            "requires",
            "pending_note",
            "replay",
            "metrics",
            "faults",
        ),
        where,
    )
    overrides = _strings(e.get("overrides"), f"{where}.overrides")
    recording = e.get("recording")
    if recording is None and not overrides and "grid" not in e:
        raise _err(
            where,
            "invalid case",
            "neither overrides (a simulated case) nor recording (a fixed run, made by its overrides)",
            "give overrides: [scenario=...]",
        )
    seeds_n = e.get("seeds", suite.get("seeds", 1))
    if isinstance(seeds_n, bool) or not isinstance(seeds_n, int) or not 1 <= seeds_n <= 1000:
        raise _err(where, f"invalid seeds={seeds_n!r}", "expected an integer within 1..1000", "e.g. seeds: 3")
    replay = _replay(e.get("replay"), f"{where}.replay", base)
    checks = _checks(e.get("metrics"), {RUN_SOURCE, *replay}, f"{where}.metrics")
    requires = [*_strings(e.get("requires"), f"{where}.requires"), *_implied(overrides, replay)]
    pending = _pending(requires, str(e.get("pending_note", "")))
    if not pending:
        unknown = [a for a in replay if a not in REPLAY_ALGORITHMS]
        if unknown:
            raise _err(
                where,
                f"unknown replay algorithm {unknown[0]!r}",
                f"known: {', '.join(sorted(REPLAY_ALGORITHMS))}",
                "fix the name",
            )
    subject: tuple[str, ...] | None = None
    if "faults" in e:
        subject = _strings(e.get("faults"), f"{where}.faults")
        unknown = [f for f in subject if f not in fault_names]
        if unknown:
            raise _err(
                f"{where}.faults",
                f"unknown fault {unknown[0]!r}",
                f"faults: {', '.join(fault_names) or '(none)'}",
                "fix the name",
            )
    rec = (base / str(recording)).resolve() if recording is not None else None
    description = str(e.get("description", ""))
    cells = _grid_cells(_mapping(e.get("grid"), f"{where}.grid"), f"{where}.grid") if "grid" in e else [{}]
    out = []
    for cell in cells:
        label = ",".join(f"{k}={_override_value(v)}" for k, v in cell.items())
        out.append(
            Case(
                f"{name}[{label}]" if cell else name,
                description,
                overrides + tuple(f"{k}={_override_value(v)}" for k, v in cell.items()),
                rec,
                tuple(range(1 if rec is not None else seeds_n)),
                replay,
                checks,
                pending,
                cell,
                name,
                subject,
            )
        )
    return out


def load_suite(path: Path, name: str, *, seeds: int | None = None) -> Suite:
    """Read suite ``name`` and every fault from the suite file.

    Raises:
        ConfigError: unreadable file, unknown suite, or a bad entry (named in the message).
    """
    where = str(path)
    if not path.is_file():
        raise _err(where, "suite file missing", "no such file", "give --file PATH or restore evals/base.yaml")
    if path.stat().st_size > MAX_SUITE_BYTES:
        raise _err(where, "suite file too large", f"over {MAX_SUITE_BYTES} bytes", "split it")
    try:
        doc = load_yaml(path, what="suite file")  # bounded: an alias bomb is refused
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise _err(where, "suite file unreadable", first, "fix the YAML") from err
    doc = _mapping(doc, where)
    _known_keys(doc, ("faults", "suites", "robustness"), where)  # robustness: evaluation.robustness
    suites = _mapping(doc.get("suites"), f"{where}: suites")
    if name not in suites:
        raise _err(where, f"unknown suite {name!r}", f"suites: {', '.join(suites) or '(none)'}", "pick one")
    faults = {
        n: _fault(n, f, f"{where}: faults.{n}", path.parent)
        for n, f in _mapping(doc.get("faults"), f"{where}: faults").items()
    }
    s = _mapping(suites[name], f"{where}: suites.{name}")
    _known_keys(
        s, ("description", "baseline", "seeds", "confidence", "overrides", "cases"), f"{where}: suites.{name}"
    )
    if seeds is not None:
        s["seeds"] = seeds
    confidence = s.get("confidence", 0.95)
    if not isinstance(confidence, float) or not 0.5 <= confidence < 1:
        raise _err(
            f"{where}: suites.{name}", f"invalid confidence={confidence!r}", "expected 0.5..0.999", "use 0.95"
        )
    if "baseline" not in s:
        raise _err(
            f"{where}: suites.{name}",
            "no baseline path",
            "--accept needs somewhere to write",
            "add baseline: baselines/NAME.parquet",
        )
    baseline = (path.parent / str(s["baseline"])).resolve()
    if baseline.suffix not in (".parquet", ".csv"):
        raise _err(
            f"{where}: suites.{name}.baseline",
            f"invalid baseline {baseline.name!r}",
            "expected .parquet or .csv",
            "e.g. baselines/base.parquet",
        )
    cases: list[Case] = []
    for cname, centry in _mapping(s.get("cases"), f"{where}: suites.{name}.cases").items():
        cases += _cases(
            str(cname), centry, s, path.parent, f"{where}: suites.{name}.cases.{cname}", list(faults)
        )
    if not cases:
        raise _err(f"{where}: suites.{name}", "no cases", "a suite needs at least one case", "add cases:")
    return Suite(
        name,
        path,
        baseline,
        float(confidence),
        _strings(s.get("overrides"), f"{where}: suites.{name}.overrides"),
        tuple(cases),
        faults,
    )


def select_faults(suite: Suite, names: list[str]) -> list[Fault]:
    """The faults to inject; unknown or pending ones are refused with one line."""
    out = []
    for n in names:
        fault = suite.faults.get(n)
        if fault is None:
            raise _err(
                "--inject",
                f"unknown fault {n!r}",
                f"known: {', '.join(suite.faults) or '(none)'}",
                "pick from the list (python -m simlan_data.evals --list)",
            )
        if fault.pending:
            raise _err(
                "--inject",
                f"fault {n!r} is pending",
                fault.pending,
                "it can be injected once that has landed",
            )
        out.append(fault)
    return out
