"""Typed configuration of the safety layer (``safety``) and of SIMLAN's collision scenarios
(``collision``); part of the schema in ``config.py``.

Checks are shared with the replay: ``SafetyConfig.params`` builds the trees' parameters through
``SafetyParams.from_dict``, which names the field and the value of anything unusable.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from simlan_data.algorithms.safety import SafetyParams
from simlan_data.config import collision as collision_scenario
from simlan_data.errors import ConfigError

_bad = ConfigError.invalid  # invalid KEY=VALUE in config: WHY; FIX


@dataclass
class ZoneConfig:
    """A restricted area: corners [x_m, y_m] in the map frame, in order around it."""

    name: str = ""
    polygon: list[Any] = field(default_factory=list)  # [[x_m, y_m], ...]; checked by make_zone (ints welcome)
    namespaces: list[str] = field(default_factory=list)  # robots it applies to; empty: every robot


@dataclass
class CollisionGuardConfig:
    enabled: bool = True
    force_threshold_n: float = 10.0  # contact normal force that counts as a collision
    resume: str = "never"  # auto | never: a robot that hit something waits for an operator
    namespaces: list[str] = field(default_factory=list)


@dataclass
class ObservabilityGuardConfig:
    enabled: bool = True
    timeout_s: float = 5.0  # SIMLAN: stop after 5 s without a camera fix
    resume: str = "auto"
    namespaces: list[str] = field(default_factory=list)


@dataclass
class RestrictedAreaGuardConfig:
    enabled: bool = True
    decel_mps2: float = 2.0  # braking the layer counts on (the twin's robots brake at 5-8 m/s^2)
    reaction_s: float = 0.0  # 0: one control period + one camera period + processing delay
    margin_m: float = 0.1
    sigma_k: float = 3.0  # plus this many standard deviations of the position estimate
    lookahead_m: float = 0.3  # a robot stopped at a zone's edge does not creep in
    resume: str = "auto"
    namespaces: list[str] = field(default_factory=list)


@dataclass
class TtcGuardConfig:
    enabled: bool = True
    stop_cpa_m: float = 2.0  # SIMLAN: CPA <= 2 m and TTC <= 2 s -> hard stop
    stop_ttc_s: float = 2.0
    slow_ttc_s: float = 6.0  # a hazard further out (TTC <= this) -> slow
    slow_speed_mps: float = 0.4  # SIMLAN's crawl speed
    resume: str = "auto"
    namespaces: list[str] = field(default_factory=list)
    robots: str = "uncoordinated"  # against other robots: uncoordinated (only while navigation.coordination is off) | always


@dataclass
class PeopleDetectionConfig:
    """Camera-based person positions from the segmentation images (a detector stand-in)."""

    enabled: bool = True
    min_pixels: int = 12
    body_radius_m: float = 0.15
    cluster_m: float = 0.8
    max_age_s: float = 1.0


@dataclass
class SafetyConfig:
    """The safety layer: one behaviour tree per robot (see simlan_data/gpss/safety.py)."""

    enabled: bool = True
    namespaces: list[str] = field(default_factory=list)  # robots with a tree; empty: every robot
    hold_s: float = 1.0  # a condition must stay clear this long before the robot drives on
    zones: list[ZoneConfig] = field(default_factory=list)
    collision: CollisionGuardConfig = field(default_factory=CollisionGuardConfig)
    observability: ObservabilityGuardConfig = field(default_factory=ObservabilityGuardConfig)
    restricted_area: RestrictedAreaGuardConfig = field(default_factory=RestrictedAreaGuardConfig)
    ttc: TtcGuardConfig = field(default_factory=TtcGuardConfig)
    people: PeopleDetectionConfig = field(default_factory=PeopleDetectionConfig)

    def params(
        self,
        *,
        control_rate_hz: float = 20.0,
        camera_rate_hz: float = 5.0,
        processing_delay_s: float = 0.0,
        coordinated: bool = False,
        known_namespaces: list[str] | None = None,
    ) -> SafetyParams:
        """The trees' parameters; ConfigError naming the field if a value is unusable."""
        section = dataclasses.asdict(self)
        section.pop("people")
        return SafetyParams.from_dict(
            section,
            control_rate_hz=control_rate_hz,
            camera_rate_hz=camera_rate_hz,
            processing_delay_s=processing_delay_s,
            coordinated=coordinated,
            known_namespaces=known_namespaces,
        )

    def __post_init__(self) -> None:
        self.params()
        p = self.people
        if p.min_pixels < 1 or not 0 <= p.body_radius_m <= 1 or p.cluster_m <= 0 or p.max_age_s <= 0:
            raise _bad(
                "safety.people",
                dataclasses.asdict(p),
                "min_pixels >= 1, body_radius_m within 0..1, cluster_m and max_age_s > 0",
                "use the defaults",
            )


@dataclass
class CollisionScenarioConfig:
    """SIMLAN's collision families (scenario=collision): see simlan_data/config/collision.py."""

    angle: float = 90.0  # the Jackal's heading relative to the truck's, degrees (0: catch-up, 180: head-on)
    truck_speed_mps: float = 1.0
    collision_type: int = 0  # 0 head-on, 1 pallet-truck side, 2 Jackal side (SIMLAN's CollisionType)
    jackal_speed_mps: float = 1.0
    point: list[float] = field(default_factory=lambda: [5.5, 1.0])  # where they meet (map)
    time_s: float = 3.0  # from the start to the contact, if nothing stops them
    overlap_m: float = 0.1
    guarded: str = "both"  # robots with a safety tree: both | jackal (SIMLAN's setup) | truck | none

    def __post_init__(self) -> None:
        if self.guarded not in collision_scenario.GUARDED:
            raise _bad(
                "collision.guarded",
                self.guarded,
                f"expected one of {', '.join(collision_scenario.GUARDED)}",
                "use both",
            )
        if self.collision_type not in (0, 1, 2):
            raise _bad(
                "collision.collision_type",
                self.collision_type,
                "0 head-on, 1 pallet-truck side, 2 Jackal side",
                "use 0, 1 or 2",
            )
        for name in ("truck_speed_mps", "jackal_speed_mps"):
            if not 0 < getattr(self, name) <= 2.0:
                raise _bad(
                    f"collision.{name}", getattr(self, name), "must be within (0, 2] m/s", "use e.g. 1.0"
                )
        if not 1.0 <= self.time_s <= 30.0:
            raise _bad("collision.time_s", self.time_s, "must be within 1..30 s", "use 3.0")
        if len(self.point) != 2:
            raise _bad("collision.point", list(self.point), "expected [x_m, y_m]", "use [5.5, 1.0]")
