"""Input checks at the boundaries that the typed config alone does not cover.

- :func:`config_error_from`: Hydra's and OmegaConf's errors (unknown key, wrong type, unknown
  group option, bad override syntax) as one :class:`ConfigError` line naming the full key, with a
  "did you mean" and a unit hint (units are in key names: ``duration_s=60``, not ``60s``);
- :func:`check_finite`: no NaN or infinity anywhere in a composed config;
- :func:`check_references`: names that refer to other parts of the config (cameras, agents,
  zones) exist. Sections added later register their own checks with
  :func:`register_reference_check` (e.g. safety zones naming agents);
- :func:`compose_config`: the run config composed and checked in-process exactly as
  ``python -m simlan_data.run`` does (tests, fuzzing, scripts).

Every failure is one line: ``error: <what> in <where>: <why>; <what to do>``.
"""

from __future__ import annotations

import copy
import difflib
import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import fields, is_dataclass
from types import UnionType
from typing import Any, Union, get_args, get_origin, get_type_hints

from hydra.errors import MissingConfigException, OverrideParseException
from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import (
    ConfigAttributeError,
    ConfigKeyError,
    InterpolationResolutionError,
    MissingMandatoryValue,
    OmegaConfBaseException,
    ValidationError,
)

from simlan_data.config.schema import Config
from simlan_data.constants import CONF_DIR
from simlan_data.errors import ConfigError, SimlanError

# a number followed by a unit, e.g. "60s", "2 m", "5Hz", "90deg"
_WITH_UNIT = re.compile(
    r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z/%°][a-zA-Z/%°0-9^]*)\s*$"
)
_UNITS = {
    "_s": "seconds",
    "_ns": "nanoseconds",
    "_m": "metres",
    "_hz": "hertz",
    "_mps": "metres per second",
    "_rps": "radians per second",
    "_rad": "radians",
    "_deg": "degrees",
    "_kg": "kilograms",
    "_mps2": "metres per second squared",
    "_rps2": "radians per second squared",
}


def _unit_of(key: str) -> str:
    for suffix, name in sorted(_UNITS.items(), key=lambda kv: -len(kv[0])):
        if key.endswith(suffix):
            return name
    return ""


def _typed_keys(prefix: str = "", obj: Any = None) -> list[str]:
    """Every dotted key of the typed config (walking a default instance; dicts of agents excluded)."""
    obj = Config() if obj is None else obj
    out: list[str] = []
    for f in fields(obj):
        key = f"{prefix}{f.name}"
        out.append(key)
        value = getattr(obj, f.name)
        if is_dataclass(value):
            out += _typed_keys(f"{key}.", value)
    return out


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """``"; did you mean X?"``-style suffix, or ``""``."""
    close = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.6)
    return f"did you mean {close[0]}?" if close else ""


def _full_key(err: OmegaConfBaseException) -> str:
    key = getattr(err, "full_key", None) or getattr(err, "key", None) or ""
    return str(key)


def _first_line(text: object) -> str:
    lines = [ln.strip() for ln in str(text).splitlines() if ln.strip()]
    return lines[0] if lines else ""


def _chain(err: BaseException | None) -> Iterable[BaseException]:
    seen = 0
    while err is not None and seen < 20:
        yield err
        err, seen = err.__cause__ or err.__context__, seen + 1


