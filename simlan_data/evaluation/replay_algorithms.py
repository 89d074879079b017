"""Import every module that registers a replay algorithm (``--algorithms`` choices)."""

from __future__ import annotations

# Each import registers with simlan_data.evaluation.replay.register(name). Add new ones here.
from simlan_data.evaluation import (  # noqa: F401
    birdseye_replay,
    localization_replay,
    people_replay,
    posemap_replay,
    replay,
    safety_replay,
    tracking_replay,
)
