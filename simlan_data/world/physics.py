"""Physics parameters of the world's object classes (config ``world.physics.<class>``).

Apart from the builder so that the config layer reads it without importing the simulator. Not
frozen: Hydra makes a frozen dataclass's node read-only (no ``world.physics.box.mass_kg=40``).
"""

from __future__ import annotations

from dataclasses import dataclass

from simlan_data.errors import ConfigError


@dataclass
class PhysicsParams:
    """Physics parameters of one class of objects: the config of ``world.physics.<class>``."""

    mass_kg: float = 0.0
    lateral_friction: float = 0.8
    rolling_friction: float = 0.0
    spinning_friction: float = 0.0
    restitution: float = 0.0
    linear_damping: float = 0.04
    angular_damping: float = 0.04

    def __post_init__(self) -> None:
        for name in NON_NEGATIVE:
            value = getattr(self, name)
            if isinstance(value, (int, float)) and value < 0:  # (not while OmegaConf builds the schema)
                raise ConfigError.invalid(
                    f"world.physics.*.{name}", value, "must be >= 0", f"set {name} to a non-negative value"
                )
        if isinstance(self.restitution, (int, float)) and not 0 <= self.restitution <= 1:
            raise ConfigError.invalid(
                "world.physics.*.restitution", self.restitution, "must be in [0, 1]", "use e.g. 0.1"
            )


NON_NEGATIVE = (
    "mass_kg",
    "lateral_friction",
    "rolling_friction",
    "spinning_friction",
    "linear_damping",
    "angular_damping",
)
