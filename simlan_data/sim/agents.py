"""Agents in the PyBullet world: differential-drive robots carrying an ArUco marker.

An agent type is data (:class:`AgentType`); :class:`DiffDriveAgent` spawns it from its URDF
(with the marker cells inserted for the agent's id), turns velocity commands into wheel motor
targets, reports its ground-truth pose and twist, and senses collisions (contacts with anything
but the floor).
"""

from __future__ import annotations

import tempfile
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._pybullet import pb, silence_c_output
from ..constants import URDF_DIR
from ..errors import ConfigError
from ..geometry.rotations import quat_from_yaw
from ..geometry.transforms import Transform
from ..world.labels import label_id
from .markers import marker_urdf

MARKER_PLACEHOLDER = "<!-- ARUCO_MARKER -->"


@dataclass(frozen=True)
class AgentType:
    """Geometry and limits of one kind of robot."""

    name: str
    urdf: str
    semantic: str
    marker_xyz: tuple[float, float, float]
    wheel_joints: tuple[str, str]
    wheel_radius_m: float
    track_m: float
    max_speed_mps: float
    max_yaw_rate_rps: float
    max_wheel_torque_nm: float
    footprint_m: tuple[float, float, float, float]  # x_min, x_max, y_min, y_max in base_link
    caster_links: tuple[str, ...] = ()
    wheel_friction: float = 1.0


AGENT_TYPES: dict[str, AgentType] = {
    "pallet_truck": AgentType(
        name="pallet_truck",
        urdf="pallet_truck.urdf",
        semantic="pallet_truck",
        marker_xyz=(-0.8, 0.0, 1.30),
        wheel_joints=("left_wheel_joint", "right_wheel_joint"),
        wheel_radius_m=0.1,
        track_m=0.72,
        max_speed_mps=2.0,
        max_yaw_rate_rps=1.0,
        max_wheel_torque_nm=120.0,
        footprint_m=(-1.15, 0.70, -0.40, 0.40),
        caster_links=("rear_caster", "left_fork_caster", "right_fork_caster"),
    ),
}


def agent_type(name: str, *, where: str = "agents[].type") -> AgentType:
    try:
        return AGENT_TYPES[name]
    except KeyError:
        raise ConfigError(
            f"unknown agent type '{name}'", where, f"known types: {', '.join(AGENT_TYPES)}", "use one of them"
        ) from None


@dataclass
class CollisionReading:
    in_collision: bool
    max_force_n: float
    total_force_n: float
    others: list[str] = field(default_factory=list)


def urdf_with_marker(kind: AgentType, marker_id: int) -> str:
    """The agent type's URDF text with the cells of ``marker_id`` inserted."""
    text = (URDF_DIR / kind.urdf).read_text()
    if MARKER_PLACEHOLDER not in text:
        raise ConfigError(
            "URDF lacks the marker placeholder",
            str(URDF_DIR / kind.urdf),
            f"no {MARKER_PLACEHOLDER} line",
            "restore the packaged URDF",
        )
    return text.replace(MARKER_PLACEHOLDER, marker_urdf(marker_id, xyz=kind.marker_xyz))


class DiffDriveAgent:
    """A spawned differential-drive robot."""

    def __init__(
        self, client: int, namespace: str, kind: AgentType, *, pose: Sequence[float], marker_id: int
    ) -> None:
        self.client, self.namespace, self.kind, self.marker_id = client, namespace, kind, int(marker_id)
        self.label = label_id(kind.semantic)
        x, y, yaw = (float(v) for v in pose)
        with tempfile.TemporaryDirectory(prefix="simlan_urdf_") as tmp:
            path = Path(tmp) / f"{namespace}.urdf"
            path.write_text(urdf_with_marker(kind, marker_id))
            with silence_c_output(stderr=True):
                self.body = pb.loadURDF(
                    str(path),
                    [x, y, 0.002],
                    list(quat_from_yaw(yaw)),
                    useFixedBase=False,
                    physicsClientId=client,
                )
        if self.body < 0:
            raise ConfigError(
                "agent URDF failed to load", kind.urdf, "PyBullet rejected it", "check the URDF"
            )
        self.links: dict[str, int] = {}
        self.joints: dict[str, int] = {}
        for j in range(pb.getNumJoints(self.body, physicsClientId=client)):
            info = pb.getJointInfo(self.body, j, physicsClientId=client)
            self.joints[info[1].decode()] = j
            self.links[info[12].decode()] = j
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
        # base_link frame vs. PyBullet's base (centre of mass) frame
        info = pb.getDynamicsInfo(self.body, -1, physicsClientId=client)
        self._com_in_link = Transform.from_quat(info[3], info[4])
        self._link_in_com = pb.invertTransform(info[3], info[4])
        self.command = (0.0, 0.0)

    # ----------------------------------------------------------------------------- state
    def pose(self) -> Transform:
        """Ground-truth map -> base_link."""
        pos, orn = pb.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        pos, orn = pb.multiplyTransforms(pos, orn, *self._link_in_com)
        return Transform.from_quat(pos, orn)

    def twist(self) -> tuple[float, float]:
        """Ground-truth forward speed (m/s, base_link x) and yaw rate (rad/s)."""
        lin, ang = pb.getBaseVelocity(self.body, physicsClientId=self.client)
        pose = self.pose()
        com = pose.apply(self._com_in_link.translation)
        v_link = np.asarray(lin) + np.cross(ang, pose.translation - com)
        return float(pose.rotation[:, 0] @ v_link), float(ang[2])

    def aabbs(self) -> list[tuple[Sequence[float], Sequence[float]]]:
        """Axis-aligned bounds of every link (for the layered renderer)."""
        out = [pb.getAABB(self.body, -1, physicsClientId=self.client)]
        out += [pb.getAABB(self.body, j, physicsClientId=self.client) for j in self.joints.values()]
        return out

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        boxes = np.array(self.aabbs(), dtype=float)
        return boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)

    # --------------------------------------------------------------------------- actuation
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

    # ------------------------------------------------------------------------------ sensing
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
