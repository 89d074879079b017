"""The GPSS loop without the simulator: localize from cameras, coordinate, plan, follow.

Data flow::

    camera tick:  JPEG per camera --> Localizer (detect, fuse) --> fixes
    control tick: Localizer.estimate --> poses --> Coordinator (who waits) --> Navigator per robot
                  --> (v, w) per robot;  people (walkers) walk their waypoints on their own

Robots never see ground truth unless ``localization.source=ground_truth`` is asked for.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray
from shapely.geometry import MultiPolygon, Polygon
from shapely.ops import unary_union

from ..agent_types import MARKER_SIZE_M, AgentType
from ..geometry.camera import CameraModel
from .coordinator import Coordinator, Decision, Intent, footprint_polygon, swept_claim
from .follower import FollowerParams, PursuitParams, WaypointFollower
from .localization import ImageSearch, Localizer, LocalizerParams, PoseEstimate
from .markers import MarkerMount
from .navigation import Navigator
from .occupancy import OccupancyGrid
from .planner import GridPlanner


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


@dataclass
class ControlOutput:
    commands: dict[str, tuple[float, float]] = field(default_factory=dict)
    estimates: dict[str, PoseEstimate] = field(default_factory=dict)
    decisions: dict[str, Decision] = field(default_factory=dict)


class GpssStack:
    """Localization, coordination and navigation for every agent of a run."""

    def __init__(
        self,
        agents: list[AgentPlan],
        cameras: dict[str, CameraModel],
        grid: OccupancyGrid,
        *,
        nav: NavigationParams,
        loc: LocalizerParams,
        source: str = "camera",
    ) -> None:
        self.agents = {a.namespace: a for a in agents}
        self.grid, self.nav, self.source = grid, nav, source
        mounts = [
            MarkerMount(
                a.namespace,
                a.marker_id,
                MARKER_SIZE_M,
                a.kind.marker_xyz[2],
                (a.kind.marker_xyz[0], a.kind.marker_xyz[1]),
            )
            for a in agents
            if a.kind.marker_xyz is not None and a.marker_id is not None and a.kind.drive == "diff"
        ]
        self.localizer = Localizer(cameras, mounts, loc)
        self.coordinator = Coordinator(safety_distance_m=nav.safety_distance_m)
        # the last pose GPSS knew of every robot: its spawn pose until the cameras first see it
        self.last_known: dict[str, tuple[float, float, float]] = {a.namespace: a.pose for a in agents}
        self.navigators: dict[str, Navigator] = {}
        self.walkers: dict[str, WaypointFollower] = {}
        planners: dict[float, GridPlanner] = {}
        for a in agents:
            if a.kind.drive == "diff":
                radius = round(a.kind.half_width_m + nav.clearance_m, 3)
                planner = planners.setdefault(radius, GridPlanner(grid, radius_m=radius))
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

    # ------------------------------------------------------------------------------- cameras
    def camera_frame(
        self, t_ns: int, camera_id: str, *, jpeg: bytes | None = None, gray: NDArray[np.uint8] | None = None
    ) -> str | None:
        """Let the localizer search one image; returns "full"/"roi" if it did, None if it skipped."""
        if self.source != "camera" or camera_id not in self.localizer.cameras:
            return None  # a camera the localizer was not given (an injected fault)
        plan = self.localizer.search_plan(t_ns, camera_id)
        if not plan:
            return None
        self.localizer.process_image(t_ns, camera_id, jpeg=jpeg, gray=gray)
        return "full" if plan == "full" else "roi"

    def search_plan(self, t_ns: int, camera_id: str) -> str | list | None:
        """Where the localizer will search this camera's image at ``t_ns`` (None: it will not)."""
        if self.source != "camera" or camera_id not in self.localizer.cameras:
            return None  # not a localizer camera (e.g. dropped by a fault): recorded, never searched
        return self.localizer.search_plan(t_ns, camera_id) or None

    def camera_detections(self, t_ns: int, camera_id: str, plan: str | list, found: ImageSearch) -> str:
        """Take what :meth:`Localizer.detect` found in a planned image (in camera order)."""
        self.localizer.observe(t_ns, camera_id, plan, found)
        return "full" if plan == "full" else "roi"

    def close_camera_tick(self, t_ns: int) -> None:
        if self.source == "camera":
            self.localizer.close_frame(t_ns)

    # ------------------------------------------------------------------------------- control
    def control(self, t_ns: int, dt_s: float, truth: dict[str, tuple[float, float, float]]) -> ControlOutput:
        """Commands for every agent. ``truth`` is used only for people and ``source=ground_truth``."""
        out = ControlOutput()
        if self.source == "camera":
            out.estimates = self.localizer.estimate(t_ns)
            poses = {ns: (e.x_m, e.y_m, e.yaw_rad) for ns, e in out.estimates.items() if e.valid}
        else:
            poses = {ns: truth[ns] for ns in self.navigators}
        self.last_known.update(poses)
        intents = []
        for ns, nav in self.navigators.items():
            if ns in poses:
                intent = nav.intent(poses[ns], self.agents[ns].number, self.agents[ns].kind.footprint_m)
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
        for ns in self.walkers:
            intents.append(Intent(ns, 10**6, truth[ns], self.agents[ns].kind.footprint_m, None, yields=False))
        if self.nav.coordination:
            out.decisions = self.coordinator.decide(t_ns, intents)
        for ns, nav in self.navigators.items():
            decision = out.decisions.get(ns)
            if decision is not None and decision.replan and ns in poses:
                self._detour(ns, poses[ns], [i for i in intents if i.namespace != ns])
            out.commands[ns] = nav.step(poses.get(ns), dt_s, decision)
        for ns, walker in self.walkers.items():
            x, y, yaw = truth[ns]
            cmd = walker.step(x, y, yaw, dt_s)
            out.commands[ns] = (cmd.linear_mps, cmd.angular_rps)
        return out

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
        c = self.coordinator
        obstacles = unary_union(
            [
                swept_claim(o, horizon_m=c.horizon_m, grow_m=0.5 * c.safety_distance_m)
                if o.namespace in c.granted
                else footprint_polygon(o.pose_xyyaw, o.footprint_m, grow_m=0.5 * c.safety_distance_m)
                for o in others
            ]
        )
        for margin in np.linspace(kind.half_width_m, reach, 5):
            plan = nav.detour(pose[0], pose[1], self._others_mask(ns, pose, others, margin))
            if plan is None:
                continue
            probe = Intent(ns, 0, pose, kind.footprint_m, plan.points_xy)
            length = float(np.sum(np.linalg.norm(np.diff(plan.points_xy, axis=0), axis=1)))
            claim = swept_claim(probe, horizon_m=length, grow_m=0.5 * c.safety_distance_m)
            # its own footprint now may touch others (that is why it waits): check the path ahead
            ahead = claim.difference(
                footprint_polygon(pose, kind.footprint_m, grow_m=0.5 * c.safety_distance_m)
            )
            if not ahead.intersects(obstacles):
                nav.adopt(plan)
                return True
        return False

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
            moving = other.namespace in self.coordinator.granted
            shape = (
                swept_claim(other, horizon_m=self.coordinator.horizon_m, grow_m=grow)
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
