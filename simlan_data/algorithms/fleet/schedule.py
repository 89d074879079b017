"""Prioritized planning in space and time over the route graph, with a reservation table.

Time is cut into steps of ``step_s`` (one block of the graph at the fleet's speed); an edge takes
``ceil(length / spacing)`` steps. Robots are planned one after the other in priority order; each
one's plan is a space-time A* (states: node, step, heading) against the reservation table of the
robots planned before it, and is then written into the table. A robot occupies, during a step,
the segment it drives (or the node it waits on) grown by its swept circle (its footprint's
circumradius), so two reserved robots are never closer than their two circles plus the safety
distance: one robot at a time in an intersection and no head-on entries into a single lane follow
from that geometry, whatever the layout.

A robot turns more than ``turn_tolerance_rad`` only at a node whose clearance covers its swept
circle. A robot whose planning fails moves to the front of the order and everyone is planned again
(priority inheritance, at most once per robot). A target already held by a robot planned earlier
(a dock) queues the robot at the nearest free node outside it. A robot still failing stays where
it is as an obstacle and is reported (``unreachable`` when its goal lies outside the graph's
component, ``blocked`` otherwise).
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.fleet.graph import RouteGraph

NO_HEADING = 8


@dataclass(frozen=True)
class Request:
    """What one robot asks of the fleet plan."""

    name: str
    start: int  # node
    goal: int | None  # node; None: the goal is off the graph
    radius_m: float  # swept circle (footprint circumradius)
    heading_rad: float | None = None  # None: may leave the start in any direction


@dataclass(frozen=True)
class Obstacle:
    """Something that does not take part in the plan (stopped, unlocalized, a person)."""

    xy: tuple[float, float]
    radius_m: float


@dataclass
class RobotPlan:
    """One robot's timed route: node per step from step 0 (its start) to the end of its plan."""

    name: str
    nodes: list[int]
    target: int  # where it ends: its goal, or a queue node outside a held goal
    queued: bool = False  # waits outside its goal (held by a robot planned before it)
    complete: bool = True  # reaches the target within the horizon


@dataclass
class FleetPlan:
    plans: dict[str, RobotPlan] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)  # name -> unreachable | blocked
    order: list[str] = field(default_factory=list)  # the priority order that was used


class Reservations:
    """Per step, the circles robots planned so far occupy: sample points and radii."""

    def __init__(self, horizon: int) -> None:
        self.horizon = horizon
        self.points: list[list[NDArray[np.float64]]] = [[] for _ in range(horizon + 1)]
        self.radii: list[list[NDArray[np.float64]]] = [[] for _ in range(horizon + 1)]

    def add_static(self, xy: tuple[float, float], radius_m: float) -> None:
        for k in range(self.horizon + 1):
            self.points[k].append(np.asarray([xy], dtype=float))
            self.radii[k].append(np.asarray([radius_m]))

    def add_plan(self, graph: RouteGraph, nodes: list[int], radius_m: float) -> None:
        """Reserve the swept segment of every step; after its plan the robot stays at its end."""
        xy = graph.xy[np.asarray(nodes + [nodes[-1]] * (self.horizon + 2 - len(nodes)))]
        for k in range(self.horizon + 1):
            a, b = xy[k], xy[k + 1]
            grow = 0.25 * float(np.linalg.norm(b - a))  # any point of a->b within len/4 of a sample
            self.points[k].append(np.stack([a, 0.5 * (a + b), b]))
            self.radii[k].append(np.full(3, radius_m + grow))

    def blocked(self, graph: RouteGraph, radius_m: float, margin_m: float) -> NDArray[np.bool_]:
        """(horizon + 1, N): the nodes a robot of ``radius_m`` may not occupy at each step."""
        out = np.zeros((self.horizon + 1, graph.size), dtype=bool)
        for k in range(self.horizon + 1):
            if not self.points[k]:
                continue
            pts, rad = np.concatenate(self.points[k]), np.concatenate(self.radii[k])
            for hits in graph.tree.query_ball_point(pts, rad + radius_m + margin_m):
                out[k, hits] = True
        return out


