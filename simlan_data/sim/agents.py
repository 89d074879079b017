"""Agents in the PyBullet world.

- :class:`DiffDriveAgent`: robots (pallet truck, forklift, jackal) with wheel motors and an ArUco
  marker, driven by velocity commands through physics;
- :class:`WalkerAgent`: a person moved kinematically along its path (the articulated humanoid of
  the pose mapping, posed from joint targets, is ``humanoid.PosedHumanoidAgent``);
- :class:`StaticAgent`: a fixed robot (the Panda arm).

All report their ground-truth pose and sense collisions (contacts with anything but the floor).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from simlan_data.geometry.rotations import quat_from_yaw
from simlan_data.sim.agent_base import Agent, CollisionReading, load_body, urdf_with_marker
from simlan_data.sim.humanoid import PosedHumanoidAgent
from simlan_data.world._pybullet import pb
from simlan_data.world.agent_types import AGENT_TYPES, AgentType, agent_type
from simlan_data.world.walker_landmarks import WALKER_INSIDE_M, WALKER_LANDMARKS_M

__all__ = [
    "AGENT_TYPES",
    "Agent",
    "AgentType",
    "CollisionReading",
    "DiffDriveAgent",
    "StaticAgent",
    "WalkerAgent",
    "agent_type",
    "spawn_agent",
    "urdf_with_marker",
]


class DiffDriveAgent(Agent):
    """A differential-drive robot driven through its wheel motors."""

    def __init__(
        self, client: int, namespace: str, kind: AgentType, *, pose: Sequence[float], marker_id: int | None
    ) -> None:
        super().__init__(
            client, namespace, kind, load_body(client, kind, namespace, marker_id, pose, fixed=False)
        )
        self.marker_id = marker_id
        self.wheel_indices = [self.joints[n] for n in kind.wheel_joints]
        for link in kind.caster_links:
            pb.changeDynamics(
                self.body,
                self.links[link],
                lateralFriction=0.0,
                spinningFriction=0.0,
                rollingFriction=0.0,
                physicsClientId=client,
            )
        for j in self.wheel_indices:
            pb.changeDynamics(self.body, j, lateralFriction=kind.wheel_friction, physicsClientId=client)

    def apply_command(self, linear_mps: float, angular_rps: float) -> tuple[float, float]:
        """Clamp a twist to the type's limits and set the wheel motors; returns the applied twist."""
        k = self.kind
        v = float(np.clip(linear_mps, -k.max_speed_mps, k.max_speed_mps))
        w = float(np.clip(angular_rps, -k.max_yaw_rate_rps, k.max_yaw_rate_rps))
        left = (v - 0.5 * w * k.track_m) / k.wheel_radius_m
        right = (v + 0.5 * w * k.track_m) / k.wheel_radius_m
        pb.setJointMotorControlArray(
            self.body,
            self.wheel_indices,
            pb.VELOCITY_CONTROL,
            targetVelocities=[left, right],
            forces=[k.max_wheel_torque_nm] * 2,
            physicsClientId=self.client,
        )
        self.command = (v, w)
        return v, w


class WalkerAgent(Agent):
    """A person: a kinematic body that turns and walks as commanded (no physics forces)."""

    def __init__(self, client: int, namespace: str, kind: AgentType, *, pose: Sequence[float]) -> None:
        super().__init__(client, namespace, kind, load_body(client, kind, namespace, None, pose, fixed=True))
        self._x, self._y, self._yaw = (float(v) for v in pose)
        self._z = 0.0

    def apply_command(self, linear_mps: float, angular_rps: float) -> tuple[float, float]:
        k = self.kind
        self.command = (
            float(np.clip(linear_mps, 0.0, k.max_speed_mps)),
            float(np.clip(angular_rps, -k.max_yaw_rate_rps, k.max_yaw_rate_rps)),
        )
        return self.command

    def step_kinematics(self, dt_s: float) -> None:
        v, w = self.command
        self._yaw += w * dt_s
        self._x += v * np.cos(self._yaw) * dt_s
        self._y += v * np.sin(self._yaw) * dt_s
        # PyBullet places a base by its centre of mass (0.95 m up in the walker): from base_link
        pos, orn = pb.multiplyTransforms(
            [self._x, self._y, self._z], list(quat_from_yaw(self._yaw)), *self._com_in_link
        )
        pb.resetBasePositionAndOrientation(self.body, pos, orn, physicsClientId=self.client)

    def place(self, xyz: Sequence[float], yaw_rad: float) -> None:
        self._x, self._y, self._z = (float(v) for v in xyz)
        self._yaw = float(yaw_rad)
        super().place(xyz, yaw_rad)

    def twist(self) -> tuple[float, float]:
        return self.command

    def landmarks(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The walker's fixed landmarks (``world/walker_landmarks.py``) at its current pose."""
        return self.pose().apply(WALKER_LANDMARKS_M), WALKER_INSIDE_M


class StaticAgent(Agent):
    """A robot fixed in place (it does not drive)."""

    def __init__(self, client: int, namespace: str, kind: AgentType, *, pose: Sequence[float]) -> None:
        super().__init__(client, namespace, kind, load_body(client, kind, namespace, None, pose, fixed=True))

    def twist(self) -> tuple[float, float]:
        return (0.0, 0.0)


def spawn_agent(
    client: int, namespace: str, kind: AgentType, *, pose: Sequence[float], marker_id: int | None
) -> Agent:
    if kind.drive == "diff":
        return DiffDriveAgent(client, namespace, kind, pose=pose, marker_id=marker_id)
    if kind.drive == "walker":
        return WalkerAgent(client, namespace, kind, pose=pose)
    if kind.drive == "posed":
        return PosedHumanoidAgent(client, namespace, kind, pose=pose)
    return StaticAgent(client, namespace, kind, pose=pose)
