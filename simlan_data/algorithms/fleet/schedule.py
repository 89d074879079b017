"""Prioritized planning in space and time over the route graph, with a reservation table.

Time is cut into steps of ``step_s`` (one block of the graph at the fleet's speed); an edge takes
``ceil(length / spacing)`` steps. Robots are planned one after the other in priority order; each
one's plan is a space-time search (safe intervals, ``search.py``) against the reservation table of
the robots planned before it, and is then written into the table.

What a robot occupies is its footprint's region (``footprint.py``): driving a straight edge, the
capsule from its tail at the edge's start to its nose at the edge's end; turning in place, the
circle of its reach. Along a route, a robot *holds* each vertex's region from the moment it leaves
the vertex before until it arrives at the vertex after (so at any time it holds the edge it drives
and the one it came by). The search checks exactly what the robot will hold, instant by instant,
against what the others hold; the executor (``execution.py``) then orders the robots on the same
regions, so plan and execution agree and the order has no cycle. Two robots side by side keep
their half widths plus the safety distance apart; one robot at a time in an intersection and no
head-on entry into a single lane follow from the geometry, whatever the layout.

A robot turns by more than ``turn_tolerance_rad`` only at a vertex where it is planned to turn in
place, and only where the clearance covers its reach (its tail does not sweep into a shelf); it
may drive an arc backwards (``Timing.reverse_ratio``). A robot
whose planning fails moves to the front of the order and everyone is planned again (priority
inheritance, at most once per robot). A goal held by a robot planned earlier (a dock) queues the
robot at the nearest free node outside it. Where that is not enough (two robots nose to nose in a
lane neither can turn in: whoever goes first, the other cannot get out of its way in time), a robot
that stands on another's way to its goal is sent first to a *shelter*, the nearest node where it
stands clear of that way, and the other is planned after it (once per pair, so planning ends; the
sheltered robot's plan is incomplete, so it is planned to its own goal again at a later replan). A
robot still failing stands where it is as an obstacle and is reported (``unreachable`` when its
goal lies outside the graph's component, ``blocked`` otherwise).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra

from simlan_data.algorithms.fleet import footprint as fp
from simlan_data.algorithms.fleet.conflicts import ConflictCache
from simlan_data.algorithms.fleet.footprint import Region
from simlan_data.algorithms.fleet.graph import RouteGraph
from simlan_data.algorithms.fleet.plans import (
    FleetPlan,
    Obstacle,
    Request,
    RobotPlan,
    Timing,
    Vertex,
    start_region,
)
from simlan_data.algorithms.fleet.search import PENALTY_M, QUEUE_EXPANSIONS, Search
from simlan_data.algorithms.fleet.turns import ToGoal

__all__ = ["FleetPlan", "Obstacle", "Request", "Reservations", "RobotPlan", "Timing", "Vertex", "plan_fleet"]


class Reservations:
    """Per step, the regions the robots planned so far hold."""

    def __init__(self, graph: RouteGraph, horizon: int, safety_m: float) -> None:
        self.graph, self.horizon, self.safety_m = graph, horizon, safety_m
        self.parts: list[list[Region]] = [[] for _ in range(horizon + 1)]
        # what stays where it is after the horizon too: obstacles, robots standing, robots at their
        # goal (not the ends of windowed plans: those robots drive on in their next window). Robots
        # at their goal stay in: without them (b40de1c) 8-robot missions planned over twice as long
        # and a held-out case reached fewer goals (docs/fleet.md, Measured)
        self.staying: list[Region] = []
        self._merged: dict[int, Region] = {}
        # robots not planned yet: where they stand, and until which step (the time they need to
        # get out of the way; after it, a robot planned earlier may take the place and the later one
        # must leave in time, or fail and go first)
        self.waiting: dict[str, tuple[Region, int, bool]] = {}  # region, until, idle
        self.free_way: dict[str, Region] = {}  # robot -> its way to its goal were nobody else there
        self.conflicts = ConflictCache(self)

    def set_waiting(self, waiting: dict[str, tuple[Region, int, bool]]) -> None:
        self.waiting = waiting
        self._merged.clear()

    def add(self, step: int, region: Region) -> None:
        self.parts[step].append(region)
        self._merged.pop(step, None)

    def add_static(self, region: Region) -> None:
        for k in range(self.horizon + 1):
            self.add(k, region)
        self.staying.append(region)

    def add_plan(self, plan: RobotPlan, *, stays: bool) -> None:
        """Reserve what the robot holds at every step; after its plan it stays on its last vertex
        (``stays``: beyond the horizon too)."""
        vs = plan.vertices
        if stays:
            self.staying.append(vs[-1].occ)
        for m, v in enumerate(vs):
            acquire = 0 if m == 0 else (vs[m - 1].depart or 0) + 1
            release = vs[m + 1].arrive if m + 1 < len(vs) else self.horizon
            for k in range(acquire, min(release, self.horizon) + 1):
                self.add(k, v.occ)

    def at(self, step: int) -> Region | None:
        parts = self.parts[step] + [reg for reg, until, _ in self.waiting.values() if step <= until]
        if not parts:
            return None
        if step not in self._merged:
            self._merged[step] = fp.region(*parts)
        return self._merged[step]

    def waiting_nodes(self, radius_m: float) -> NDArray[np.bool_]:
        """Nodes where a disc of ``radius_m`` conflicts with where a robot not planned yet stands."""
        regions = [region for region, _, _ in self.waiting.values()]
        return self._nodes_near(fp.region(*regions) if regions else None, radius_m)

    def blocked_nodes(self, step: int | None, radius_m: float) -> NDArray[np.bool_]:
        """Nodes where a disc of ``radius_m`` conflicts with what is held at ``step`` (None: with
        what stays after the horizon)."""
        staying = fp.region(*self.staying) if step is None and self.staying else None
        return self._nodes_near(staying if step is None else self.at(step), radius_m)

    def _nodes_near(self, held: Region | None, radius_m: float) -> NDArray[np.bool_]:
        """Nodes where a disc of ``radius_m`` conflicts with ``held`` (none when it is None)."""
        if held is None:
            return np.zeros(self.graph.size, dtype=bool)
        xy = self.graph.xy
        d = fp.segment_distances(xy, xy, held[0], held[1])
        return np.asarray((d < radius_m + held[2][None, :] + self.safety_m).any(axis=1), dtype=bool)


def plan_fleet(
    graph: RouteGraph, requests: list[Request], obstacles: list[Obstacle], timing: Timing
) -> FleetPlan:
    """Plan every request in order (earlier = higher priority), with inheritance on failure."""
    order = [r.name for r in requests]
    by_name = {r.name: r for r in requests}
    promoted: set[str] = set()
    standing: set[str] = set()  # failed even when first: stands still, for everyone
    ahead: set[tuple[str, str]] = set()  # (blocker, robot): the blocker was moved before it once
    sheltered: dict[str, int] = {}  # robot -> the shelter it is planned to instead of its goal
    tried: set[tuple[str, str]] = set()  # (robot, blocker) pairs given a shelter once
    while True:
        requests = [by_name[n] for n in order]
        result = _plan_in_order(graph, requests, obstacles, timing, standing, sheltered)
        moved = _blockers_first(order, result.blockers, ahead)
        if moved is not None:
            order = moved  # a robot standing in an earlier one's way is planned (out of it) first
            continue
        failed = [n for n in order if n in result.failures and n not in standing]
        if not failed:
            result.order, result.sheltered = order, dict(sheltered)
            return result
        first = failed[0]
        if first in promoted or by_name[first].idle:  # no plan even first (an idle robot never goes
            # first): a robot on another's way goes to a shelter first; else the others must plan
            # around where it stands
            shelter = _next_shelter(result, tried, sheltered) if timing.shelters else None
            if shelter is not None:
                blocker, node = shelter
                sheltered[blocker] = node
                order = [blocker] + [n for n in order if n != blocker]
                continue
            standing.add(first)
            continue
        promoted.add(first)  # priority inheritance: it goes first, everyone is planned again
        order = [first] + [n for n in order if n != first]


def _blockers_first(
    order: list[str], blockers: dict[str, list[str]], ahead: set[tuple[str, str]]
) -> list[str] | None:
    """The order with the blockers of the first blocked robot moved just before it (each pair at most
    once, so the replanning ends), or None when there is nothing to move."""
    for name in order:
        new = [b for b in blockers.get(name, []) if (b, name) not in ahead]
        if new:
            ahead.update((b, name) for b in new)
            rest = [n for n in order if n not in new]
            at = rest.index(name)
            return rest[:at] + new + rest[at:]
    return None


def _next_shelter(
    result: FleetPlan, tried: set[tuple[str, str]], sheltered: dict[str, int]
) -> tuple[str, int] | None:
    """The first (robot, robot in its way) pair not tried yet whose second has a shelter off the
    first's way: (that robot, shelter node); marks the pair tried."""
    for (name, b), node in result.shelters.items():
        if (name, b) in tried or b in sheltered:
            continue
        tried.add((name, b))
        if node is not None:
            return b, node
    return None


