"""The safety trees' one config (``algorithms.safety`` when ``algorithms/safety=trees``).

``TreesConfig`` is what ``conf/``, the live run and the replay read: Hydra types it (lists, nested
dataclasses, str/float/bool), its ``__post_init__`` checks it (nested sections given as dicts, as
a recorded config or ``--set`` gives them, are turned into their dataclasses and checked too). The
zones' shapes are derived from it (``TreesConfig.zone_shapes``). What the run adds and is not
configuration (its control and camera periods, the localizer's processing delay, whether the
coordinator is on) comes with the :class:`~simlan_data.algorithms.roles.SafetyContext`;
:class:`TreeParams` holds both for the trees.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

from simlan_data.algorithms.safety.geometry import Zone, make_zone
from simlan_data.errors import ConfigError

RESUME_POLICIES = ("auto", "never")
TTC_ROBOTS = ("uncoordinated", "always")
CAUSES = ("collision", "unobserved", "restricted_area", "ttc")
WHERE = "algorithms.safety"  # where the config lives (the key names in messages)
SECTIONS = {  # config key -> cause
    "collision": "collision",
    "observability": "unobserved",
    "restricted_area": "restricted_area",
    "ttc": "ttc",
}


def _check_condition(obj: Any, key: str, checks: dict[str, tuple[float, float]]) -> None:
    """The checks every condition section shares: its resume policy and its value ranges."""
    if obj.resume not in RESUME_POLICIES:
        raise ConfigError(
            f"invalid {WHERE}.{key}.resume={obj.resume!r}",
            "config",
            f"expected one of {', '.join(RESUME_POLICIES)}",
            f"set {WHERE}.{key}.resume=auto",
        )
    for name, (lo, hi) in checks.items():
        value = getattr(obj, name)
        if not lo <= value <= hi:
            raise ConfigError(
                f"invalid {WHERE}.{key}.{name}={value!r}",
                "config",
                f"must be within {lo:g}..{hi:g}",
                f"use the default {next(f.default for f in dataclasses.fields(obj) if f.name == name)!r}",
            )


@dataclass
class ZoneConfig:
    """A restricted area: corners [x_m, y_m] in the map frame, in order around it."""

    name: str = ""
    polygon: list[Any] = field(default_factory=list)  # [[x_m, y_m], ...]; checked by make_zone (ints welcome)
    namespaces: list[str] = field(default_factory=list)  # robots it applies to; empty: every robot


@dataclass
class CollisionConfig:
    enabled: bool = True
    force_threshold_n: float = 10.0  # contact normal force that counts as a collision
    resume: str = "never"  # auto | never: a robot that hit something waits for an operator
    namespaces: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        _check_condition(self, "collision", {"force_threshold_n": (0.0, 1e6)})


@dataclass
class ObservabilityConfig:
    enabled: bool = True
    timeout_s: float = 5.0  # SIMLAN: stop after 5 s without a camera fix
    resume: str = "auto"
    namespaces: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        _check_condition(self, "observability", {"timeout_s": (0.05, 3600.0)})


@dataclass
class RestrictedAreaConfig:
    enabled: bool = True
    decel_mps2: float = 2.0  # braking the layer counts on (the twin's robots brake at 5-8 m/s^2)
    reaction_s: float = 0.0  # 0: one control period + one camera period + processing delay
    margin_m: float = 0.1
    sigma_k: float = 3.0  # plus this many standard deviations of the position estimate
    lookahead_m: float = 0.3  # a robot stopped at a zone's edge does not creep in
    resume: str = "auto"
    namespaces: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        _check_condition(
            self,
            "restricted_area",
            {
                "decel_mps2": (0.05, 50.0),
                "reaction_s": (0.0, 10.0),
                "margin_m": (0.0, 5.0),
                "sigma_k": (0.0, 10.0),
                "lookahead_m": (0.0, 5.0),
            },
        )


@dataclass
class TtcConfig:
    enabled: bool = True
    stop_cpa_m: float = 2.0  # SIMLAN: CPA <= 2 m and TTC <= 2 s -> hard stop
    stop_ttc_s: float = 2.0
    slow_ttc_s: float = 6.0  # a hazard further out (TTC <= this) -> slow
    slow_speed_mps: float = 0.4  # SIMLAN's crawl speed
    resume: str = "auto"
    namespaces: list[str] = field(default_factory=list)
    # against other robots: "uncoordinated" - only while navigation.coordination is off (the
    # coordinator keeps coordinated robots apart along their plans, closer than SIMLAN's 2 m); "always"
    robots: str = "uncoordinated"

    def __post_init__(self) -> None:
        _check_condition(
            self,
            "ttc",
            {
                "stop_cpa_m": (0.0, 50.0),
                "stop_ttc_s": (0.0, 60.0),
                "slow_ttc_s": (0.0, 600.0),
                "slow_speed_mps": (0.0, 3.0),
            },
        )
        if self.robots not in TTC_ROBOTS:
            raise ConfigError(
                f"invalid {WHERE}.ttc.robots={self.robots!r}",
                "config",
                f"expected one of {', '.join(TTC_ROBOTS)}",
                f"set {WHERE}.ttc.robots=uncoordinated",
            )
        if self.slow_ttc_s < self.stop_ttc_s:
            raise ConfigError(
                f"invalid {WHERE}.ttc.slow_ttc_s={self.slow_ttc_s!r}",
                "config",
                f"must be >= {WHERE}.ttc.stop_ttc_s={self.stop_ttc_s!r} (slowing covers the hazards further out)",
                "use e.g. 6.0",
            )


_SECTION_CLASSES: dict[str, type] = {
    "collision": CollisionConfig,
    "observability": ObservabilityConfig,
    "restricted_area": RestrictedAreaConfig,
    "ttc": TtcConfig,
}


def _known_keys(kind: type, raw: dict[str, Any], where: str) -> None:
    """Refuse a key ``kind`` does not have, naming it and the known ones."""
    known = [f.name for f in dataclasses.fields(kind)]
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise ConfigError(
            f"unknown key {where}.{unknown[0]}", "config", f"known: {', '.join(known)}", "check the spelling"
        )


def _section(key: str, value: Any) -> Any:
    """A condition section from a dict (a recorded config, ``--set``): unknown keys refused."""
    kind = _SECTION_CLASSES[key]
    if isinstance(value, kind):
        return value
    raw = dict(value or {})
    _known_keys(kind, raw, f"{WHERE}.{key}")
    raw["namespaces"] = list(raw.get("namespaces") or ())
    return kind(**raw)


def _zone(i: int, value: Any) -> ZoneConfig:
    """A zone from a dict: unknown keys refused."""
    if isinstance(value, ZoneConfig):
        return value
    raw = dict(value or {})
    _known_keys(ZoneConfig, raw, f"{WHERE}.zones[{i}]")
    return ZoneConfig(
        str(raw.get("name", "")), list(raw.get("polygon") or []), list(raw.get("namespaces") or [])
    )


@dataclass
class TreesConfig:
    """The safety trees (``safety.trees``): one behaviour tree per robot; see tree.py."""

    enabled: bool = True
    namespaces: list[str] = field(default_factory=list)  # robots with a tree; empty: every robot
    hold_s: float = 1.0  # a condition must stay clear this long before the robot drives on
    zones: list[ZoneConfig] = field(default_factory=list)
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    observability: ObservabilityConfig = field(default_factory=ObservabilityConfig)
    restricted_area: RestrictedAreaConfig = field(default_factory=RestrictedAreaConfig)
    ttc: TtcConfig = field(default_factory=TtcConfig)

    def __post_init__(self) -> None:
        self.namespaces = list(self.namespaces or ())
        self.zones = [_zone(i, z) for i, z in enumerate(self.zones or ())]
        shapes = self.zone_shapes  # make_zone checks every zone
        names = [z.name for z in shapes]
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise ConfigError(
                f"invalid {WHERE}.zones",
                "config",
                f"two zones are named '{dup}'",
                "give every zone its own name",
            )
        for key in _SECTION_CLASSES:
            setattr(self, key, _section(key, getattr(self, key)))
        self.hold_s = float(self.hold_s)
        if not 0 <= self.hold_s <= 600:
            raise ConfigError(
                f"invalid {WHERE}.hold_s={self.hold_s!r}", "config", "must be within 0..600 s", "use 1.0"
            )

    @cached_property
    def zone_shapes(self) -> tuple[Zone, ...]:
        """The zones as shapes (derived from ``zones``; ConfigError naming a zone that is unusable)."""
        return tuple(
            make_zone(z.name, z.polygon, tuple(z.namespaces), where=f"{WHERE}.zones[{i}]")
            for i, z in enumerate(self.zones)
        )

    def condition(self, cause: str) -> Any:
        """The config section of a cause (collision, unobserved, restricted_area, ttc)."""
        return {
            "collision": self.collision,
            "unobserved": self.observability,
            "restricted_area": self.restricted_area,
            "ttc": self.ttc,
        }[cause]

    def applies(self, namespace: str, cause: str | None = None) -> bool:
        """Whether ``namespace`` has a tree (``cause`` None) or that condition in its tree."""
        if not self.enabled or (self.namespaces and namespace not in self.namespaces):
            return False
        if cause is None:
            return True
        cond = self.condition(cause)
        return bool(cond.enabled) and (not cond.namespaces or namespace in cond.namespaces)

    def check_namespaces(self, known: Sequence[str], *, where: str = WHERE) -> None:
        """Every namespace a zone or condition names must be an agent of the run."""
        lists: list[tuple[str, Sequence[str]]] = [(f"{where}.namespaces", self.namespaces)]
        lists += [(f"{where}.zones[{i}].namespaces", z.namespaces) for i, z in enumerate(self.zones)]
        lists += [
            (f"{where}.{key}.namespaces", self.condition(cause).namespaces) for key, cause in SECTIONS.items()
        ]
        for field_name, names in lists:
            for ns in names:
                if ns not in known:
                    raise ConfigError(
                        f"invalid {field_name}={list(names)}",
                        "config",
                        f"there is no agent '{ns}' in this run",
                        f"use one of {', '.join(known) or '(no agents)'}",
                    )


@dataclass(frozen=True)
class TreeParams:
    """What the trees run on: their config and what the run adds to it (not configuration).

    Built from the config and the :class:`~simlan_data.algorithms.roles.SafetyContext` (its
    control and camera periods, the localizer's processing delay, the coordinator on or off).
    """

    config: TreesConfig = field(default_factory=TreesConfig)
    control_period_s: float = 0.05
    camera_period_s: float = 0.2
    processing_delay_s: float = 0.0
    coordinated: bool = False  # navigation.coordination of the run

    @classmethod
    def of(cls, config: TreesConfig, context: Any) -> TreeParams:
        """From the config and a SafetyContext (or anything with its run fields)."""
        return cls(
            config,
            float(getattr(context, "control_period_s", 0.05)),
            float(getattr(context, "camera_period_s", 0.2)),
            float(getattr(context, "processing_delay_s", 0.0)),
            bool(getattr(context, "coordinated", False)),
        )

    @property
    def zones(self) -> tuple[Zone, ...]:
        return self.config.zone_shapes

    def ttc_against_robots(self) -> bool:
        """Whether the TTC condition looks at other robots (it always looks at people and fixed agents)."""
        return self.config.ttc.robots == "always" or not self.coordinated

    @property
    def reaction_s(self) -> float:
        """How long a robot drives on after a hazard begins: one control period + one camera period."""
        if self.config.restricted_area.reaction_s > 0:
            return self.config.restricted_area.reaction_s
        return self.control_period_s + self.camera_period_s + self.processing_delay_s


def trees_config(values: Mapping[str, Any] | None = None) -> TreesConfig:
    """The config from plain values (a recorded section, a test's dict); checked."""
    return TreesConfig(**dict(values or {}))
