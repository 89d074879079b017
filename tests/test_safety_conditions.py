"""Safety layer on hand-made inputs: each condition node, the tree's hold/latch/resume logic, the
geometry it rests on (stopping distance, swept footprints, CPA/TTC), config checks, people
fusion and tracking, and the geometry of SIMLAN's collision cases."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import Polygon

from simlan_data.algorithms import registry
from simlan_data.algorithms.people import PersonDetection, PersonTracker, fuse_people
from simlan_data.algorithms.roles import SafetyContext as RunContext
from simlan_data.algorithms.safety import (
    DRIVE,
    SLOW,
    STOP,
    Mover,
    RobotEstimate,
    RobotSafetyTree,
    RobotSpec,
    SafetyLayer,
    SafetyWorld,
    TreeParams,
    TreesConfig,
    clamp_command,
    make_zone,
)
from simlan_data.algorithms.safety.conditions import (
    SafetyContext,
    contact,
    enters_zone,
    swept_region,
    unobserved,
    worst_approach,
)
from simlan_data.algorithms.safety.geometry import (
    approach,
    footprint_polygon,
    stopping_distance_m,
    swept_rollout,
)
from simlan_data.config.algorithms import plain
from simlan_data.config.collision import collision_setup, travel_m
from simlan_data.config.validation import compose_config as checked_config
from simlan_data.errors import ConfigError
from simlan_data.world.agent_types import AGENT_TYPES

TRUCK = AGENT_TYPES["pallet_truck"].footprint_m
JACKAL = AGENT_TYPES["jackal"].footprint_m
S = 1_000_000_000


def _params(coordinated: bool = False, **sections: dict) -> TreeParams:
    return TreeParams(TreesConfig(**sections), 1.0 / 20.0, 1.0 / 5.0, 0.0, coordinated)


def _ctx(params: TreeParams, *, pose=(0.0, 0.0, 0.0), speed=0.0, age=0.0, footprint=TRUCK) -> SafetyContext:
    ctx = SafetyContext(RobotSpec("robot_agent_1", footprint, 1.0), params, params.zones)
    ctx.estimate = RobotEstimate(pose, speed, 0.0, 0.0, age, pose)
    return ctx


# ------------------------------------------------------------------------------ conditions


def test_contact_condition_fires_above_the_force_threshold_only() -> None:
    ctx = _ctx(_params(collision={"force_threshold_n": 50.0}))
    ctx.contact = (49.0, ("shelf_1",))
    assert contact(ctx) is None
    ctx.contact = (50.0, ("robot_agent_2",))
    finding = contact(ctx)
    assert finding is not None and finding.cause == "collision" and finding.other == "robot_agent_2"


def test_observability_condition_counts_the_age_of_the_newest_fix() -> None:
    ctx = _ctx(_params(observability={"timeout_s": 1.0}), age=0.95)
    assert unobserved(ctx) is None
    ctx.estimate = RobotEstimate(None, fix_age_s=1.05)  # withheld estimate: only its age is known
    assert unobserved(ctx) is not None
    ctx.estimate = RobotEstimate(None, fix_age_s=-1.0)  # never seen
    assert "never seen" in unobserved(ctx).detail  # type: ignore[union-attr]


def test_zone_condition_triggers_at_the_stopping_distance_ahead_and_not_beside() -> None:
    zone = {"name": "bay", "polygon": [[5, -3], [8, -3], [8, 3], [5, 3]]}
    params = _params(zones=[zone], restricted_area={"decel_mps2": 2.0, "margin_m": 0.1, "lookahead_m": 0.3})
    reach = stopping_distance_m(1.0, 2.0, params.reaction_s) + 0.3 + 0.1  # 0.25 + 0.25 + 0.4 = 0.9 m
    front = TRUCK[1]
    far = _ctx(params, pose=(5.0 - front - reach - 0.05, 0.0, 0.0), speed=1.0)
    near = _ctx(params, pose=(5.0 - front - reach + 0.05, 0.0, 0.0), speed=1.0)
    assert enters_zone(far) is None
    finding = enters_zone(near)
    assert finding is not None and finding.other == "bay"
    # faster: the same place is too close
    assert enters_zone(_ctx(params, pose=(5.0 - front - reach - 0.05, 0.0, 0.0), speed=1.5)) is not None
    # driving along the zone's edge 0.3 m beside it: clear
    beside = _ctx(params, pose=(6.0, -3.0 - 0.4 - 0.3, 0.0), speed=1.5)
    assert enters_zone(beside) is None
    # standing inside
    assert "inside" in enters_zone(_ctx(params, pose=(6.0, 0.0, 0.0))).detail  # type: ignore[union-attr]


def test_zone_condition_holds_a_stopped_robot_whose_plan_leads_in() -> None:
    params = _params(zones=[{"name": "bay", "polygon": [[5, -3], [8, -3], [8, 3], [5, 3]]}])
    ctx = _ctx(params, pose=(5.0 - TRUCK[1] - 0.6, 0.0, 0.0), speed=0.0)
    assert enters_zone(ctx) is None  # standing: nothing would enter
    ctx.held = ctx.held.__class__(STOP, "restricted_area")
    ctx.navigating = True
    ctx.plan = np.array([[ctx.estimate.pose[0], 0.0], [12.0, 0.0]])  # type: ignore[index]
    assert enters_zone(ctx) is not None  # released, it would drive in at its cruise speed
    ctx.plan = np.array([[ctx.estimate.pose[0], 0.0], [ctx.estimate.pose[0], -6.0]])  # type: ignore[index]
    assert enters_zone(ctx) is None  # its plan turns away


def test_a_held_robot_whose_plan_reverses_is_swept_tail_first() -> None:
    # a pallet truck (base_link near its nose, 1.15 m of it behind) held, its plan backing 6 m west.
    # Swept as if it drove forwards along the plan, its nose would lead and the area swept would end
    # 0.45 m short of where its tail goes; reversing, the tail leads (SafetyWorld.reversing)
    params = _params()
    ctx = _ctx(params, pose=(0.0, 0.0, 0.0))
    ctx.held = ctx.held.__class__(STOP, "restricted_area")
    ctx.navigating = True
    ctx.plan = np.array([[0.0, 0.0], [-6.0, 0.0]])
    forwards = swept_region(ctx)
    ctx.reversing = True
    backwards = swept_region(ctx)
    here = footprint_polygon((0.0, 0.0, 0.0), TRUCK)
    assert backwards.contains(here) and forwards.contains(here)
    assert backwards.bounds[0] == pytest.approx(forwards.bounds[0] - (-TRUCK[0] - TRUCK[1]), abs=0.02)
    # a zone just beyond what the nose-first sweep reaches: only the tail-first sweep enters it
    x0 = forwards.bounds[0]
    ctx.zones = params.config.__class__(
        zones=[{"name": "bay", "polygon": [[x0 - 0.3, -2], [x0 - 0.05, -2], [x0 - 0.05, 2], [x0 - 0.3, 2]]}]
    ).zone_shapes
    assert enters_zone(ctx) is not None
    ctx.reversing = False
    assert enters_zone(ctx) is None


def test_cpa_and_ttc_of_two_constant_velocity_agents() -> None:
    head_on = approach(np.zeros(2), np.array([1.0, 0.0]), np.array([10.0, 0.0]), np.array([-1.0, 0.0]), 1.0)
    assert head_on.cpa_m == pytest.approx(0.0)
    assert head_on.t_cpa_s == pytest.approx(5.0)  # SIMLAN's TTC: time to the closest point
    assert head_on.ttc_s == pytest.approx(4.5)  # the circles (1 m together) touch 0.5 s earlier
    crossing = approach(np.zeros(2), np.array([1.0, 0.0]), np.array([4.0, -3.0]), np.array([0.0, 1.0]), 0.5)
    assert crossing.t_cpa_s == pytest.approx(3.5) and crossing.cpa_m == pytest.approx(np.hypot(0.5, 0.5))
    apart = approach(np.zeros(2), np.array([-1.0, 0.0]), np.array([3.0, 0.0]), np.array([1.0, 0.0]), 1.0)
    assert apart.t_cpa_s < 0
    still = approach(np.zeros(2), np.zeros(2), np.array([3.0, 0.0]), np.zeros(2), 1.0)
    assert still.ttc_s == float("inf")


def test_ttc_condition_is_simlans_rule_hard_stop_near_slow_further_out() -> None:
    params = _params()
    ctx = _ctx(params, pose=(0.0, 0.0, 0.0), speed=1.0, footprint=JACKAL)

    def other_at(x: float, y: float = 0.0, vx: float = 0.0) -> Mover:
        return Mover("robot_agent_2", x, y, vx, 0.0, 0.47)

    ctx.others = [other_at(3.0)]  # 3 m ahead, standing: contact (0.94 m) in ~2.1 s
    assert worst_approach(ctx, STOP) is None and worst_approach(ctx, SLOW) is not None
    ctx.others = [other_at(2.5)]
    stop = worst_approach(ctx, STOP)
    assert stop is not None and stop.ttc_s <= 2.0 and stop.other == "robot_agent_2"
    ctx.others = [other_at(2.5, 2.5)]  # passes 2.5 m to the side: beyond SIMLAN's 2 m CPA
    assert worst_approach(ctx, SLOW) is None
    ctx.others = [other_at(-3.0, vx=-1.0)]  # behind and driving away
    assert worst_approach(ctx, SLOW) is None
    ctx.others = [other_at(-2.5, vx=2.5)]  # catching up from behind: stopping would not help
    assert worst_approach(ctx, STOP) is None
    ctx.others = [Mover("robot_agent_2", 2.5, -2.5, -0.7, 0.7, 0.47)]  # closing in from behind-right
    assert worst_approach(ctx, STOP) is not None  # it drives into the other's path: stopping helps
    ctx.estimate = RobotEstimate((0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0))
    ctx.others = [other_at(2.0, vx=-1.0)]
    assert worst_approach(ctx, STOP) is None  # standing already: nothing to stop
    ctx.others = [other_at(20.0)]  # far: TTC beyond the slow horizon
    assert worst_approach(ctx, SLOW) is None


def test_swept_rollout_covers_the_stopping_path_and_turns() -> None:
    pose = (0.0, 0.0, 0.0)
    straight = swept_rollout(pose, TRUCK, 1.0, 0.0, decel_mps2=2.0, reaction_s=0.25, lookahead_m=0.0)
    d = stopping_distance_m(1.0, 2.0, 0.25)
    assert straight.bounds[2] == pytest.approx(TRUCK[1] + d, abs=0.02)
    turning = swept_rollout(pose, TRUCK, 1.0, 0.8, decel_mps2=2.0, reaction_s=0.25, lookahead_m=0.0)
    assert turning.bounds[3] > straight.bounds[3] + 0.05  # swings to the left
    assert turning.contains(footprint_polygon(pose, TRUCK))


# -------------------------------------------------------------------------------- the tree


def _tick(tree: RobotSafetyTree, t_s: float, **kwargs):
    est = kwargs.pop("estimate", RobotEstimate((0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0)))
    return tree.tick(round(t_s * S), est, **kwargs)


def test_tree_holds_for_hold_s_then_resumes_and_latches_collisions() -> None:
    params = _params(hold_s=1.0, collision={"resume": "never"})
    tree = RobotSafetyTree(RobotSpec("robot_agent_1", TRUCK, 1.0), params)
    assert _tick(tree, 0.0).state == DRIVE
    stale = RobotEstimate((0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 6.0, (0.0, 0.0, 0.0))
    d = _tick(tree, 0.05, estimate=stale)
    assert (d.state, d.cause, d.speed_limit_mps) == (STOP, "unobserved", 0.0)
    assert _tick(tree, 0.10).state == STOP  # clear, but not for 1 s yet
    assert _tick(tree, 1.0).state == STOP
    assert _tick(tree, 1.10).state == DRIVE
    d = _tick(tree, 1.15, contact_force=(200.0, ("shelf_3",)))
    assert (d.state, d.cause) == (STOP, "collision")
    for t in (2.0, 5.0, 30.0):  # resume: never
        assert _tick(tree, t).state == STOP
    assert "Contact?" in tree.ascii() and "ClearFor(1 s)?" in tree.ascii()


def test_tree_slows_for_a_far_hazard_and_stays_stopped_while_any_hazard_remains() -> None:
    params = _params(hold_s=0.5)
    tree = RobotSafetyTree(RobotSpec("robot_agent_1", JACKAL, 1.0), params)
    moving = RobotEstimate((0.0, 0.0, 0.0), 1.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0))
    far, near = Mover("p", 5.0, 0.0, 0.0, 0.0, 0.36), Mover("p", 2.0, 0.0, 0.0, 0.0, 0.36)
    d = _tick(tree, 0.0, estimate=moving, others=[far])
    assert (d.state, d.speed_limit_mps) == (SLOW, 0.4)
    assert clamp_command(d, 1.0, 0.5) == (0.4, pytest.approx(0.2))
    assert _tick(tree, 0.05, estimate=moving, others=[near]).state == STOP
    assert clamp_command(tree.ctx.decision, 1.0, 0.5) == (0.0, 0.0)
    # the person stands 5 m ahead on its way: no crawling towards it, it stays stopped
    for t in (0.10, 0.60, 2.0):
        assert _tick(tree, t, others=[far], navigating=True).state == STOP
    assert _tick(tree, 2.05, others=[], navigating=True).state == STOP  # clear, but not for 0.5 s yet
    assert _tick(tree, 2.45, others=[], navigating=True).state == STOP
    assert _tick(tree, 2.50, others=[], navigating=True).state == DRIVE  # 0.5 s after the last hazard


def test_layer_events_are_deterministic_and_ttc_ignores_coordinated_robots() -> None:
    spec1, spec2 = RobotSpec("robot_agent_1", TRUCK, 1.0), RobotSpec("robot_agent_2", JACKAL, 1.0)

    def run(params: TreeParams) -> list:
        run = RunContext(
            [spec1, spec2], (), params.control_period_s, params.camera_period_s, 0.0, params.coordinated
        )
        layer = SafetyLayer(params.config, run)
        for k in range(40):
            x = -6.0 + 0.05 * k
            est = {
                "robot_agent_1": RobotEstimate((x, 0.0, 0.0), 1.0, 0.0, 0.01, 0.05, (x, 0.0, 0.0)),
                "robot_agent_2": RobotEstimate((0.0, 0.0, np.pi), 1.0, 0.0, 0.01, 0.05, (0.0, 0.0, np.pi)),
            }
            layer.step(
                SafetyWorld(k * S // 20, est, navigating={"robot_agent_1": True, "robot_agent_2": True})
            )
        return [(e.stamp_ns, e.namespace, e.action, e.cause) for e in layer.events]

    uncoordinated = _params()
    first, second = run(uncoordinated), run(uncoordinated)
    assert first == second and ("robot_agent_1", STOP, "ttc") in {e[1:] for e in first}
    coordinated = _params(coordinated=True)
    assert run(coordinated) == []
    always = _params(coordinated=True, ttc={"robots": "always"})
    assert run(always) == first


# ------------------------------------------------------------------------- config checks


@pytest.mark.parametrize(
    ("zones", "message"),
    [
        (
            [{"name": "x", "polygon": [[0, 0], [2, 2], [2, 0], [0, 2]]}],
            "not a simple polygon .*Self-intersection",
        ),
        ([{"name": "x", "polygon": [[0, 0], [1, 0]]}], "needs at least 3 distinct corners"),
        ([{"name": "x", "polygon": [[0, 0], [1, 0], [0, 0]]}], "needs at least 3 distinct corners"),
        ([{"name": "", "polygon": [[0, 0], [1, 0], [0, 1]]}], "every zone needs a name"),
        ([{"name": "a", "polygon": [[0, 0], [1, 0], [0, 1]]}] * 2, "two zones are named 'a'"),
    ],
)
def test_bad_zones_are_refused_with_the_field_named(zones: list, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        TreesConfig(zones=zones)


def test_unknown_namespaces_and_values_are_refused() -> None:
    zone = {"name": "a", "polygon": [[0, 0], [1, 0], [0, 1]], "namespaces": ["robot_agent_9"]}
    with pytest.raises(
        ConfigError, match=r"algorithms\.safety\.zones\[0\].namespaces.*no agent 'robot_agent_9'"
    ):
        TreesConfig(zones=[zone]).check_namespaces(["robot_agent_1"])
    with pytest.raises(ConfigError, match=r"algorithms\.safety\.ttc.namespaces.*no agent 'robot_agent_7'"):
        TreesConfig(ttc={"namespaces": ["robot_agent_7"]}).check_namespaces(["robot_agent_1"])
    with pytest.raises(ConfigError, match=r"algorithms\.safety\.collision.resume='sometimes'"):
        TreesConfig(collision={"resume": "sometimes"})
    with pytest.raises(ConfigError, match=r"algorithms\.safety\.ttc.slow_ttc_s=1.0.*must be >="):
        TreesConfig(ttc={"slow_ttc_s": 1.0})
    with pytest.raises(ConfigError, match=r"algorithms\.safety\.ttc.stop_cpa\b"):
        TreesConfig(ttc={"stop_cpa": 1.0})
    with pytest.raises(ConfigError, match=r"unknown key 'zone' for safety 'trees'"):
        registry.resolve("safety", "trees").make_config({"zone": []}, where="replay --set")
    with pytest.raises(ConfigError, match=r"algorithms\.safety\.zones\[0\].namespaces=\['robot_agent_9'\]"):
        checked_config(
            ["algorithms.safety.zones=[{name: a, polygon: [[0,0],[1,0],[0,1]], namespaces: [robot_agent_9]}]"]
        )
    with pytest.raises(ConfigError, match=r"algorithms\.safety\.ttc.resume='sometimes'"):
        checked_config(["algorithms.safety.ttc.resume=sometimes"])


def test_zone_from_the_composed_config_reaches_the_trees() -> None:
    cfg = checked_config(["scenario=restricted_zone"])
    selected = cfg.algorithms.safety
    assert selected.name == "trees"
    config = registry.resolve("safety", selected.name).make_config(plain(selected), where="test")
    run = RunContext(
        [], (), 1.0 / cfg.control_rate_hz, 1.0 / cfg.cameras.rate_hz, 0.0, cfg.navigation.coordination
    )
    params = TreeParams.of(config, run)
    (zone,) = params.zones
    assert zone.name == "loading_bay" and zone.namespaces == ("robot_agent_1",)
    assert zone.polygon.equals(Polygon([(4, -2.4), (7, -2.4), (7, 3.2), (4, 3.2)]))
    assert params.coordinated and not params.ttc_against_robots()
    assert params.reaction_s == pytest.approx(0.05 + 0.2)
    assert make_zone("z", [[0, 0], [1, 0], [1, 1]], where="w").applies_to("robot_agent_4")


# ------------------------------------------------------------------------------ people


def test_people_fusion_merges_cameras_and_the_tracker_estimates_velocity() -> None:
    dets = [
        PersonDetection("162", 1.00, 2.00, 300),
        PersonDetection("163", 1.10, 2.05, 200),
        PersonDetection("163", 6.00, 0.00, 150),
    ]
    fused = fuse_people(dets, 0.8)
    assert len(fused) == 2
    assert fused[0] == pytest.approx((1.04, 2.02), abs=1e-6)
    tracker = PersonTracker()
    for k in range(15):  # 5 Hz, walking +x at 1.2 m/s
        tracker.update(k * S // 5, [(0.24 * k, 1.0)])
    (person,) = tracker.people(15 * S // 5)
    assert person.vx_mps == pytest.approx(1.2, abs=0.1) and abs(person.vy_mps) < 0.05
    assert person.x_m == pytest.approx(0.24 * 15, abs=0.05)
    assert tracker.people(20 * S) == []  # not seen for longer than max_age_s


# ------------------------------------------------------------------ SIMLAN's collision cases


@pytest.mark.parametrize("angle", [0, 45, 90, 135, 180])
@pytest.mark.parametrize("ctype", [0, 1, 2])
@pytest.mark.parametrize("speed", [0.5, 1.5])
def test_collision_cases_touch_at_the_contact_pose_and_start_apart(
    angle: int, ctype: int, speed: float
) -> None:
    setup = collision_setup(angle, speed, ctype, overlap_m=0.1)
    truck = footprint_polygon(setup.contact_truck, TRUCK)
    jackal = footprint_polygon(setup.contact_jackal, JACKAL)
    if setup.closing:
        assert truck.intersects(jackal)
        assert truck.intersection(jackal).area < 0.1  # overlap by design is small
    start_t = footprint_polygon(setup.truck_pose, TRUCK)
    start_j = footprint_polygon(setup.jackal_pose, JACKAL)
    assert start_t.distance(start_j) > 0.3
    moved = np.hypot(
        setup.contact_truck[0] - setup.truck_pose[0], setup.contact_truck[1] - setup.truck_pose[1]
    )
    assert moved == pytest.approx(travel_m(speed, 3.0), abs=1e-3)


def test_travel_with_the_followers_acceleration() -> None:
    assert travel_m(1.2, 1.0, 0.6) == pytest.approx(0.3)  # still accelerating
    assert travel_m(1.2, 3.0, 0.6) == pytest.approx(1.2 * 3.0 - 1.2**2 / 1.2)