def _standing(r: Request) -> RobotPlan:
    occ = start_region(r, turn=False)
    return RobotPlan(r.name, [Vertex(r.start, 0, None, occ, loose=True)], r.start, complete=False)


def _plan_in_order(
    graph: RouteGraph,
    requests: list[Request],
    obstacles: list[Obstacle],
    timing: Timing,
    standing: set[str],
    sheltered: dict[str, int] | None = None,
) -> FleetPlan:
    sheltered = sheltered or {}
    table = Reservations(graph, timing.horizon, timing.safety_m)
    for o in obstacles:
        table.add_static(o.region())
    out = FleetPlan()
    pending = []
    for r in requests:  # robots that cannot be planned stand where they are, for everyone
        lanes = graph.for_width(r.lane_radius_m)
        if r.goal is None or lanes.components[r.goal] != lanes.components[r.start]:
            out.failures[r.name] = "unreachable"
            table.add_plan(_standing(r), stays=True)
        elif r.name in standing:
            out.failures[r.name] = "blocked"
            out.plans[r.name] = _standing(r)
            table.add_plan(out.plans[r.name], stays=True)
        else:
            pending.append(r)
    # a robot keeps off where the robots after it stand (they may not get away in time: a robot
    # planned earlier does not drive through one that cannot turn or has nowhere to go)
    waiting = {r.name: (start_region(r, turn=False), _clear_steps(r, timing), r.idle) for r in pending}
    by_name = {r.name: r for r in pending}
    for r in pending:
        del waiting[r.name]
        table.set_waiting(dict(waiting))
        shelter = sheltered.get(r.name)
        if shelter is not None:  # it clears another's way first (planned to its own goal later)
            plan = _plan_one(graph, replace(r, goal=shelter, goal_xy=None), table, timing, queue=False)
            if plan is not None:
                plan.complete = False
        else:
            plan = _plan_one(graph, r, table, timing)
        if waiting and shelter is None and (plan is None or not plan.complete):
            out.blockers[r.name] = _blocking(graph, r, table, timing, waiting)
            way = table.free_way.get(r.name)
            for b in out.blockers[r.name] if timing.shelters else []:
                out.shelters[(r.name, b)] = _shelter(graph, by_name[b], table, timing, way)
        if plan is None and shelter is None and timing.shelters:
            # whose plan drives through where it stands (it could not get out of the way in time)
            here = start_region(r, turn=False)
            for e, p in out.plans.items():
                if e not in out.failures and any(
                    fp.conflict(v.occ, here, timing.safety_m) for v in p.vertices[1:]
                ):
                    way = fp.region(*[v.occ for v in p.vertices])
                    out.shelters[(e, r.name)] = _shelter(graph, r, table, timing, way)
        if plan is None:
            out.failures[r.name] = "blocked"
            plan = _standing(r)
        out.plans[r.name] = plan
        table.add_plan(plan, stays=(plan.complete and not plan.queued) or r.name in out.failures)
    return out


