"""Kinds of agents (data only, no simulator): geometry, limits, marker mount, how they move.

Used by the simulator to spawn agents and by the algorithms (and replay) to know where a
robot carries its marker and how large it is.
"""

from __future__ import annotations

from dataclasses import dataclass

from simlan_data.errors import ConfigError

MARKER_SIZE_M = 0.5  # SIMLAN: DICT_5X5_1000, 0.5 m


@dataclass(frozen=True)
class AgentType:
    """One kind of agent."""

    name: str
    urdf: str  # file in assets/urdf, or "pybullet_data:<path>"
    semantic: str
    drive: (
        str  # "diff" (wheel motors), "walker" (kinematic, walks its path), "posed" (joint targets), "static"
    )
    marker_xyz: tuple[float, float, float] | None = None  # marker face centre in base_link
    wheel_joints: tuple[str, str] = ("left_wheel_joint", "right_wheel_joint")
    wheel_radius_m: float = 0.1
    track_m: float = 0.72
    max_speed_mps: float = 2.0
    max_yaw_rate_rps: float = 1.0
    max_wheel_torque_nm: float = 120.0
    footprint_m: tuple[float, float, float, float] = (-0.5, 0.5, -0.5, 0.5)  # x0, x1, y0, y1 in base_link
    caster_links: tuple[str, ...] = ()
    wheel_friction: float = 1.0
    default_speed_mps: float = 1.0
    # how fast the drive reaches a commanded speed, braking included (measured on the simulated
    # body: torque- or grip-limited); the localizer's motion model brakes the estimate so
    accel_mps2: float = 7.5

    @property
    def has_marker(self) -> bool:
        return self.marker_xyz is not None

    @property
    def half_width_m(self) -> float:
        """Half the footprint's width: the planner keeps this plus a clearance from obstacles."""
        return float(max(abs(self.footprint_m[2]), abs(self.footprint_m[3])))

    @property
    def radius_m(self) -> float:
        """Circumscribed radius of the footprint about base_link."""
        x0, x1, y0, y1 = self.footprint_m
        return float(max(abs(x0), abs(x1)) ** 2 + max(abs(y0), abs(y1)) ** 2) ** 0.5


_TRUCK_CASTERS = ("rear_caster", "left_fork_caster", "right_fork_caster")

AGENT_TYPES: dict[str, AgentType] = {
    "pallet_truck": AgentType(
        "pallet_truck",
        "pallet_truck.urdf",
        "pallet_truck",
        "diff",
        marker_xyz=(-0.8, 0.0, 1.30),
        footprint_m=(-1.15, 0.70, -0.40, 0.40),
        caster_links=_TRUCK_CASTERS,
    ),
    # same base as the pallet truck, another look (mast, counterweight) and label
    "forklift": AgentType(
        "forklift",
        "forklift.urdf",
        "forklift",
        "diff",
        marker_xyz=(-0.8, 0.0, 1.30),
        footprint_m=(-1.15, 0.95, -0.45, 0.45),
        caster_links=_TRUCK_CASTERS,
        accel_mps2=6.7,  # (mast and counterweight: heavier than the pallet truck)
    ),
    # Clearpath Jackal-sized: 0.51 x 0.43 m, marker on a plate 0.55 m up
    "jackal": AgentType(
        "jackal",
        "jackal.urdf",
        "jackal",
        "diff",
        marker_xyz=(0.0, 0.0, 0.55),
        wheel_radius_m=0.098,
        track_m=0.37,
        max_speed_mps=2.0,
        max_yaw_rate_rps=2.0,
        max_wheel_torque_nm=20.0,
        footprint_m=(-0.33, 0.33, -0.33, 0.33),
        caster_links=("front_caster", "rear_caster"),
        default_speed_mps=1.0,
        accel_mps2=5.0,  # (grip-limited: the casters carry part of its weight)
    ),
    "humanoid": AgentType(
        "humanoid",
        "walker.urdf",
        "humanoid",
        "walker",
        max_speed_mps=1.6,
        max_yaw_rate_rps=3.0,
        footprint_m=(-0.2, 0.2, -0.3, 0.3),
        default_speed_mps=1.2,
    ),
    # the articulated humanoid of the pose mapping (issue 6): 47 joints on SIMLAN's support arm,
    # posed from joint targets (motion files, pose-mapper predictions); it does not walk
    "posed_humanoid": AgentType(
        "posed_humanoid",
        "humanoid.urdf",
        "humanoid",
        "posed",
        footprint_m=(-0.35, 1.0, -0.85, 0.85),
    ),
    "panda": AgentType(
        "panda",
        "pybullet_data:franka_panda/panda.urdf",
        "panda",
        "static",
        footprint_m=(-0.2, 0.6, -0.3, 0.3),
    ),
}


def agent_type(name: str, *, where: str = "agents.<ns>.type") -> AgentType:
    try:
        return AGENT_TYPES[name]
    except KeyError:
        raise ConfigError(
            f"unknown agent type '{name}'", where, f"known types: {', '.join(AGENT_TYPES)}", "use one of them"
        ) from None
