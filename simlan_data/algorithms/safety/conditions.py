"""Inputs, conditions and outputs of a robot's safety tree (pure functions over estimates)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.safety.geometry import (
    Approach,
    Footprint,
    Pose2D,
    Zone,
    approach,
    centre_velocity,
    circumradius,
    footprint_centre,
    footprint_polygon,
    path_ahead,
    stopping_distance_m,
    swept_path,
    swept_rollout,
    tail_first,
)
from simlan_data.algorithms.safety.params import TreeParams

DRIVE, SLOW, STOP = "drive", "slow", "stop"


@dataclass(frozen=True)
class RobotSpec:
    """What the safety layer knows about an agent: its footprint and how fast it means to go."""

    namespace: str
    footprint: Footprint
    cruise_mps: float = 1.0
    kind: str = "robot"  # robot | person | static


@dataclass(frozen=True)
class RobotEstimate:
    """GPSS's knowledge of one robot at a control tick (the localizer's output)."""

    pose: Pose2D | None  # None: no valid estimate
    speed_mps: float = 0.0
    yaw_rate_rps: float = 0.0
    sigma_xy_m: float = 0.0
    fix_age_s: float = -1.0  # time since the image of the newest fix; < 0: never seen
    last_pose: Pose2D | None = None  # where it was last known (spawn pose before the first fix)


@dataclass(frozen=True)
class Mover:
    """Another agent as a robot's tree sees it: a circle moving at constant velocity."""

    name: str
    x_m: float
    y_m: float
    vx_mps: float
    vy_mps: float
    radius_m: float


@dataclass
class SafetyWorld:
    """Everything the layer reads at one control tick."""

    stamp_ns: int
    estimates: dict[str, RobotEstimate]
    contacts: dict[str, tuple[float, tuple[str, ...]]] = field(default_factory=dict)  # max force, bodies
    people: list[Mover] = field(default_factory=list)
    plans: dict[str, NDArray[np.float64] | None] = field(default_factory=dict)
    navigating: dict[str, bool] = field(default_factory=dict)
    # robots whose plan (the part ahead, as ``plans`` gives it) is driven backwards
    reversing: dict[str, bool] = field(default_factory=dict)


@dataclass(frozen=True)
class Finding:
    cause: str
    detail: str
    other: str = ""
    ttc_s: float = float("inf")
    cpa_m: float = float("inf")


@dataclass(frozen=True)
class SafetyDecision:
    state: str = DRIVE  # drive | slow | stop
    cause: str = ""  # what holds the robot ("" while it drives freely)
    speed_limit_mps: float | None = None
    detail: str = ""
    other: str = ""


FREE = SafetyDecision()


@dataclass(frozen=True)
class SafetyEvent:
    stamp_ns: int
    namespace: str
    cause: str
    action: str  # stop | slow | resume
    pose: Pose2D | None  # the estimate, or where the robot was last known if there is none
    speed_mps: float
    detail: str
    other: str = ""
    pose_valid: bool = True  # False: no valid estimate at that tick (pose is the last known one)


@dataclass(frozen=True)
class Monitor:
    """Values for the per-robot state topic (under the estimated motion)."""

    min_ttc_s: float = float("inf")
    cpa_m: float = float("inf")
    nearest_m: float = float("inf")
    nearest: str = ""
    zone_clearance_m: float = float("inf")


# ------------------------------------------------------------------------------- conditions


