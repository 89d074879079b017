"""The GPSS loop without the simulator: localize from cameras, coordinate, plan, follow.

Data flow::

    camera tick:  JPEG per camera --> Localizer (detect, fuse) --> fixes
                  JPEG (or segmentation, the oracle) per camera --> PersonDetector (robots'
                  boxes at the last control tick removed) --> fused people --> PersonTracker
    control tick: Localizer.estimate --> poses --> Coordinator (who waits) --+
                  estimates, contacts, tracked people, plans --> SafetyMonitor -+--> Navigator per
                  robot (speed limits of both) --> (v, w) after the safety layer, per robot;
                  people (walkers) walk their waypoints on their own

Robots never see ground truth unless ``localization.source=ground_truth`` is asked for: other
robots come from the localizer, people from the cameras' person detector.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from shapely.geometry import MultiPolygon, Polygon
from shapely.ops import unary_union

from simlan_data.algorithms.aruco_localizer import ArucoLocalizer
from simlan_data.algorithms.coordinator import Decision, Intent, footprint_polygon, swept_claim
from simlan_data.algorithms.coverage import SeenFloor, robot_floors, seen_by_all
from simlan_data.algorithms.follower import FollowerParams, PursuitParams, WaypointFollower
from simlan_data.algorithms.gpss_coordinator import GpssCoordinator, GpssCoordinatorConfig
from simlan_data.algorithms.localization import ImageSearch, LocalizerParams, PoseEstimate
from simlan_data.algorithms.markers import MarkerMount
from simlan_data.algorithms.navigation import Navigator
from simlan_data.algorithms.occupancy import OccupancyGrid
from simlan_data.algorithms.people import (
    Footprint,
    PeopleParams,
    PersonDetection,
    PersonDetector,
    PersonTracker,
    fuse_people,
)
from simlan_data.algorithms.planner import GridPlanner, Plan
from simlan_data.algorithms.roles import (
    CameraFrame,
    CoordinatorContext,
    LocalizerContext,
    SafetyContext,
    searches,
)
from simlan_data.algorithms.safety import (
    FREE,
    STOP,
    Monitor,
    Mover,
    RobotEstimate,
    RobotSpec,
    SafetyDecision,
    SafetyEvent,
    SafetyWorld,
    clamp_command,
    mover_of,
    transition_events,
)
from simlan_data.geometry.camera import CameraModel
from simlan_data.world.agent_types import MARKER_SIZE_M, AgentType

DRIVE_KINDS = {"diff": "robot", "walker": "person", "static": "static"}
DEFAULT_CLAIM_HORIZON_M = 3.0  # a detour keeps clear of this much of a driving robot's plan
PERSON_FOOTPRINT = (-0.2, 0.2, -0.3, 0.3)  # the humanoid's footprint, for the coordinator


@dataclass(frozen=True)
class AgentPlan:
    """What the stack needs to know about one agent."""

    namespace: str
    number: int
    kind: AgentType
    marker_id: int | None
    goals: list[list[float]]
    speed_mps: float
    loop: bool = False
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)  # where it was spawned (known to GPSS)


@dataclass(frozen=True)
class NavigationParams:
    clearance_m: float = 0.4
    lookahead_m: float = 1.2
    goal_tolerance_m: float = 0.3
    max_yaw_rate_rps: float = 0.8
    coordination: bool = True
    safety_distance_m: float = 0.6
    unseen_cost: float = 25.0  # per metre of floor where no camera sees the robot (camera steering)


@dataclass
class ControlOutput:
    commands: dict[str, tuple[float, float]] = field(default_factory=dict)
    estimates: dict[str, PoseEstimate] = field(default_factory=dict)
    decisions: dict[str, Decision] = field(default_factory=dict)
    safety: dict[str, SafetyDecision] = field(default_factory=dict)


def _marker_mounts(agents: list[AgentPlan]) -> list[MarkerMount]:
    """Where each marked robot carries its marker: the ones the localizer must find."""
    return [
        MarkerMount(
            a.namespace,
            a.marker_id,
            MARKER_SIZE_M,
            a.kind.marker_xyz[2],
            (a.kind.marker_xyz[0], a.kind.marker_xyz[1]),
            a.kind.accel_mps2,
        )
        for a in agents
        if a.kind.marker_xyz is not None and a.marker_id is not None and a.kind.drive == "diff"
    ]


def robot_footprints(agents: Iterable[AgentPlan]) -> dict[str, Footprint]:
    """Every robot's and static agent's footprint: what the RGB person detector removes."""
    return {a.namespace: a.kind.footprint_m for a in agents if a.kind.drive in ("diff", "static")}


def robot_poses(
    agents: Iterable[AgentPlan], last_known: Mapping[str, tuple[float, float, float]]
) -> dict[str, tuple[float, float, float]]:
    """Where GPSS believes each robot (its last valid estimate, else its spawn pose) and each
    static agent (where it was placed)."""
    return {
        a.namespace: (last_known[a.namespace] if a.kind.drive == "diff" else a.pose)
        for a in agents
        if a.kind.drive in ("diff", "static")
    }


class GpssStack:
    """Localization, coordination and navigation for every agent of a run."""

    def __init__(
        self,
        agents: list[AgentPlan],
        cameras: dict[str, CameraModel],
        grid: OccupancyGrid,
        *,
        nav: NavigationParams,
        localizer: Callable[[LocalizerContext], Any] | None = None,
        coordinator: Callable[[CoordinatorContext], Any] | None = None,
        source: str = "camera",
        safety: Callable[[SafetyContext], Any] | None = None,
        people: PeopleParams | None = None,
        control_period_s: float = 0.05,
        camera_period_s: float = 0.2,
        processing_delay_s: float = 0.0,
    ) -> None:
        self.agents = {a.namespace: a for a in agents}
        self.grid, self.nav, self.source = grid, nav, source
        mounts = _marker_mounts(agents)
        self.cameras = cameras
        self.seen = self._seen_floors(agents)
        self.localized = [m.namespace for m in mounts]  # the robots the localizer must find
        make = localizer or (lambda ctx: ArucoLocalizer(LocalizerParams(), ctx))
        self.localizer = make(LocalizerContext(cameras, mounts))
        self.searching = searches(self.localizer)  # the optional fast path (see roles)
        self._frames: dict[str, CameraFrame] = {}
        make_coordinator = coordinator or (lambda ctx: GpssCoordinator(GpssCoordinatorConfig(), ctx))
        self.coordinator = make_coordinator(
            CoordinatorContext(
                safety_distance_m=nav.safety_distance_m,
                grid=grid,
                seen=None if not self.seen else seen_by_all(self.seen.values()).by_heading,
            )
        )
        self._granted: set[str] = set()  # robots the coordinator let drive at the last decision
        # the last pose GPSS knew of every robot: its spawn pose until the cameras first see it
        self.last_known: dict[str, tuple[float, float, float]] = {a.namespace: a.pose for a in agents}
        self._build_navigators(agents)
        self._build_safety(agents, safety, control_period_s, camera_period_s, processing_delay_s)
        self._speeds: dict[str, tuple[float, float]] = {}  # last command per robot (ground-truth source)
        self._build_person_detector(people)

    def _seen_floors(self, agents: list[AgentPlan]) -> dict[tuple[float, float, float], SeenFloor]:
        """Per marker mount of the robots: the floor where the cameras see it (``coverage``), when
        robots steer on the cameras and ``unseen_cost`` > 0; else none (every floor counts)."""
        if self.source != "camera" or not self.cameras or self.nav.unseen_cost <= 0:
            return {}
        kinds = [a.kind for a in agents]
        return robot_floors(self.grid, self.cameras.values(), kinds, clearance_m=self.nav.clearance_m)

    def _build_navigators(self, agents: list[AgentPlan]) -> None:
        """Give every robot a navigator (planners shared per radius and marker mount) and every
        person a walker."""
        nav = self.nav
        self.navigators: dict[str, Navigator] = {}
        self.walkers: dict[str, WaypointFollower] = {}
        planners: dict[tuple[float, Any], GridPlanner] = {}
        for a in agents:
            if a.kind.drive == "diff":
                radius = round(a.kind.half_width_m + nav.clearance_m, 3)
                seen = self.seen.get(a.kind.marker_xyz) if a.kind.marker_xyz is not None else None
                key = (radius, a.kind.marker_xyz if seen is not None else None)
                if key not in planners:
                    planners[key] = GridPlanner(
                        self.grid,
                        radius_m=radius,
                        seen=None if seen is None else seen.by_heading,
                        unseen_cost=nav.unseen_cost,
                    )
                planner = planners[key]
                pursuit = PursuitParams(
                    max_speed_mps=min(a.speed_mps, a.kind.max_speed_mps),
                    min_lookahead_m=0.6 * nav.lookahead_m,
                    max_lookahead_m=1.6 * nav.lookahead_m,
                    max_yaw_rate_rps=min(nav.max_yaw_rate_rps, a.kind.max_yaw_rate_rps),
                    goal_tolerance_m=nav.goal_tolerance_m,
                )
                self.navigators[a.namespace] = Navigator(a.namespace, a.goals, planner, pursuit, loop=a.loop)
            elif a.kind.drive == "walker":
                self.walkers[a.namespace] = WaypointFollower(
                    a.goals,
                    FollowerParams(speed_mps=a.speed_mps, max_yaw_rate_rps=2.5, turn_in_place_rad=1.2),
                    loop=a.loop,
                )

    def _build_safety(
        self,
        agents: list[AgentPlan],
        safety: Callable[[SafetyContext], Any] | None,
        control_period_s: float,
        camera_period_s: float,
        processing_delay_s: float,
    ) -> None:
        """Describe every agent to the safety monitor (specs, static obstacles) and build it."""
        specs = {
            a.namespace: RobotSpec(
                a.namespace,
                a.kind.footprint_m,
                min(a.speed_mps, a.kind.max_speed_mps),
                DRIVE_KINDS.get(a.kind.drive, "static"),
            )
            for a in agents
        }
        static = [
            m
            for a in agents
            if a.kind.drive == "static"
            and (m := mover_of(specs[a.namespace], RobotEstimate(a.pose))) is not None
        ]
        self.specs = specs
        # the safety monitor (None: no safety layer); its context carries what the run adds
        run = SafetyContext(
            list(specs.values()),
            static,
            control_period_s,
            camera_period_s,
            processing_delay_s,
            self.nav.coordination,
        )
        self.safety = safety(run) if safety is not None else None
        # the events published on /safety/events: the monitor's own (``events``) where it keeps
        # them (the built-in), else each change of a robot's state or cause (transition_events)
        own_events = getattr(self.safety, "events", None)
        self.safety_events: list[SafetyEvent] = own_events if own_events is not None else []
        self._derive_events = self.safety is not None and own_events is None
        self._safety_state: dict[str, SafetyDecision] = {}  # the last decision per robot
        self._cancelled: set[str] = set()

    def _build_person_detector(self, people: PeopleParams | None) -> None:
        """Build the person detector and tracker (people carry no marker: GPSS finds them in the
        cameras' images, every robot's and static agent's body box removed: robot_boxes)."""
        self.people_params = people or PeopleParams(enabled=False)
        self.person_detector = (
            PersonDetector(self.cameras, self.people_params, robot_footprints(self.agents.values()))
            if self.people_params.enabled and self.source == "camera" and self.walkers
            else None
        )
        # where GPSS believed the robots at the last control tick (what the detector removes)
        self._robot_poses = robot_poses(self.agents.values(), self.last_known)
        self.person_tracker = PersonTracker(self.people_params)
        self._people_frame: list[PersonDetection] = []
        self._walked: list[tuple[float, float]] = []  # people who walked, at the last camera tick
        self.last_people: list[tuple[float, float]] | None = None  # fused at the last camera tick

    # ------------------------------------------------------------------------------- cameras
    def search_plan(self, t_ns: int, camera_id: str) -> str | list | None:
        """Where the localizer will search this camera's image at ``t_ns`` (None: it will not)."""
        if self.source != "camera" or camera_id not in self.cameras or not self.searching:
            return None  # not a localizer camera (e.g. dropped by a fault): recorded, never searched
        return self.localizer.search_plans(t_ns, [camera_id])[0] or None

    def wants_frames(self, camera_id: str) -> bool:
        """True if the localizer takes this camera's frames whole (no searching protocol)."""
        return self.source == "camera" and camera_id in self.cameras and not self.searching

    def camera_image(self, frame: CameraFrame) -> None:
        """Hand one camera's frame to a localizer without the searching protocol (camera order)."""
        self._frames[frame.camera_id] = frame

    def camera_detections(self, t_ns: int, camera_id: str, plan: str | list, found: ImageSearch) -> str:
        """Take what :meth:`Localizer.detect` found in a planned image (in camera order)."""
        self.localizer.observe_search(t_ns, camera_id, plan, found)
        return "full" if plan == "full" else "roi"

    @property
    def people_reads(self) -> str | None:
        """What the person detector reads: ``rgb`` (colour images), ``segmentation_oracle``
        (segmentation images) or None (no detector)."""
        return None if self.person_detector is None else self.person_detector.params.detector

    def people_frame(
        self, camera_id: str, labels: NDArray[np.uint8] | None, frame: CameraFrame | None = None
    ) -> None:
        """Let the person detector look at one camera's image (colour: ``frame``, decoded from the
        recorded JPEG; segmentation: ``labels``), robots where GPSS believed them at the last
        control tick."""
        if self.person_detector is not None and camera_id in self.cameras:
            bgr = None if frame is None else frame.bgr
            found = self.person_detector.detect(
                camera_id, labels=labels, bgr=bgr, robot_poses=self._robot_poses, people_xy=self._walked
            )
            self._people_frame.extend(found)

    def close_camera_tick(self, t_ns: int) -> None:
        if self.source == "camera" and self.searching:
            self.localizer.close_frame(t_ns)
        elif self.source == "camera":
            frames, self._frames = self._frames, {}
            self.localizer.observe(t_ns, frames)
        if self.person_detector is not None:
            self.last_people = fuse_people(self._people_frame, self.people_params.cluster_m)
            self._people_frame = []
            self.person_tracker.update(t_ns, self.last_people)
            self._walked = self.person_tracker.walked(t_ns)

    def robot_estimates(
        self, estimates: dict[str, PoseEstimate], truth: dict[str, tuple[float, float, float]]
    ) -> dict[str, RobotEstimate]:
        """What GPSS knows of every robot, as the safety layer reads it."""
        out = {}
        for ns in self.navigators:
            if self.source != "camera":
                v, w = self._speeds.get(ns, (0.0, 0.0))
                out[ns] = RobotEstimate(truth[ns], v, w, 0.0, 0.0, truth[ns])
                continue
            e = estimates.get(ns)
            if e is None:
                out[ns] = RobotEstimate(None, last_pose=self.last_known[ns])
                continue
            if not e.valid:  # withheld: only its age is known (what /<ns>/localization_status says)
                out[ns] = RobotEstimate(None, fix_age_s=e.age_s, last_pose=self.last_known[ns])
                continue
            sigma = float(np.sqrt(max(e.covariance[0, 0], e.covariance[1, 1])))
            pose = (e.x_m, e.y_m, e.yaw_rad)
            out[ns] = RobotEstimate(pose, e.speed_mps, e.yaw_rate_rps, sigma, e.age_s, self.last_known[ns])
        return out

    # ------------------------------------------------------------------------------- control
    def control(
        self,
        t_ns: int,
        dt_s: float,
        truth: dict[str, tuple[float, float, float]],
        contacts: dict[str, tuple[float, tuple[str, ...]]] | None = None,
    ) -> ControlOutput:
        """Commands for every agent, after the safety layer. ``truth`` moves the people (walkers)
        and steers robots only with ``source=ground_truth``; ``contacts`` are the robots' collision
        sensor readings (max force, bodies touched)."""
        out = ControlOutput()
        poses = self._poses(t_ns, truth, out)
        intents, people = self._intents(t_ns, poses, truth)
        if self.nav.coordination:
            out.decisions = self.coordinator.decide(t_ns, intents)
            self._granted = {ns for ns, d in out.decisions.items() if d.speed_limit_mps is None}
        if self.safety is not None and getattr(self.safety, "trees", True):
            self._safety_step(t_ns, out, truth, contacts, people)
        self._commands(out, poses, intents, truth, dt_s)
        self._speeds = dict(out.commands)
        return out

    def _poses(
        self, t_ns: int, truth: dict[str, tuple[float, float, float]], out: ControlOutput
    ) -> dict[str, tuple[float, float, float]]:
        """Read the robots' poses (the localizer's valid estimates, or ground truth) into last_known."""
        if self.source == "camera":
            out.estimates = self.localizer.estimate(t_ns)
            poses = {ns: (e.x_m, e.y_m, e.yaw_rad) for ns, e in out.estimates.items() if e.valid}
        else:
            poses = {ns: truth[ns] for ns in self.navigators}
        self.last_known.update(poses)
        self._robot_poses = robot_poses(self.agents.values(), self.last_known)
        return poses

    def _intents(
        self,
        t_ns: int,
        poses: dict[str, tuple[float, float, float]],
        truth: dict[str, tuple[float, float, float]],
    ) -> tuple[list[Intent], list[Mover]]:
        """Gather every robot's and person's intent for the coordinator, and the people seen."""
        intents = []
        for ns, nav in self.navigators.items():
            if ns in poses:
                intent = nav.intent(poses[ns], self.agents[ns].number, self.agents[ns].kind.footprint_m)
                if intent is not None and nav.goal is not None:  # a fleet coordinator routes to it
                    intent = replace(intent, goal_xy=(float(nav.goal[0]), float(nav.goal[1])))
            else:  # not localized: it stands still where it was last known, others keep clear
                intent = Intent(
                    ns,
                    self.agents[ns].number,
                    self.last_known[ns],
                    self.agents[ns].kind.footprint_m,
                    None,
                    yields=False,
                )
            if intent is not None:
                intents.append(intent)
        people = self.person_tracker.people(t_ns) if self.person_detector is not None else []
        if self.source != "camera":  # steering on ground truth: people too
            for ns in self.walkers:
                intents.append(
                    Intent(ns, 10**6, truth[ns], self.agents[ns].kind.footprint_m, None, yields=False)
                )
                v, w = self._speeds.get(ns, (0.0, 0.0))
                est = RobotEstimate(truth[ns], v, w, 0.0, 0.0, truth[ns])
                if (m := mover_of(self.specs[ns], est)) is not None:
                    people.append(m)
        for person in people:  # where the cameras see people (never their ground truth)
            heading = float(np.arctan2(person.vy_mps, person.vx_mps))
            intents.append(
                Intent(
                    person.name,
                    10**6,
                    (person.x_m, person.y_m, heading),
                    PERSON_FOOTPRINT,
                    None,
                    yields=False,
                )
            )
        return intents, people

    def _safety_step(
        self,
        t_ns: int,
        out: ControlOutput,
        truth: dict[str, tuple[float, float, float]],
        contacts: dict[str, tuple[float, tuple[str, ...]]] | None,
        people: list[Mover],
    ) -> None:
        """Build the safety world of this tick, step the monitor on it and record its events."""
        assert self.safety is not None
        ahead = {ns: nav.ahead() for ns, nav in self.navigators.items()}
        world = SafetyWorld(
            t_ns,
            self.robot_estimates(out.estimates, truth),
            dict(contacts or {}),
            people,
            {ns: ahead[ns][0] for ns in self.navigators},
            {ns: nav.goal is not None for ns, nav in self.navigators.items()},
            {ns: ahead[ns][1] for ns in self.navigators},
        )
        out.safety = self.safety.step(world)
        if self._derive_events:
            self.safety_events.extend(transition_events(self._safety_state, out.safety, world))
        self._safety_state.update(out.safety)

    def _commands(
        self,
        out: ControlOutput,
        poses: dict[str, tuple[float, float, float]],
        intents: list[Intent],
        truth: dict[str, tuple[float, float, float]],
        dt_s: float,
    ) -> None:
        """Step every navigator under its safety decision and coordination, then every walker."""
        for ns, nav in self.navigators.items():
            guard = out.safety.get(ns, FREE)
            if guard.state == STOP:  # zero command, navigation cancelled (replanned on resume)
                if ns not in self._cancelled:
                    nav.cancel()
                    self._cancelled.add(ns)
                out.commands[ns] = (0.0, 0.0)
                continue
            self._cancelled.discard(ns)
            decision = out.decisions.get(ns)
            if decision is not None and decision.path_xy is not None:
                self._follow_route(nav, decision)
            if decision is not None and decision.replan and ns in poses:
                self._detour(ns, poses[ns], [i for i in intents if i.namespace != ns])
            if guard.speed_limit_mps is not None:
                limits = [guard.speed_limit_mps] + (
                    [] if decision is None or decision.speed_limit_mps is None else [decision.speed_limit_mps]
                )
                # (the coordinator's other fields stay: a robot it holds must not turn in place)
                decision = (
                    replace(decision, speed_limit_mps=min(limits), replan=False)
                    if decision is not None
                    else Decision(min(limits))
                )
            v, w = nav.step(poses.get(ns), dt_s, decision)
            out.commands[ns] = clamp_command(guard, v, w)
        for ns, walker in self.walkers.items():
            x, y, yaw = truth[ns]
            cmd = walker.step(x, y, yaw, dt_s)
            out.commands[ns] = (cmd.linear_mps, cmd.angular_rps)

    @staticmethod
    def _follow_route(nav: Navigator, d: Decision) -> None:
        """Follow the coordinator's route (a fleet plan: ``path_xy``, segments driven backwards,
        vertices where it turns on the spot) unless it is the path followed already."""
        assert d.path_xy is not None
        if nav.goal is None:  # every goal done: the coordinator moves it out of the others' way
            nav.move_aside(d.path_xy, d.path_reverse, d.path_stops)
            return
        plan = nav.plan
        same_way = plan is not None and (plan.reverse, plan.stops) == (d.path_reverse, d.path_stops)
        if same_way and plan is not None and np.array_equal(plan.points_xy, d.path_xy):
            return
        length = float(np.sum(np.linalg.norm(np.diff(d.path_xy, axis=0), axis=1)))
        nav.adopt(Plan(d.path_xy, length, 0, d.path_reverse, d.path_stops))

    def safety_states(self) -> dict[str, tuple[SafetyDecision, Monitor]]:
        """Every guarded robot's decision and state-topic values after the last control tick: the
        monitor's own ``decisions`` and ``monitors`` where it keeps them (the built-in), else its
        last decisions with no values."""
        monitors = getattr(self.safety, "monitors", None)
        decisions = getattr(self.safety, "decisions", None)
        if monitors is not None and decisions is not None:
            return {ns: (d, monitors[ns]) for ns, d in decisions.items() if ns in monitors}
        return {ns: (d, Monitor()) for ns, d in self._safety_state.items()}

    def _detour(self, ns: str, pose: tuple[float, float, float], others: list[Intent]) -> bool:
        """Plan ``ns`` around the others; adopt the plan only if the coordinator will let it drive.

        The detour must keep clear of the robots that drive on (their claims) and of the others'
        footprints. The planner keeps the robot's centre a margin away from them; a long robot
        swings its ends out in turns, so the margin grows from its half width to its
        circumradius until the swept footprint of the whole detour is clear.
        """
        nav, kind = self.navigators[ns], self.agents[ns].kind
        x0, x1, y0, y1 = kind.footprint_m
        reach = float(np.hypot(max(abs(x0), abs(x1)), max(abs(y0), abs(y1))))
        horizon, grow = self._claim_horizon_m(), 0.5 * self.nav.safety_distance_m
        obstacles = unary_union(
            [
                swept_claim(o, horizon_m=horizon, grow_m=grow)
                if o.namespace in self._granted
                else footprint_polygon(o.pose_xyyaw, o.footprint_m, grow_m=grow)
                for o in others
            ]
        )
        for margin in np.linspace(kind.half_width_m, reach, 5):
            plan = nav.detour(pose[0], pose[1], self._others_mask(ns, pose, others, margin))
            if plan is None:
                continue
            probe = Intent(ns, 0, pose, kind.footprint_m, plan.points_xy)
            length = float(np.sum(np.linalg.norm(np.diff(plan.points_xy, axis=0), axis=1)))
            claim = swept_claim(probe, horizon_m=length, grow_m=grow)
            # its own footprint now may touch others (that is why it waits): check the path ahead
            ahead = claim.difference(footprint_polygon(pose, kind.footprint_m, grow_m=grow))
            if not ahead.intersects(obstacles):
                nav.adopt(plan)
                return True
        return False

    def _claim_horizon_m(self) -> float:
        """How far ahead a driving robot claims the floor, for detours: the coordinator's own
        horizon where it has one (the built-in's ``horizon_m``), else 3 m."""
        return float(getattr(self.coordinator, "horizon_m", DEFAULT_CLAIM_HORIZON_M))

    def _others_mask(
        self, ns: str, pose: tuple[float, float, float], others: list[Intent], margin_m: float
    ) -> NDArray[np.bool_]:
        """Grid cells the centre of ``ns`` must avoid on a detour: where the others stand, and where
        the ones that drive on will drive, grown by ``margin_m`` plus the safety distance. The
        robot's own footprint is left free: it may stand closer than that to the robot it waits
        for and must be able to back away.
        """
        mask = np.zeros(self.grid.shape, dtype=np.uint8)
        grow = margin_m + self.nav.safety_distance_m
        for other in others:
            moving = other.namespace in self._granted
            shape = (
                swept_claim(other, horizon_m=self._claim_horizon_m(), grow_m=grow)
                if moving
                else footprint_polygon(other.pose_xyyaw, other.footprint_m, grow_m=grow)
            )
            self._fill(mask, shape, 1)
        self._fill(mask, footprint_polygon(pose, self.agents[ns].kind.footprint_m), 0)
        return mask.astype(bool)

    def _fill(self, mask: NDArray[np.uint8], shape: Polygon | MultiPolygon, value: int) -> None:
        x0, y0 = self.grid.origin_xy_m
        for poly in getattr(shape, "geoms", [shape]):
            pts = np.asarray(poly.exterior.coords)[:, :2]
            px = np.stack(
                [(pts[:, 0] - x0) / self.grid.resolution_m, (pts[:, 1] - y0) / self.grid.resolution_m], axis=1
            )
            cv2.fillPoly(mask, [np.round(px).astype(np.int32)], value)
