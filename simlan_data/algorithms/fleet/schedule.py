"""Prioritized planning in space and time over the route graph, with a reservation table.

Time is cut into steps of ``step_s`` (one block of the graph at the fleet's speed); an edge takes
``ceil(length / spacing)`` steps. Robots are planned one after the other in priority order; each
one's plan is a space-time A* against the reservation table of the robots planned before it, and
is then written into the table.

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
place, and only where the clearance covers its reach (its tail does not sweep into a shelf). A robot
whose planning fails moves to the front of the order and everyone is planned again (priority
inheritance, at most once per robot). A goal held by a robot planned earlier (a dock) queues the
robot at the nearest free node outside it. A robot still failing stands where it is as an obstacle
and is reported (``unreachable`` when its goal lies outside the graph's component, ``blocked``
otherwise).
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.fleet import footprint as fp
from simlan_data.algorithms.fleet.conflicts import ConflictCache
from simlan_data.algorithms.fleet.footprint import Region, Shape
from simlan_data.algorithms.fleet.graph import RouteGraph
from simlan_data.algorithms.fleet.turns import ToGoal

START = -1  # ``prev`` of the start state: the robot stands at its real pose
FROM_START = -2  # ``prev`` of the first vertex after it: the edge starts at the real pose
PENALTY_M = 1000.0  # the search's guide avoids nodes held to the horizon at this extra cost
MAX_EXPANSIONS = 40_000  # a search that expands more states than this gives up (reported blocked)
QUEUE_EXPANSIONS = 4_000  # the same for a search to a queue node (near; up to 12 are tried)


@dataclass(frozen=True)
class Request:
    """What one robot asks of the fleet plan."""

    name: str
    start: int  # node it is snapped to
    goal: int | None  # node; None: the goal is off the graph
    shape: Shape
    start_xy: tuple[float, float]
    heading_rad: float | None = None  # None: may leave the start in any direction
    goal_xy: tuple[float, float] | None = None  # the real goal, driven to from the goal node
    start_turnable: bool = True  # it may turn in place where it stands
    idle: bool = False  # every goal done: its goal is where it parks; it moves aside, never goes first


@dataclass(frozen=True)
class Obstacle:
    """Something that does not take part in the plan (stopped, unlocalized, a person)."""

    xy: tuple[float, float]
    radius_m: float
    yaw_rad: float | None = None  # with ``shape``: its footprint at this heading, else a circle
    shape: Shape | None = None

    def region(self) -> Region:
        if self.shape is not None and self.yaw_rad is not None:
            return fp.pose(self.shape, np.asarray(self.xy), self.yaw_rad)
        c = np.asarray([self.xy], dtype=float)
        return c, c.copy(), np.array([self.radius_m])


@dataclass
class Vertex:
    """A place on a robot's route: the node, when it arrives and leaves, what it holds meanwhile."""

    node: int
    arrive: int  # step it arrives (0: the start)
    depart: int | None  # step it starts for the next vertex (None: it stays)
    occ: Region  # what it holds from leaving the vertex before until arriving at the one after
    loose: bool = False  # where it stands now, or its way off it: kept off others, not the safety distance


@dataclass
class RobotPlan:
    """One robot's timed route."""

    name: str
    vertices: list[Vertex]
    target: int  # where it ends: its goal, or a queue node outside a held goal
    queued: bool = False  # waits outside its goal (held by a robot planned before it)
    complete: bool = True  # reaches the target within the horizon

    @property
    def nodes(self) -> list[int]:
        """Node of the last vertex reached, per step, up to the arrival at the last one."""
        out: list[int] = []
        for a, b in zip(self.vertices, self.vertices[1:] + [None]):
            out.extend([a.node] * ((b.arrive if b is not None else a.arrive + 1) - a.arrive))
        return out