@dataclass
class SafetyContext:
    """One robot's inputs and state, shared by the behaviours of its tree."""

    spec: RobotSpec
    params: TreeParams
    zones: tuple[Zone, ...]
    stamp_ns: int = 0
    estimate: RobotEstimate = field(default_factory=lambda: RobotEstimate(None))
    contact: tuple[float, tuple[str, ...]] = (0.0, ())
    others: list[Mover] = field(default_factory=list)
    plan: NDArray[np.float64] | None = None  # the last plan seen (kept when navigation drops it)
    navigating: bool = False
    reversing: bool = False  # its plan ahead is driven backwards (its tail leads)
    held: SafetyDecision = FREE
    finding: Finding | None = None
    decision: SafetyDecision = FREE
    latched: Finding | None = None
    last_hazard_ns: int | None = None

    @property
    def intended(self) -> bool:
        """True while held: look at the motion it would make if released."""
        return self.held.state != DRIVE

    def direction(self) -> NDArray[np.float64] | None:
        """Unit vector the robot would set off in: along its plan, else its heading."""
        pose = self.estimate.pose
        if pose is None:
            return None
        if self.plan is not None:
            ahead = path_ahead(self.plan, pose[0], pose[1], 1.0)
            d = ahead[-1] - ahead[0]
            n = float(np.hypot(d[0], d[1]))
            if n > 0.05:
                return np.asarray(d / n)
        return np.array([np.cos(pose[2]), np.sin(pose[2])])


def contact(ctx: SafetyContext) -> Finding | None:
    force, bodies = ctx.contact
    if force >= ctx.params.config.collision.force_threshold_n and force > 0:
        who = ", ".join(bodies) or "something"
        return Finding("collision", f"contact {force:.0f} N with {who}", bodies[0] if bodies else "")
    return None


def unobserved(ctx: SafetyContext) -> Finding | None:
    age, timeout = ctx.estimate.fix_age_s, ctx.params.config.observability.timeout_s
    if age < 0:
        return Finding("unobserved", "never seen by a camera")
    if age > timeout:
        return Finding("unobserved", f"no camera fix for {age:.2f} s (timeout {timeout:g} s)")
    return None


def swept_region(ctx: SafetyContext) -> Any:
    """The area the robot's footprint may cover before it stands still (grown by the margins)."""
    p = ctx.params.config.restricted_area
    est = ctx.estimate
    assert est.pose is not None
    reaction = ctx.params.reaction_s
    pose, footprint = est.pose, ctx.spec.footprint
    if ctx.intended and ctx.navigating and ctx.reversing:
        pose, footprint = tail_first(pose, footprint)  # the same rectangle: it sets off backwards
    if ctx.intended and ctx.navigating and ctx.plan is not None:
        length = stopping_distance_m(ctx.spec.cruise_mps, p.decel_mps2, reaction) + p.lookahead_m
        region = swept_path(pose, footprint, path_ahead(ctx.plan, pose[0], pose[1], length))
    else:
        speed = est.speed_mps
        if ctx.intended and ctx.navigating:
            speed = max(abs(speed), ctx.spec.cruise_mps)
        region = swept_rollout(
            pose,
            footprint,
            speed,
            est.yaw_rate_rps,
            decel_mps2=p.decel_mps2,
            reaction_s=reaction,
            lookahead_m=p.lookahead_m,
        )
    return region.buffer(p.margin_m + p.sigma_k * est.sigma_xy_m)


def enters_zone(ctx: SafetyContext) -> Finding | None:
    if ctx.estimate.pose is None or not ctx.zones:
        return None
    region = swept_region(ctx)
    now = footprint_polygon(ctx.estimate.pose, ctx.spec.footprint)
    for zone in ctx.zones:
        if region.intersects(zone.polygon):
            gap = float(now.distance(zone.polygon))
            where = "inside" if gap <= 0 else f"{gap:.2f} m ahead"
            return Finding("restricted_area", f"zone '{zone.name}' {where}", zone.name)
    return None


def _own_motion(ctx: SafetyContext) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    est = ctx.estimate
    if est.pose is None:
        return None
    centre = footprint_centre(est.pose, ctx.spec.footprint)
    velocity = centre_velocity(est.pose, ctx.spec.footprint, est.speed_mps, est.yaw_rate_rps)
    if ctx.intended:
        direction = ctx.direction()
        if ctx.navigating and direction is not None:
            velocity = direction * max(ctx.spec.cruise_mps, float(np.hypot(*velocity)))
    return centre, velocity