@dataclass(frozen=True)
class Timing:
    """How the plan's clock relates to the graph."""

    spacing_m: float
    horizon: int  # steps
    safety_m: float  # extra distance kept between two robots' circles
    turn_tolerance_rad: float = np.pi / 3
    moves: list[list[tuple[int, int, int]]] | None = field(default=None, compare=False)

    def steps(self, length_m: float) -> int:
        return max(1, int(np.ceil(length_m / self.spacing_m - 1e-6)))

    def margin(self, graph: RouteGraph) -> float:
        """Safety distance plus half the longest edge (a robot anywhere on its own edge)."""
        return self.safety_m + 0.5 * float(graph.lengths_m.max(initial=0.0))


def plan_fleet(
    graph: RouteGraph, requests: list[Request], obstacles: list[Obstacle], timing: Timing
) -> FleetPlan:
    """Plan every request in order (earlier = higher priority), with inheritance on failure."""
    if timing.moves is None:
        timing = replace(timing, moves=_moves(graph, timing))
    order = [r.name for r in requests]
    by_name = {r.name: r for r in requests}
    promoted: set[str] = set()
    standing: set[str] = set()  # failed even when first: stands still, for everyone
    while True:
        result = _plan_in_order(graph, [by_name[n] for n in order], obstacles, timing, standing)
        failed = [n for n in order if n in result.failures and n not in standing]
        if not failed:
            result.order = order
            return result
        first = failed[0]
        if first in promoted:  # no plan even first: the others must plan around where it stands
            standing.add(first)
            continue
        promoted.add(first)  # priority inheritance: it goes first, everyone is planned again
        order = [first] + [n for n in order if n != first]


def _plan_in_order(
    graph: RouteGraph,
    requests: list[Request],
    obstacles: list[Obstacle],
    timing: Timing,
    standing: set[str],
) -> FleetPlan:
    table = Reservations(timing.horizon)
    for o in obstacles:
        table.add_static(o.xy, o.radius_m)
    out = FleetPlan()
    pending = []
    for r in requests:  # robots that cannot be planned stand where they are, for everyone
        if r.goal is None or graph.components[r.goal] != graph.components[r.start]:
            out.failures[r.name] = "unreachable"
            table.add_plan(graph, [r.start], r.radius_m)
        elif r.name in standing:
            out.failures[r.name] = "blocked"
            out.plans[r.name] = RobotPlan(r.name, [r.start], r.start, complete=False)
            table.add_plan(graph, [r.start], r.radius_m)
        else:
            pending.append(r)
    for r in pending:
        plan = _plan_one(graph, r, table, timing)
        if plan is None:
            out.failures[r.name] = "blocked"
            plan = RobotPlan(r.name, [r.start], r.start, complete=False)
        out.plans[r.name] = plan
        table.add_plan(graph, plan.nodes, r.radius_m)
    return out


def _plan_one(graph: RouteGraph, r: Request, table: Reservations, timing: Timing) -> RobotPlan | None:
    """Space-time A* to the goal, or to a queue node outside it when the goal is held."""
    assert r.goal is not None
    blocked = table.blocked(graph, r.radius_m, timing.margin(graph))
    blocked[0, r.start] = False  # where it stands now is its own
    last = np.where(blocked.any(axis=0), blocked.shape[0] - 1 - np.argmax(blocked[::-1], axis=0), -1)
    dist = graph.distances_to(r.goal)
    if last[r.goal] < timing.horizon:  # the goal frees within the horizon: go there
        nodes = _search(graph, r, r.goal, blocked, last, dist, timing)
        if nodes is not None:
            return RobotPlan(r.name, nodes, r.goal, complete=nodes[-1] == r.goal)
    # held to the end of the horizon (a dock in use): the nearest node that stays free from the
    # second half of the horizon on, well outside the goal's conflict zone
    free_late = last < timing.horizon // 2
    # twice the conflict distance: the one served can leave past the queue
    apart = np.linalg.norm(graph.xy - graph.xy[r.goal], axis=1) > 2 * (2 * r.radius_m + timing.margin(graph))
    candidates = np.flatnonzero(free_late & apart & np.isfinite(dist))
    for node in candidates[np.argsort(dist[candidates], kind="stable")][:12]:
        wait_dist = graph.distances_to(int(node))
        nodes = _search(graph, r, int(node), blocked, last, wait_dist, timing)
        if nodes is not None and nodes[-1] == node:
            return RobotPlan(r.name, nodes, int(node), queued=True)
    return None


