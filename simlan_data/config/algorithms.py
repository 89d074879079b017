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
from typing import Any

from hydra.core.config_store import ConfigStore

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
    """The algorithm's config dataclass with a ``name`` field: the Hydra node of the option."""
    base = spec.config_class
    params = getattr(base, "__dataclass_params__", None)
    return make_dataclass(
        f"{base.__name__}Selection",
        [(registry.NAME_KEY, str, field(default=spec.name))],
        bases=(base,),
        frozen=bool(params and params.frozen),
    )


def selected_by_path(overrides: Iterable[str]) -> list[tuple[str, str]]:
    """(role, module:Class) of every ``algorithms/ROLE=module:Class`` among the overrides."""
    out = []
    for item in overrides:
        m = _SELECT.match(item)
        if m and m["role"] in ROLES and ":" in m["name"]:
            out.append((m["role"], m["name"]))
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
    for role, name in selected_by_path(sys.argv[1:] if overrides is None else overrides):
        spec = registry.resolve(role, name, where="command line")
        cs.store(group=GROUP.format(role=role), name=name, node=selection_node(spec))


def plain(config: Any) -> dict[str, Any]:
    """A selected algorithm's config as plain values, without its ``name``."""
    return {
        f.name: getattr(config, f.name)
        for f in dataclasses.fields(config)
        if f.name != registry.NAME_KEY
    }
