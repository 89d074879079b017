"""One robot's space-time A* against the reservation table (``schedule.py`` orders the robots).

States are (node, step, the node it came from, whether it turns in place here); what the robot holds
for each is its footprint's region (``footprint.py``, see ``schedule.py``). The guide is the route
length still to drive (``turns.py``), a consistent heuristic, so the first state popped at the
target is the earliest arrival and the first one popped at the horizon ends nearest to it.
"""

from __future__ import annotations

import heapq
import itertools
import math
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.fleet import footprint as fp
from simlan_data.algorithms.fleet.conflicts import ConflictCache
from simlan_data.algorithms.fleet.footprint import Region
from simlan_data.algorithms.fleet.graph import RouteGraph
from simlan_data.algorithms.fleet.plans import Request, RobotPlan, Timing, Vertex, start_region
from simlan_data.algorithms.fleet.turns import ToGoal


class Reservations(Protocol):
    """What the search reads of the reservation table (``schedule.Reservations``; a protocol, so
    that the table's module can import the search without an import cycle)."""

    conflicts: ConflictCache

    def at(self, step: int) -> Region | None: ...


START = -1  # ``prev`` of the start state: the robot stands at its real pose
FROM_START = -2  # ``prev`` of the first vertex after it: the edge starts at the real pose
PENALTY_M = 1000.0  # the search's guide avoids nodes held to the horizon at this extra cost
MAX_EXPANSIONS = 40_000  # a search that expands more states than this gives up (reported blocked)
QUEUE_EXPANSIONS = 4_000  # the same for a search to a queue node (near; up to 12 are tried)


State = tuple[int, int, int, bool]  # node, step, previous node (START, FROM_START), turns here


class Search:
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
                self._regions[key] = start_region(self.r, turn=key[1])
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