def config_error_from(err: BaseException) -> ConfigError | None:
    """A one-line ConfigError for a Hydra/OmegaConf composition error, or None if it is none."""
    for cur in _chain(err):
        if isinstance(cur, (ConfigKeyError, ConfigAttributeError)) and "not in" in str(cur):
            return _unknown_key(cur)
        if isinstance(cur, ValidationError):
            return _bad_value(cur)
        if isinstance(cur, MissingMandatoryValue):
            key = _full_key(cur)
            return ConfigError(
                f"missing value for {key}", "config", "the key has no default", f"set it, e.g. {key}=..."
            )
        if isinstance(cur, OverrideParseException):
            return ConfigError(
                "invalid override",
                "command line",
                _first_line(cur),
                "write KEY=VALUE, lists as KEY=[a,b], quote values with spaces",
            )
        if isinstance(cur, MissingConfigException):
            m = re.search(r"Could not find '([^'/]+)/([^']*)'", str(cur))
            if m:
                options = sorted(p.stem for p in (CONF_DIR / m.group(1)).glob("*.yaml"))
                hint = did_you_mean(m.group(2), options)
                return ConfigError(
                    f"unknown {m.group(1)}={m.group(2)}",
                    "config",
                    f"no such option in conf/{m.group(1)}/",
                    (hint + " " if hint else "") + f"options: {', '.join(options)}",
                )
    return None


def _unknown_key(err: OmegaConfBaseException) -> ConfigError:
    full = _full_key(err)
    m = re.search(r"Key '([^']+)' not in '([^']+)'", str(err))
    key, owner = (m.group(1), m.group(2)) if m else (full.rsplit(".", 1)[-1], "the config")
    full = full or key
    parent = full.rsplit(".", 1)[0] if "." in full else ""
    owner_type = getattr(err, "object_type", None)  # the dataclass that lacks the key (a plug-in's too)
    if is_dataclass(owner_type):
        candidates = [f"{parent}.{f.name}" if parent else f.name for f in fields(owner_type)]
    else:
        candidates = [
            k for k in _typed_keys() if k.rsplit(".", 1)[0] == parent or (not parent and "." not in k)
        ]
    if not candidates:  # a key inside an agent or another dict of dataclasses
        from simlan_data.config.schema import AgentConfig

        candidates = [f"{parent}.{f.name}" for f in fields(AgentConfig) if f.name != "namespace"]
    hint = did_you_mean(full, candidates)
    return ConfigError(
        f"unknown key {full}",
        "config",
        f"{owner} has no such key",
        hint or "see `python -m simlan_data.run --help` and --cfg job for the keys",
    )


def _bad_value(err: ValidationError) -> ConfigError:
    full = _full_key(err) or "a config value"
    text = _first_line(err)
    if (
        "is not a subclass of AgentConfig" in text
    ):  # OmegaConf cannot add a typed dict entry from the command line
        return ConfigError(
            f"cannot add agent {full}",
            "command line",
            "new agents go in a spawn list file",
            "write DIR/agents/NAME.yaml like conf/agents/four_robots.yaml and run with "
            "'hydra.searchpath=[file://DIR]' agents=NAME",
        )
    nested = re.search(r"Value (\S+) \((\w+)\) is incompatible with type hint '(\w+)'", text)
    if nested and nested.group(2) == "int" and nested.group(3) == "float":
        return ConfigError(
            f"invalid {full}",
            "config",
            f"{nested.group(1)} is an integer, and numbers in nested lists are not converted",
            "write every number with a decimal point, e.g. [[1.0, 2.0]]",
        )
    m = re.search(r"Value '(.*)' of type '([^']+)' could not be converted to (\w+)", text)
    if not m:
        return ConfigError(f"invalid {full}", "config", text, "see --help for its type")
    value, got, want = m.group(1), m.group(2), m.group(3)
    leaf = full.rsplit(".", 1)[-1]
    unit = _unit_of(leaf)
    with_unit = _WITH_UNIT.match(value)
    if with_unit and unit:
        fix = f"units are part of the key's name ({leaf}: {unit}): write {full}={with_unit.group(1)}"
    elif with_unit:
        fix = f"give a plain number: {full}={with_unit.group(1)}"
    elif want == "Integer" and got == "float":
        fix = "give a whole number"
    else:
        fix = f"give {'an' if want[0] in 'AEIOU' else 'a'} {want.lower()}" + (f" in {unit}" if unit else "")
    return ConfigError(f"invalid {full}={value!r}", "config", f"expected {want}, got {got}", fix)


