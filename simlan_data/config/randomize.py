"""The ``randomize`` section: domain randomization for datasets and robustness sweeps (issue 24).

Everything is off by default (``randomize=off``); ``randomize=on`` turns every effect on at
moderate strengths. Each effect draws from its own seeded stream (``seeding.run_rng(seed,
"randomize", <effect>)``), so turning one on or off leaves the others' draws alone; what was drawn
is published once on ``/simlan/randomization`` (``sim/randomize.py``, docs/sensors.md):

- ``light``: the warehouse lights' intensity and colour, one draw per run, applied to every
  rendered colour image (in linear light);
- ``time_of_day``: the sun through the roof's skylights: sunlit patches on the floor, brighter
  where a camera sees them and nothing stands in them;
- ``materials``: floor and shelf colours (a tint per run);
- ``placement``: boxes and pallets moved a few centimetres and turned a few degrees (never into
  an agent's start or route);
- ``distractors``: static primitives (bins, crates, drums) on free floor, away from agents,
  goals, routes and each other, labelled ``furniture`` in the semantic images;
- ``agents``: each agent's paint (its ArUco marker keeps its black and white cells).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simlan_data.errors import ConfigError


def _non_negative(key: str, value: float, fix: str) -> None:
    if not value >= 0:
        raise ConfigError.invalid(f"randomize.{key}", value, "must be >= 0", fix)


def _below_one(key: str, value: float, fix: str) -> None:
    if not 0 <= value < 1:
        raise ConfigError.invalid(f"randomize.{key}", value, "must be within 0..1 (1 would allow black)", fix)


@dataclass
class LightConfig:
    """The lights: intensity x (1 +- intensity), each colour channel x (1 +- colour), per run."""

    enabled: bool = False
    intensity: float = 0.0  # relative spread of the light's intensity (uniform)
    colour: float = 0.0  # relative spread of each channel's gain (a warmer or cooler light)

    def __post_init__(self) -> None:
        _below_one("light.intensity", self.intensity, "use 0.3")
        _below_one("light.colour", self.colour, "use 0.1")


@dataclass
class TimeOfDayConfig:
    """The sun through the skylights: a time of day drawn per run, sunlit floor patches."""

    enabled: bool = False
    hours: list[float] = field(default_factory=lambda: [7.0, 18.0])  # local solar time range, drawn uniformly
    day_of_year: int = 172  # the sun's declination (172: midsummer)
    latitude_deg: float = 57.7  # Gothenburg (Volvo's GPSS site)
    sun_strength: float = 0.0  # a sunlit patch is 1 + this x sin(sun elevation) times brighter (linear light)

    def __post_init__(self) -> None:
        hours = list(self.hours)
        if len(hours) != 2 or not 0 <= hours[0] <= hours[1] <= 24:
            raise ConfigError.invalid(
                "randomize.time_of_day.hours",
                hours,
                "must be [from, to] within 0..24, from <= to",
                "use [7, 18]",
            )
        if not 1 <= self.day_of_year <= 366:
            raise ConfigError.invalid(
                "randomize.time_of_day.day_of_year", self.day_of_year, "must be within 1..366", "use 172"
            )
        if not -90 <= self.latitude_deg <= 90:
            raise ConfigError.invalid(
                "randomize.time_of_day.latitude_deg", self.latitude_deg, "must be within -90..90", "use 57.7"
            )
        _non_negative("time_of_day.sun_strength", self.sun_strength, "use 1.0")


@dataclass
class MaterialsConfig:
    """Floor and shelf colours: every floor (shelf) colour x a brightness within 1 +- spread, each
    channel within 1 +- spread / 3 of that, per run."""

    enabled: bool = False
    floor: float = 0.0  # spread of the floor's colours (concrete slabs, joints)
    shelf: float = 0.0  # spread of the shelves' colours (uprights, beams, decks)

    def __post_init__(self) -> None:
        _below_one("materials.floor", self.floor, "use 0.2")
        _below_one("materials.shelf", self.shelf, "use 0.3")


@dataclass
class PlacementConfig:
    """Boxes and pallets moved and turned (uniform), except where that could reach an agent's route."""

    enabled: bool = False
    xy_m: float = 0.0  # at most this far in x and in y
    yaw_deg: float = 0.0  # at most this many degrees about the vertical

    def __post_init__(self) -> None:
        _non_negative("placement.xy_m", self.xy_m, "use 0.03")
        _non_negative("placement.yaw_deg", self.yaw_deg, "use 3")
        if self.xy_m > 0.5 or self.yaw_deg > 45:
            raise ConfigError.invalid(
                "randomize.placement",
                f"xy_m={self.xy_m}, yaw_deg={self.yaw_deg}",
                "a jitter is a few centimetres and degrees (at most 0.5 m and 45 degrees)",
                "use xy_m=0.03 yaw_deg=3",
            )


@dataclass
class DistractorsConfig:
    """Static primitives on free floor the cameras see, away from agents, goals, routes and each other."""

    enabled: bool = False
    count: int = 0  # how many (fewer if the free floor runs out: the run log says so)
    min_size_m: float = 0.3  # footprint side (or diameter), drawn uniformly
    max_size_m: float = 0.8  # (heights 0.4..1.1 m)
    clearance_m: float = 0.5  # kept from every route corridor, agent, goal and other distractor

    def __post_init__(self) -> None:
        if not 0 <= self.count <= 200:
            raise ConfigError.invalid(
                "randomize.distractors.count", self.count, "must be within 0..200", "use 8"
            )
        if not 0 < self.min_size_m <= self.max_size_m <= 3.0:
            raise ConfigError.invalid(
                "randomize.distractors",
                f"min_size_m={self.min_size_m}, max_size_m={self.max_size_m}",
                "must be 0 < min_size_m <= max_size_m <= 3",
                "use min_size_m=0.3 max_size_m=0.8",
            )
        _non_negative("distractors.clearance_m", self.clearance_m, "use 0.5")


@dataclass
class AgentPaintConfig:
    """Agents' colours: hue turned by up to hue_deg, saturation and value x (1 +- spread); markers kept."""

    enabled: bool = False
    hue_deg: float = 0.0  # each agent's hue turned by up to this (180: any hue)
    saturation: float = 0.0  # saturation x (1 +- this)
    value: float = 0.0  # value (lightness) x (1 +- this)

    def __post_init__(self) -> None:
        if not 0 <= self.hue_deg <= 180:
            raise ConfigError.invalid(
                "randomize.agents.hue_deg", self.hue_deg, "must be within 0..180", "use 180 (any hue)"
            )
        _below_one("agents.saturation", self.saturation, "use 0.3")
        _below_one("agents.value", self.value, "use 0.2")


@dataclass
class RandomizeConfig:
    """Domain randomization: ``randomize=on`` (every effect on) or ``randomize=off`` (none, the default)."""

    name: str = "off"  # the conf/randomize file chosen
    light: LightConfig = field(default_factory=LightConfig)
    time_of_day: TimeOfDayConfig = field(default_factory=TimeOfDayConfig)
    materials: MaterialsConfig = field(default_factory=MaterialsConfig)
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    distractors: DistractorsConfig = field(default_factory=DistractorsConfig)
    agents: AgentPaintConfig = field(default_factory=AgentPaintConfig)

    @property
    def active(self) -> bool:
        """True when any effect is on (off: the run is the same, byte for byte, as without the group)."""
        return any(
            getattr(self, name).enabled
            for name in ("light", "time_of_day", "materials", "placement", "distractors", "agents")
        )
