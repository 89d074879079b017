"""The ``algorithms`` section: which algorithm plays each role, with that algorithm's own config.

Every registered algorithm (entry-point group ``simlan_data.algorithms``, ours included) becomes an
option of the Hydra config group ``algorithms/<role>``, whose node is the algorithm's own config
dataclass plus its ``name``::

    python -m simlan_data.run algorithms/localizer=centroid algorithms.localizer.min_area_px=30
    python -m simlan_data.run algorithms/localizer=my_pkg.loc:MyLocalizer      # by import path

Hydra then checks the keys and types against the algorithm's dataclass, and ``OmegaConf.to_object``
builds it (its ``__post_init__`` checks run), as for every other section.
"""

from __future__ import annotations

import dataclasses
import re
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field, make_dataclass
from typing import Any, get_type_hints

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from simlan_data.algorithms import registry
from simlan_data.algorithms.roles import ROLES

GROUP = "algorithms/{role}"
_SELECT = re.compile(r"^\+{0,2}algorithms/(?P<role>\w+)=(?P<name>.+)$")


@dataclass
class AlgorithmsConfig:
    """One node per role: the selected algorithm's config (its dataclass) and its ``name``."""

    localizer: Any = None
    coordinator: Any = None
    safety: Any = None
    stitcher: Any = None
    posemap: Any = None


def selection_node(spec: registry.AlgorithmSpec) -> type:
    """The Hydra node of an option: the algorithm's config fields plus its ``name``.

    A copy of the fields, not a subclass: a frozen config dataclass would make the node read-only
    (no ``algorithms.ROLE.KEY=VALUE`` overrides). Its ``__post_init__`` builds the algorithm's own
    dataclass from the values, so the algorithm's checks run when the config is built.
    """
    base = spec.config_class
    hints = get_type_hints(base)
    fields = []
    for f in dataclasses.fields(base):
        if not f.init:
            continue
        if f.default is not dataclasses.MISSING:
            fields.append((f.name, hints[f.name], field(default=f.default)))
        elif f.default_factory is not dataclasses.MISSING:
            fields.append((f.name, hints[f.name], field(default_factory=f.default_factory)))
        else:
            fields.append((f.name, hints[f.name], field(default=MISSING)))
    fields.append((registry.NAME_KEY, str, field(default=spec.name)))

    def __post_init__(self: Any) -> None:  # noqa: N807 - the dataclass hook
        values = plain(self)
        if any(v == MISSING for v in values.values()):
            return  # OmegaConf building the node itself
        spec.make_config(values, where=f"config algorithms.{spec.role}")

    return make_dataclass(f"{base.__name__}Selection", fields, namespace={"__post_init__": __post_init__})


def selected(overrides: Iterable[str]) -> list[tuple[str, str]]:
    """(role, name) of every ``algorithms/ROLE=NAME`` among the overrides (a sweep's lists split)."""
    out = []
    for item in overrides:
        m = _SELECT.match(item)
        if m is None:
            continue
        role = m["role"]
        if role not in ROLES:
            registry.resolve(role, m["name"], where="command line")  # one line: the known roles
        for name in m["name"].split(","):
            out.append((role, name.strip()))
    return out


def register_algorithms(overrides: Iterable[str] | None = None) -> None:
    """Store every registered algorithm (and those named by import path) as a Hydra option.

    Raises:
        ConfigError: an import path that does not load or does not implement its role.
    """
    cs = ConfigStore.instance()
    for role in ROLES:
        for name in registry.names(role):
            spec = registry.resolve(role, name)
            cs.store(group=GROUP.format(role=role), name=name, node=selection_node(spec))
    for role, name in selected(sys.argv[1:] if overrides is None else overrides):
        spec = registry.resolve(role, name, where="command line")  # unknown: lists the registered
        if ":" in name:
            cs.store(group=GROUP.format(role=role), name=name, node=selection_node(spec))


def plain(config: Any) -> dict[str, Any]:
    """A selected algorithm's config as plain values, without its ``name``."""
    return {
        f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.name != registry.NAME_KEY
    }


def selected_algorithm(algorithms: AlgorithmsConfig, role: str) -> tuple[registry.AlgorithmSpec, Any]:
    """The algorithm a typed config selects for ``role`` and its own checked config; the built-in
    with its defaults where the config has no node for the role (one built without Hydra's
    defaults list)."""
    where = f"config algorithms.{role}"
    node = getattr(algorithms, role)
    if node is None:
        return registry.from_config(None, role, where=where)
    spec = registry.resolve(role, node.name, where="config")
    return spec, spec.make_config(plain(node), where=where)
