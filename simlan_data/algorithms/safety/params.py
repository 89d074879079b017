"""Parameters of the safety layer, built and checked from the ``safety`` config section.

``SafetyParams.from_dict`` is the one place a safety config is checked: the run's typed config
(``config_safety.py``) and the replay's ``--set`` overrides both go through it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from simlan_data.algorithms.safety.geometry import Zone, make_zone
from simlan_data.errors import ConfigError

RESUME_POLICIES = ("auto", "never")
TTC_ROBOTS = ("uncoordinated", "always")
CAUSES = ("collision", "unobserved", "restricted_area", "ttc")
SECTION_KEYS = {
    "enabled",
    "namespaces",
    "hold_s",
    "zones",
    "collision",
    "observability",
    "restricted_area",
    "ttc",
    "people",
}


@dataclass(frozen=True)
class CollisionParams:
    enabled: bool = True
    force_threshold_n: float = 10.0
    resume: str = "never"  # a robot that hit something waits for an operator
    namespaces: tuple[str, ...] = ()


@dataclass(frozen=True)
class ObservabilityParams:
    enabled: bool = True
    timeout_s: float = 5.0  # SIMLAN
    resume: str = "auto"
    namespaces: tuple[str, ...] = ()


@dataclass(frozen=True)
class RestrictedAreaParams:
    enabled: bool = True
    decel_mps2: float = 2.0  # braking the layer counts on (the twin's robots brake at 5-8 m/s^2)
    reaction_s: float = 0.0  # 0: one control period + one camera period + processing delay
    margin_m: float = 0.1
    sigma_k: float = 3.0  # plus this many standard deviations of the position estimate
    lookahead_m: float = 0.3
    resume: str = "auto"
    namespaces: tuple[str, ...] = ()


@dataclass(frozen=True)
class TtcParams:
    enabled: bool = True
    stop_cpa_m: float = 2.0  # SIMLAN
    stop_ttc_s: float = 2.0  # SIMLAN
    slow_ttc_s: float = 6.0  # "further out" (SIMLAN: any TTC)
    slow_speed_mps: float = 0.4  # SIMLAN
    resume: str = "auto"
    namespaces: tuple[str, ...] = ()
    # robots: "uncoordinated" - against other robots only while the central coordinator is off
    # (it keeps coordinated robots apart along their plans, closer than SIMLAN's 2 m); "always"
    robots: str = "uncoordinated"


@dataclass(frozen=True)
class SafetyParams:
    """Everything the trees need; built from the ``safety`` config section."""

    enabled: bool = True
    namespaces: tuple[str, ...] = ()  # robots with a tree; empty: every robot
    hold_s: float = 1.0  # a condition must stay clear this long before the robot drives on
    zones: tuple[Zone, ...] = ()
    collision: CollisionParams = field(default_factory=CollisionParams)
    observability: ObservabilityParams = field(default_factory=ObservabilityParams)
    restricted_area: RestrictedAreaParams = field(default_factory=RestrictedAreaParams)
    ttc: TtcParams = field(default_factory=TtcParams)
    control_period_s: float = 0.05
    camera_period_s: float = 0.2
    processing_delay_s: float = 0.0
    coordinated: bool = False  # navigation.coordination of the run

    def ttc_against_robots(self) -> bool:
        """Whether the TTC condition looks at other robots (it always looks at people and fixed agents)."""
        return self.ttc.robots == "always" or not self.coordinated

    @property
    def reaction_s(self) -> float:
        """How long a robot drives on after a hazard begins: one control period + one camera period."""
        if self.restricted_area.reaction_s > 0:
            return self.restricted_area.reaction_s
        return self.control_period_s + self.camera_period_s + self.processing_delay_s

    def condition(self, cause: str) -> Any:
        return {
            "collision": self.collision,
            "unobserved": self.observability,
            "restricted_area": self.restricted_area,
            "ttc": self.ttc,
        }[cause]

    def applies(self, namespace: str, cause: str | None = None) -> bool:
        if not self.enabled or (self.namespaces and namespace not in self.namespaces):
            return False
        if cause is None:
            return True
        cond = self.condition(cause)
        return bool(cond.enabled) and (not cond.namespaces or namespace in cond.namespaces)

    @staticmethod
    def from_dict(
        section: Mapping[str, Any] | None,
        *,
        control_rate_hz: float = 20.0,
        camera_rate_hz: float = 5.0,
        processing_delay_s: float = 0.0,
        coordinated: bool = False,
        known_namespaces: Sequence[str] | None = None,
        where: str = "safety",
    ) -> SafetyParams:
        """Params from a config section (plain dict); ConfigError naming the field if it is bad."""
        s = dict(section or {})
        unknown_keys = sorted(set(s) - SECTION_KEYS)
        if unknown_keys:
            raise ConfigError(
                f"unknown key {where}.{unknown_keys[0]}",
                "config",
                f"known: {', '.join(sorted(SECTION_KEYS))}",
                "check the spelling",
            )
        zones = tuple(
            make_zone(
                str(z.get("name", "")),
                z.get("polygon") or [],
                tuple(z.get("namespaces") or ()),
                where=f"{where}.zones[{i}]",
            )
            for i, z in enumerate(s.get("zones") or [])
        )
        names = [z.name for z in zones]
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise ConfigError(
                f"invalid {where}.zones",
                "config",
                f"two zones are named '{dup}'",
                "give every zone its own name",
            )

        def section_of(key: str, kind: type, checks: dict[str, tuple[float, float]]) -> Any:
            raw = dict(s.get(key) or {})
            unknown = sorted(set(raw) - {f.name for f in dataclasses.fields(kind)})
            if unknown:
                raise ConfigError(
                    f"unknown key {where}.{key}.{unknown[0]}",
                    "config",
                    f"known: {', '.join(f.name for f in dataclasses.fields(kind))}",
                    "check the spelling",
                )
            raw["namespaces"] = tuple(raw.get("namespaces") or ())
            obj = kind(**raw)
            if obj.resume not in RESUME_POLICIES:
                raise ConfigError(
                    f"invalid {where}.{key}.resume={obj.resume!r}",
                    "config",
                    f"expected one of {', '.join(RESUME_POLICIES)}",
                    f"set {where}.{key}.resume=auto",
                )
            for name, (lo, hi) in checks.items():
                value = getattr(obj, name)
                if not lo <= value <= hi:
                    raise ConfigError(
                        f"invalid {where}.{key}.{name}={value!r}",
                        "config",
                        f"must be within {lo:g}..{hi:g}",
                        f"use the default {getattr(kind(), name)!r}",
                    )
            return obj

        collision = section_of("collision", CollisionParams, {"force_threshold_n": (0.0, 1e6)})
        observability = section_of("observability", ObservabilityParams, {"timeout_s": (0.05, 3600.0)})
        restricted = section_of(
            "restricted_area",
            RestrictedAreaParams,
            {
                "decel_mps2": (0.05, 50.0),
                "reaction_s": (0.0, 10.0),
                "margin_m": (0.0, 5.0),
                "sigma_k": (0.0, 10.0),
                "lookahead_m": (0.0, 5.0),
            },
        )
        ttc = section_of(
            "ttc",
            TtcParams,
            {
                "stop_cpa_m": (0.0, 50.0),
                "stop_ttc_s": (0.0, 60.0),
                "slow_ttc_s": (0.0, 600.0),
                "slow_speed_mps": (0.0, 3.0),
            },
        )
        if ttc.robots not in TTC_ROBOTS:
            raise ConfigError(
                f"invalid {where}.ttc.robots={ttc.robots!r}",
                "config",
                f"expected one of {', '.join(TTC_ROBOTS)}",
                f"set {where}.ttc.robots=uncoordinated",
            )
        if ttc.slow_ttc_s < ttc.stop_ttc_s:
            raise ConfigError(
                f"invalid {where}.ttc.slow_ttc_s={ttc.slow_ttc_s!r}",
                "config",
                f"must be >= {where}.ttc.stop_ttc_s={ttc.stop_ttc_s!r} (slowing covers the hazards further out)",
                "use e.g. 6.0",
            )
        hold_s = float(s.get("hold_s", 1.0))
        if not 0 <= hold_s <= 600:
            raise ConfigError(
                f"invalid {where}.hold_s={hold_s!r}", "config", "must be within 0..600 s", "use 1.0"
            )
        params = SafetyParams(
            enabled=bool(s.get("enabled", True)),
            namespaces=tuple(s.get("namespaces") or ()),
            hold_s=hold_s,
            zones=zones,
            collision=collision,
            observability=observability,
            restricted_area=restricted,
            ttc=ttc,
            control_period_s=1.0 / control_rate_hz,
            camera_period_s=1.0 / camera_rate_hz,
            processing_delay_s=processing_delay_s,
            coordinated=coordinated,
        )
        if known_namespaces is not None:
            params.check_namespaces(known_namespaces, where=where)
        return params

    def check_namespaces(self, known: Sequence[str], *, where: str = "safety") -> None:
        """Every namespace a zone or condition names must be an agent of the run."""
        lists: list[tuple[str, tuple[str, ...]]] = [(f"{where}.namespaces", self.namespaces)]
        lists += [(f"{where}.zones[{i}].namespaces", z.namespaces) for i, z in enumerate(self.zones)]
        lists += [
            (f"{where}.{key}.namespaces", self.condition(cause).namespaces)
            for key, cause in (
                ("collision", "collision"),
                ("observability", "unobserved"),
                ("restricted_area", "restricted_area"),
                ("ttc", "ttc"),
            )
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