# ------------------------------------------------------------------------------ interpolations
def resolve_interpolations(cfg: DictConfig) -> DictConfig:
    """A copy of ``cfg`` with every interpolation replaced by what it gives, each value checked
    against the schema as it is assigned (``OmegaConf.to_object`` alone does not check what an
    interpolation gives for a whole section: ``faults=${now:%Y}`` reached the checks as a string).

    Raises:
        ConfigError: naming the key whose interpolation gives a value of the wrong type.
    """
    resolved = copy.deepcopy(cfg)
    try:
        OmegaConf.resolve(resolved)
    except ValidationError as err:
        if _full_key(err):  # a value OmegaConf names (as to_object would have): the usual message
            raise _bad_value(err) from None
        # a whole section, which OmegaConf does not name: resolution goes in order and stops at
        # the failing node, the first one still unresolved
        key, text = _first_interpolation(resolved)
        raise ConfigError(
            f"invalid {key}={text!r}",
            "config",
            _first_line(err),
            "give a value of the key's type (an interpolation has to give one too)",
        ) from None
    except InterpolationResolutionError as err:  # a resolver's own check (scenario=fleet's missions)
        own = next((e for e in _chain(err) if isinstance(e, SimlanError)), None)
        if own is None:
            raise
        raise own from None
    return resolved


def _first_interpolation(node: DictConfig | ListConfig, prefix: str = "") -> tuple[str, str]:
    """The full key and text of the first interpolation left in ``node`` (depth first)."""
    keys: Iterable[Any] = node.keys() if isinstance(node, DictConfig) else range(len(node))
    for k in keys:
        full = f"{prefix}[{k}]" if isinstance(node, ListConfig) else (f"{prefix}.{k}" if prefix else str(k))
        if OmegaConf.is_interpolation(node, k):
            return full, str(node._get_node(k)._value())  # type: ignore[union-attr]
        child = node._get_node(k)
        if isinstance(child, (DictConfig, ListConfig)):
            found = _first_interpolation(child, full)
            if found[0]:
                return found
    return "", ""


# ------------------------------------------------------------------------------ finite values
def check_finite(node: Any, prefix: str = "") -> None:
    """Refuse NaN and infinity anywhere in a config (DictConfig, or plain dicts and lists).

    Raises:
        ConfigError: naming the first non-finite value's key.
    """
    if isinstance(node, (DictConfig, ListConfig)):
        node = OmegaConf.to_container(node, resolve=False, throw_on_missing=False)
    if isinstance(node, dict):
        for k, v in node.items():
            check_finite(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            check_finite(v, f"{prefix}[{i}]")
    elif isinstance(node, float) and not math.isfinite(node):
        unit = _unit_of(prefix.split(".")[-1].split("[")[0])
        raise ConfigError(
            f"invalid {prefix}={node}",
            "config",
            "not a finite number",
            f"give a number{' in ' + unit if unit else ''}",
        )


def check_nulls(node: Any, schema: type = Config, prefix: str = "") -> None:
    """Refuse null where the schema has no place for it (``~key +key=null`` gets past OmegaConf's
    own type check: the re-added key is untyped), and a list or mapping as an element of a list
    of numbers or strings (OmegaConf lets ``cameras.ids=[[]]`` through as ``list[int]``).

    Raises:
        ConfigError: naming the first such key.
    """
    if isinstance(node, (DictConfig, ListConfig)):
        node = OmegaConf.to_container(node, resolve=False, throw_on_missing=False)
    if not isinstance(node, dict):
        return
    hints = get_type_hints(schema)
    for f in fields(schema):
        if f.name not in node:
            continue
        key, value, hint = f"{prefix}{f.name}", node[f.name], hints[f.name]
        members = get_args(hint) if get_origin(hint) in (Union, UnionType) else (hint,)
        if value is None and type(None) not in members and Any not in members:
            raise ConfigError.invalid(
                key, None, "must not be null", f"give {key} a value or drop the override"
            )
        for member in members:
            if is_dataclass(member) and isinstance(member, type):
                check_nulls(value, member, f"{key}.")
            _check_scalar_elements(key, value, member)


SCALARS = (int, float, str, bool)


def _check_scalar_elements(key: str, value: Any, hint: Any) -> None:
    """Refuse a nested list or mapping in a value typed as a list of scalars."""
    args = get_args(hint)
    if get_origin(hint) is not list or not args or args[0] not in SCALARS or not isinstance(value, list):
        return
    for item in value:
        if isinstance(item, (list, dict)):
            kind = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}[args[0]]
            raise ConfigError.invalid(
                key,
                value,
                f"each element must be {kind}, not a {type(item).__name__}",
                f"write a flat list: {key}=[a,b]",
            )


