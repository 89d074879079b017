"""Agents in the PyBullet world.

- :class:`DiffDriveAgent`: robots (pallet truck, forklift, jackal) with wheel motors and an ArUco
  marker, driven by velocity commands through physics;
- :class:`WalkerAgent`: a person moved kinematically along its path (the articulated humanoid of
  the pose mapping, posed from joint targets, is ``humanoid.PosedHumanoidAgent``);
- :class:`StaticAgent`: a fixed robot (the Panda arm).

All report their ground-truth pose and sense collisions (contacts with anything but the floor).
"""

from __future__ import annotations

import tempfile
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pybullet_data

from simlan_data.constants import URDF_DIR
from simlan_data.errors import ConfigError
from simlan_data.geometry.rotations import quat_from_yaw
from simlan_data.geometry.transforms import Transform
from simlan_data.sim.markers import marker_urdf
from simlan_data.world._pybullet import pb, silence_c_output
from simlan_data.world.agent_types import AGENT_TYPES, MARKER_SIZE_M, AgentType, agent_type
from simlan_data.world.labels import label_id

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

MARKER_PLACEHOLDER = "<!-- ARUCO_MARKER -->"
VISUAL_MARGIN_M = 0.08


@dataclass
class CollisionReading:
    in_collision: bool
    max_force_n: float
    total_force_n: float
    others: list[str] = field(default_factory=list)


def urdf_with_marker(kind: AgentType, marker_id: int | None) -> str:
    """The agent type's URDF text, with the cells of ``marker_id`` inserted if it carries one."""
    text = (URDF_DIR / kind.urdf).read_text()
    if kind.marker_xyz is None or marker_id is None:
        return text
    if MARKER_PLACEHOLDER not in text:
        raise ConfigError(
            "URDF lacks the marker placeholder",
            str(URDF_DIR / kind.urdf),
            f"no {MARKER_PLACEHOLDER} line",
            "restore the packaged URDF",
        )
    return text.replace(MARKER_PLACEHOLDER, marker_urdf(marker_id, xyz=kind.marker_xyz, size_m=MARKER_SIZE_M))


class Agent:
    """What every agent can do: pose, bounds, collision sensing."""

    def __init__(self, client: int, namespace: str, kind: AgentType, body: int) -> None:
        self.client, self.namespace, self.kind, self.body = client, namespace, kind, body
        self.label = label_id(kind.semantic)
        self.links: dict[str, int] = {}
        self.joints: dict[str, int] = {}
        for j in range(pb.getNumJoints(body, physicsClientId=client)):
            info = pb.getJointInfo(body, j, physicsClientId=client)
            self.joints[info[1].decode()] = j
            self.links[info[12].decode()] = j
        info = pb.getDynamicsInfo(body, -1, physicsClientId=client)
        self._com_in_link = (info[3], info[4])
        self._link_in_com = pb.invertTransform(info[3], info[4])
        self.command = (0.0, 0.0)

    def pose(self) -> Transform:
        """Ground-truth map -> base_link (PyBullet's base frame is the centre of mass)."""
        pos, orn = pb.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        pos, orn = pb.multiplyTransforms(pos, orn, *self._link_in_com)
        return Transform.from_quat(pos, orn)

    def twist(self) -> tuple[float, float]:
        """Ground-truth forward speed (m/s, along base_link x) and yaw rate (rad/s)."""
        lin, ang = pb.getBaseVelocity(self.body, physicsClientId=self.client)
        pose = self.pose()
        return float(pose.rotation[:, 0] @ np.asarray(lin)), float(ang[2])

    def aabbs(self) -> list[tuple[Sequence[float], Sequence[float]]]:
        """Bounds of everything the agent draws (for the layered renderer).

        PyBullet's AABBs come from collision shapes: they are grown by ``VISUAL_MARGIN_M`` for
        visuals that stick out a little (sleeves, shoes), and the marker plate, which has no
        collision shape at all, is added from its known geometry.
        """
        m = VISUAL_MARGIN_M
        out: list[tuple[Sequence[float], Sequence[float]]] = []
        for link in (-1, *self.joints.values()):
            lo, hi = pb.getAABB(self.body, link, physicsClientId=self.client)
            out.append(([lo[0] - m, lo[1] - m, lo[2] - m], [hi[0] + m, hi[1] + m, hi[2] + m]))
        if self.kind.marker_xyz is not None:
            h = 0.5 * MARKER_SIZE_M * 9.0 / 7.0 + 0.01  # quiet zone: one cell around the 7x7 grid
            plate = (
                np.array([[sx * h, sy * h, dz] for sx in (-1, 1) for sy in (-1, 1) for dz in (-0.03, 0.01)])
                + self.kind.marker_xyz
            )
            corners = self.pose().apply(plate)
            out.append((corners.min(axis=0).tolist(), corners.max(axis=0).tolist()))
        return out

    def apply_command(self, linear_mps: float, angular_rps: float) -> tuple[float, float]:  # noqa: ARG002 - fixed agents ignore commands
        return (0.0, 0.0)

    def step_kinematics(self, dt_s: float) -> None:
        """Move a kinematic agent by ``dt_s`` (no-op for physical ones)."""

    def collisions(self, ignore: Collection[int], names: Mapping[int, str]) -> CollisionReading:
        """Contacts with any body but ``ignore`` (the floor): forces and who was touched."""
        contacts = pb.getContactPoints(bodyA=self.body, physicsClientId=self.client)
        forces, others = [], set()
        for c in contacts:
            other = c[2]
            if other in ignore or other == self.body:
                continue
            forces.append(float(c[9]))
            others.add(names.get(other, f"body_{other}"))
        if not forces:
            return CollisionReading(False, 0.0, 0.0, [])
        return CollisionReading(True, max(forces), float(sum(forces)), sorted(others))


