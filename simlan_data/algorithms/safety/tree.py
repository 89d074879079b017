"""Safety layer: one behaviour tree per robot (py_trees), ticked at the control rate.

Data flow per control tick (the live run and the replay build the same ``SafetyWorld``)::

    localizer estimates (pose, speed, fix age) of every robot --+
    collision sensor reading of every robot                      |
    people tracked from the cameras (people.py)                  +--> SafetyLayer.step
    plans and navigation state                                  --+        |
                                                 one tree per robot, highest priority first:
    Selector "<ns> safety" (memory=False)
      Sequence "latched"     Latched?         -> Stop        (a stop whose resume policy is never)
      Sequence "collision"   Contact?         -> Stop        contact force above the threshold
      Sequence "unobserved"  Unobserved?      -> Stop        no camera fix for longer than the timeout
      Sequence "restricted"  EntersZone?      -> Stop        footprint grown by the stopping distance
      Sequence "ttc stop"    TtcHazard(stop)? -> Stop        CPA <= 2 m and TTC <= 2 s (SIMLAN)
      Sequence "ttc slow"    TtcHazard(slow)? -> Slow        a hazard further out: 0.4 m/s
      Sequence "resume"      ClearFor(hold)?  -> Drive
      KeepHeld                                               clear, but not for long enough yet
                                                        |
                               SafetyDecision per robot (drive | slow | stop) + SafetyEvents

The conditions look at the robot's *estimated* motion while it drives freely, and at the motion it
would make if released (its cruise speed along its plan) while it is held, so that it is released
only when driving on would be clear. Everything runs on estimates, never on ground truth.

Each tree holds its inputs in a plain per-robot context object rather than on the py_trees
blackboard: the blackboard is one store per process, and the replay runs live and
counterfactual trees side by side.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import py_trees
from numpy.typing import NDArray
from py_trees.common import Status

from simlan_data.algorithms.safety.conditions import (
    DRIVE,
    FREE,
    SLOW,
    STOP,
    Finding,
    Monitor,
    Mover,
    RobotEstimate,
    RobotSpec,
    SafetyContext,
    SafetyDecision,
    SafetyEvent,
    SafetyWorld,
    contact,
    enters_zone,
    monitor,
    unobserved,
    worst_approach,
)
from simlan_data.algorithms.safety.geometry import centre_velocity, circumradius, footprint_centre
from simlan_data.algorithms.safety.params import TreeParams, TreesConfig
from simlan_data.constants import NS_PER_S

# ----------------------------------------------------------------------------- behaviours


class _Check(py_trees.behaviour.Behaviour):
    """Condition node: SUCCESS when ``check`` finds a hazard (kept in the context for the action)."""

    def __init__(
        self, name: str, ctx: SafetyContext, check: Callable[[SafetyContext], Finding | None]
    ) -> None:
        super().__init__(name)
        self.ctx, self.check = ctx, check

    def update(self) -> Status:
        finding = self.check(self.ctx)
        if finding is None:
            return Status.FAILURE
        self.ctx.finding = finding
        return Status.SUCCESS


class _Hold(py_trees.behaviour.Behaviour):
    """Action node: stop (zero command, navigation cancelled) or slow the robot."""

    def __init__(self, name: str, ctx: SafetyContext, state: str, speed_mps: float | None) -> None:
        super().__init__(name)
        self.ctx, self.state, self.speed = ctx, state, speed_mps

    def update(self) -> Status:
        ctx, finding = self.ctx, self.ctx.finding
        assert finding is not None
        t = ctx.stamp_ns
        ctx.last_hazard_ns = t
        if self.state == STOP:
            if ctx.latched is None and ctx.params.config.condition(finding.cause).resume == "never":
                ctx.latched = finding
        elif ctx.held.state == STOP:
            # a stopped robot is not let off to crawl towards a hazard that is still there (it would
            # creep on, stop, creep on...): it stays stopped until everything is clear for hold_s
            ctx.decision = ctx.held
            return Status.SUCCESS
        ctx.decision = SafetyDecision(
            self.state,
            finding.cause,
            0.0 if self.state == STOP else self.speed,
            finding.detail,
            finding.other,
        )
        return Status.SUCCESS


class _Latched(py_trees.behaviour.Behaviour):
    def __init__(self, ctx: SafetyContext) -> None:
        super().__init__("Latched?")
        self.ctx = ctx

    def update(self) -> Status:
        if self.ctx.latched is None:
            return Status.FAILURE
        self.ctx.finding = self.ctx.latched
        return Status.SUCCESS


class _ClearFor(py_trees.behaviour.Behaviour):
    """SUCCESS when the robot is not held, or no hazard was seen for ``hold_s``."""

    def __init__(self, ctx: SafetyContext) -> None:
        super().__init__(f"ClearFor({ctx.params.config.hold_s:g} s)?")
        self.ctx = ctx

    def update(self) -> Status:
        ctx = self.ctx
        if ctx.held.state == DRIVE or ctx.last_hazard_ns is None:
            return Status.SUCCESS
        clear = ctx.stamp_ns - ctx.last_hazard_ns >= ctx.params.config.hold_s * NS_PER_S
        return Status.SUCCESS if clear else Status.FAILURE


class _Drive(py_trees.behaviour.Behaviour):
    def __init__(self, ctx: SafetyContext) -> None:
        super().__init__("Drive")
        self.ctx = ctx

    def update(self) -> Status:
        self.ctx.decision = FREE
        return Status.SUCCESS


class _KeepHeld(py_trees.behaviour.Behaviour):
    def __init__(self, ctx: SafetyContext) -> None:
        super().__init__("KeepHeld")
        self.ctx = ctx

    def update(self) -> Status:
        self.ctx.decision = self.ctx.held
        return Status.SUCCESS


def build_tree(ctx: SafetyContext) -> py_trees.composites.Selector:
    """The tree of one robot: only the branches of the conditions that apply to it."""
    ns, p = ctx.spec.namespace, ctx.params.config

    def branch(name: str, check: py_trees.behaviour.Behaviour, action: py_trees.behaviour.Behaviour) -> Any:
        return py_trees.composites.Sequence(name, memory=False, children=[check, action])

    children: list[py_trees.behaviour.Behaviour] = [
        branch("latched", _Latched(ctx), _Hold("Stop", ctx, STOP, 0.0))
    ]
    if p.applies(ns, "collision"):
        children.append(branch("collision", _Check("Contact?", ctx, contact), _Hold("Stop", ctx, STOP, 0.0)))
    if p.applies(ns, "unobserved"):
        children.append(
            branch("unobserved", _Check("Unobserved?", ctx, unobserved), _Hold("Stop", ctx, STOP, 0.0))
        )
    if p.applies(ns, "restricted_area") and ctx.zones:
        children.append(
            branch("restricted", _Check("EntersZone?", ctx, enters_zone), _Hold("Stop", ctx, STOP, 0.0))
        )
    if p.applies(ns, "ttc"):
        children.append(
            branch(
                "ttc stop",
                _Check("TtcHazard(stop)?", ctx, lambda c: worst_approach(c, STOP)),
                _Hold("Stop", ctx, STOP, 0.0),
            )
        )
        children.append(
            branch(
                "ttc slow",
                _Check("TtcHazard(slow)?", ctx, lambda c: worst_approach(c, SLOW)),
                _Hold("Slow", ctx, SLOW, p.ttc.slow_speed_mps),
            )
        )
    children.append(branch("resume", _ClearFor(ctx), _Drive(ctx)))
    children.append(_KeepHeld(ctx))
    return py_trees.composites.Selector(f"{ns} safety", memory=False, children=children)


class RobotSafetyTree:
    """One robot's tree and its context."""

    def __init__(self, spec: RobotSpec, params: TreeParams) -> None:
        zones = tuple(z for z in params.zones if z.applies_to(spec.namespace))
        self.ctx = SafetyContext(spec, params, zones)
        self.root = build_tree(self.ctx)
        self.tree = py_trees.trees.BehaviourTree(self.root)

    def tick(
        self,
        stamp_ns: int,
        estimate: RobotEstimate,
        *,
        contact_force: tuple[float, tuple[str, ...]] = (0.0, ()),
        others: Sequence[Mover] = (),
        plan: NDArray[np.float64] | None = None,
        navigating: bool = False,
        reversing: bool = False,
    ) -> SafetyDecision:
        ctx = self.ctx
        ctx.stamp_ns, ctx.estimate, ctx.contact = stamp_ns, estimate, contact_force
        ctx.others, ctx.navigating = list(others), navigating
        if plan is not None:
            ctx.plan, ctx.reversing = plan, reversing
        ctx.finding = None
        self.tree.tick()
        ctx.held = ctx.decision
        return ctx.decision

    def ascii(self) -> str:
        return str(py_trees.display.ascii_tree(self.root))


