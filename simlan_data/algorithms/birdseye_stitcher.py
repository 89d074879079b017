"""The built-in bird's-eye stitcher (``gpss``), registered like any plug-in: best view, feathered.

Each canvas pixel shows the camera that sees it most sharply, blended over ``feather_m`` either
side of the borders between cameras (see :mod:`simlan_data.algorithms.birdseye`). The canvas it
fills (region, scale, plane) is not its config: every stitcher gets it in its context
(:class:`~simlan_data.algorithms.roles.StitcherContext`, from the ``birdseye`` config section),
and the metrics score every stitcher on that same canvas.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from simlan_data.algorithms.birdseye import BirdseyeStitcher
from simlan_data.algorithms.roles import StitcherContext
from simlan_data.errors import ConfigError

KEY = "algorithms.stitcher."


@dataclass(frozen=True)
class GpssStitcherConfig:
    """The built-in stitcher's parameters (``algorithms.stitcher.*``)."""

    feather_m: float = 0.2  # blend width across a seam between two cameras, each side
    distort: bool = True  # false: ignore the lens distortion (the pinhole model, to measure its cost)

    def __post_init__(self) -> None:
        try:
            feather_m = float(self.feather_m)
        except (TypeError, ValueError):
            raise ConfigError.invalid(
                KEY + "feather_m", self.feather_m, "expected a number", "use 0.2"
            ) from None
        if not (math.isfinite(feather_m) and 0 < feather_m <= 5):
            raise ConfigError.invalid(KEY + "feather_m", self.feather_m, "must be within (0, 5] m", "use 0.2")
        if not isinstance(self.distort, bool):
            raise ConfigError.invalid(KEY + "distort", self.distort, "expected true or false", "use true")
        object.__setattr__(self, "feather_m", feather_m)


class GpssStitcher(BirdseyeStitcher):
    """The :class:`BirdseyeStitcher` built from its config and the stitcher context."""

    role: ClassVar[str] = "stitcher"
    config_class: ClassVar[type] = GpssStitcherConfig

    def __init__(self, config: GpssStitcherConfig, context: StitcherContext) -> None:
        super().__init__(context.cameras, context.canvas, feather_m=config.feather_m, distort=config.distort)
