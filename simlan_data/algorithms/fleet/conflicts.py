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

import itertools
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
        self.mid = 0.5 * (self.p + self.q)  # each piece's bounding circle
        self.bound = 0.5 * np.linalg.norm(self.q - self.p, axis=1) + self.r
        self._by_anchor = np.argsort(self.anchor, kind="stable")  # pieces grouped by anchor node
        self._starts = np.searchsorted(self.anchor[self._by_anchor], np.arange(graph.size + 1))
        # how far a piece reaches from its anchor node: the longest edge behind it, its own length
        self.extent_m = float(graph.lengths_m.max(initial=0.0)) + shape.reach_m + shape.half_width_m

    def piece(self, k: int) -> Region:
        return self.p[k : k + 1], self.q[k : k + 1], self.r[k : k + 1]

    def hit_by(self, regions: list[Region], margin_m: float) -> NDArray[np.bool_]:
        """Per region and piece: whether the piece comes closer to the region than their radii plus
        ``margin_m``. One tree query finds the nodes near each capsule (sampled every SAMPLE_M); only
        the pieces anchored there are measured, capsule by piece."""
        p, q, rad = fp.region(*regions)
        owner = np.repeat(np.arange(len(regions)), [len(r[2]) for r in regions])
        n = np.maximum(2, np.ceil(np.linalg.norm(q - p, axis=1) / SAMPLE_M).astype(np.int64) + 1)
        cap = np.repeat(np.arange(len(p)), n)
        t = np.concatenate([np.linspace(0.0, 1.0, k) for k in n.tolist()])
        pts = p[cap] + t[:, None] * (q - p)[cap]
        hits = self.graph.tree.query_ball_point(pts, rad[cap] + margin_m + self.extent_m + SAMPLE_M)
        counts = np.fromiter((len(h) for h in hits), dtype=np.int64, count=len(hits))
        nodes = np.fromiter(itertools.chain.from_iterable(hits), dtype=np.int64, count=int(counts.sum()))
        pairs = np.unique(np.repeat(cap, counts) * self.graph.size + nodes)
        c, node = pairs // self.graph.size, pairs % self.graph.size
        per = self._starts[node + 1] - self._starts[node]  # pieces anchored at each node
        c = np.repeat(c, per)
        first = np.repeat(self._starts[node] - np.cumsum(per) + per, per)
        k = self._by_anchor[first + np.arange(len(c))]
        mid, bound = 0.5 * (p + q), 0.5 * np.linalg.norm(q - p, axis=1) + rad
        gap = np.linalg.norm(self.mid[k] - mid[c], axis=1) - self.bound[k] - bound[c]
        near = gap < margin_m  # bounding circles first: most pairs are far apart
        c, k = c[near], k[near]
        d = fp.pair_distances(self.p[k], self.q[k], p[c], q[c])
        close = d < self.r[k] + rad[c] + margin_m
        out = np.zeros((len(regions), len(self.r)), dtype=bool)
        out[owner[c[close]], k[close]] = True
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
        new = parts[folded:]
        self._measure(shape, pieces, new)
        for region in new:
            bad = bad | self._hits[(shape, id(region))][1]
        self._planned[(shape, step)] = (bad, len(parts))
        missing = [(n, region) for n, region in waiting if (shape, n) not in self._waiting]
        if missing:
            rows = pieces.hit_by([region for _, region in missing], self.table.safety_m)
            for (n, _), row in zip(missing, rows):
                self._waiting[(shape, n)] = row
        for name, _ in waiting:
            bad = bad | self._waiting[(shape, name)]
        return bad

    def _measure(self, shape: Shape, pieces: Pieces, regions: list[Region]) -> None:
        """Measure the regions not measured yet against the shape's pieces, all at once."""
        todo = {id(r): r for r in regions if (shape, id(r)) not in self._hits}
        if todo:
            rows = pieces.hit_by(list(todo.values()), self.table.safety_m)
            for (key, region), row in zip(todo.items(), rows):
                # (the region is kept with its answer: its id stays its own)
                self._hits[(shape, key)] = (region, row)
