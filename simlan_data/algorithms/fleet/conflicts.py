"""Which of a robot's shared route pieces conflict with what is reserved, per plan step.

A robot's search asks, step after step, whether the region it would hold is free. Most of those
regions are shared pieces of the route graph: driving a directed edge (a capsule from the tail at
its start to the nose at its end) or turning in place at a node (the circle of its reach); their
geometry depends only on the robot's shape. So the answer is kept per (shape, step) as one boolean
per piece, and each reserved region is folded into it once, when it is first needed: robots of the
same shape planned after each other share the work, instead of each search measuring every piece
against every robot planned before it. Robots not planned yet (where they stand, for a few steps)
are folded in per search, from a per-(shape, robot) answer that does not depend on the step.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.fleet import footprint as fp
from simlan_data.algorithms.fleet.footprint import Region, Shape
from simlan_data.algorithms.fleet.graph import RouteGraph


class Table(Protocol):
    """What the cache reads of the reservation table (``schedule.Reservations``)."""

    graph: RouteGraph
    safety_m: float
    parts: list[list[Region]]  # per step, the regions reserved
    waiting: dict[str, tuple[Region, int, bool]]  # robots not planned yet: region, until step, idle


SAMPLE_M = 0.5  # a reserved capsule is sampled this finely to find the pieces near it


class Pieces:
    """A shape's shared pieces on a graph: every directed edge driven, then a turn at every node."""

    def __init__(self, graph: RouteGraph, shape: Shape) -> None:
        arcs = graph.arcs
        a, b = graph.xy[arcs[:, 0]], graph.xy[arcs[:, 1]]
        d = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1), 1e-9)[:, None]
        self.graph, self.n_arcs = graph, len(arcs)
        self.p = np.concatenate([a + shape.back_m * d, graph.xy])
        self.q = np.concatenate([b + shape.front_m * d, graph.xy])
        self.r = np.concatenate([np.full(len(arcs), shape.half_width_m), np.full(graph.size, shape.reach_m)])
        self.anchor = np.concatenate([arcs[:, 1], np.arange(graph.size)])  # the node each piece ends at
        # how far a piece reaches from its anchor node: the longest edge behind it, its own length
        self.extent_m = float(graph.lengths_m.max(initial=0.0)) + shape.reach_m + shape.half_width_m

    def piece(self, k: int) -> Region:
        return self.p[k : k + 1], self.q[k : k + 1], self.r[k : k + 1]

    def hit_by(self, region: Region, margin_m: float) -> NDArray[np.bool_]:
        """Per piece: whether it comes closer to ``region`` than their radii plus ``margin_m``."""
        out = np.zeros(len(self.r), dtype=bool)
        near = np.zeros(self.graph.size, dtype=bool)
        for a, b, rad in zip(*region):
            n = max(2, int(np.ceil(np.linalg.norm(b - a) / SAMPLE_M)) + 1)
            pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
            reach = rad + margin_m + self.extent_m + SAMPLE_M
            for hits in self.graph.tree.query_ball_point(pts, reach):
                near[hits] = True
        cand = np.flatnonzero(near[self.anchor])
        if len(cand):
            d = fp.segment_distances(self.p[cand], self.q[cand], region[0], region[1])
            out[cand] = (d < self.r[cand][:, None] + region[2][None, :] + margin_m).any(axis=1)
        return out


class ConflictCache:
    """Per shape and step, the pieces that conflict with the reservations (see the module doc)."""

    def __init__(self, table: Table) -> None:
        self.table = table
        self._pieces: dict[Shape, Pieces] = {}
        self._planned: dict[tuple[Shape, int], tuple[NDArray[np.bool_], int]] = {}
        self._waiting: dict[tuple[Shape, str], NDArray[np.bool_]] = {}
        # a plan reserves the same region object at every step it holds it: measured once
        self._hits: dict[tuple[Shape, int], tuple[Region, NDArray[np.bool_]]] = {}

    def pieces(self, shape: Shape) -> Pieces:
        if shape not in self._pieces:
            self._pieces[shape] = Pieces(self.table.graph, shape)
        return self._pieces[shape]

    def bad(self, shape: Shape, step: int) -> NDArray[np.bool_] | None:
        """Per piece of ``shape``: conflicts at ``step`` (None: nothing is reserved then)."""
        parts = self.table.parts[step]
        waiting = [(n, w[0]) for n, w in self.table.waiting.items() if step <= w[1]]
        if not parts and not waiting:
            return None
        pieces = self.pieces(shape)
        bad, folded = self._planned.get((shape, step), (np.zeros(len(pieces.r), dtype=bool), 0))
        for region in parts[folded:]:
            bad = bad | self._hit(shape, pieces, region)
        self._planned[(shape, step)] = (bad, len(parts))
        for name, region in waiting:
            if (shape, name) not in self._waiting:
                self._waiting[(shape, name)] = pieces.hit_by(region, self.table.safety_m)
            bad = bad | self._waiting[(shape, name)]
        return bad

    def _hit(self, shape: Shape, pieces: Pieces, region: Region) -> NDArray[np.bool_]:
        key = (shape, id(region))
        if key not in self._hits:  # (the region is kept with its answer: its id stays its own)
            self._hits[key] = (region, pieces.hit_by(region, self.table.safety_m))
        return self._hits[key][1]