def _moves(graph: RouteGraph, timing: Timing) -> list[list[tuple[int, int, int]]]:
    """Per node: (neighbour, steps to drive there, heading index 0..7) of every edge."""
    d = graph.xy[graph.edges[:, 1]] - graph.xy[graph.edges[:, 0]]
    heading = np.round(np.arctan2(d[:, 1], d[:, 0]) / (np.pi / 4)).astype(int) % 8
    steps = [timing.steps(length) for length in graph.lengths_m.tolist()]
    out: list[list[tuple[int, int, int]]] = [[] for _ in range(graph.size)]
    for (u, v), n, h in zip(graph.edges.tolist(), steps, heading.tolist()):
        out[u].append((v, n, h))
        out[v].append((u, n, (h + 4) % 8))
    return [sorted(m) for m in out]


def _search(
    graph: RouteGraph,
    r: Request,
    target: int,
    blocked: NDArray[np.bool_],
    last: NDArray[np.int64],
    dist: NDArray[np.float64],
    timing: Timing,
) -> list[int] | None:
    """Earliest arrival at ``target`` that it can then hold; else the plan that ends nearest to it
    at the horizon (a windowed plan); None if it cannot even keep clear until the horizon."""
    horizon = timing.horizon
    if not np.isfinite(dist[r.start]):
        return None
    h = (dist / timing.spacing_m).tolist()
    turnable = graph.turnable(r.radius_m).tolist()
    busy = blocked.tolist()  # list indexing is several times faster than numpy's in this loop
    moves = _moves(graph, timing) if timing.moves is None else timing.moves
    max_turn = int(np.floor(timing.turn_tolerance_rad / (np.pi / 4) + 1e-9))
    start_heading = NO_HEADING if r.heading_rad is None else int(np.round(r.heading_rad / (np.pi / 4))) % 8
    last_target = int(last[target])
    start = (r.start, 0, start_heading)
    parent: dict[tuple[int, int, int], tuple[int, int, int] | None] = {start: None}
    heap = [(h[r.start], 0, r.start, start_heading)]
    best_end: tuple[float, tuple[int, int, int]] | None = None
    while heap:
        _, k, u, heading = heapq.heappop(heap)
        state = (u, k, heading)
        if u == target and k > last_target:
            return _unwind(parent, state)
        if k >= horizon:
            if best_end is None or h[u] < best_end[0]:
                best_end = (h[u], state)
            continue
        for v, steps, d in [(u, 1, heading), *moves[u]]:
            if v != u and heading != NO_HEADING and not turnable[u]:
                turn = min((d - heading) % 8, (heading - d) % 8)
                if turn > max_turn:
                    continue  # its footprint would sweep into an obstacle turning here
            k2 = min(k + steps, horizon)
            if any(busy[j][u] or busy[j][v] for j in range(k + 1, k2 + 1)):
                continue
            nxt = (v, k2, d)
            if nxt in parent:
                continue
            parent[nxt] = state
            heapq.heappush(heap, (k2 + h[v], k2, v, d))
    return _unwind(parent, best_end[1]) if best_end is not None else None


def _unwind(parent: dict, state: tuple[int, int, int]) -> list[int]:
    """Node per step from the start to ``state`` (edges of several steps repeat their start)."""
    chain = []
    s: tuple[int, int, int] | None = state
    while s is not None:
        chain.append(s)
        s = parent[s]
    chain.reverse()
    nodes = [chain[0][0]]
    for (_, k0, _), (v, k1, _) in itertools.pairwise(chain):
        nodes.extend([nodes[-1]] * (k1 - k0 - 1) + [v])
    return nodes