# ------------------------------------------------------------------------------ unknown keys
def check_known_keys(node: Any, schema: Any = Config, prefix: str = "") -> None:
    """Refuse keys the schema does not have (``+recording.fsynk=true`` forces a new key into the
    typed config, and building the dataclasses ignores it).

    Open by design: nodes typed ``Any`` or ``dict[str, Any]``, except ``algorithms.ROLE``, checked
    against the selected algorithm's config class (plus ``name``); ``hydra`` is Hydra's.

    Raises:
        ConfigError: naming the first unknown key, with a "did you mean".
    """
    if isinstance(node, (DictConfig, ListConfig)):
        node = OmegaConf.to_container(node, resolve=False, throw_on_missing=False)
    members = get_args(schema) if get_origin(schema) in (Union, UnionType) else (schema,)
    for member in members:
        if is_dataclass(member) and isinstance(member, type):
            _check_dataclass_keys(node, member, prefix)
            return
        origin, args = get_origin(member), get_args(member)
        if origin is dict and len(args) == 2 and isinstance(node, dict):
            for k, v in node.items():
                check_known_keys(v, args[1], f"{prefix}{k}.")
            return
        if origin is list and args and isinstance(node, list):
            for i, v in enumerate(node):
                check_known_keys(v, args[0], f"{prefix[:-1]}[{i}].")
            return


def _check_dataclass_keys(node: Any, schema: type, prefix: str) -> None:
    if not isinstance(node, dict):
        return  # a value of the wrong kind (or an interpolation): the type checks say so
    from simlan_data.config.algorithms import AlgorithmsConfig

    hints = get_type_hints(schema)
    known = {f.name: hints[f.name] for f in fields(schema)}
    for key in node:
        if prefix == "" and schema is Config and key == "hydra":
            continue
        if key not in known:
            full = f"{prefix}{key}"
            close = did_you_mean(str(key), known).removeprefix("did you mean ")
            hint = f"did you mean {prefix}{close}" if close else ""
            raise ConfigError(
                f"unknown key {full}",
                "config",
                f"{schema.__name__} has no such key",
                hint or "see `python -m simlan_data.run --help` and --cfg job for the keys",
            )
    for key, value in node.items():
        if key not in known:
            continue
        if schema is AlgorithmsConfig and isinstance(value, dict):
            _check_algorithm_keys(value, key, f"{prefix}{key}.")
        elif schema is AlgorithmsConfig and value is not None:  # algorithms.safety=0: not a section
            raise ConfigError(
                f"invalid {prefix}{key}={value!r}",
                "config",
                "expected the selected algorithm's section (its keys), not a value",
                f"select an algorithm with {prefix.replace('.', '/')}{key}=NAME and set its keys with "
                f"{prefix}{key}.KEY=VALUE",
            )
        else:
            check_known_keys(value, known[key], f"{prefix}{key}.")