def _blocking(
    graph: RouteGraph,
    r: Request,
    table: Reservations,
    timing: Timing,
    waiting: dict[str, tuple[Region, int, bool]],
) -> list[str]:
    """The robots not planned yet whose standing places keep ``r`` from its goal: those its plan
    would cross if they were not there (none when it cannot reach its goal even then). The way
    that plan takes is kept in ``table.free_way[r.name]`` (for shelters)."""
    table.set_waiting({})
    try:  # (one search: the goal, no queue; only a plan that arrives counts)
        free = _plan_one(graph, r, table, timing, queue=False, complete_only=True)
    finally:
        table.set_waiting(waiting)
    if free is None or not free.complete or free.queued:
        return []
    table.free_way[r.name] = fp.region(*[v.occ for v in free.vertices])
    return [
        n
        for n, (standing, _, idle) in waiting.items()
        if not idle
        and any(fp.conflict(v.occ, standing, 0.0 if v.loose else timing.safety_m) for v in free.vertices)
    ]


def _shelter(
    graph: RouteGraph, b: Request, table: Reservations, timing: Timing, way: Region | None
) -> int | None:
    """The node nearest to ``b`` (route length) where ``b``, turned any way, stands clear of
    another robot's ``way`` to its goal and of whatever stays held; None if there is none."""
    if way is None:
        return None
    graph = graph.for_width(b.lane_radius_m)
    xy = graph.xy
    reach = b.shape.reach_m
    d = fp.segment_distances(xy, xy, way[0], way[1])
    clear = ~(d < reach + way[2][None, :] + timing.safety_m).any(axis=1)
    clear &= ~table.blocked_nodes(None, reach)
    clear &= graph.components == graph.components[b.start]
    if graph.seen_node is not None:
        clear &= graph.seen_node  # where the cameras see it at every heading: it is not lost there
    if not clear.any():
        return None
    dist = np.asarray(dijkstra(graph.matrix, directed=False, indices=b.start))
    dist[~clear] = np.inf
    node = int(np.argmin(dist))
    return node if np.isfinite(dist[node]) else None


