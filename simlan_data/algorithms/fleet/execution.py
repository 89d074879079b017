"""Executing a fleet plan on robots that run late: an action dependency graph (ADG).

A plan says where each robot is at each step; real robots are early, late or stopped. Following
Hönig et al. (2019, "Persistent and robust execution of MAPF schedules in warehouses"), the plan
is turned into an order of events instead of times: robot i may take the m-th vertex of its route
(the region it holds for it, ``schedule.py``) only when every robot j has given up each
conflicting region that j's plan holds earlier (by arriving at its next vertex). The order is a total order on (planned step, priority), so the
wait-for graph can have no cycle while every robot moves: the robot with the earliest pending
event is never waiting. A robot that does not move although allowed (stopped by safety, a
collision, a fault) breaks that; the coordinator then replans with it as an obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.fleet.footprint import Region, conflict
from simlan_data.algorithms.fleet.graph import RouteGraph
from simlan_data.algorithms.fleet.schedule import FleetPlan, RobotPlan


@dataclass
class Route:
    """A robot's plan without its waits: the vertices it passes, when, and what it holds for each."""

    name: str
    nodes: list[int]
    steps: list[int]  # arrival step per vertex
    departs: list[float]  # step it leaves each vertex for the next (inf: it stays)
    occs: list[Region]  # per vertex: held from leaving the vertex before until arriving at the next
    loose: list[bool]  # per vertex: where it stood at planning or its way off it (no safety distance)
    rank: int  # its place in the priority order the plan used
    progress: int = 0  # the last vertex it has reached
    deps: list[list[tuple[str, int]]] | None = None  # per vertex: (robot, vertex) it must wait for
    backs: list[bool] = field(default_factory=list)  # per vertex: it drives there reversing
    turns: list[bool] = field(default_factory=list)  # per vertex: it turns on the spot there

    @classmethod
    def from_plan(cls, plan: RobotPlan, rank: int) -> Route:
        vs = plan.vertices
        return cls(
            plan.name,
            [v.node for v in vs],
            [v.arrive for v in vs],
            [float(v.depart) if v.depart is not None else np.inf for v in vs],
            [v.occ for v in vs],
            [v.loose for v in vs],
            rank,
            backs=[v.back for v in vs],
            turns=[v.turn for v in vs],
        )

    def acquire(self, m: int) -> float:
        """When the plan has it take vertex ``m`` (leaving the vertex before)."""
        return -np.inf if m == 0 else self.departs[m - 1]

    def release(self, m: int) -> float:
        """When the plan has it give vertex ``m`` up (arriving at the vertex after)."""
        return float(self.steps[m + 1]) if m + 1 < len(self.steps) else np.inf


def _bounds(occs: list[Region]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A circle around each region (centre, radius): a cheap test before the exact one."""
    centres = np.array([0.5 * (o[0].mean(axis=0) + o[1].mean(axis=0)) for o in occs])
    radii = np.array(
        [
            max(np.linalg.norm(o[0] - c, axis=1).max(), np.linalg.norm(o[1] - c, axis=1).max()) + o[2].max()
            for o, c in zip(occs, centres)
        ]
    )
    return centres, radii


def build_routes(plan: FleetPlan, margin_m: float) -> dict[str, Route]:
    """The routes of ``plan`` with their dependencies (the ADG's edges between robots): robot a
    takes vertex m only after every robot b that holds a conflicting region earlier in the plan
    has given it up."""
    rank = {n: i for i, n in enumerate(plan.order)}
    routes = {n: Route.from_plan(p, rank.get(n, len(rank))) for n, p in plan.plans.items()}
    for r in routes.values():
        r.deps = [[] for _ in r.nodes]
    bounds = {n: _bounds(r.occs) for n, r in routes.items()}
    names = sorted(routes, key=lambda n: routes[n].rank)
    for a in names:
        ra, (ca, rad_a) = routes[a], bounds[a]
        for b in names:
            if a == b:
                continue
            rb, (cb, rad_b) = routes[b], bounds[b]
            near = (
                np.linalg.norm(ca[:, None] - cb[None, :], axis=2) < rad_a[:, None] + rad_b[None, :] + margin_m
            )
            for m, m2 in zip(*np.nonzero(near)):
                margin = 0.0 if ra.loose[m] or rb.loose[m2] else margin_m  # as the plan kept them apart
                if m == 0 or not conflict(ra.occs[m], rb.occs[m2], margin):
                    continue  # it stands on its first vertex already
                if _before(rb, int(m2), ra, int(m)):
                    ra.deps[m].append((b, int(m2)))  # type: ignore[index]
    return routes


def _before(rb: Route, m2: int, ra: Route, m: int) -> bool:
    """Whether b's vertex m2 comes before a's vertex m (the plan keeps them apart in time; where
    it does not, as around robots standing, by (take time, rank))."""
    if rb.release(m2) <= ra.acquire(m):
        return True
    if ra.release(m) <= rb.acquire(m2):
        return False
    return (rb.acquire(m2), rb.rank) < (ra.acquire(m), ra.rank)


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
        along = float(np.dot(xy - a, seg) / length) if length > 1e-9 else -np.inf
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