def _check_algorithm_keys(node: dict[str, Any], role: str, prefix: str) -> None:
    """``algorithms.ROLE``: the selected algorithm's config fields and ``name``."""
    from simlan_data.algorithms import registry
    from simlan_data.config.algorithms import selection_node

    name = node.get(registry.NAME_KEY)
    if not isinstance(name, str) or "${" in name:
        return
    try:
        spec = registry.resolve(role, name, where="config")
    except SimlanError:
        return  # an unknown algorithm: the composition's own check names it
    node_type = selection_node(spec)
    node_type.__name__ = spec.config_class.__name__  # the name users know
    _check_dataclass_keys(node, node_type, prefix)


# ------------------------------------------------------------------------------- references
ReferenceCheck = Callable[[Config], None]
REFERENCE_CHECKS: list[ReferenceCheck] = []


def register_reference_check(fn: ReferenceCheck) -> ReferenceCheck:
    """Decorator: run ``fn(cfg)`` with the other reference checks (it raises ConfigError).

    A config section whose values name other things (zones naming agents, a pose mapper naming a
    humanoid) registers a check here, using :func:`require_known` for the message.
    """
    if fn not in REFERENCE_CHECKS:
        REFERENCE_CHECKS.append(fn)
    return fn


def require_known(field: str, names: Sequence[Any], known: Iterable[Any], what: str) -> None:
    """Raise ConfigError if a name in ``names`` (the value of ``field``) is not in ``known``.

    ``what`` says what the names refer to, e.g. "agent" or "zone".
    """
    pool = [str(k) for k in known]
    for name in names:
        if str(name) not in pool:
            hint = did_you_mean(str(name), pool)
            raise ConfigError(
                f"unknown {what} {name!r} in {field}",
                "config",
                f"no {what} of that name (known: {', '.join(pool) or 'none'})",
                hint or f"name one of the configured {what}s",
            )


def check_references(cfg: Config) -> None:
    """Run every registered reference check.

    Built in elsewhere: camera ids against the calibration files (``sim.scene.load_cameras``),
    agents named by a scenario against the spawn list (``AgentConfig.check``: an agent without a
    pose was never spawned). The ``safety`` section (zones naming agents) registers its own.
    """
    for check in REFERENCE_CHECKS:
        check(cfg)


# ---------------------------------------------------------------------------------- compose
def compose_config(overrides: Sequence[str]) -> Config:
    """Compose and check the run config in-process, as ``python -m simlan_data.run`` does.

    Raises:
        ConfigError: for every kind of bad override or value.
    """
    from hydra import compose, initialize_config_dir

    from simlan_data.config.safe_yaml import check_config_dirs
    from simlan_data.config.schema import register_configs

    check_config_dirs(overrides)  # before OmegaConf copies out an alias bomb
    register_configs(list(overrides))
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            cfg = compose("config", overrides=list(overrides))
    except Exception as err:  # Hydra's composition fails in assorted ways on odd overrides
        translated = config_error_from(err)
        if translated is not None:
            raise translated from None
        raise ConfigError(
            "invalid configuration",
            "command line",
            f"{type(err).__name__}: {_first_line(err) or 'composition failed'}",
            "see --help for the valid groups and keys",
        ) from None
    return to_config(cfg)


def to_config(cfg: DictConfig) -> Config:
    """Build the typed config; range and reference checks raise ConfigError."""
    plain = OmegaConf.to_container(cfg, resolve=False, throw_on_missing=False)  # one walk for all
    check_known_keys(plain)
    check_finite(plain)
    check_nulls(plain)
    resolved = resolve_interpolations(cfg)
    try:
        obj = OmegaConf.to_object(resolved)
    except SimlanError:
        raise
    except Exception as err:
        cur: BaseException | None = err
        while cur is not None:
            if isinstance(cur, SimlanError):
                raise cur from None
            cur = cur.__cause__ or cur.__context__
        translated = config_error_from(err)
        if translated is not None:
            raise translated from None
        raise
    assert isinstance(obj, Config)
    check_references(obj)
    return obj
