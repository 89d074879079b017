"""Route lengths for a robot that drives forwards and turns in place only where it has room.

A robot on the route graph that cannot reverse (``Timing.reverse_ratio`` 0, the default) changes
heading by more than the turn tolerance only at a node whose clearance covers its reach
(``RouteGraph.turnable``). Plain graph distances
ignore both: from inside a single-lane aisle facing a dead end, the way back looks short although
the robot can never take it, and a windowed plan guided by them left a pallet truck standing in
the upper aisle for the rest of an 8-robot mission. The search (``search.py``) is guided by plain
lengths first (``TurnGraph.to_goal(forward=False)``: as the first guide, forward-only lengths sent
trucks to the same turning pocket at once) and by forward-only ones when a plan would leave the
robot standing.

Here the states are the directed edges (arcs) of the graph, "just arrived at v from u", and a move
from arc (u, v) to arc (v, w) exists when the heading change is within the tolerance or the robot
may turn at v. Dijkstra over the reversed moves from every arc that ends at the goal gives, per
arc, the length still to drive; a state from which the goal cannot be reached gets ``inf``, so a
search guided by them never enters it. Both kinds are cached per goal and avoided nodes.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

CACHED = 512  # goals (with what they avoid) whose lengths are kept


class TurnGraph:
    """The moves between arcs of a route graph for one robot reach (see the module docstring)."""

    def __init__(
        self,
        arcs: NDArray[np.int64],
        lengths_m: NDArray[np.float64],
        angles: NDArray[np.float64],
        turnable: NDArray[np.bool_],
        tolerance_rad: float,
        size: int,
    ) -> None:
        self.arcs, self.lengths_m, self.size = arcs, lengths_m, size
        self.angles: list[float] = angles.tolist()
        self.tolerance_rad = tolerance_rad
        self.out: list[list[int]] = [[] for _ in range(size)]  # arcs leaving each node
        for k, u in enumerate(arcs[:, 0].tolist()):
            self.out[u].append(k)
        src, dst = [], []
        angle = self.angles
        for a, v in enumerate(arcs[:, 1].tolist()):
            for b in self.out[v]:
                if turnable[v] or self.within(angle[a], angle[b]):
                    src.append(a)
                    dst.append(b)
        self.moves = (np.asarray(src, dtype=np.int64), np.asarray(dst, dtype=np.int64))
        self._cache: dict[tuple, ToGoal] = {}  # replans ask the same again

    def within(self, heading: float, angle: float) -> bool:
        return angle_off(heading, angle) <= self.tolerance_rad

    def to_goal(
        self,
        goal: int,
        avoid: NDArray[np.bool_] | None = None,
        penalty_m: float = 0.0,
        *,
        forward: bool = True,
        soft: NDArray[np.bool_] | None = None,
        soft_m: float = 0.0,
    ) -> ToGoal:
        """Length still to drive to ``goal`` from every arc and node; with ``avoid``, every arc
        touching an avoided node costs ``penalty_m`` more, and with ``soft`` every arc touching one
        of those nodes ``soft_m`` more."""
        avoided = avoid is not None and bool(avoid.any())
        softened = soft is not None and soft_m > 0.0 and bool(soft.any())
        key = (
            goal,
            np.packbits(avoid).tobytes() if avoid is not None and avoided else None,
            penalty_m,
            forward,
            np.packbits(soft).tobytes() if soft is not None and softened else None,
            soft_m,
        )
        if key not in self._cache:
            if len(self._cache) >= CACHED:
                del self._cache[next(iter(self._cache))]  # the oldest
            cost = self.lengths_m
            if avoid is not None and avoided:
                cost = cost + penalty_m * (avoid[self.arcs[:, 0]] | avoid[self.arcs[:, 1]])
            if soft is not None and softened:
                cost = cost + soft_m * (soft[self.arcs[:, 0]] | soft[self.arcs[:, 1]])
            self._cache[key] = self._forward(goal, cost) if forward else self._plain(goal, cost)
        return self._cache[key]

    def _plain(self, goal: int, cost: NDArray[np.float64]) -> ToGoal:
        """Route lengths that ignore heading: any turn anywhere (the arc's end node's length)."""
        # the arcs reversed: lengths from the goal there are lengths to it (an arc may cost more one
        # way: the part of it no camera sees driven that way, RouteGraph.arc_bias)
        graph = csr_matrix((cost, (self.arcs[:, 1], self.arcs[:, 0])), shape=(self.size, self.size))
        node_m = np.asarray(dijkstra(graph, directed=True, indices=goal))
        arc_m = node_m[self.arcs[:, 1]]
        return ToGoal(self, goal, arc_m, node_m, cost + arc_m, plain=True)

    def _forward(self, goal: int, cost: NDArray[np.float64]) -> ToGoal:
        src, dst = self.moves
        n = len(self.arcs)
        # reversed moves: from the arc after to the arc before, weighted by the arc after
        rev = csr_matrix((cost[dst], (dst, src)), shape=(n, n))  # (lengths > 0: no entry vanishes)
        ends = np.flatnonzero(self.arcs[:, 1] == goal)
        if len(ends):
            arc_m = np.asarray(dijkstra(rev, directed=True, indices=ends, min_only=True))
        else:
            arc_m = np.full(n, np.inf)
        leave = cost + arc_m  # from the arc's start node, driving it first
        node_m = np.full(self.size, np.inf)
        np.minimum.at(node_m, self.arcs[:, 0], leave)
        node_m[goal] = 0.0
        arc_m[ends] = 0.0
        return ToGoal(self, goal, arc_m, node_m, leave)


class ToGoal:
    """Lengths to one goal: after arriving by an arc, from a node turning there, or on a heading."""

    def __init__(
        self,
        turns: TurnGraph,
        goal: int,
        arc_m: NDArray[np.float64],
        node_m: NDArray[np.float64],
        leave: NDArray[np.float64],
        *,
        plain: bool = False,
    ) -> None:
        self.turns, self.goal, self.plain = turns, goal, plain
        self.arc = arc_m.tolist()  # arrived at the arc's end node, facing along it
        self.node = node_m.tolist()  # at the node, free to turn
        self.node_array = node_m
        self._leave = leave

    def facing(self, node: int, heading: float | None) -> float:
        """From ``node`` facing ``heading`` without turning in place (None: any heading)."""
        if heading is None or self.plain or self.node[node] == 0.0:
            return self.node[node]
        ok = [
            self._leave[b] for b in self.turns.out[node] if self.turns.within(heading, self.turns.angles[b])
        ]
        return float(min(ok, default=math.inf))


def angle_off(heading: float, angle: float) -> float:
    """How far ``angle`` lies from ``heading`` (radians, 0..pi)."""
    return abs((angle - heading + math.pi) % (2 * math.pi) - math.pi)
