"""Safety layer: one py_trees behaviour tree per robot over the estimates GPSS steers on.

- ``geometry``: zones, stopping distance, swept footprints, CPA and TTC (shapely/numpy);
- ``params``: the one config (``TreesConfig``: ``algorithms.safety``) and what the run adds to it;
- ``conditions``: the tree's inputs (``SafetyWorld``), its condition functions and outputs;
- ``tree``: the behaviour tree of one robot and the ``SafetyLayer`` of all robots (registered as
  ``safety.trees``).
"""

from __future__ import annotations

from simlan_data.algorithms.safety.conditions import (
    DRIVE,
    FREE,
    SLOW,
    STOP,
    Finding,
    Monitor,
    Mover,
    RobotEstimate,
    RobotSpec,
    SafetyDecision,
    SafetyEvent,
    SafetyWorld,
    transition_events,
)
from simlan_data.algorithms.safety.geometry import Zone, make_zone
from simlan_data.algorithms.safety.params import (
    CAUSES,
    RESUME_POLICIES,
    CollisionConfig,
    ObservabilityConfig,
    RestrictedAreaConfig,
    TreeParams,
    TreesConfig,
    TtcConfig,
    ZoneConfig,
)
from simlan_data.algorithms.safety.tree import (
    RobotSafetyTree,
    SafetyLayer,
    build_tree,
    clamp_command,
    mover_of,
)

__all__ = [
    "CAUSES",
    "DRIVE",
    "FREE",
    "RESUME_POLICIES",
    "SLOW",
    "STOP",
    "CollisionConfig",
    "Finding",
    "Monitor",
    "Mover",
    "ObservabilityConfig",
    "RestrictedAreaConfig",
    "RobotEstimate",
    "RobotSafetyTree",
    "RobotSpec",
    "SafetyDecision",
    "SafetyEvent",
    "SafetyLayer",
    "SafetyWorld",
    "TreeParams",
    "TreesConfig",
    "TtcConfig",
    "Zone",
    "ZoneConfig",
    "build_tree",
    "clamp_command",
    "make_zone",
    "mover_of",
    "transition_events",
]
