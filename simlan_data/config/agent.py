"""One agent's config (``agents.robot_agent_N``): type, pose, marker id, goals, speed."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Optional

from simlan_data.errors import ConfigError

NAMESPACE_RE = re.compile(r"^robot_agent_(0|[1-9]\d*)$")  # one spelling per number
_bad = ConfigError.invalid  # invalid KEY=VALUE in config: WHY; FIX


@dataclass
class AgentConfig:
    """One agent (SIMLAN's ROBOTS/HUMANOIDS entries): type, initial pose, marker id, goals.

    Agents are keyed by namespace (robot_agent_N) in ``agents``; the marker id defaults to N.
    Robots plan to their goals in order and steer on the camera estimate; a humanoid walks
    straight from goal to goal; a Panda stays where it is.
    """

    type: str = "pallet_truck"
    pose: list[float] = field(default_factory=list)  # [x_m, y_m, yaw_rad]; empty: not spawned
    marker_id: Optional[int] = None  # noqa: UP045 - OmegaConf needs typing.Optional
    goals: list[list[float]] = field(default_factory=list)
    speed_mps: float = 1.0
    loop: bool = False
    namespace: str = ""  # set from the key in ``agents``

    def check(self, namespace: str) -> None:
        self.namespace = namespace
        m = NAMESPACE_RE.match(namespace)
        if not m:
            raise _bad(
                "agents",
                namespace,
                "agent keys must be robot_agent_N (SIMLAN's namespaces)",
                "rename it, e.g. robot_agent_1",
            )
        if self.marker_id is None:
            self.marker_id = int(m.group(1))
        if not 0 <= self.marker_id < 1000:
            raise _bad(
                f"agents.{namespace}.marker_id",
                self.marker_id,
                "DICT_5X5_1000 has ids 0..999",
                "use the N of robot_agent_N",
            )
        if len(self.pose) == 0:
            # a scenario (or an override) set goals or a speed for an agent no spawn list has
            raise ConfigError(
                f"unknown agent {namespace}",
                "config",
                "something refers to it (a scenario's goals, an override) but the spawn list does not spawn it (no pose)",
                "choose a spawn list that has it (e.g. agents=four_robots) or add it to yours with a type and pose",
            )
        if len(self.pose) != 3:
            raise _bad(
                f"agents.{namespace}.pose",
                list(self.pose),
                "expected [x_m, y_m, yaw_rad]",
                "give three numbers",
            )
        if abs(self.pose[2]) > 2 * math.pi + 1e-6:
            raise _bad(
                f"agents.{namespace}.pose[2]",
                self.pose[2],
                "yaw_rad must be within [-2 pi, 2 pi] radians (this looks like degrees)",
                f"give radians, e.g. {math.radians(self.pose[2]):.4f}",
            )
        for i, goal in enumerate(self.goals):
            if len(goal) != 2:
                raise _bad(
                    f"agents.{namespace}.goals[{i}]",
                    list(goal),
                    "expected [x_m, y_m]",
                    "give two numbers per goal",
                )
        if not 0 < self.speed_mps <= 3.0:
            raise _bad(
                f"agents.{namespace}.speed_mps", self.speed_mps, "must be within (0, 3] m/s", "use e.g. 1.0"
            )

    @property
    def number(self) -> int:
        m = NAMESPACE_RE.match(self.namespace)
        assert m is not None
        return int(m.group(1))
