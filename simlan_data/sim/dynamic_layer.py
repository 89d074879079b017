"""What the layered renderer's dynamic layer needs: a client without the warehouse meshes, and
which agents moved.

A region render pays a fixed cost for every mesh in the client (vertex work in Mesa's software
rasterizer, twice with segmentation) however small the region: 3.0 ms for an 8x8 region of the
full warehouse against 1.6 ms without its merged visual meshes (measured, benchmarks/perf.py).
The meshes carry no collision shape, so once every camera has its static layer they are removed
from the client and the region renders draw only what can move; they come back, from the same
visual shapes, whenever a static layer must be rendered again::

    build world -> static layers (meshes present, agents absent) -> remove meshes -> spawn agents
    each camera tick: agents that moved -> their boxes -> region renders, composited by depth
    a world object was pushed: meshes back, agents hidden -> stale static layers -> remove meshes

PyBullet's EGL plugin cannot serve two clients in one process (the second context breaks the
first's renders), so the dynamic layer lives in the physics client itself.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence

import numpy as np

from simlan_data.sim.agents import Agent
from simlan_data.sim.rendering import Aabb, LabelTable
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import WorldBodies

# m: an agent whose bounds changed less than this since it was last drawn is not drawn again
# (0.1 mm: 1 % of a pixel at the ceiling cameras' distances)
REDRAW_TOLERANCE_M = 1e-4


class StaticMeshes:
    """The world's visual-only meshes: removed from the client except while static layers render."""

    def __init__(self, client: int, world: WorldBodies, labels: LabelTable) -> None:
        self.client, self.labels = client, labels
        self._shapes = [(world.labels[b], *world.visual_shapes[b]) for b in sorted(world.visual_shapes)]
        self.bodies: list[int] = sorted(world.visual_shapes)

    @property
    def present(self) -> bool:
        return bool(self.bodies)

    def remove(self) -> None:
        for body in self.bodies:
            pb.removeBody(body, physicsClientId=self.client)
        self.bodies = []

    def restore(self) -> None:
        """Create the meshes again (new body ids: the label table learns them)."""
        if self.present:
            return
        for label, visual, rgba in self._shapes:
            body = pb.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=-1,
                baseVisualShapeIndex=visual,
                physicsClientId=self.client,
            )
            pb.changeVisualShape(body, -1, rgbaColor=list(rgba), physicsClientId=self.client)
            self.labels.set(body, label)
            self.bodies.append(body)

    @contextlib.contextmanager
    def shown(self) -> Iterator[None]:
        """Have the meshes in the client for the block (as they were before, afterwards)."""
        was_present = self.present
        self.restore()
        try:
            yield
        finally:
            if not was_present:
                self.remove()


class MovedAgents:
    """Which agents moved since they were last drawn, and the boxes the cameras must redraw."""

    def __init__(self, agents: Sequence[Agent]) -> None:
        self.agents = list(agents)
        self._drawn: dict[str, tuple[np.ndarray, list[Aabb]]] = {}

    def boxes(self) -> list[Aabb]:
        """Boxes of every agent that moved (where it was last drawn and where it is now).

        What ``CameraRenderer.render`` needs; agents that stood still are left out, so cameras
        that see only them reuse their last image.
        """
        out: list[Aabb] = []
        for agent in self.agents:
            boxes = agent.aabbs()
            state = np.asarray(boxes, dtype=float).ravel()
            last = self._drawn.get(agent.namespace)
            if last is not None and np.abs(state - last[0]).max() <= REDRAW_TOLERANCE_M:
                continue
            out += boxes + (last[1] if last is not None else [])
            self._drawn[agent.namespace] = (state, boxes)
        return out