def _clear_steps(r: Request, timing: Timing) -> int:
    """Steps a robot needs to get off where it stands: a turn and its length plus the safety distance."""
    return 1 + timing.steps(r.shape.front_m - r.shape.back_m + timing.safety_m)


def _plan_one(
    graph: RouteGraph,
    r: Request,
    table: Reservations,
    timing: Timing,
    *,
    queue: bool = True,
    complete_only: bool = False,
) -> RobotPlan | None:
    """A space-time search to the goal, or (``queue``) to a queue node outside it when the goal is held."""
    assert r.goal is not None
    graph = graph.for_width(r.lane_radius_m)  # the edges it is wide enough for
    search = Search(graph, r, table, timing)
    # the search's guide: route lengths that avoid what stays held to the horizon (robots parked,
    # obstacles), so a detour round a lane that stays blocked is found without searching the lane
    staying = table.blocked_nodes(None, r.shape.half_width_m)
    # ... and passes by where the robots not planned yet stand, where it can: a way through them
    # leaves them no room to get out of it (a forklift standing across the corridor and a pallet
    # truck facing it, each planned straight through the other: both blocked for good)
    others = table.waiting_nodes(r.shape.half_width_m) if timing.soft_waiting else None
    goal = r.goal

    def guide(forward: bool) -> ToGoal:
        to = search.to_goal(goal, avoid=staying, forward=forward, soft=others)
        if search.start_h(to) < PENALTY_M / timing.spacing_m:
            return to
        return search.to_goal(goal, forward=forward, soft=others)  # every way passes something that stays

    to = guide(forward=False)
    if not table.blocked_nodes(timing.horizon, r.shape.half_width_m)[r.goal]:  # free at the horizon
        plan = search.run(r.goal, to, tail=r.goal_xy, complete_only=complete_only)
        if plan is not None and not plan.complete and len(plan.vertices) == 1:
            # it would stand still: plain route lengths may point the way it cannot turn to (a lane
            # too narrow to turn in), forward-only ones send it on to where it can
            ahead = search.run(r.goal, guide(forward=True), tail=r.goal_xy)
            plan = ahead if ahead is not None and len(ahead.vertices) > 1 else plan
        if plan is not None:
            return plan
    if not queue:
        return None
    # held to the end of the horizon (a dock in use): the nearest node that stays free from the
    # second half of the horizon on, twice the conflict distance from the goal (the robot served
    # leaves past the queue)
    dist = to.node_array
    apart = np.linalg.norm(graph.xy - graph.xy[r.goal], axis=1) > 2 * (2 * r.shape.reach_m + timing.safety_m)
    candidates = np.flatnonzero(apart & np.isfinite(dist))
    tried = 0
    for node in candidates[np.argsort(dist[candidates], kind="stable")]:
        if tried >= 12:
            break
        if any(search.held_at(int(node), k) for k in range(timing.horizon // 2, timing.horizon + 1)):
            continue
        tried += 1
        plan = search.run(
            int(node),
            search.to_goal(int(node)),
            tail=None,
            budget=QUEUE_EXPANSIONS,
            complete_only=True,
            then=r.goal,
        )
        if plan is not None and plan.vertices[-1].node == node:
            plan.queued = True
            return plan
    return None
