"""The fleet coordinator (``algorithms/coordinator=fleet``): one plan for the whole fleet.

Data flow per control tick::

    intents (pose, footprint, goal) --> movers / obstacles (stopped, unlocalized, people)
        --> replan? (new goal, stop, deviation, windowed plan) --> plan_fleet (graph, reservations)
        --> routes + dependencies (ADG) --> progress of each robot along its route
        --> frontier (the furthest vertex it may enter) --> Decision(path_xy, speed limit)

Each robot is sent its route as a path (``Decision.path_xy``: the navigator follows it) and a
speed limit that stops it before the first vertex it may not enter yet.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.coordinator import Decision, Intent, footprint_polygon
from simlan_data.algorithms.fleet.config import FleetConfig
from simlan_data.algorithms.fleet.execution import Route, advance, build_routes, frontier, wait_cycles
from simlan_data.algorithms.fleet.footprint import Shape
from simlan_data.algorithms.fleet.graph import RouteGraph, build_route_graph
from simlan_data.algorithms.fleet.schedule import FleetPlan, Obstacle, Request, Timing, plan_fleet
from simlan_data.algorithms.fleet.turns import angle_off
from simlan_data.algorithms.occupancy import OccupancyGrid
from simlan_data.algorithms.roles import CoordinatorContext
from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError

log = logging.getLogger(__name__)

SLOW_REPLAN_S = 1.0  # a replan longer than this (wall time) is logged with the robots' poses
MOVED_M = 0.05  # less than this in stall_s: not moving
MOVED_RAD = 0.1  # ... and turned less than this: a robot turning on the spot is moving
IDLE_PRIORITY = 10**9  # idle robots are planned after every robot with a goal


def reach_of(footprint_m: tuple[float, float, float, float]) -> float:
    """The radius of the circle a footprint sweeps turning about its centre (base_link)."""
    x0, x1, y0, y1 = footprint_m
    return float(np.hypot(max(abs(x0), abs(x1)), max(abs(y0), abs(y1))))


@dataclass
class _Robot:
    """What the coordinator remembers of one robot between ticks."""

    goal: tuple[float, float] | None = None
    park: tuple[float, float] | None = None  # idle (every goal done): where it stands when not in the way
    path_xy: NDArray[np.float64] | None = None
    path_reverse: tuple[bool, ...] | None = None  # per segment of path_xy: driven backwards
    path_stops: tuple[int, ...] | None = None  # vertices of path_xy where it turns on the spot
    moved_at_ns: int = 0
    moved_from: tuple[float, float] = (0.0, 0.0)
    moved_yaw: float = 0.0  # its heading then
    waiting_since_ns: int | None = None
    granted_since_ns: int | None = None  # allowed to drive on since then (its frontier ahead of it)
    stopped_since_ns: int | None = None  # treated as an obstacle from then on


@dataclass
class FleetState:
    """The plan in force and what it has observed (read by tests and metrics)."""

    plan: FleetPlan = field(default_factory=FleetPlan)
    routes: dict[str, Route] = field(default_factory=dict)
    planned_at_ns: int = 0
    replans: int = 0
    deadlocks: int = 0  # wait-for cycles or waits past deadlock_after_s on a robot that does not move
    failures: dict[str, str] = field(default_factory=dict)  # robot -> unreachable | blocked
    stops: int = 0  # robots taken for stopped (allowed to drive, not moving for stall_s): planned around


class FleetCoordinator:
    """Prioritized space-time planning on a route graph, executed through an ADG."""

    role: ClassVar[str] = "coordinator"
    config_class: ClassVar[type] = FleetConfig

    def __init__(self, config: FleetConfig, context: CoordinatorContext) -> None:
        grid = getattr(context, "grid", None)
        if not isinstance(grid, OccupancyGrid):
            raise ConfigError(
                "the fleet coordinator needs the occupancy grid",
                "algorithms/coordinator=fleet",
                "its context has no grid",
                "run it through GpssStack (it passes the grid), or build CoordinatorContext(grid=...)",
            )
        self.config, self.grid = config, grid
        self.seen = getattr(context, "seen", None)  # the floor the cameras see (None: all)
        self.safety_m = context.safety_distance_m + config.safety_m
        self.graph: RouteGraph | None = None
        self.state = FleetState()
        self._robots: dict[str, _Robot] = {}
        self.waits: dict[str, int] = {}  # ticks spent waiting, per robot (as the gpss coordinator)
        self._force_replan = False
        self._standstill_ns = 0  # the last standstill of the fleet (deadlock_after_s counts from it)

    # ------------------------------------------------------------------ the role's method
    def decide(self, t_ns: int, intents: list[Intent]) -> dict[str, Decision]:
        # robots with a goal, then idle robots (every goal done): planned last, they stay where they
        # are unless they stand in someone's way, then they move aside (and come back later)
        movers = [i for i in intents if i.yields and i.goal_xy is not None]
        movers += [self._idle(t_ns, i) for i in intents if i.yields and i.goal_xy is None]
        graph = self._graph(intents)
        self._observe(t_ns, movers)
        if self._must_replan(t_ns, movers):
            names = {i.namespace for i in movers}
            self._replan(t_ns, graph, movers, [i for i in intents if i.namespace not in names])
        return self._decisions(t_ns, graph, movers, intents)

    def _idle(self, t_ns: int, intent: Intent) -> Intent:
        """An idle robot as a mover of the lowest priority whose goal is its parking place (where it
        became idle)."""
        r = self._robots.setdefault(
            intent.namespace,
            _Robot(moved_at_ns=t_ns, moved_from=intent.pose_xyyaw[:2], moved_yaw=intent.pose_xyyaw[2]),
        )
        if r.park is None:
            r.park = (float(intent.pose_xyyaw[0]), float(intent.pose_xyyaw[1]))
        return replace(intent, goal_xy=r.park, priority=IDLE_PRIORITY + intent.priority)

    # ------------------------------------------------------------------ steps
    def _graph(self, intents: list[Intent]) -> RouteGraph:
        """Build the route graph once, for the narrowest robot seen at the first tick (on the floor
        the cameras see, where robots steer on them); each robot drives the edges of its own width
        (``RouteGraph.for_width``): a Jackal passes where a pallet truck does not."""
        if self.graph is None:
            robots = [i for i in intents if i.yields] or intents
            reach = max((reach_of(i.footprint_m) for i in robots), default=0.5)
            self.graph = build_route_graph(
                self.grid,
                radius_m=min(
                    (self._lane_radius(i) for i in robots), default=0.5 + self.config.lane_clearance_m
                ),
                spacing_m=self.config.spacing_m,
                reach_m=reach,
                seen=self.seen,
                unseen_cost=self.config.unseen_cost,
            )
        return self.graph

    def _lane_radius(self, intent: Intent) -> float:
        """How far a robot's centre keeps from obstacles on its lanes: half its width plus the lane
        clearance."""
        return max(abs(intent.footprint_m[2]), abs(intent.footprint_m[3])) + self.config.lane_clearance_m

    def _observe(self, t_ns: int, movers: list[Intent]) -> None:
        """Track movement: a robot allowed to drive that has not moved for stall_s is stopped."""
        for i in movers:
            r = self._robots.setdefault(
                i.namespace, _Robot(moved_at_ns=t_ns, moved_from=i.pose_xyyaw[:2], moved_yaw=i.pose_xyyaw[2])
            )
            xy = i.pose_xyyaw[:2]
            turned = angle_off(r.moved_yaw, i.pose_xyyaw[2])
            if np.hypot(xy[0] - r.moved_from[0], xy[1] - r.moved_from[1]) > MOVED_M or turned > MOVED_RAD:
                r.moved_at_ns, r.moved_from, r.moved_yaw = t_ns, xy, float(i.pose_xyyaw[2])
                r.stopped_since_ns = None
            route = self.state.routes.get(i.namespace)
            if route is not None and self.graph is not None:
                advance(
                    route,
                    np.asarray(xy),
                    self.graph,
                    frontier(self.state.routes, i.namespace)[0],
                    self.config.reach_m,
                )
            granted = route is not None and frontier(self.state.routes, i.namespace)[0] > route.progress
            if not granted:
                r.granted_since_ns = None
            elif r.granted_since_ns is None:
                r.granted_since_ns = t_ns
            # stalled: allowed to drive for stall_s and not moving (a robot that waited its turn
            # is not stopped the moment it may go: it needs time to start)
            since = max(r.moved_at_ns, r.granted_since_ns or 0)
            stalled = t_ns - since > self.config.stall_s * NS_PER_S
            if granted and stalled and r.stopped_since_ns is None:
                r.stopped_since_ns = t_ns
                self.state.stops += 1

    def _must_replan(self, t_ns: int, movers: list[Intent]) -> bool:
        names = {i.namespace for i in movers}
        if self._force_replan:
            self._force_replan = False
            return True
        stopped = {n for n, r in self._robots.items() if r.stopped_since_ns is not None}
        if names - stopped != set(self.state.plan.plans) | set(self.state.plan.failures):
            return True
        for i in movers:
            r = self._robots[i.namespace]
            if r.goal != i.goal_xy:
                return True
            if r.stopped_since_ns is not None and r.stopped_since_ns >= self.state.planned_at_ns:
                return True  # stopped since the plan: plan around it
        pending = (
            bool(self.state.plan.failures)
            or any(r.stopped_since_ns is not None for r in self._robots.values())
            or self._window_spent()
        )
        return pending and t_ns - self.state.planned_at_ns >= self.config.replan_s * NS_PER_S

    def _window_spent(self) -> bool:
        """Whether a robot with a windowed or queued plan has driven half of it: time to plan the
        next window (rolling horizon). Replanning sooner changes where windows end while the robots
        drive them, and robots then turn back and forth between two ways round."""
        for name, plan in self.state.plan.plans.items():
            route = self.state.routes.get(name)
            spent = route is not None and 2 * route.progress >= len(route.nodes) - 1
            if spent and (not plan.complete or plan.queued):
                return True
        return False

    def _replan(self, t_ns: int, graph: RouteGraph, movers: list[Intent], others: list[Intent]) -> None:
        """Plan every moving robot from where it is (stopped ones and the others are obstacles)."""
        snap = 1.5 * self.config.spacing_m
        obstacles = [self._obstacle(i) for i in others]
        requests = []
        for i in sorted(movers, key=self._order_key):
            r = self._robots[i.namespace]
            r.goal = i.goal_xy
            if i.priority < IDLE_PRIORITY:
                r.park = None  # a goal again: it parks where it ends up next
            if r.stopped_since_ns is not None and r.stopped_since_ns < t_ns:
                obstacles.append(self._obstacle(i))
                continue  # until it moves again (on its own navigator's plan): then it rejoins
            xy = i.pose_xyyaw[:2]
            lane_radius = self._lane_radius(i)
            lanes = graph.for_width(lane_radius)
            start = lanes.start_node(xy, i.pose_xyyaw[2], within_m=snap)
            if start is None:
                obstacles.append(self._obstacle(i))
                continue
            assert i.goal_xy is not None
            shape = self._shape(i)
            requests.append(
                Request(
                    i.namespace,
                    start,
                    lanes.nearest(i.goal_xy, within_m=snap),
                    shape,
                    xy,
                    i.pose_xyyaw[2],
                    goal_xy=i.goal_xy,
                    start_turnable=graph.floor_clearance_at(xy) >= shape.reach_m,
                    idle=i.priority >= IDLE_PRIORITY,
                    lane_radius_m=lane_radius,
                )
            )
        timing = Timing(
            self.config.spacing_m,
            self.config.horizon_steps,
            self.safety_m,
            reverse_ratio=self.config.reverse_ratio,
            start_back_ratio=self.config.start_back_ratio,
            shelters=self.config.shelters,
            soft_waiting=self.config.soft_waiting,
            unseen_limit=self.config.unseen_limit,
        )
        started = time.perf_counter()
        plan = plan_fleet(graph, requests, obstacles, timing)
        took = time.perf_counter() - started
        if took > SLOW_REPLAN_S:  # (the run's log: where the planning time of a slow run went)
            log.info(
                "fleet replan at %.1f s took %.1f s: %s",
                t_ns / NS_PER_S,
                took,
                ", ".join(
                    f"{i.namespace} at ({i.pose_xyyaw[0]:.2f}, {i.pose_xyyaw[1]:.2f}, {i.pose_xyyaw[2]:.2f})"
                    for i in movers
                ),
            )
        self.state.plan, self.state.planned_at_ns = plan, t_ns
        self.state.routes = build_routes(plan, self.safety_m)
        self.state.failures.update(plan.failures)
        self.state.replans += 1
        for i in movers:
            route = self.state.routes.get(i.namespace)
            r = self._robots[i.namespace]
            if i.priority >= IDLE_PRIORITY and i.namespace in plan.failures and not self._at(i, r.park):
                # an idle robot that cannot get back to where it parked (it moved aside) parks where
                # it is: standing failed, it held the spot for good, and once that spot was another
                # robot's goal that robot queued for ever (4 robots, seed 7); parked here, it is
                # planned last and moves aside when a robot with a goal needs the place. Not again
                # where it already parks: a standing robot's pose jitters by micrometres, the new
                # park was a new goal, and a new goal a replan at every tick (a run's planning took
                # 8 s of wall time per second simulated, a pallet truck parked at its goal)
                r.park = (float(i.pose_xyyaw[0]), float(i.pose_xyyaw[1]))
            if route is None:
                r.path_xy, r.path_reverse, r.path_stops = None, None, None
            else:
                mine = plan.plans[i.namespace]
                r.path_xy, r.path_reverse, r.path_stops = self._path(
                    graph, route, i, mine.vertices[-1].turn, arrives=mine.complete and not mine.queued
                )

    def _order_key(self, intent: Intent) -> tuple[bool, int, int, str]:
        """Planning order: the order the last plan settled on (after its promotions), then the
        robots' priorities. A replan that started from the fixed priorities again undid the last
        plan's promotions: two robots swapped their precedence at every replan and turned back and
        forth in one lane for good (4 robots, seed 87)."""
        last = self.state.plan.order
        rank = last.index(intent.namespace) if intent.namespace in last else len(last)
        return (intent.priority >= IDLE_PRIORITY, rank, intent.priority, intent.namespace)

    def _shape(self, intent: Intent) -> Shape:
        return Shape.of(intent.footprint_m, tolerance_m=self.config.tracking_m)

    def _obstacle(self, intent: Intent) -> Obstacle:
        """Something not in the plan: its footprint where it stands (grown by the tracking error)."""
        shape = self._shape(intent)
        return Obstacle(intent.pose_xyyaw[:2], shape.reach_m, intent.pose_xyyaw[2], shape)

    def _path(
        self, graph: RouteGraph, route: Route, intent: Intent, turns_last: bool, *, arrives: bool = True
    ) -> tuple[NDArray[np.float64], tuple[bool, ...] | None, tuple[int, ...] | None]:
        """The path the navigator follows: from the robot through the route's vertices to its goal,
        per segment whether it is driven backwards (None: none is), and the path's vertices where
        the plan turns it on the spot (None: nowhere after the start). The way from the last
        vertex to the goal is driven as the robot arrived there, unless it turns there. A plan that
        does not arrive (windowed, queued) ends at its last vertex: the straight way on from there to
        the goal crossed shelves, and the follower's lookahead turned the robot towards it."""
        pts = [np.asarray(intent.pose_xyyaw[:2], dtype=float)] + [graph.xy[n] for n in route.nodes[1:]]
        backs = list(route.backs[1:])
        turns = list(route.turns[1:]) if route.turns else [False] * len(backs)
        if intent.goal_xy is not None and arrives:
            pts.append(np.asarray(intent.goal_xy, dtype=float))
            backs.append(bool(route.backs[-1]) and not turns_last)
            turns.append(False)
        keep, flags, stops = [pts[0]], [], []
        for a, p, back, turn in zip(pts, pts[1:], backs, turns):
            if np.linalg.norm(p - a) > 1e-6:
                keep.append(p)
                flags.append(back)
            if turn:
                stops.append(len(keep) - 1)  # it turns where it stands after this vertex
        stops = [k for k in stops if 0 < k < len(keep) - 1]
        if len(keep) < 2:
            return np.asarray([pts[0], pts[0]]), None, None
        return np.asarray(keep), (tuple(flags) if any(flags) else None), (tuple(stops) or None)

    def _decisions(
        self, t_ns: int, graph: RouteGraph, movers: list[Intent], intents: list[Intent]
    ) -> dict[str, Decision]:
        out: dict[str, Decision] = {}
        waits: dict[str, list[str]] = {}
        for i in movers:
            ns, r = i.namespace, self._robots[i.namespace]
            route = self.state.routes.get(ns)
            if r.stopped_since_ns is not None:
                # stopped: an obstacle for the plan until it moves on its own (not towards another)
                out[ns] = (
                    Decision(0.0, turn_in_place=False) if self._closing_in(i, intents) else Decision(None)
                )
                continue
            if route is None or r.path_xy is None or ns in self.state.plan.failures:
                out[ns] = Decision(0.0, turn_in_place=False)  # off the graph or failed: stands for the others
                continue
            if i.priority >= IDLE_PRIORITY and len(route.nodes) == 1 and self._at(i, r.park):
                out[ns] = Decision(0.0, turn_in_place=False)  # idle where it parks: it stands
                continue
            last, holders = frontier(self.state.routes, ns)
            plan = self.state.plan.plans[ns]
            free_to_goal = last == len(route.nodes) - 1 and plan.complete and not plan.queued
            limit = None if free_to_goal else self._limit(graph, route, i, last)
            if limit == 0.0 and holders:  # stopped at its frontier: it waits for them (wait-for edges)
                waits[ns] = holders
            if limit == 0.0:
                self.waits[ns] = self.waits.get(ns, 0) + 1
                r.waiting_since_ns = r.waiting_since_ns if r.waiting_since_ns is not None else t_ns
            else:
                r.waiting_since_ns = None
            # held at its frontier it stands still: a turn's circle is reserved only where planned
            out[ns] = Decision(
                limit,
                tuple(holders) if limit == 0.0 else (),
                path_xy=r.path_xy,
                turn_in_place=limit != 0.0,
                path_reverse=r.path_reverse,
                path_stops=r.path_stops,
            )
        self._check_deadlock(t_ns, waits, movers)
        return out

    def _closing_in(self, intent: Intent, intents: list[Intent]) -> bool:
        """Whether a robot released to its own navigator (counted stopped) would, driving ``brake_m``
        straight on, bring its footprint nearer another agent's than the safety distance. The plan
        no longer keeps it apart, and the safety layer's TTC rule (on circumscribed circles) skips
        an approach once two circles overlap: a released pallet truck closed to 0.10 m on a
        forklift turning in place (docs/fleet.md, the open safety finding)."""
        x, y, yaw = intent.pose_xyyaw
        ahead = (x + self.config.brake_m * np.cos(yaw), y + self.config.brake_m * np.sin(yaw), yaw)
        here = footprint_polygon(intent.pose_xyyaw, intent.footprint_m)
        sweep = here.union(footprint_polygon(ahead, intent.footprint_m))
        for other in intents:
            if other.namespace == intent.namespace:
                continue
            theirs = footprint_polygon(other.pose_xyyaw, other.footprint_m)
            near = sweep.distance(theirs)
            if near < self.safety_m and near < here.distance(theirs) - 1e-3:
                return True
        return False

    def _at(self, intent: Intent, xy: tuple[float, float] | None) -> bool:
        return xy is not None and bool(
            np.hypot(intent.pose_xyyaw[0] - xy[0], intent.pose_xyyaw[1] - xy[1]) <= self.config.reach_m
        )

    def _limit(self, graph: RouteGraph, route: Route, intent: Intent, last: int) -> float | None:
        """Speed limit that stops the robot on vertex ``last`` (the last one it may enter)."""
        xy = np.asarray(intent.pose_xyyaw[:2])
        pts = graph.xy[route.nodes[route.progress + 1 : last + 1]]
        if len(pts):
            rest = float(np.linalg.norm(pts[0] - xy) + np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
        else:
            rest = 0.0
        if rest <= 0.5 * self.config.reach_m:
            return 0.0
        if rest >= self.config.brake_m:
            return None
        return max(0.05, self.config.speed_mps * rest / self.config.brake_m)

    def _check_deadlock(self, t_ns: int, waits: dict[str, list[str]], movers: list[Intent]) -> None:
        """Count a deadlock (and replan at the next tick) on a wait-for cycle, a wait longer than
        deadlock_after_s, or a standstill: no robot with a goal has moved for deadlock_after_s (their
        plans all stand still: no wait-for edge says why). The replan plans around the robots that
        stopped; after a standstill the robot planned first goes last (the persisted order is what
        held them: 4 robots, seed 0, two trucks side by side closer than the safety distance)."""
        bound = self.config.deadlock_after_s * NS_PER_S
        busy = [i.namespace for i in movers if i.priority < IDLE_PRIORITY]
        standstill = len(busy) >= 2 and all(
            t_ns - max(self._robots[n].moved_at_ns, self._standstill_ns) > bound for n in busy
        )
        if standstill:
            self._standstill_ns = t_ns
            order = self.state.plan.order
            self.state.plan.order = order[1:] + order[:1]
        long_wait = any(
            (r := self._robots[ns]).waiting_since_ns is not None
            and t_ns - r.waiting_since_ns > bound
            and all(t_ns - self._robots[h].moved_at_ns > bound for h in holders if h in self._robots)
            for ns, holders in waits.items()
        )
        if wait_cycles(waits) or long_wait or standstill:
            self.state.deadlocks += 1
            self._force_replan = True
            for r in self._robots.values():
                r.waiting_since_ns = None