def _load(
    client: int, kind: AgentType, namespace: str, marker_id: int | None, pose: Sequence[float], *, fixed: bool
) -> int:
    x, y, yaw = (float(v) for v in pose)
    orn = list(quat_from_yaw(yaw))
    with tempfile.TemporaryDirectory(prefix="simlan_urdf_") as tmp, silence_c_output(stderr=True):
        if kind.urdf.startswith("pybullet_data:"):
            path = str(Path(pybullet_data.getDataPath()) / kind.urdf.split(":", 1)[1])
            body = pb.loadURDF(path, [x, y, 0.0], orn, useFixedBase=fixed, physicsClientId=client)
        else:
            path = str(Path(tmp) / f"{namespace}.urdf")
            Path(path).write_text(urdf_with_marker(kind, marker_id))
            body = pb.loadURDF(path, [x, y, 0.002], orn, useFixedBase=fixed, physicsClientId=client)
    if body < 0:
        raise ConfigError("agent URDF failed to load", kind.urdf, "PyBullet rejected it", "check the URDF")
    return body


class DiffDriveAgent(Agent):
    """A differential-drive robot driven through its wheel motors."""

    def __init__(
        self, client: int, namespace: str, kind: AgentType, *, pose: Sequence[float], marker_id: int | None
    ) -> None:
        super().__init__(
            client, namespace, kind, _load(client, kind, namespace, marker_id, pose, fixed=False)
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
        super().__init__(client, namespace, kind, _load(client, kind, namespace, None, pose, fixed=True))
        self._x, self._y, self._yaw = (float(v) for v in pose)

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
            [self._x, self._y, 0.0], list(quat_from_yaw(self._yaw)), *self._com_in_link
        )
        pb.resetBasePositionAndOrientation(self.body, pos, orn, physicsClientId=self.client)

    def twist(self) -> tuple[float, float]:
        return self.command


class StaticAgent(Agent):
    """A robot fixed in place (it does not drive)."""

    def __init__(self, client: int, namespace: str, kind: AgentType, *, pose: Sequence[float]) -> None:
        super().__init__(client, namespace, kind, _load(client, kind, namespace, None, pose, fixed=True))

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
        from simlan_data.sim.humanoid import PosedHumanoidAgent  # humanoid.py builds on this module

        return PosedHumanoidAgent(client, namespace, kind, pose=pose)
    return StaticAgent(client, namespace, kind, pose=pose)
