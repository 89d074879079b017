"""Executing a fleet plan on robots that run late: an action dependency graph (ADG).

A plan says where each robot is at each step; real robots are early, late or stopped. Following
Hönig et al. (2019, "Persistent and robust execution of MAPF schedules in warehouses"), the plan
is turned into an order of events instead of times: robot i may enter the m-th vertex of its route
only when every robot j has left each vertex that conflicts with it and that j's plan visits
earlier (ties by priority). The order is a total order on (planned step, priority), so the
wait-for graph can have no cycle while every robot moves: the robot with the earliest pending
event is never waiting. A robot that does not move although allowed (stopped by safety, a
collision, a fault) breaks that; the coordinator then replans with it as an obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.fleet.graph import RouteGraph
from simlan_data.algorithms.fleet.schedule import FleetPlan


@dataclass
class Route:
    """A robot's plan without its waits: the vertices it passes and the step it reaches each."""

    name: str
    nodes: list[int]
    steps: list[int]
    rank: int  # its place in the priority order the plan used
    radius_m: float
    progress: int = 0  # the last vertex it has reached
    deps: list[list[tuple[str, int]]] | None = None  # per vertex: (robot, vertex) it must wait for

    @classmethod
    def from_nodes(cls, name: str, nodes: list[int], rank: int, radius_m: float) -> Route:
        keep = [0] + [k for k in range(1, len(nodes)) if nodes[k] != nodes[k - 1]]
        return cls(name, [nodes[k] for k in keep], keep, rank, radius_m)


def build_routes(
    graph: RouteGraph, plan: FleetPlan, radii: dict[str, float], margin_m: float
) -> dict[str, Route]:
    """The routes of ``plan`` with their dependencies (the ADG's edges between robots)."""
    rank = {n: i for i, n in enumerate(plan.order)}
    routes = {
        n: Route.from_nodes(n, p.nodes, rank.get(n, len(rank)), radii[n]) for n, p in plan.plans.items()
    }
    for r in routes.values():
        r.deps = [[] for _ in r.nodes]
    names = sorted(routes, key=lambda n: routes[n].rank)
    for a in names:
        ra = routes[a]
        xa = graph.xy[ra.nodes]
        for b in names:
            if a == b:
                continue
            rb = routes[b]
            xb = graph.xy[rb.nodes]
            near = (
                np.linalg.norm(xa[:, None, :] - xb[None, :, :], axis=2) < ra.radius_m + rb.radius_m + margin_m
            )
            ta, tb = np.asarray(ra.steps)[:, None], np.asarray(rb.steps)[None, :]
            before = (tb < ta) | ((tb == ta) & (rb.rank < ra.rank))
            for m, m2 in zip(*np.nonzero(near & before)):
                if m > 0:  # it stands on its first vertex already
                    ra.deps[m].append((b, int(m2)))  # type: ignore[index]
    return routes


def allowed(routes: dict[str, Route], name: str, vertex: int) -> list[str]:
    """The robots ``name`` still waits for before entering its route's ``vertex`` (empty: go)."""
    r = routes[name]
    assert r.deps is not None
    return sorted({b for b, m2 in r.deps[vertex] if b in routes and routes[b].progress <= m2})


def frontier(routes: dict[str, Route], name: str) -> tuple[int, list[str]]:
    """The furthest vertex ``name`` may drive to now, and who holds the next one."""
    r = routes[name]
    m = r.progress
    while m + 1 < len(r.nodes):
        waits = allowed(routes, name, m + 1)
        if waits:
            return m, waits
        m += 1
    return m, []


def advance(route: Route, xy: NDArray[np.float64], graph: RouteGraph, limit: int, reach_m: float) -> None:
    """Move ``route.progress`` up to ``limit`` past every vertex the robot at ``xy`` has reached
    (within ``reach_m``, or passed: its projection on the route lies beyond it)."""
    while route.progress < limit:
        a, b = graph.xy[route.nodes[route.progress]], graph.xy[route.nodes[route.progress + 1]]
        seg = b - a
        length = float(np.linalg.norm(seg))
        along = float(np.dot(xy - a, seg) / length) if length > 1e-9 else length
        if np.linalg.norm(xy - b) <= reach_m or along >= length - reach_m:
            route.progress += 1
        else:
            return


def wait_cycles(waits: dict[str, list[str]]) -> list[list[str]]:
    """Cycles of the wait-for graph (robot -> the robots it waits for), each once, sorted."""
    cycles: list[list[str]] = []
    done: set[str] = set()
    for start in sorted(waits):
        path, seen = [start], {start: 0}
        node = start
        while True:
            nxt = sorted(waits.get(node, []))
            if not nxt or node in done:
                break
            node = nxt[0]
            if node in seen:
                cyc = path[seen[node] :]
                key = tuple(sorted(cyc))
                if key not in {tuple(sorted(c)) for c in cycles}:
                    cycles.append(cyc)
                break
            seen[node] = len(path)
            path.append(node)
        done.update(path)
    return cycles
