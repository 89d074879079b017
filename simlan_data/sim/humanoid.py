"""The articulated humanoid in PyBullet: posed kinematically from joint targets.

Joint targets (47, SIMLAN's order: ``skeleton.JOINT_NAMES``) come from motion files, random
configurations (datasets) or a pose mapper's predictions (the drive). Posing is kinematic:
``resetJointState`` puts every joint at its target at once, and position motors hold it there
while physics steps (the body hangs from its support arm, as SIMLAN's does, and nothing pushes it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from simlan_data.sim.agent_base import Agent, load_body
from simlan_data.world._pybullet import pb
from simlan_data.world.agent_types import AgentType
from simlan_data.world.skeleton import JOINT_NAMES, LANDMARK_INSIDE_M, LOWER, UPPER, landmark_positions

HOLD_FORCE_N = 1000.0


class PosedHumanoidAgent(Agent):
    """A humanoid on its support arm whose 47 joints are set from targets (no walking)."""

    def __init__(self, client: int, namespace: str, kind: AgentType, *, pose: Sequence[float]) -> None:
        super().__init__(client, namespace, kind, load_body(client, kind, namespace, None, pose, fixed=True))
        self.joint_indices = [self.joints[n] for n in JOINT_NAMES]
        self.targets = np.zeros(len(JOINT_NAMES))
        self.set_joints(self.targets)

    def set_joints(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Pose the body (clipped to the joint limits); returns the targets applied."""
        q = np.clip(np.asarray(q, dtype=np.float64), LOWER, UPPER)
        for j, value in zip(self.joint_indices, q):
            pb.resetJointState(self.body, j, float(value), physicsClientId=self.client)
        pb.setJointMotorControlArray(
            self.body,
            self.joint_indices,
            pb.POSITION_CONTROL,
            targetPositions=q.tolist(),
            forces=[HOLD_FORCE_N] * len(q),
            physicsClientId=self.client,
        )
        self.targets = q
        return q

    def joint_positions(self) -> NDArray[np.float64]:
        """Measured joint positions (47), SIMLAN's order."""
        states = pb.getJointStates(self.body, self.joint_indices, physicsClientId=self.client)
        return np.array([s[0] for s in states])

    def landmarks_world(self) -> NDArray[np.float64]:
        """World positions (33, 3) of the MediaPipe landmarks for the current targets."""
        return landmark_positions(self.targets[None], self.pose().matrix())[0]

    def landmarks(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The landmarks where the body is drawn: at the measured joints (the motors hold the
        targets against gravity, a fraction of a millimetre off), unlike :meth:`landmarks_world`."""
        return landmark_positions(self.joint_positions()[None], self.pose().matrix())[0], LANDMARK_INSIDE_M

    def aabb(self) -> tuple[list[float], list[float]]:
        """One box around the whole body (the layered renderer draws one region per camera)."""
        boxes = self.aabbs()
        lo = np.min([b[0] for b in boxes], axis=0)
        hi = np.max([b[1] for b in boxes], axis=0)
        return lo.tolist(), hi.tolist()

    def twist(self) -> tuple[float, float]:
        return (0.0, 0.0)
