"""The base of every agent: a body loaded from its URDF, its pose, bounds and collisions.

:mod:`simlan_data.sim.agents` (the drives, ``spawn_agent``) and :mod:`simlan_data.sim.humanoid`
(the posed humanoid) both build on it; it imports neither, so the two do not import each other.
"""

from __future__ import annotations

import tempfile
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pybullet_data
from numpy.typing import NDArray

from simlan_data.constants import URDF_DIR
from simlan_data.errors import ConfigError
from simlan_data.geometry.rotations import quat_from_yaw
from simlan_data.geometry.transforms import Transform
from simlan_data.sim.markers import marker_urdf
from simlan_data.world._pybullet import pb, silence_c_output
from simlan_data.world.agent_types import MARKER_SIZE_M, AgentType
from simlan_data.world.labels import label_id

__all__ = ["Agent", "CollisionReading", "load_body", "urdf_with_marker"]

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

    def landmarks(self) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """A person's 33 body landmarks (MediaPipe Pose's order) in map (33, 3) and how deep under
        the body's surface each lies (33,); None for an agent that is not a person."""
        return None

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

    def place(self, xyz: Sequence[float], yaw_rad: float) -> None:
        """Put base_link at ``xyz`` facing ``yaw_rad`` (a kinematic move: a replayed trajectory)."""
        pos, orn = pb.multiplyTransforms(list(xyz), list(quat_from_yaw(yaw_rad)), *self._com_in_link)
        pb.resetBasePositionAndOrientation(self.body, pos, orn, physicsClientId=self.client)

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


def load_body(
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
