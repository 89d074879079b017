"""The route graph of a warehouse, derived from its occupancy grid (any layout, nothing hand-placed).

The floor is cut into square blocks of ``spacing_m``. In each block the free cell of greatest
clearance (capped, ties towards the block centre) becomes a node: in an aisle narrower than a
block that is the aisle's centre line (the medial axis, where clearance peaks), in open floor the
block centre. Nodes of neighbouring blocks (8-neighbourhood) are joined where the straight segment
between them keeps the robot's radius from every obstacle. The result is a sampled medial axis of
narrow passages plus a lattice of lanes over open floor.

Each node keeps its clearance: a robot may turn in place only at a node whose clearance covers its
swept circle (``RouteGraph.turnable``). Node kinds follow from the graph: ``end`` (one edge),
``lane`` (two), ``junction`` (three or more: an intersection or a passing place).

Given the floor the cameras see (``coverage.SeenFloor`` per heading: robots that steer on the
cameras), each arc (an edge driven one way) gets a guide weight: 1 + ``unseen_cost`` times the
share of it driven where no camera sees the robot that way (``RouteGraph.arc_bias``). The route
guide (``turns.py``) then keeps robots on seen floor where a seen way exists, and still finds a
way where none does (a start, a goal or a passing place off the seen floor). A robot turns in
place only at a node seen at every heading (a turn elsewhere can lose the cameras half way).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from simlan_data.algorithms.fleet.footprint import Shape
from simlan_data.algorithms.fleet.turns import TurnGraph
from simlan_data.algorithms.occupancy import OccupancyGrid
from simlan_data.geometry.rotations import wrap_angle

_NEIGHBOURS = ((0, 1), (1, -1), (1, 0), (1, 1))  # half of the 8-neighbourhood: each pair once


@dataclass(frozen=True)
class RouteGraph:
    """Nodes (xy, clearance) and undirected edges of the route graph."""

    xy: NDArray[np.float64]  # (N, 2) node positions in the map frame
    clearance_m: NDArray[np.float64]  # (N,) distance from each node to the nearest obstacle
    edges: NDArray[np.int64]  # (E, 2) node pairs, u < v
    radius_m: float  # the robot radius the graph was built for
    # (2E,) per arc of ``arcs``: how much longer the route guide counts it (None: 1 everywhere)
    arc_bias: NDArray[np.float64] | None = None
    # (N,) where a robot may turn in place as far as the cameras go: seen at every heading (None: all)
    seen_node: NDArray[np.bool_] | None = None
    grid: OccupancyGrid | None = None  # the floor it was built on (checks beyond the lanes' width)
    floor_clearance_m: NDArray[np.float64] | None = None  # per cell of ``grid``: to the nearest obstacle
    # (2E,) per arc: the share of it no camera sees driven that way (None: no cameras given)
    arc_unseen: NDArray[np.float64] | None = None
    # (E,) per edge: the least clearance along it (None: unknown; every edge keeps ``radius_m``)
    edge_clearance_m: NDArray[np.float64] | None = None
    # (E,) per edge: whether this graph's robots may drive it (None: all; see ``for_width``)
    edge_ok: NDArray[np.bool_] | None = None

    @property
    def size(self) -> int:
        return len(self.xy)

    @cached_property
    def lengths_m(self) -> NDArray[np.float64]:
        """(E,) edge lengths."""
        return np.linalg.norm(self.xy[self.edges[:, 0]] - self.xy[self.edges[:, 1]], axis=1)

    @cached_property
    def usable(self) -> NDArray[np.bool_]:
        """(N,) nodes this graph's robots may stand on (their lane radius clear of obstacles)."""
        return np.asarray(self.clearance_m >= self.radius_m - 1e-9)

    @cached_property
    def arc_ok(self) -> NDArray[np.bool_]:
        """(2E,) per arc of ``arcs``: whether this graph's robots may drive it."""
        ok = np.ones(len(self.edges), dtype=bool) if self.edge_ok is None else self.edge_ok
        return np.concatenate([ok, ok])

    def for_width(self, radius_m: float) -> RouteGraph:
        """The graph for robots of lane radius ``radius_m``: the same nodes and arcs (indices are
        shared, so plans of robots of every width meet in one reservation table), but only the edges
        that keep that radius clear are driven (their neighbours, lengths, components). The graph is
        built for the narrowest robot; the view for a wider one drives exactly the edges a graph
        built for it would have (a node is the block's clearest cell whatever the radius). A graph
        narrower than this one is this one."""
        if radius_m <= self.radius_m + 1e-9 or self.edge_clearance_m is None:
            return self
        key = round(radius_m, 6)
        if key not in self._views:
            ok = self.edge_clearance_m >= radius_m
            self._views[key] = replace(self, radius_m=radius_m, edge_ok=ok)
        return self._views[key]

    @cached_property
    def _views(self) -> dict[float, RouteGraph]:
        return {}

    @cached_property
    def _driven(self) -> NDArray[np.int64]:
        """The edges this graph's robots may drive."""
        return self.edges if self.edge_ok is None else self.edges[self.edge_ok]

    @cached_property
    def neighbours(self) -> list[list[int]]:
        """Adjacency lists of the edges driven (sorted: deterministic searches)."""
        adj: list[list[int]] = [[] for _ in range(self.size)]
        for u, v in self._driven.tolist():
            adj[u].append(v)
            adj[v].append(u)
        return [sorted(a) for a in adj]

    @cached_property
    def matrix(self) -> csr_matrix:
        """Symmetric sparse matrix of the driven edges' lengths (scipy.sparse.csgraph's input)."""
        u, v = self._driven[:, 0], self._driven[:, 1]
        lengths = self.lengths_m if self.edge_ok is None else self.lengths_m[self.edge_ok]
        data = np.concatenate([lengths, lengths])
        return csr_matrix((data, (np.concatenate([u, v]), np.concatenate([v, u]))), shape=(self.size,) * 2)

    @cached_property
    def arcs(self) -> NDArray[np.int64]:
        """(2E, 2) directed edges: every edge both ways."""
        return np.concatenate([self.edges, self.edges[:, ::-1]])

    @cached_property
    def arc_index(self) -> dict[tuple[int, int], int]:
        """(u, v) -> row of ``arcs``."""
        return {(u, v): k for k, (u, v) in enumerate(self.arcs.tolist())}

    @cached_property
    def arc_geometry(self) -> list[list[tuple[int, float, float]]]:
        """Per node: (neighbour, length, direction angle) of each edge leaving it (plain floats: the
        space-time search reads these millions of times)."""
        out: list[list[tuple[int, float, float]]] = []
        for u, vs in enumerate(self.neighbours):
            d = self.xy[vs] - self.xy[u] if vs else np.zeros((0, 2))
            lengths = np.hypot(d[:, 0], d[:, 1]).tolist()
            angles = np.arctan2(d[:, 1], d[:, 0]).tolist()
            out.append(list(zip(vs, lengths, angles, strict=True)))
        return out

    @cached_property
    def arc_angle(self) -> dict[tuple[int, int], float]:
        """(u, v) -> direction angle of the edge from u to v."""
        return {(u, v): a for u, arcs in enumerate(self.arc_geometry) for v, _, a in arcs}

    @cached_property
    def components(self) -> NDArray[np.int32]:
        """Connected-component label of every node."""
        return connected_components(self.matrix, directed=False)[1]

    @cached_property
    def tree(self) -> cKDTree:
        return cKDTree(self.xy)

    def kinds(self) -> list[str]:
        """``end``, ``lane`` or ``junction`` per node (from its number of edges)."""
        degree = np.array([len(a) for a in self.neighbours])
        return ["end" if d <= 1 else "lane" if d == 2 else "junction" for d in degree]

    def turnable(self, reach_m: float) -> NDArray[np.bool_]:
        """Nodes where a robot whose footprint reaches ``reach_m`` from its centre turns in place
        without sweeping into an obstacle."""
        ok = self.clearance_m >= reach_m
        return ok if self.seen_node is None else ok & self.seen_node

    @cached_property
    def _turn_graphs(self) -> dict[tuple[float, float], TurnGraph]:
        return {}

    @cached_property
    def _reversing_clear(self) -> dict[Shape, list[bool]]:
        return {}

    def floor_clearance_at(self, xy: tuple[float, float]) -> float:
        """Distance from ``xy`` to the nearest obstacle of the floor (0 off it or without a grid)."""
        if self.grid is None or self.floor_clearance_m is None:
            return 0.0
        cell = self.grid.to_cell(xy)
        return float(self.floor_clearance_m[cell]) if self.grid.inside(cell) else 0.0

    def capsules_clear(
        self, p: NDArray[np.float64], q: NDArray[np.float64], radius_m: float
    ) -> NDArray[np.bool_]:
        """Whether each segment p[i]q[i] grown by ``radius_m`` keeps off every obstacle of the
        floor (sampled every half cell; True everywhere without a grid). Edges keep the lane's
        width clear; a robot's length past a node (its tail reversing) is checked here."""
        field = self.floor_clearance_m
        if self.grid is None or field is None or not len(p):
            return np.ones(len(p), dtype=bool)
        rows, cols = _samples(self.grid, p, q)
        inside = (rows >= 0) & (rows < field.shape[0]) & (cols >= 0) & (cols < field.shape[1])
        clear = np.where(
            inside, field[rows.clip(0, field.shape[0] - 1), cols.clip(0, field.shape[1] - 1)], 0.0
        )
        return np.asarray((clear >= radius_m - 0.5 * self.grid.resolution_m).all(axis=1))

    def pivot_clear(self, xy: NDArray[np.float64], shape: Shape, from_rad: float, to_rad: float) -> bool:
        """Whether a robot of ``shape`` (its real rectangle, without the tracking allowance) standing
        at ``xy`` turns on the spot from ``from_rad`` to ``to_rad`` (the shorter way) without its
        outline crossing an obstacle of the floor (sampled every 0.05 rad; True without a grid)."""
        if self.grid is None:
            return True
        turn = float(wrap_angle(to_rad - from_rad))
        yaws = from_rad + np.linspace(0.0, turn, max(2, int(np.ceil(abs(turn) / 0.05)) + 1))
        half = shape.half_width_m - shape.tolerance_m
        corners = np.array(
            [[shape.back_m, -half], [shape.front_m, -half], [shape.front_m, half], [shape.back_m, half]]
        )
        c, s_ = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
        x = xy[0] + c * corners[None, :, 0] - s_ * corners[None, :, 1]  # (yaws, 4)
        y = xy[1] + s_ * corners[None, :, 0] + c * corners[None, :, 1]
        pts = np.stack([x, y], axis=-1)
        p, q = pts.reshape(-1, 2), np.roll(pts, -1, axis=1).reshape(-1, 2)  # the outline's sides
        return bool(self.capsules_clear(p, q, self.grid.resolution_m).all())

    def reversing_clear(self, shape: Shape) -> list[bool]:
        """Per arc: whether a robot of ``shape`` reversing along it keeps its tail, which leads,
        off the floor's obstacles (built once per shape)."""
        if shape not in self._reversing_clear:
            a, b = self.xy[self.arcs[:, 0]], self.xy[self.arcs[:, 1]]
            d = b - a
            d = d / np.maximum(np.linalg.norm(d, axis=1), 1e-9)[:, None]
            back = shape.reversed()
            ok = self.capsules_clear(a + back.back_m * d, b + back.front_m * d, shape.half_width_m)
            self._reversing_clear[shape] = ok.tolist()
        return self._reversing_clear[shape]

    def turns(self, reach_m: float, tolerance_rad: float) -> TurnGraph:
        """The forward-only moves of a robot of reach ``reach_m`` (built once per reach)."""
        key = (round(reach_m, 6), round(tolerance_rad, 6))
        if key not in self._turn_graphs:
            arcs = self.arcs
            d = self.xy[arcs[:, 1]] - self.xy[arcs[:, 0]]
            lengths = np.hypot(d[:, 0], d[:, 1])
            lengths = np.where(self.arc_ok, lengths, np.inf)  # arcs too narrow for these robots
            self._turn_graphs[key] = TurnGraph(
                arcs,
                lengths if self.arc_bias is None else lengths * self.arc_bias,
                np.arctan2(d[:, 1], d[:, 0]),
                self.turnable(reach_m),
                tolerance_rad,
                self.size,
            )
        return self._turn_graphs[key]

    def nearest(self, xy: tuple[float, float], *, within_m: float) -> int | None:
        """The node nearest to ``xy`` (of those this graph's robots may stand on) if one lies
        within ``within_m``, else None."""
        near = self._near(xy, within_m)
        return near[0] if near else None

    def _near(self, xy: tuple[float, float], within_m: float) -> list[int]:
        """The usable nodes within ``within_m`` of ``xy``, nearest first."""
        here = np.asarray(xy, dtype=float)
        near = [n for n in self.tree.query_ball_point(here, within_m) if self.usable[n]]
        return sorted(near, key=lambda n: (float(np.hypot(*(self.xy[n] - here))), n))

    def start_node(self, xy: tuple[float, float], heading_rad: float, *, within_m: float) -> int | None:
        """The node a robot at ``xy`` facing ``heading_rad`` starts from: the nearest within
        ``within_m``, unless no edge leaves it ahead of that heading (a stub beside the lane the robot
        drives): then the nearest node ahead of the robot that has one. None if no node is near."""
        here = np.asarray(xy, dtype=float)
        near = self._near(xy, within_m)
        if not near:
            return None
        ahead = np.array([np.cos(heading_rad), np.sin(heading_rad)])

        def way_on(n: int) -> bool:
            return any(float((self.xy[v] - self.xy[n]) @ ahead) > 0.0 for v in self.neighbours[n])

        if way_on(near[0]):
            return int(near[0])
        for n in near[1:]:
            if float((self.xy[n] - here) @ ahead) >= 0.0 and way_on(n):
                return int(n)
        return int(near[0])


