"""One robot's space-time search against the reservation table (``schedule.py`` orders the robots).

A *place* is (node, the node it came from, whether it turns in place here, whether it came
reversing); what the robot holds there is its footprint's region (``footprint.py``, see
``schedule.py``). With ``Timing.reverse_ratio`` > 0 a robot may drive an arc backwards (taking
1 / reverse_ratio as many steps), holding what driving it forwards the other way holds. The search runs over safe
intervals (SIPP, Phillips & Likhachev 2011): a state is a place and one maximal run of plan steps
in which that region is free of reservations, reached at its earliest step; waiting is implicit
(it may stay as long as the interval lasts), so a robot that must wait costs one state, not one per
step and per place it could wait at. A move leaves when the next place is free and both places must
stay free until it arrives, exactly the rule the reservation table books. The guide is the route
length still to drive (``turns.py``), a consistent heuristic, so the first state popped at the
target (free to the horizon) is the earliest arrival, and the first popped at the horizon ends
nearest to it (a windowed plan). Before (a state per step), a 12-robot replan took 5x the CPU.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterator
from typing import Protocol, cast

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.fleet import footprint as fp
from simlan_data.algorithms.fleet.conflicts import ConflictCache
from simlan_data.algorithms.fleet.footprint import Region
from simlan_data.algorithms.fleet.graph import RouteGraph
from simlan_data.algorithms.fleet.plans import Request, RobotPlan, Timing, Vertex, start_region
from simlan_data.algorithms.fleet.turns import ToGoal, angle_off


class Reservations(Protocol):
    """What the search reads of the reservation table (``schedule.Reservations``; a protocol, so
    that the table's module can import the search without an import cycle)."""

    conflicts: ConflictCache

    def at(self, step: int) -> Region | None: ...


START = -1  # ``prev`` of the start state: the robot stands at its real pose
FROM_START = -2  # ``prev`` of the first vertex after it: the edge starts at the real pose
SNAP_M = 0.5  # the robot keeps its heading driving onto its own start node closer than this
PENALTY_M = 1000.0  # the search's guide avoids nodes held to the horizon at this extra cost
SOFT_M = 3.0  # ... and passes by where robots not planned yet stand at this extra cost per arc
MAX_EXPANSIONS = 40_000  # a search that expands more states than this gives up (reported blocked)
QUEUE_EXPANSIONS = 4_000  # the same for a search to a queue node (near; up to 12 are tried)


Place = tuple[int, int, bool, bool]  # node, previous node (START, FROM_START), turns here, came reversing
Key = tuple[Place, int]  # a place and one of its safe intervals (its index)
Link = tuple[Key, int, int]  # the key before, the step it left it, the step it arrived


class Search:
    """One robot's searches against one state of the reservation table (see the module doc)."""

    def __init__(self, graph: RouteGraph, r: Request, table: Reservations, timing: Timing) -> None:
        self.graph, self.r, self.table, self.timing = graph, r, table, timing
        self.start_xy = np.asarray(r.start_xy, dtype=float)
        self.turnable = graph.turnable(r.shape.reach_m).tolist()
        self.turns = graph.turns(r.shape.reach_m, timing.turn_tolerance_rad)
        self._regions: dict[tuple, Region] = {}
        self.pieces = table.conflicts.pieces(r.shape)  # shared: every directed edge, every turn
        self.tail: tuple[float, float] | None = None
        self.expanded = 0  # states expanded by its runs (docs/benchmarks/fleet.md's cost figures)
        self._ivs: dict[tuple, list[tuple[int, int]]] = {}
        self._bad_all: NDArray[np.bool_] | None = None  # (pieces, steps); empty: nothing reserved
        self._held: tuple | None = None
        self._ever_bad: list[bool] = []
        self._always = [(1, timing.horizon)]
        self._pivots: dict[float, bool] = {}  # arc angle off the start -> whether it may pivot to it
        self.target = -1
        self.reversing = timing.reverse_ratio > 0.0  # it may drive an arc backwards
        # per arc: reversing along it keeps the robot's tail, which leads, off the shelves (the
        # graph keeps a lane's width clear, not a truck's 1.15 m past the node it backs to)
        # (shared by every search of this shape on the graph)
        self.back_clear: list[bool] = graph.reversing_clear(r.shape) if self.reversing else []
        # per arc: driven that way, the robot's marker leaves the cameras for too long (it would be
        # stopped, lost); empty: no limit (no cameras, no limit set, or a start off their floor)
        self.blind: list[bool] = self._blind_arcs()

    # ------------------------------------------------------------------ geometry

    def heading(self, node: int, prev: int, back: bool = False) -> float | None:
        """Where the robot faces at ``node`` having come from ``prev`` (``back``: reversing)."""
        if prev == START:
            return self.r.heading_rad
        if prev >= 0:
            angle = self.graph.arc_angle[(prev, node)]
            return angle + math.pi if back else angle
        d = self.graph.xy[node] - self.start_xy
        if node == self.r.start and np.hypot(*d) < SNAP_M:
            return self.r.heading_rad  # a step onto its own node is a correction, not a turn
        if np.hypot(*d) <= 1e-9:
            return None
        angle = float(np.arctan2(d[1], d[0]))
        return angle + math.pi if back else angle

    def occ(self, node: int, prev: int, turn: bool, back: bool = False) -> Region:
        """What the robot holds for a vertex (see the module docstring)."""
        units, specials = self._units(node, prev, turn, back)
        parts = [self._special(k) for k in specials]
        parts += [self.pieces.piece(u) for u in units]
        return fp.region(*parts)

    def _units(self, node: int, prev: int, turn: bool, back: bool = False) -> tuple[list[int], list[tuple]]:
        """A vertex's region as shared pieces (arcs, circles) and pieces of this search only.
        Reversing from ``prev`` to ``node`` the footprint sweeps what driving forwards from ``node``
        to ``prev`` sweeps (the same capsule): the reversed arc's piece."""
        units: list[int] = []
        specials: list[tuple] = []
        if prev == START:
            return units, [("start", turn)]
        if prev == FROM_START:
            specials.append(("from_start", node, back))
        else:
            units.append(self.graph.arc_index[(node, prev) if back else (prev, node)])
        if turn:
            units.append(self.pieces.n_arcs + node)
        if node == self.target and self.tail is not None:
            specials.append(("tail", node, self.tail, back and not turn))
        return units, specials

    def _special(self, key: tuple) -> Region:
        if key not in self._regions:
            if key[0] == "start":
                self._regions[key] = start_region(self.r, turn=key[1])
            else:  # driving off the start pose onto a node, or from the target node to the real goal
                a, b = (
                    (self.start_xy, self.graph.xy[key[1]])
                    if key[0] == "from_start"
                    else (
                        self.graph.xy[key[1]],
                        np.asarray(key[2]),
                    )
                )
                shape = self.r.shape.reversed() if key[-1] else self.r.shape
                self._regions[key] = fp.drive(shape, a, b)
        return self._regions[key]

    def held_at(self, node: int, step: int) -> bool:
        """Whether even a robot standing on ``node`` (its width around it) conflicts at ``step``."""
        held = self.table.at(step)
        if held is None:
            return False
        c = self.graph.xy[node][None, :]
        return fp.conflict((c, c.copy(), np.array([self.r.shape.half_width_m])), held, self.timing.safety_m)

    # ------------------------------------------------------------------ search
    def to_goal(
        self,
        goal: int,
        avoid: NDArray[np.bool_] | None = None,
        *,
        forward: bool = False,
        soft: NDArray[np.bool_] | None = None,
    ) -> ToGoal:
        """Route lengths to ``goal``; ``forward``: for a robot that cannot reverse and turns only where
        it may (``turns.py``); ``avoid``: nodes to keep off; ``soft``: nodes to pass by where it can
        (where robots not planned yet stand: ``SOFT_M`` more per arc touching one)."""
        return self.turns.to_goal(goal, avoid, PENALTY_M, forward=forward, soft=soft, soft_m=SOFT_M)

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
        backs = self.reversing or self.timing.start_back_ratio > 0.0
        for v, length, angle in self._arcs(r.start, START):
            heading = r.heading_rad
            if (
                heading is not None
                and length > 1e-9
                and (not self.turns.within(heading, angle) or not self._may_pivot(START, angle))
            ):
                if backs and angle_off(heading, angle + math.pi) <= self.timing.cusp_tolerance_rad:
                    best = min(best, length + to.facing(v, angle + math.pi))
                continue
            rest = to.facing(v, angle) if v == r.start else to.arc[self.graph.arc_index[(r.start, v)]]
            best = min(best, length + rest)
        return best / self.timing.spacing_m

    def _h(self, to: ToGoal, place: Place) -> float:
        """The guide's steps to the goal from a place (after the start)."""
        v, came, turn, back = place
        if turn:
            return to.node[v] / self.timing.spacing_m
        if came >= 0 and not back:
            return to.arc[self.graph.arc_index[(came, v)]] / self.timing.spacing_m
        return to.facing(v, self.heading(v, came, back)) / self.timing.spacing_m

    # ------------------------------------------------------------------ search
    def run(
        self,
        target: int,
        to: ToGoal,
        *,
        tail: tuple[float, float] | None,
        budget: int = MAX_EXPANSIONS,
        complete_only: bool = False,
        then: int | None = None,
    ) -> RobotPlan | None:
        """Earliest arrival at ``target`` that it can then hold; else the plan that ends nearest to it
        at the horizon (a windowed plan); None if it cannot even keep clear until the horizon. The
        guide ``to`` (route lengths to ``target``) also keeps it out of places it could not leave.
        ``complete_only``: None instead of a windowed plan, found sooner (the search stops once no
        state left can arrive within the horizon). ``then``: where it drives on to afterwards (a
        queue node's goal): it only enters places from which it can reach ``then`` driving forwards."""
        r, horizon = self.r, self.timing.horizon
        self.target, self.tail = target, tail
        # guided by plain route lengths, it still never enters a place from which it could not
        # reach the target driving forwards (a dead end facing the wall: robots do not reverse)
        # (a robot queued facing a shelf, where it cannot turn, stood there for good: 4 robots, seed 38)
        if then is not None:
            exits: ToGoal | None = self.to_goal(then, forward=True)
        else:
            exits = self.to_goal(target, forward=True) if to.plain else None
        if exits is not None and (self.reversing or not math.isfinite(self.start_h(exits))):
            exits = None  # already in such a place: it can only try (or it reverses out of them)
        parent: dict[Key, Link | None] = {}
        best: dict[Key, int] = {}
        heap: list[tuple[float, int, int, int, Key, bool]] = []  # f, -arrival, tie, arrival, key, to horizon
        for place in self._start_places(to):
            parent[(place, 0)], best[(place, 0)] = None, 0
            heapq.heappush(heap, (self._start_h(to, place[2]), 0, len(heap), 0, (place, 0), False))
        closed: set[Key] = set()
        tie, stop = len(heap), self.expanded + budget
        while heap and self.expanded < stop:
            f, _, _, t, key, to_horizon = heapq.heappop(heap)
            if complete_only and f > horizon:
                return None  # an arrival within the horizon has f <= horizon (its guide is 0 there)
            if to_horizon:  # waits where it is to the horizon: the windowed plan
                return self._plan(parent, key, complete=False)
            if key in closed:
                continue
            closed.add(key)
            self.expanded += 1
            (u, prev, _, _), end = key[0], self._intervals(key[0])[key[1]][1]
            if u == target and (prev != START or r.start == target) and end >= horizon:
                return self._plan(parent, key, complete=True)
            if t >= horizon:
                return self._plan(parent, key, complete=False)
            if end >= horizon:  # it may wait here to the horizon
                heapq.heappush(heap, (horizon + f - t, -horizon, tie := tie + 1, horizon, key, True))
            for key2, depart, k2, h2 in self._moves(key, t, end, to, exits):
                if key2 not in closed and best.get(key2, horizon + 1) > k2:
                    best[key2], parent[key2] = k2, (key, depart, k2)
                    heapq.heappush(heap, (k2 + h2, -k2, tie := tie + 1, k2, key2, False))
        return None  # it cannot even keep clear until the horizon (or the search gave up)

    def _start_places(self, to: ToGoal) -> list[Place]:
        """Where it stands, without and with a turn in place, if it can stay there for a step."""
        r, out = self.r, []
        for turn in (False, True):
            if (turn and not r.start_turnable) or not math.isfinite(self._start_h(to, turn)):
                continue
            ivs = self._intervals((r.start, START, turn, False))
            if ivs and ivs[0][0] == 1:
                out.append((r.start, START, turn, False))
        return out

    def _moves(
        self, key: Key, t: int, end: int, to: ToGoal, exits: ToGoal | None
    ) -> Iterator[tuple[Key, int, int, float]]:
        """(next place and interval, step it leaves, step it arrives, guide there) of each move from
        a place it holds from step ``t`` to at most ``end``: it waits until the next place is free,
        and both must stay free until it arrives."""
        horizon = self.timing.horizon
        for place2, s, h2 in self._next_places(key[0], to, exits):
            for j, (a2, b2) in enumerate(self._intervals(place2)):
                depart = max(t, a2 - 1)
                arrive = min(depart + s, horizon)
                if arrive > end:
                    break  # here is taken before it would arrive (later intervals start later)
                if arrive <= b2:
                    yield (place2, j), depart, arrive, h2

    def _next_places(self, place: Place, to: ToGoal, exits: ToGoal | None) -> list[tuple[Place, int, float]]:
        """(next place, steps to drive there, guide there) of each move from ``place``; not into a
        place whose forward-only length to the target (``exits``) is infinite."""
        u, prev, turn, back = place
        heading = self.heading(u, prev, back)
        came = FROM_START if prev == START else u
        steps, turnable = self.timing.steps, self.turnable
        free = heading is None or turn  # it may leave in any direction (forwards)
        # a change of direction (a cusp; leaving the start backwards) only nearly in line
        turn_tol, cusp_tol = self.timing.turn_tolerance_rad, self.timing.cusp_tolerance_rad
        ahead_tol, back_tol = (cusp_tol, turn_tol) if back else (turn_tol, cusp_tol)
        backs = self.reversing or (prev == START and self.timing.start_back_ratio > 0.0)
        pivots = prev == START  # leaving the start pose forwards may need a pivot (_may_pivot)
        out = []
        blind = self.blind
        for v, length, angle in self._arcs(u, prev):
            ways = []  # (reversing, steps)
            if free or length <= 1e-9 or angle_off(cast(float, heading), angle) <= ahead_tol:
                if not (blind and self._blind(u, v, prev, back=False)) and (
                    not pivots or self._may_pivot(START, angle)
                ):
                    ways.append((False, steps(length)))
            elif (
                backs
                and angle_off(cast(float, heading), angle + math.pi) <= back_tol
                and self._may_back(u, v, prev)
                and not (blind and self._blind(u, v, prev, back=True))
            ):
                ratio = self.timing.reverse_ratio if self.reversing else self.timing.start_back_ratio
                ways.append((True, steps(length / ratio)))
            for back2, s in ways:
                for turn2 in (False, True) if turnable[v] else (False,):
                    place2 = (v, came, turn2, back2)
                    h2 = self._h(to, place2)
                    if math.isfinite(h2) and (exits is None or math.isfinite(self._h(exits, place2))):
                        out.append((place2, s, h2))
        return out

    def _blind_arcs(self) -> list[bool]:
        share, limit = self.graph.arc_unseen, self.timing.unseen_limit
        if share is None or limit >= 1.0:
            return []
        # a robot off the cameras' floor (every way out of its node unseen, either way) finds its way back
        start, index = self.r.start, self.graph.arc_index
        ways = [share[index[arc]] for v in self.graph.neighbours[start] for arc in ((start, v), (v, start))]
        if ways and min(ways) > limit:
            return []
        return (share > limit).tolist()

    def _blind(self, u: int, v: int, prev: int, *, back: bool) -> bool:
        """Whether driving from ``u`` to ``v`` (``back``: backwards, facing from v to u) leaves the
        cameras for too long; a robot may still drive onto its target."""
        if prev == START or u == v or v == self.target:
            return False
        return self.blind[self.graph.arc_index[(v, u) if back else (u, v)]]

    def _may_pivot(self, prev: int, angle: float) -> bool:
        """Whether a robot leaving its start pose (``prev`` START) on an arc at ``angle`` may: more
        than nearly in line it pivots as it starts, so only where its outline turns that far clear of
        the floor's obstacles (a forklift parked beside a shelf swung its tail into it leaving on an
        arc 52 degrees off its heading). Later vertices: True (their turns keep to the lanes; the
        search's hot loop asks only for the start)."""
        heading = self.r.heading_rad
        if prev != START or heading is None or self.r.start_turnable:
            return True
        if angle_off(heading, angle) <= self.timing.cusp_tolerance_rad:
            return True
        key = round(angle, 6)
        if key not in self._pivots:
            self._pivots[key] = self.graph.pivot_clear(self.start_xy, self.r.shape, heading, angle)
        return self._pivots[key]

    def _may_back(self, u: int, v: int, prev: int) -> bool:
        """Whether reversing from ``u`` (from the start pose where ``prev`` is START) to ``v``
        keeps the tail off the shelves."""
        if prev != START:
            return self.back_clear[self.graph.arc_index[(u, v)]]
        p, q, _ = fp.drive(self.r.shape.reversed(), self.start_xy, self.graph.xy[v])
        return bool(self.graph.capsules_clear(p, q, self.r.shape.half_width_m)[0])

    def _intervals(self, place: Place) -> list[tuple[int, int]]:
        """Maximal runs of steps (first, last; within 1..horizon) in which what the robot holds at
        ``place`` is free of reservations."""
        node, prev, turn, back = place
        key = (*place, self.tail) if node == self.target else place
        got = self._ivs.get(key)
        if got is not None:
            return got
        units, specials = self._units(node, prev, turn, back)
        bad = self._bad_matrix()
        if not specials and (bad is None or not any(self._ever_bad[u] for u in units)):
            out = self._always  # nothing is ever reserved there (most places)
        else:
            free = np.ones(self.timing.horizon + 1, dtype=bool)
            if bad is not None:
                for u in units:
                    free &= ~bad[u]
            for k in specials:
                free &= self._special_free(k)
            free[0] = False
            edges = np.flatnonzero(np.diff(np.concatenate(([False], free, [False])).astype(np.int8)))
            out = [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]
        self._ivs[key] = out
        return out

    def _bad_matrix(self) -> NDArray[np.bool_] | None:
        """Per shared piece and step: whether it conflicts (None: nothing is reserved at any step)."""
        if self._bad_all is None:
            rows = [self.table.conflicts.bad(self.r.shape, j) for j in range(self.timing.horizon + 1)]
            if all(b is None for b in rows):
                self._bad_all = np.zeros((0, 0), dtype=bool)
            else:
                n = len(self.pieces.r)
                z = np.zeros(n, dtype=bool)
                self._bad_all = np.ascontiguousarray(np.stack([z if b is None else b for b in rows]).T)
                self._ever_bad = cast(list[bool], self._bad_all.any(axis=1).tolist())
        return self._bad_all if self._bad_all.size else None

    def _special_free(self, key: tuple) -> NDArray[np.bool_]:
        """Per step: whether a piece of this search only (start, way off it, tail) is free."""
        p, q, rad, steps = self._held_all()
        free = np.ones(self.timing.horizon + 1, dtype=bool)
        if len(rad):
            reg = self._special(key)
            margin = 0.0 if key[0] in ("start", "from_start") else self.timing.safety_m
            d = fp.segment_distances(reg[0], reg[1], p, q)
            hit = (d < reg[2][:, None] + rad[None, :] + margin).any(axis=0)
            free[steps[hit]] = False
        return free

    def _held_all(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
        """Every step's held region, concatenated, with the step of each capsule."""
        if self._held is None:
            parts, steps = [], []
            for j in range(self.timing.horizon + 1):
                held = self.table.at(j)
                if held is not None:
                    parts.append(held)
                    steps.append(np.full(len(held[2]), j))
            if parts:
                p, q, rad = fp.region(*parts)
                self._held = (p, q, rad, np.concatenate(steps))
            else:
                e = np.zeros((0, 2))
                self._held = (e, e.copy(), np.zeros(0), np.zeros(0, dtype=np.int64))
        return self._held

    def _plan(self, parent: dict[Key, Link | None], key: Key, *, complete: bool) -> RobotPlan:
        """The route to ``key``: a vertex per place, with the steps it arrives and leaves."""
        chain: list[tuple[Place, int, int]] = []  # place, step it left the one before, arrival
        while (link := parent[key]) is not None:
            chain.append((key[0], link[1], link[2]))
            key = link[0]
        chain.reverse()
        place0 = key[0]
        vertices = [Vertex(place0[0], 0, None, self.occ(place0[0], START, place0[2]), loose=True)]
        for (v, came, turn, back), depart, arrive in chain:
            vertices[-1].depart = depart
            occ = self.occ(v, came, turn, back)
            vertices.append(Vertex(v, arrive, None, occ, loose=came == FROM_START, back=back, turn=turn))
        return RobotPlan(
            self.r.name, vertices, self.target, complete=complete and vertices[-1].node == self.target
        )

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