# ---------------------------------------------------------------------------------- layer


def mover_of(spec: RobotSpec, estimate: RobotEstimate) -> Mover | None:
    """A robot as the others see it: where GPSS believes it is, at its estimated velocity."""
    pose = estimate.pose or estimate.last_pose
    if pose is None:
        return None
    centre = footprint_centre(pose, spec.footprint)
    v = (
        centre_velocity(pose, spec.footprint, estimate.speed_mps, estimate.yaw_rate_rps)
        if estimate.pose is not None
        else np.zeros(2)
    )
    return Mover(
        spec.namespace,
        float(centre[0]),
        float(centre[1]),
        float(v[0]),
        float(v[1]),
        circumradius(spec.footprint),
    )


class SafetyLayer:
    """The trees of every guarded robot; turns per-tick snapshots into decisions and events.

    The built-in safety monitor, registered as ``safety.trees``: built from its one config
    (:class:`TreesConfig`) and the run's :class:`~simlan_data.algorithms.roles.SafetyContext`
    (robots, static obstacles, the run's clocks), like any plug-in. Beyond the protocol's ``step``
    it keeps ``events`` (appended at every change of a robot's state or cause), ``monitors`` (the
    values of each robot's state topic), ``trees`` and ``zones`` (published once).
    """

    role = "safety"
    config_class = TreesConfig

    def __init__(self, config: TreesConfig, context: Any) -> None:
        params = TreeParams.of(config, context)
        agents = list(context.robots)
        self.params = params
        self.zones = params.zones
        self.specs = {a.namespace: a for a in agents}
        self.static = list(context.static)
        self.trees = {
            a.namespace: RobotSafetyTree(a, params)
            for a in agents
            if a.kind == "robot" and config.applies(a.namespace)
        }
        self.decisions: dict[str, SafetyDecision] = dict.fromkeys(self.trees, FREE)
        self.monitors: dict[str, Monitor] = {}
        self.events: list[SafetyEvent] = []

    def step(self, world: SafetyWorld) -> dict[str, SafetyDecision]:
        """Tick every tree once; new events are appended to ``events``."""
        movers = {
            ns: m
            for ns, est in world.estimates.items()
            if ns in self.specs and (m := mover_of(self.specs[ns], est)) is not None
        }
        for ns, tree in self.trees.items():
            est = world.estimates.get(ns, RobotEstimate(None))
            robots = [m for o, m in movers.items() if o != ns] if self.params.ttc_against_robots() else []
            others = robots + list(world.people) + self.static
            before = self.decisions[ns]
            decision = tree.tick(
                world.stamp_ns,
                est,
                contact_force=world.contacts.get(ns, (0.0, ())),
                others=others,
                plan=world.plans.get(ns),
                navigating=world.navigating.get(ns, False),
                reversing=world.reversing.get(ns, False),
            )
            self.monitors[ns] = monitor(tree.ctx)
            self.decisions[ns] = decision
            if (decision.state, decision.cause) != (before.state, before.cause):
                action = decision.state if decision.state != DRIVE else "resume"
                cause = decision.cause or before.cause
                detail = (
                    decision.detail
                    if decision.state != DRIVE
                    else f"clear for {self.params.config.hold_s:g} s"
                )
                self.events.append(
                    SafetyEvent(
                        world.stamp_ns,
                        ns,
                        cause,
                        action,
                        est.pose or est.last_pose,
                        est.speed_mps,
                        detail,
                        decision.other if decision.state != DRIVE else before.other,
                        est.pose is not None,
                    )
                )
        return dict(self.decisions)


def clamp_command(decision: SafetyDecision, linear_mps: float, angular_rps: float) -> tuple[float, float]:
    """The command after the safety layer: zero when stopped, speed-limited when slowed."""
    if decision.state == STOP:
        return 0.0, 0.0
    if decision.state == SLOW and decision.speed_limit_mps is not None:
        limit = decision.speed_limit_mps
        if abs(linear_mps) > limit:
            scale = limit / abs(linear_mps)
            return float(np.sign(linear_mps) * limit), angular_rps * scale
    return linear_mps, angular_rps
