"""docs/plugins.md's skeleton, filled in: the centroid example's detector with its own gain."""

from dataclasses import dataclass

from simlan_data.algorithms.localization import PoseEstimate
from simlan_data.algorithms.roles import LocalizerContext


@dataclass(frozen=True)
class MyConfig:
    gain: float = 0.5

    def __post_init__(self) -> None:
        if not 0 < self.gain <= 1:
            raise ValueError(f"gain must be in (0, 1], got {self.gain}")


class MyLocalizer:
    role = "localizer"
    config_class = MyConfig

    def __init__(self, config: MyConfig, context: LocalizerContext) -> None:
        self.config, self.cameras, self.robots = config, dict(context.cameras), list(context.robots)
        from simlan_centroid_localizer import CentroidConfig, CentroidLocalizer  # the example plug-in

        self._inner = CentroidLocalizer(CentroidConfig(alpha=config.gain), context)

    def observe(self, t_ns, frames):
        return self._inner.observe(t_ns, frames)

    def command(self, t_ns, namespace, linear_mps, angular_rps):
        return self._inner.command(t_ns, namespace, linear_mps, angular_rps)

    def estimate(self, t_ns) -> dict[str, PoseEstimate]:
        return self._inner.estimate(t_ns)