def worst_approach(ctx: SafetyContext, level: str) -> Finding | None:
    """The other agent with the smallest TTC among those within SIMLAN's hazard rule.

    Only hazards that stopping helps with count: if the robot standing still would meet the
    other as soon or sooner (being caught up from behind, or already standing), the hazard is
    the other's to avoid (SIMLAN's rule, on relative velocity alone, stops the robot in front of
    a faster one too, which only brings the collision forward).
    """
    own = _own_motion(ctx)
    if own is None:
        return None
    centre, velocity = own
    p = ctx.params.config.ttc
    limit_s = p.stop_ttc_s if level == STOP else p.slow_ttc_s
    radius = circumradius(ctx.spec.footprint)
    best: Finding | None = None

    def hazard(a: Approach, contact_m: float) -> bool:
        return a.t_cpa_s >= 0 and a.cpa_m <= max(p.stop_cpa_m, contact_m) and a.ttc_s <= limit_s

    for other in ctx.others:
        contact_m = radius + other.radius_m
        where, v_other = np.array([other.x_m, other.y_m]), np.array([other.vx_mps, other.vy_mps])
        a = approach(centre, velocity, where, v_other, contact_m)
        if not hazard(a, contact_m):
            continue
        standing = approach(centre, np.zeros(2), where, v_other, contact_m)
        if hazard(standing, contact_m) and standing.ttc_s <= a.ttc_s:
            continue  # stopping would not help: the other must avoid it
        if best is None or a.ttc_s < best.ttc_s:
            best = Finding(
                "ttc",
                f"cpa {a.cpa_m:.2f} m in {a.ttc_s:.2f} s with {other.name}",
                other.name,
                a.ttc_s,
                a.cpa_m,
            )
    return best


def monitor(ctx: SafetyContext) -> Monitor:
    """TTC, nearest agent and zone clearance under the estimated motion (for the state topic)."""
    est = ctx.estimate
    if est.pose is None:
        return Monitor()
    centre = footprint_centre(est.pose, ctx.spec.footprint)
    velocity = centre_velocity(est.pose, ctx.spec.footprint, est.speed_mps, est.yaw_rate_rps)
    radius = circumradius(ctx.spec.footprint)
    ttc, cpa, nearest, who = float("inf"), float("inf"), float("inf"), ""
    for o in ctx.others:
        a = approach(
            centre, velocity, np.array([o.x_m, o.y_m]), np.array([o.vx_mps, o.vy_mps]), radius + o.radius_m
        )
        if a.distance_m < nearest:
            nearest, who = a.distance_m, o.name
        if a.t_cpa_s >= 0 and a.ttc_s < ttc:
            ttc, cpa = a.ttc_s, a.cpa_m
    now = footprint_polygon(est.pose, ctx.spec.footprint)
    clearance = min((float(now.distance(z.polygon)) for z in ctx.zones), default=float("inf"))
    return Monitor(ttc, cpa, nearest, who, clearance)


def transition_events(
    before: dict[str, SafetyDecision], decisions: dict[str, SafetyDecision], world: SafetyWorld
) -> list[SafetyEvent]:
    """The events of a monitor that keeps none: each change of a robot's state or cause (as the
    built-in writes them: action stop | slow | resume, where the robot was, what held it)."""
    out = []
    for ns, decision in decisions.items():
        last = before.get(ns, FREE)
        if (decision.state, decision.cause) == (last.state, last.cause):
            continue
        est = world.estimates.get(ns, RobotEstimate(None))
        driving = decision.state == DRIVE
        out.append(
            SafetyEvent(
                world.stamp_ns,
                ns,
                decision.cause or last.cause,
                "resume" if driving else decision.state,
                est.pose or est.last_pose,
                est.speed_mps,
                decision.detail,
                last.other if driving else decision.other,
                est.pose is not None,
            )
        )
    return out
