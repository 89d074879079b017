"""The agents' recent past, to render what a late camera saw (issue 24: exposure instants, delay).

A free-running camera exposes at its own phase, and its frame reaches the algorithms a transport
delay later: the frame a camera tick delivers shows the scene ``lag`` seconds before the tick.
``PoseHistory`` keeps every agent's base pose and joint positions at every physics step of the
last ``keep_s`` seconds; ``place(t)`` puts the agents where they were at ``t`` (linear between two
steps, quaternions normalized; before the first step: the first). The caller restores the
simulation afterwards (``pybullet.saveState``/``restoreState``), so the physics never sees it.
Everything else of the scene (pallets an agent pushed, the light) is drawn as it is at the tick.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from simlan_data.sim.agent_base import Agent
from simlan_data.world._pybullet import pb


class PoseHistory:
    """Base pose (7) and joint positions of every agent, per recorded instant."""

    def __init__(self, agents: Sequence[Agent], keep_s: float, client: int) -> None:
        self.agents, self.client = list(agents), client
        self.keep_ns = int(keep_s * 1e9)
        self._joints = [list(range(pb.getNumJoints(a.body, physicsClientId=a.client))) for a in self.agents]
        self._times: deque[int] = deque()
        self._states: deque[list[NDArray[np.float64]]] = deque()

    def record(self, t_ns: int) -> None:
        """Store the agents' state at ``t_ns`` (call once per physics step, in time order)."""
        states = []
        for agent, joints in zip(self.agents, self._joints, strict=True):
            pos, orn = pb.getBasePositionAndOrientation(agent.body, physicsClientId=agent.client)
            q = (
                [s[0] for s in pb.getJointStates(agent.body, joints, physicsClientId=agent.client)]
                if joints
                else []
            )
            states.append(np.array([*pos, *orn, *q], dtype=np.float64))
        self._times.append(t_ns)
        self._states.append(states)
        while len(self._times) > 2 and self._times[1] <= t_ns - self.keep_ns:
            self._times.popleft()
            self._states.popleft()

    def state_at(self, t_ns: int) -> list[NDArray[np.float64]]:
        """Every agent's state at ``t_ns``: between the two recorded instants around it."""
        times = self._times
        if t_ns <= times[0]:
            return self._states[0]
        if t_ns >= times[-1]:
            return self._states[-1]
        hi = int(np.searchsorted(np.fromiter(times, dtype=np.int64, count=len(times)), t_ns))
        t0, t1 = times[hi - 1], times[hi]
        w = (t_ns - t0) / (t1 - t0)
        out = []
        for a, b in zip(self._states[hi - 1], self._states[hi], strict=True):
            s = a + (b - a) * w
            qa, qb = a[3:7], b[3:7]
            if float(qa @ qb) < 0:  # the shorter way round
                s[3:7] = qa + (-qb - qa) * w
            s[3:7] /= np.linalg.norm(s[3:7])
            out.append(s)
        return out

    def place(self, t_ns: int) -> None:
        """Put every agent where it was at ``t_ns`` (base and joints)."""
        for agent, joints, s in zip(self.agents, self._joints, self.state_at(t_ns), strict=True):
            c = agent.client
            pb.resetBasePositionAndOrientation(
                agent.body, s[0:3].tolist(), s[3:7].tolist(), physicsClientId=c
            )
            for j, value in zip(joints, s[7:], strict=True):
                pb.resetJointState(agent.body, j, float(value), physicsClientId=c)