@dataclass
class FleetPlan:
    plans: dict[str, RobotPlan] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)  # name -> unreachable | blocked
    order: list[str] = field(default_factory=list)  # the priority order that was used
    # robot -> robots planned after it whose standing place keeps it from its goal
    blockers: dict[str, list[str]] = field(default_factory=dict)


@dataclass(frozen=True)
class Timing:
    """How the plan's clock relates to the graph."""

    spacing_m: float
    horizon: int  # steps
    safety_m: float  # distance kept between two robots' regions
    turn_tolerance_rad: float = math.radians(50.0)  # larger heading changes need a turn in place

    def steps(self, length_m: float) -> int:
        return max(1, math.ceil(length_m / self.spacing_m - 1e-6))


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

    def blocked_nodes(self, step: int | None, radius_m: float) -> NDArray[np.bool_]:
        """Nodes where a disc of ``radius_m`` conflicts with what is held at ``step`` (None: with
        what stays after the horizon)."""
        staying = fp.region(*self.staying) if step is None and self.staying else None
        held = staying if step is None else self.at(step)
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
    while True:
        result = _plan_in_order(graph, [by_name[n] for n in order], obstacles, timing, standing)
        moved = _blockers_first(order, result.blockers, ahead)
        if moved is not None:
            order = moved  # a robot standing in an earlier one's way is planned (out of it) first
            continue
        failed = [n for n in order if n in result.failures and n not in standing]
        if not failed:
            result.order = order
            return result
        first = failed[0]
        if first in promoted or by_name[first].idle:  # no plan even first (an idle robot never goes
            # first): the others must plan around where it stands
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


def _standing(r: Request) -> RobotPlan:
    occ = _start_region(r, turn=False)
    return RobotPlan(r.name, [Vertex(r.start, 0, None, occ, loose=True)], r.start, complete=False)


