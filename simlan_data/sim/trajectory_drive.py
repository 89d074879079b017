"""Agents moved along a tracker's trajectories (``experiment=trajectory``; docs/trajectories.md).

Each tracker id is the agent ``robot_agent_<id>`` (spawned by the config where the tracker first
sees it). At every physics step, before that step's ground truth and camera images, every such
agent is placed where :meth:`Tracks.at` says it is (linear between the tracker's stamps). A robot's
base is made massless, i.e. static in PyBullet, so physics (gravity, its wheel motors, contacts)
does not move it between placements; a walker is kinematic already.

An object the tracker does not see at a time is hidden: moved ``HIDDEN_Z_M`` below the floor where
it was (no camera sees it, nothing touches it) and its ground truth says so by that depth; the
trajectory exporter leaves such poses out (``simlan_data.apps.trajectory_export``).
"""

from __future__ import annotations

from simlan_data.algorithms.trajectory import Tracks
from simlan_data.config.schema import Config
from simlan_data.config.trajectory import load_tracks
from simlan_data.sim.agent_base import Agent
from simlan_data.world._pybullet import pb

__all__ = ["HIDDEN_BELOW_M", "HIDDEN_Z_M", "TrajectoryDriver", "make_trajectory_driver"]

HIDDEN_Z_M = -100.0  # where an object the tracker does not see waits
HIDDEN_BELOW_M = -50.0  # a ground-truth z under this is a hidden object


class TrajectoryDriver:
    """Places the tracked agents at each step's time."""

    def __init__(self, tracks: Tracks, agents: list[Agent]) -> None:
        self.tracks = tracks
        by_ns = {a.namespace: a for a in agents}
        self.agents = [by_ns[f"robot_agent_{oid}"] for oid in tracks.ids]
        for agent in self.agents:  # static for physics: only placements move it
            pb.changeDynamics(agent.body, -1, mass=0.0, physicsClientId=agent.client)

    def place(self, t_ns: int) -> None:
        for agent, pose in zip(self.agents, self.tracks.at(t_ns), strict=True):
            if pose is None:
                x, y = agent.pose().translation[:2]
                agent.place((float(x), float(y), HIDDEN_Z_M), agent.pose().yaw())
            else:
                agent.place(pose[:3], pose[3])

    def commands(self, t_ns: int) -> dict[str, tuple[float, float]]:
        """Each tracked agent's velocity at ``t_ns`` (``Tracks.velocities``), by namespace: what the
        localizer is told it was commanded, and what is recorded on its ``cmd_vel``."""
        return {a.namespace: vw for a, vw in zip(self.agents, self.tracks.velocities(t_ns), strict=True)}


def make_trajectory_driver(cfg: Config, agents: list[Agent]) -> TrajectoryDriver | None:
    """The driver of a run with a tracker file (``trajectory.file``; the config checked that the
    agents are the file's), else None."""
    if not cfg.trajectory.file:
        return None
    return TrajectoryDriver(load_tracks(cfg.trajectory), agents)
