from dataclasses import dataclass

from simlan_data.algorithms.birdseye_stitcher import GpssStitcher, GpssStitcherConfig


@dataclass(frozen=True)
class MyStitchConfig:
    feather_m: float = 0.5


class MyStitcher(GpssStitcher):
    role = "stitcher"
    config_class = MyStitchConfig

    def __init__(self, config, context):
        super().__init__(GpssStitcherConfig(feather_m=config.feather_m), context)