def _plan_in_order(
    graph: RouteGraph,
    requests: list[Request],
    obstacles: list[Obstacle],
    timing: Timing,
    standing: set[str],
) -> FleetPlan:
    table = Reservations(graph, timing.horizon, timing.safety_m)
    for o in obstacles:
        table.add_static(o.region())
    out = FleetPlan()
    pending = []
    for r in requests:  # robots that cannot be planned stand where they are, for everyone
        if r.goal is None or graph.components[r.goal] != graph.components[r.start]:
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
    waiting = {r.name: (_start_region(r, turn=False), _clear_steps(r, timing), r.idle) for r in pending}
    for r in pending:
        del waiting[r.name]
        table.set_waiting(dict(waiting))
        plan = _plan_one(graph, r, table, timing)
        if waiting and (plan is None or not plan.complete):
            out.blockers[r.name] = _blocking(graph, r, table, timing, waiting)
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
    would cross if they were not there (none when it cannot reach its goal even then)."""
    table.set_waiting({})
    try:
        free = _plan_one(graph, r, table, timing, queue=False)  # (one search: the goal, no queue)
    finally:
        table.set_waiting(waiting)
    if free is None or not free.complete or free.queued:
        return []
    return [
        n
        for n, (standing, _, idle) in waiting.items()
        if not idle
        and any(fp.conflict(v.occ, standing, 0.0 if v.loose else timing.safety_m) for v in free.vertices)
    ]


def _clear_steps(r: Request, timing: Timing) -> int:
    """Steps a robot needs to get off where it stands: a turn and its length plus the safety distance."""
    return 1 + timing.steps(r.shape.front_m - r.shape.back_m + timing.safety_m)


def _plan_one(
    graph: RouteGraph, r: Request, table: Reservations, timing: Timing, *, queue: bool = True
) -> RobotPlan | None:
    """Space-time A* to the goal, or (``queue``) to a queue node outside it when the goal is held."""
    assert r.goal is not None
    search = _Search(graph, r, table, timing)
    # the search's guide: route lengths that avoid what stays held to the horizon (robots parked,
    # obstacles), so a detour round a lane that stays blocked is found without searching the lane
    staying = table.blocked_nodes(None, r.shape.half_width_m)
    goal = r.goal

    def guide(forward: bool) -> ToGoal:
        to = search.to_goal(goal, avoid=staying, forward=forward)
        if search.start_h(to) < PENALTY_M / timing.spacing_m:
            return to
        return search.to_goal(goal, forward=forward)  # every way passes something that stays

    to = guide(forward=False)
    if not table.blocked_nodes(timing.horizon, r.shape.half_width_m)[r.goal]:  # free at the horizon
        plan = search.run(r.goal, to, tail=r.goal_xy)
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
        plan = search.run(int(node), search.to_goal(int(node)), tail=None, budget=QUEUE_EXPANSIONS)
        if plan is not None and plan.vertices[-1].node == node:
            plan.queued = True
            return plan
    return None


def _start_region(r: Request, *, turn: bool) -> Region:
    xy = np.asarray(r.start_xy, dtype=float)
    if r.heading_rad is None:
        return fp.circle(r.shape, xy)
    here = fp.pose(r.shape, xy, r.heading_rad)
    return fp.region(here, fp.circle(r.shape, xy)) if turn else here


State = tuple[int, int, int, bool]  # node, step, previous node (START, FROM_START), turns here


class _Search:
    """Space-time A* of one robot against the reservation table (states: node, step, the node it
    came from, whether it turns in place here)."""

    def __init__(self, graph: RouteGraph, r: Request, table: Reservations, timing: Timing) -> None:
        self.graph, self.r, self.table, self.timing = graph, r, table, timing
        self.start_xy = np.asarray(r.start_xy, dtype=float)
        self.turnable = graph.turnable(r.shape.reach_m).tolist()
        self.turns = graph.turns(r.shape.reach_m, timing.turn_tolerance_rad)
        self._bad: dict[int, NDArray[np.bool_] | None] = {}
        self._free: dict[tuple, bool] = {}
        self._regions: dict[tuple, Region] = {}
        self.pieces = table.conflicts.pieces(r.shape)  # shared: every directed edge, every turn
        self.tail: tuple[float, float] | None = None
        self.target = -1

    # ------------------------------------------------------------------ geometry
    def heading(self, node: int, prev: int) -> float | None:
        if prev == START:
            return self.r.heading_rad
        if prev >= 0:
            return self.graph.arc_angle[(prev, node)]
        d = self.graph.xy[node] - self.start_xy
        return float(np.arctan2(d[1], d[0])) if np.hypot(*d) > 1e-9 else None

    def occ(self, node: int, prev: int, turn: bool) -> Region:
        """What the robot holds for a vertex (see the module docstring)."""
        units, specials = self._units(node, prev, turn)
        parts = [self._special(k) for k in specials]
        parts += [self.pieces.piece(u) for u in units]
        return fp.region(*parts)

    def _units(self, node: int, prev: int, turn: bool) -> tuple[list[int], list[tuple]]:
        """A vertex's region as shared pieces (arcs, circles) and pieces of this search only."""
        units: list[int] = []
        specials: list[tuple] = []
        if prev == START:
            return units, [("start", turn)]
        if prev == FROM_START:
            specials.append(("from_start", node))
        else:
            units.append(self.graph.arc_index[(prev, node)])
        if turn:
            units.append(self.pieces.n_arcs + node)
        if node == self.target and self.tail is not None:
            specials.append(("tail", node, self.tail))
        return units, specials

    def _special(self, key: tuple) -> Region:
        if key not in self._regions:
            if key[0] == "start":
                self._regions[key] = _start_region(self.r, turn=key[1])
            elif key[0] == "from_start":
                self._regions[key] = fp.drive(self.r.shape, self.start_xy, self.graph.xy[key[1]])
            else:
                self._regions[key] = fp.drive(self.r.shape, self.graph.xy[key[1]], np.asarray(key[2]))
        return self._regions[key]

    def _bad_units(self, step: int) -> NDArray[np.bool_] | None:
        """Per shared piece: whether it conflicts with what is held at ``step`` (None: nothing is)."""
        if step not in self._bad:
            self._bad[step] = self.table.conflicts.bad(self.r.shape, step)
        return self._bad[step]

    def free(self, step: int, parts: tuple[tuple[int, int, bool], ...]) -> bool:
        """Whether the vertices ``parts`` (node, prev, turn) are free of reservations at ``step``."""
        bad = self._bad_units(step)
        if bad is None:
            return True
        for p in parts:
            units, specials = self._units(*p)
            if any(bad[u] for u in units):
                return False
            for k in specials:
                ck = (step, k)
                if ck not in self._free:
                    held = self.table.at(step)
                    assert held is not None
                    # where it stands now may already be within the safety distance of others
                    # (it came there under the safety layer): it may leave as long as it touches none
                    margin = 0.0 if k[0] in ("start", "from_start") else self.timing.safety_m
                    self._free[ck] = not fp.conflict(self._special(k), held, margin)
                if not self._free[ck]:
                    return False
        return True

    def held_at(self, node: int, step: int) -> bool:
        """Whether even a robot standing on ``node`` (its width around it) conflicts at ``step``."""
        held = self.table.at(step)
        if held is None:
            return False
        c = self.graph.xy[node][None, :]
        return fp.conflict((c, c.copy(), np.array([self.r.shape.half_width_m])), held, self.timing.safety_m)

    # ------------------------------------------------------------------ search
    def to_goal(self, goal: int, avoid: NDArray[np.bool_] | None = None, *, forward: bool = False) -> ToGoal:
        """Route lengths to ``goal``; ``forward``: for a robot that cannot reverse and turns only where
        it may (``turns.py``); ``avoid``: nodes to keep off."""
        return self.turns.to_goal(goal, avoid, PENALTY_M, forward=forward)

    def start_h(self, to: ToGoal) -> float:
        """The guide's steps to the goal from where the robot stands (the better of its two starts)."""
        return min(self._start_h(to, turn) for turn in (False, True))

    def _start_h(self, to: ToGoal, turn: bool) -> float:
        r = self.r
        if r.start == to.goal:
            return 0.0
        if turn and not r.start_turnable:
            return math.inf
        if turn or to.plain:
            return to.node[r.start] / self.timing.spacing_m
        best = math.inf
        for v, length, angle in self._arcs(r.start, START):
            if r.heading_rad is not None and length > 1e-9 and not self.turns.within(r.heading_rad, angle):
                continue
            rest = to.facing(v, angle) if v == r.start else to.arc[self.graph.arc_index[(r.start, v)]]
            best = min(best, length + rest)
        return best / self.timing.spacing_m

    def _h(self, to: ToGoal, state: State) -> float:
        """The guide's steps to the goal from a state (after the start)."""
        v, _, came, turn = state
        if turn:
            return to.node[v] / self.timing.spacing_m
        if came >= 0:
            return to.arc[self.graph.arc_index[(came, v)]] / self.timing.spacing_m
        return to.facing(v, self.heading(v, came)) / self.timing.spacing_m

    def run(
        self,
        target: int,
        to: ToGoal,
        *,
        tail: tuple[float, float] | None,
        budget: int = MAX_EXPANSIONS,
    ) -> RobotPlan | None:
        """Earliest arrival at ``target`` that it can then hold; else the plan that ends nearest to it
        at the horizon (a windowed plan); None if it cannot even keep clear until the horizon. The
        guide ``to`` (forward-only lengths to ``target``) also keeps it out of places it could not
        leave."""
        r, horizon = self.r, self.timing.horizon
        if (self.target, self.tail) != (target, tail):
            self.target, self.tail = target, tail
            self._free = {k: v for k, v in self._free.items() if k[1][0] != "tail"}
        parent: dict[State, State | None] = {}
        heap: list[tuple[float, int, State]] = []
        tie = 0
        for turn in (False, True):
            h0 = self._start_h(to, turn)
            if (turn and not r.start_turnable) or not math.isfinite(h0):
                continue
            s = (r.start, 0, START, turn)
            parent[s] = None
            heapq.heappush(heap, (h0, tie := tie + 1, s))
        expanded = 0
        while heap and expanded < budget:
            f, _, state = heapq.heappop(heap)
            expanded += 1
            u, k, prev, turn = state
            if u == target and (prev != START or r.start == target) and self._holds(state):
                return self._plan(parent, state, complete=True)
            if k >= horizon:  # the first state popped at the horizon ends nearest to the target
                # (consistent heuristic, f = horizon + h): the windowed plan
                return self._plan(parent, state, complete=False)
            h_here = f - k
            for nxt in self._moves(state):
                if nxt in parent:
                    continue
                h = h_here if nxt[0] == u and nxt[2] == prev else self._h(to, nxt)
                if not math.isfinite(h):
                    continue  # a place it could not leave towards the target
                here = (u, prev, turn)
                parts = (here,) if nxt[0] == u and nxt[2] == prev else (here, (nxt[0], nxt[2], nxt[3]))
                if not all(self.free(j, parts) for j in range(k + 1, nxt[1] + 1)):
                    continue
                parent[nxt] = state
                heapq.heappush(heap, (nxt[1] + h, tie := tie + 1, nxt))
        return None  # it cannot even keep clear until the horizon (or the search gave up)

    def _holds(self, state: State) -> bool:
        u, k, prev, turn = state
        return all(self.free(j, ((u, prev, turn),)) for j in range(k + 1, self.timing.horizon + 1))

    def _moves(self, state: State) -> list[State]:
        """Wait, or drive to a neighbour (or, from the real start pose, to the start node)."""
        u, k, prev, turn = state
        horizon = self.timing.horizon
        out: list[State] = [(u, min(k + 1, horizon), prev, turn)]
        heading = self.heading(u, prev)
        came = FROM_START if prev == START else u
        tolerance, steps, turnable = self.timing.turn_tolerance_rad, self.timing.steps, self.turnable
        for v, length, angle in self._arcs(u, prev):
            if heading is not None and not turn and length > 1e-9:
                off = abs((angle - heading + math.pi) % (2 * math.pi) - math.pi)
                if off > tolerance:
                    continue  # would have to turn in place here, which this state does not
            k2 = min(k + steps(length), horizon)
            out.append((v, k2, came, False))
            if turnable[v]:
                out.append((v, k2, came, True))
        return out

    def _arcs(self, u: int, prev: int) -> list[tuple[int, float, float]]:
        """(neighbour, length, angle) of each move from ``u``; from the real start pose they are
        measured from there, and the start node itself is one of them."""
        if prev != START:
            return self.graph.arc_geometry[u]
        here = self.start_xy
        targets = list(self.graph.neighbours[u])
        if float(np.linalg.norm(here - self.graph.xy[u])) > 0.05:
            targets.append(u)
        out = []
        for v in targets:
            d = self.graph.xy[v] - here
            out.append((v, float(np.hypot(*d)), float(np.arctan2(d[1], d[0]))))
        return out

    def _plan(self, parent: dict[State, State | None], state: State, *, complete: bool) -> RobotPlan:
        chain: list[State] = []
        s: State | None = state
        while s is not None:
            chain.append(s)
            s = parent[s]
        chain.reverse()
        vertices = [Vertex(chain[0][0], 0, None, self.occ(chain[0][0], START, chain[0][3]), loose=True)]
        for a, b in itertools.pairwise(chain):
            if (b[0], b[2]) == (a[0], a[2]):
                continue  # a wait
            vertices[-1].depart = a[1]
            vertices.append(Vertex(b[0], b[1], None, self.occ(b[0], b[2], b[3]), loose=b[2] == FROM_START))
        return RobotPlan(
            self.r.name, vertices, self.target, complete=complete and vertices[-1].node == self.target
        )
