"""The built-in coordinator (``gpss``), registered like any plug-in: right of way by priority.

Each robot claims the floor its footprint sweeps over the next ``horizon_m`` of its plan; in
priority order a robot drives if its claim is clear of the others' footprints and of the claims
already granted, else it waits; one that waited ``deadlock_after_s`` for a robot that does not
drive on is told to replan around it (see :class:`~simlan_data.algorithms.coordinator.Coordinator`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from simlan_data.algorithms.coordinator import Coordinator
from simlan_data.algorithms.roles import CoordinatorContext
from simlan_data.errors import ConfigError


@dataclass(frozen=True)
class GpssCoordinatorConfig:
    """The built-in coordinator's parameters (``algorithms.coordinator.*``)."""

    horizon_m: float = 3.0  # how far along its plan a driving robot claims the floor
    deadlock_after_s: float = 3.0  # waiting this long for a robot that does not move: replan around it

    def __post_init__(self) -> None:
        key = "algorithms.coordinator."
        if not 0 < self.horizon_m <= 50:
            raise ConfigError.invalid(key + "horizon_m", self.horizon_m, "must be within 0..50 m", "use 3.0")
        if not 0 < self.deadlock_after_s <= 600:
            raise ConfigError.invalid(
                key + "deadlock_after_s", self.deadlock_after_s, "must be within 0..600 s", "use 3.0"
            )


class GpssCoordinator(Coordinator):
    """The :class:`Coordinator` built from its config and the fleet's safety distance."""

    role: ClassVar[str] = "coordinator"
    config_class: ClassVar[type] = GpssCoordinatorConfig

    def __init__(self, config: GpssCoordinatorConfig, context: CoordinatorContext) -> None:
        super().__init__(
            safety_distance_m=context.safety_distance_m,
            horizon_m=config.horizon_m,
            deadlock_after_s=config.deadlock_after_s,
        )
