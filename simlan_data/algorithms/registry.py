"""Find, check and build the algorithm of each role: entry points or an import path.

An algorithm is registered under a name in the entry-point group ``simlan_data.algorithms``
(ours in simlan_data's own pyproject.toml, a user's in theirs), as ``NAME`` or ``ROLE.NAME`` (the
prefix lets one package give one name to algorithms of several roles)::

    [project.entry-points."simlan_data.algorithms"]
    centroid = "my_package.localizer:CentroidLocalizer"
    "stitcher.fast" = "my_package.stitch:FastStitcher"

or named by import path, ``my_package.localizer:CentroidLocalizer``, without registering. The
class says its role (``role``) and its config dataclass (``config_class``); see
:mod:`simlan_data.algorithms.roles`.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from simlan_data.algorithms.roles import CONTEXTS, PROTOCOLS, ROLES, missing_methods
from simlan_data.errors import ConfigError, PluginError, SimlanError

ENTRY_POINT_GROUP = "simlan_data.algorithms"
DEFAULTS = {  # the built-in algorithm of each role (registered like any other)
    "localizer": "aruco",
    "coordinator": "gpss",
    "safety": "trees",
    "stitcher": "gpss",
    "posemap": "trained",
}
NAME_KEY = "name"  # the config key that selects the algorithm of a role


@dataclass(frozen=True)
class AlgorithmSpec:
    """A resolved algorithm: its class, its config dataclass and where it came from."""

    role: str
    name: str
    cls: type
    config_class: type
    origin: str  # "entry point NAME = VALUE (DIST)" or "import path"

    def make_config(self, values: Mapping[str, Any], *, where: str) -> Any:
        """The config dataclass from plain values (a recorded config, --set options); checked."""
        known = {f.name for f in dataclasses.fields(self.config_class) if f.init}
        unknown = sorted(set(values) - known - {NAME_KEY})
        if unknown:
            raise ConfigError(
                f"unknown key {unknown[0]!r} for {self.role} {self.name!r}",
                where,
                f"{self.config_class.__name__} has {', '.join(sorted(known)) or 'no keys'}",
                "check the spelling, or select the algorithm that has this key",
            )
        kwargs = {k: _as_field(self.config_class, k, v) for k, v in values.items() if k in known}
        try:
            return self.config_class(**kwargs)
        except ConfigError:
            raise
        except (TypeError, ValueError) as err:
            raise ConfigError(
                f"invalid config for {self.role} {self.name!r}", where, str(err), "fix the value"
            ) from err

    def build(self, config: Any, context: Any, *, where: str = "") -> Any:
        """An instance: ``cls(config, context)``; a failing constructor is reported with the name."""
        if not isinstance(context, CONTEXTS[self.role]):
            raise TypeError(f"{self.role} context must be {CONTEXTS[self.role].__name__}")
        try:
            return self.cls(config, context)
        except ConfigError:
            raise
        except Exception as err:
            raise ConfigError(
                f"{self.role} {self.name!r} could not be built",
                where or self.origin,
                f"{type(err).__name__}: {err}",
                "fix the plug-in or its config",
            ) from err


def _as_field(config_class: type, key: str, value: Any) -> Any:
    """Lists stay lists; a tuple-typed field gets a tuple (recorded configs hold lists)."""
    ftype = {f.name: f.type for f in dataclasses.fields(config_class)}[key]
    if isinstance(value, list) and "tuple" in str(ftype):
        return tuple(value)
    return value


@cache
def _entry_points() -> tuple[EntryPoint, ...]:
    return tuple(entry_points(group=ENTRY_POINT_GROUP))


def _origin(ep: EntryPoint) -> str:
    dist = getattr(ep, "dist", None)
    return f"entry point {ep.name} = {ep.value}" + (f" ({dist.name})" if dist is not None else "")


def _load(target: str, *, where: str, role: str) -> type:
    """The class at ``module:Class`` (or ``module.Class``)."""
    module_name, _, attr = target.partition(":") if ":" in target else target.rpartition(".")
    try:
        module = importlib.import_module(module_name)
        obj = module
        for part in attr.split("."):
            obj = getattr(obj, part)
    except Exception as err:
        raise ConfigError(
            f"cannot import {role} {target!r}",
            where,
            f"{type(err).__name__}: {err}",
            "install the package that provides it, or fix the import path (module:Class)",
        ) from err
    if not isinstance(obj, type):
        raise ConfigError(
            f"{role} {target!r} is not a class", where, f"it is {type(obj).__name__}", "name the class"
        )
    return obj


def names(role: str) -> list[str]:
    """The registered names of ``role``'s algorithms (loads every entry point once)."""
    return sorted(name for (r, name) in _registered() if r == role)


@cache
def _registered() -> dict[tuple[str, str], AlgorithmSpec]:
    """(role, name) -> spec for every entry point that loads and declares a role."""
    out: dict[tuple[str, str], AlgorithmSpec] = {}
    for ep in _entry_points():
        try:
            cls = ep.load()
        except Exception:  # reported when it is selected (see resolve)
            continue
        role = getattr(cls, "role", None)
        prefix, name = _split(ep.name)
        if role in ROLES and isinstance(cls, type) and prefix in (None, role):
            config_class = getattr(cls, "config_class", None)
            if isinstance(config_class, type) and dataclasses.is_dataclass(config_class):
                out[(role, name)] = AlgorithmSpec(role, name, cls, config_class, _origin(ep))
    return out


def _split(entry_point_name: str) -> tuple[str | None, str]:
    """(role, name) of an entry point named ``ROLE.NAME``, (None, name) of one named ``NAME``."""
    role, dot, name = entry_point_name.partition(".")
    return (role, name) if dot and role in ROLES else (None, entry_point_name)