def build_route_graph(
    grid: OccupancyGrid,
    *,
    radius_m: float,
    spacing_m: float,
    reach_m: float | None = None,
    seen: NDArray[np.bool_] | None = None,
    unseen_cost: float = 0.0,
) -> RouteGraph:
    """The route graph of ``grid`` for robots of radius ``radius_m`` (centre at least that far from
    obstacles); ``reach_m`` caps the clearance a node seeks (default: radius + half a block);
    ``seen`` (HEADINGS, rows, cols): the floor the cameras see per heading (None: all of it), an
    arc's unseen share weighted by ``unseen_cost`` in the route guide."""
    clearance = grid.clearance_m().astype(np.float64)
    res = grid.resolution_m
    b = max(1, round(spacing_m / res))
    rows, cols = clearance.shape
    br, bc = -(-rows // b), -(-cols // b)
    padded = np.zeros((br * b, bc * b))
    padded[:rows, :cols] = clearance
    cap = (reach_m if reach_m is not None else radius_m) + 0.5 * spacing_m
    # score: clearance up to the cap, then closeness to the block centre (a tiny tie-breaker)
    offs = (np.arange(b) - (b - 1) / 2.0) ** 2
    centre_pen = 1e-4 * (offs[:, None] + offs[None, :]) * res
    score = np.minimum(padded, cap).reshape(br, b, bc, b).transpose(0, 2, 1, 3) - centre_pen
    free = (padded >= radius_m).reshape(br, b, bc, b).transpose(0, 2, 1, 3)
    score = np.where(free, score, -np.inf).reshape(br, bc, b * b)
    best = score.argmax(axis=2)
    has = np.isfinite(np.take_along_axis(score, best[..., None], axis=2)[..., 0])
    block_r, block_c = np.nonzero(has)
    cell_r = block_r * b + best[block_r, block_c] // b
    cell_c = block_c * b + best[block_r, block_c] % b
    xy = grid.to_xy(np.stack([cell_r, cell_c], axis=1))
    index = -np.ones((br, bc), dtype=np.int64)
    index[block_r, block_c] = np.arange(len(block_r))
    edges, edge_clearance = _free_edges(index, xy, clearance, radius_m, grid)
    bias, seen_node, unseen = None, None, None
    if seen is not None and len(edges):
        unseen = _unseen_share(grid, xy, edges, seen)
        if unseen_cost > 0:
            bias = 1.0 + unseen_cost * unseen
            seen_node = np.asarray(seen[:, cell_r, cell_c].all(axis=0))
    return RouteGraph(
        xy,
        clearance[cell_r, cell_c],
        edges,
        radius_m,
        bias,
        seen_node,
        grid,
        clearance,
        unseen,
        edge_clearance,
    )


def _unseen_share(
    grid: OccupancyGrid, xy: NDArray[np.float64], edges: NDArray[np.int64], seen: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """Per arc (every edge, then every edge reversed: ``RouteGraph.arcs``): the share of its samples
    (every half cell) where no camera sees a robot driving it that way."""
    p, q = xy[edges[:, 0]], xy[edges[:, 1]]
    rows, cols = _samples(grid, p, q)
    bins = seen.shape[0]
    d = q - p
    k = np.round(np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi / bins)).astype(np.int64) % bins
    inside = (rows >= 0) & (cols >= 0) & (rows < grid.shape[0]) & (cols < grid.shape[1])
    r, c = rows.clip(0, grid.shape[0] - 1), cols.clip(0, grid.shape[1] - 1)
    out = []
    for way in (k, (k + bins // 2) % bins):
        unseen = ~seen[way[:, None], r, c] | ~inside
        out.append(unseen.mean(axis=1))
    return np.concatenate(out)


def _samples(
    grid: OccupancyGrid, p: NDArray[np.float64], q: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Grid rows and columns of points every half cell along each segment p -> q (same count each)."""
    n = max(2, int(np.ceil(np.linalg.norm(q - p, axis=1).max() / (0.5 * grid.resolution_m))) + 1)
    t = np.linspace(0.0, 1.0, n)[None, :, None]
    pts = p[:, None, :] + t * (q - p)[:, None, :]
    rows = np.floor((pts[..., 1] - grid.origin_xy_m[1]) / grid.resolution_m).astype(np.int64)
    cols = np.floor((pts[..., 0] - grid.origin_xy_m[0]) / grid.resolution_m).astype(np.int64)
    return rows, cols


def _free_edges(
    index: NDArray[np.int64],
    xy: NDArray[np.float64],
    clearance: NDArray[np.float64],
    radius_m: float,
    grid: OccupancyGrid,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Pairs of nodes in neighbouring blocks whose straight segment keeps ``radius_m`` clear (every
    cell it crosses), with the least clearance along each."""
    pairs = []
    br, bc = index.shape
    for dr, dc in _NEIGHBOURS:
        r0, r1, c0, c1 = max(0, -dr), br - max(0, dr), max(0, -dc), bc - max(0, dc)
        a = index[r0:r1, c0:c1]
        b = index[r0 + dr : r1 + dr, c0 + dc : c1 + dc]
        ok = (a >= 0) & (b >= 0)
        pairs.append(np.stack([a[ok], b[ok]], axis=1))
    cand = np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    if not len(cand):
        return cand, np.zeros(0)
    rows, cols = _samples(grid, xy[cand[:, 0]], xy[cand[:, 1]])
    inside = (rows >= 0) & (cols >= 0) & (rows < clearance.shape[0]) & (cols < clearance.shape[1])
    least = np.where(
        inside, clearance[rows.clip(0, clearance.shape[0] - 1), cols.clip(0, clearance.shape[1] - 1)], 0.0
    ).min(axis=1)
    ok = least >= radius_m
    out, least = np.sort(cand[ok], axis=1), least[ok]
    order = np.lexsort((out[:, 1], out[:, 0]))
    return out[order], least[order]