def resolve(role: str, name: str, *, where: str = "algorithms") -> AlgorithmSpec:
    """The algorithm named ``name`` for ``role``: a registered name or ``module:Class``.

    Raises:
        ConfigError: unknown role or name (the registered names listed), an entry point or import
            path that does not load, a class that does not implement the role's protocol.
    """
    if role not in ROLES:
        raise ConfigError(
            f"unknown role {role!r}", where, f"roles are {', '.join(ROLES)}", "choose one of them"
        )
    where = f"{where} (algorithms/{role}={name})"
    spec = _registered().get((role, name))
    if spec is None:
        if ":" in name:
            cls = _load(name, where=where, role=role)
            spec = AlgorithmSpec(role, name, cls, getattr(cls, "config_class", None), "import path")  # type: ignore[arg-type]
        else:
            broken = [
                ep
                for ep in _entry_points()
                if _split(ep.name)[1] == name and _split(ep.name)[0] in (None, role)
            ]
            if broken:  # registered, but it does not load or declares another role
                cls = _load(broken[0].value, where=where, role=role)
                spec = AlgorithmSpec(role, name, cls, getattr(cls, "config_class", None), _origin(broken[0]))  # type: ignore[arg-type]
            else:
                raise ConfigError(
                    f"no {role} named {name!r}",
                    where,
                    f"registered {role}s: {', '.join(names(role)) or 'none'}",
                    "choose a registered name, install the plug-in's package, or give module:Class",
                )
    check(spec, where=where)
    return spec


def check(spec: AlgorithmSpec, *, where: str) -> None:
    """Raise ConfigError unless the class declares ``spec.role`` and implements its protocol."""
    declared = getattr(spec.cls, "role", None)
    if declared != spec.role:
        raise ConfigError(
            f"{spec.cls.__module__}.{spec.cls.__qualname__} is not a {spec.role}",
            where,
            f"its role is {declared!r}" if declared else "it declares no role",
            f'set role = "{spec.role}" on the class'
            + (f", or select it for role {declared!r}" if declared else ""),
        )
    if spec.config_class is None or not dataclasses.is_dataclass(spec.config_class):
        raise ConfigError(
            f"{spec.role} {spec.name!r} has no config dataclass",
            where,
            "config_class is missing or not a dataclass",
            "set config_class = <a @dataclass with defaults> on the class",
        )
    missing = missing_methods(spec.role, spec.cls)
    if missing:
        raise ConfigError(
            f"{spec.cls.__module__}.{spec.cls.__qualname__} does not implement the {spec.role} protocol",
            where,
            f"missing method{'s' if len(missing) > 1 else ''}: {', '.join(missing)}",
            f"implement them (see simlan_data.algorithms.roles.{PROTOCOLS[spec.role].__name__})",
        )


def selection(config: Mapping[str, Any] | None, role: str) -> tuple[str, dict[str, Any]]:
    """(name, config values) of ``role`` in a run's plain config (a recording's /simlan/config)."""
    section = dict(((config or {}).get("algorithms") or {}).get(role) or {})
    name = str(section.pop(NAME_KEY, DEFAULTS[role]))
    return name, section


def from_config(
    config: Mapping[str, Any] | None,
    role: str,
    *,
    name: str | None = None,
    overrides: Mapping[str, Any] | None = None,
    where: str = "recorded config",
) -> tuple[AlgorithmSpec, Any]:
    """The algorithm and its checked config for ``role`` from a plain run config (+ overrides).

    ``name`` selects another algorithm than the recorded one; then the recorded values of the
    recorded algorithm are not used (they belong to another config class).
    """
    recorded_name, values = selection(config, role)
    if name is not None and name != recorded_name:
        values = {}
    spec = resolve(role, name or recorded_name, where=where)
    values.update(overrides or {})
    return spec, spec.make_config(values, where=where)


class Guarded:
    """An algorithm instance whose failures name it and the simulated time (exit 1, not a crash).

    Attribute access passes through; a call that raises becomes a :class:`PluginError`. The last
    integer ``t_ns`` an algorithm was called with (or ``world.t_ns``) gives the time.
    """

    def __init__(self, inner: Any, spec: AlgorithmSpec) -> None:
        self._inner, self._spec = inner, spec
        self._t_ns: int | None = None

    def at(self, t_ns: int) -> Guarded:
        """Tell the guard the simulated time of the next call (for methods that take no time,
        such as ``stitch``), so that a failure names it: ``guarded.at(t_ns).stitch(frames)``."""
        self._t_ns = t_ns
        return self

    def __getattr__(self, attr: str) -> Any:
        value = getattr(self._inner, attr)
        if not callable(value) or attr.startswith("_"):
            return value  # data (``timings``, ``zones``...) is read afresh each time
        wrapped = self._wrap(attr, value)
        if inspect.ismethod(value):  # a bound method does not change: wrap it once, not per call
            self.__dict__[attr] = wrapped
        return wrapped

    def _wrap(self, attr: str, fn: Any) -> Any:
        def call(*args: Any, **kwargs: Any) -> Any:
            first = args[0] if args else None
            t_ns = first if isinstance(first, int) else getattr(first, "t_ns", None)
            if isinstance(t_ns, int):
                self._t_ns = t_ns
            try:
                return fn(*args, **kwargs)
            except SimlanError:
                raise
            except Exception as err:
                when = f"at t={self._t_ns / 1e9:.3f} s" if self._t_ns is not None else "before the first tick"
                raise PluginError(
                    f"{self._spec.role} {self._spec.name!r} failed in {attr}()",
                    f"{when} ({self._spec.origin})",
                    f"{type(err).__name__}: {err}",
                    "fix the plug-in; rerun with --debug for its traceback",
                ) from err

        return call
