"""GPSS navigation: grid planning and pure pursuit on small maps, coordination of several robots
on the real warehouse grid (navigation dry run), SIMLAN's Nav2 map."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from conftest import compose_config
from simlan_data.algorithms.coordinator import Coordinator, Decision, Intent
from simlan_data.algorithms.dryrun import dry_run
from simlan_data.algorithms.follower import PathFollower, PursuitParams
from simlan_data.algorithms.navigation import Navigator
from simlan_data.algorithms.occupancy import OccupancyGrid, grid_from_nav2_map
from simlan_data.algorithms.planner import GridPlanner, Plan, PlanningError
from simlan_data.algorithms.stack import AgentPlan, NavigationParams
from simlan_data.config.validation import to_config
from simlan_data.constants import MAPS_DIR
from simlan_data.sim.scene import load_inputs
from simlan_data.world.agent_types import AGENT_TYPES

RES = 0.05


def _room_with_wall() -> OccupancyGrid:
    """10 m x 6 m room, walls all round, an inner wall at x = 5 m with a 1.2 m gap at y = 4.4..5.6."""
    occ = np.zeros((int(6 / RES), int(10 / RES)), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    col = int(5 / RES)
    occ[:, col - 2 : col + 2] = True
    occ[int(4.4 / RES) : int(5.6 / RES), col - 2 : col + 2] = False
    return OccupancyGrid(occ, (0.0, 0.0), RES)


def _min_clearance_along(grid: OccupancyGrid, points: np.ndarray) -> float:
    clearance = grid.clearance_m()
    dense = np.concatenate(
        [
            np.linspace(a, b, max(2, int(np.linalg.norm(b - a) / (RES / 2))))
            for a, b in itertools.pairwise(points)
        ]
    )
    return float(min(clearance[grid.to_cell(p)] for p in dense))


def test_planner_goes_through_the_gap_and_keeps_its_radius() -> None:
    grid = _room_with_wall()
    planner = GridPlanner(grid, radius_m=0.4)
    plan = planner.plan((1.5, 1.5), (8.5, 1.5))
    xs = plan.points_xy[:, 0]
    crossing = np.argmax(xs > 5.0)
    a, b = plan.points_xy[crossing - 1], plan.points_xy[crossing]
    y_at_wall = a[1] + (5.0 - a[0]) / (b[0] - a[0]) * (b[1] - a[1])
    assert 4.4 + 0.4 <= y_at_wall <= 5.6 - 0.4  # through the gap, radius kept from its edges
    assert _min_clearance_along(grid, plan.points_xy) >= 0.4 - RES
    # the straight line is 7 m; the way through the gap is about 2 x hypot(3.5, 3.5)
    assert 9.0 < plan.length_m < 11.5
    assert len(plan.points_xy) <= 8  # smoothed: a handful of corners, not a staircase


def test_planner_refuses_what_cannot_be_done() -> None:
    grid = _room_with_wall()
    with pytest.raises(PlanningError, match="inside an obstacle"):
        GridPlanner(grid, radius_m=0.4).plan((1.5, 1.5), (5.0, 1.0))
    with pytest.raises(PlanningError, match="no path"):
        GridPlanner(grid, radius_m=0.7).plan((1.5, 1.5), (8.5, 1.5))  # wider than the gap
    with pytest.raises(PlanningError, match="no path"):
        GridPlanner(grid, radius_m=0.4).plan((1.5, 1.5), (8.5, 1.5), max_length_m=8.0)


def test_pure_pursuit_drives_a_unicycle_along_the_plan_to_the_goal() -> None:
    grid = _room_with_wall()
    plan = GridPlanner(grid, radius_m=0.4).plan((1.5, 1.5), (8.5, 1.5))
    follower = PathFollower(plan.points_xy, PursuitParams(max_speed_mps=1.0, goal_tolerance_m=0.2))
    x, y, yaw, dt = 1.5, 1.5, np.pi, 0.05  # facing away from the route: it must turn first
    clearance = grid.clearance_m()
    worst, driven, peak_w = np.inf, 0.0, 0.0
    for _ in range(int(60 / dt)):
        v, w = follower.step(x, y, yaw, dt)
        peak_w = max(peak_w, abs(w))
        x, y, yaw = x + v * np.cos(yaw) * dt, y + v * np.sin(yaw) * dt, yaw + w * dt
        driven += abs(v) * dt
        worst = min(worst, float(clearance[grid.to_cell((x, y))]))
        if follower.done:
            break
    assert follower.done
    assert np.hypot(x - 8.5, y - 1.5) < 0.2
    assert worst > 0.3  # never closer than 0.3 m to a wall (the plan kept 0.4 m)
    assert driven < 1.1 * plan.length_m
    assert peak_w <= 0.8 + 1e-9


def test_pure_pursuit_reverses_the_segments_marked_backwards_and_stops_at_each_cusp() -> None:
    # east 6 m, back west 4 m reversing (still facing east), then north forwards: a route that turns
    # back on itself, as a fleet plan gives it to a robot that backs out of a corridor
    path = np.array([[0.0, 0.0], [6.0, 0.0], [2.0, 0.0], [2.0, 3.0]])
    follower = PathFollower(
        path, PursuitParams(max_speed_mps=1.0, goal_tolerance_m=0.2), (False, True, False)
    )
    x, y, yaw, dt = 0.0, 0.0, 0.0, 0.05
    trace = []
    for _ in range(int(60 / dt)):
        v, w = follower.step(x, y, yaw, dt)
        trace.append((x, y, yaw, v, follower.section))
        x, y, yaw = x + v * np.cos(yaw) * dt, y + v * np.sin(yaw) * dt, yaw + w * dt
        if follower.done:
            break
    assert follower.done and np.hypot(x - 2.0, y - 3.0) < 0.2
    t = np.array(trace)
    assert 5.7 < t[:, 0].max() < 6.3  # drove to the cusp, not past it
    back = t[t[:, 4] == 1]
    moving = back[np.abs(back[:, 3]) > 1e-6]
    assert len(moving) and (moving[:, 3] < 0).all()  # reversing: negative speed ...
    assert np.cos(moving[:, 2]).min() > 0.95  # ... facing east all the way
    assert np.abs(back[:, 1]).max() < 0.1  # on the line
    assert (t[t[:, 4] == 2][:, 3] >= 0).all()  # then forwards again
    with pytest.raises(ValueError, match="3 segments"):
        PathFollower(path, PursuitParams(), (True,))


def _turn_spots(stops: tuple[int, ...] | None) -> np.ndarray:
    """Where a unicycle following a hairpin (east 6 m, then back west-north-west) turns on the spot."""
    path = np.array([[0.0, 0.0], [6.0, 0.0], [0.0, 1.5]])
    follower = PathFollower(path, PursuitParams(max_speed_mps=1.0, goal_tolerance_m=0.2), stops=stops)
    x, y, yaw, dt = 0.0, 0.0, 0.0, 0.05
    spots = []
    for _ in range(int(60 / dt)):
        v, w = follower.step(x, y, yaw, dt)
        if v == 0.0 and abs(w) > 1e-6:
            spots.append((x, y))
        x, y, yaw = x + v * np.cos(yaw) * dt, y + v * np.sin(yaw) * dt, yaw + w * dt
        if follower.done:
            break
    assert follower.done and np.hypot(x, y - 1.5) < 0.2
    return np.array(spots)


def test_pure_pursuit_turns_on_the_spot_only_at_the_vertices_it_is_told_to_stop_at() -> None:
    # a fleet plan turns a robot on the spot at a vertex and reserves the turn's circle there only
    # ... and turns there, not up to its goal tolerance (0.2 m) short: a pallet truck that turned
    # 0.28 m short of its turn vertex swept its tail into a shelf end (PursuitParams.stop_tolerance_m)
    planned = _turn_spots((1,))
    assert len(planned) and np.hypot(planned[:, 0] - 6.0, planned[:, 1]).max() < 0.07
    # pursued across the corner, the robot starts turning a lookahead before it (the collision
    # of a pallet truck with a shelf end, docs/fleet.md)
    pursued = _turn_spots(None)
    assert len(pursued) and np.hypot(pursued[:, 0] - 6.0, pursued[:, 1]).max() > 0.4


def test_coordinator_lets_the_first_robot_on_and_holds_the_one_that_would_cut_it_off() -> None:
    truck = AGENT_TYPES["pallet_truck"].footprint_m
    east = Intent("robot_agent_1", 1, (0.0, 0.0, 0.0), truck, np.array([[0.0, 0.0], [6.0, 0.0]]))
    # crossing from the south, 2 m ahead of robot 1: its claim crosses robot 1's claim
    north = Intent("robot_agent_2", 2, (2.5, -2.5, np.pi / 2), truck, np.array([[2.5, -2.5], [2.5, 3.0]]))
    far = Intent("robot_agent_3", 3, (20.0, 5.0, 0.0), truck, np.array([[20.0, 5.0], [25.0, 5.0]]))
    c = Coordinator(safety_distance_m=0.6, horizon_m=3.0, deadlock_after_s=3.0)
    out = c.decide(0, [north, far, east])
    assert out["robot_agent_1"].speed_limit_mps is None
    assert out["robot_agent_2"].speed_limit_mps == 0.0
    assert out["robot_agent_2"].blocked_by == ("robot_agent_1",)
    assert out["robot_agent_3"].speed_limit_mps is None
    assert not out["robot_agent_2"].replan  # robot 1 drives on: waiting resolves it


def test_coordinator_breaks_a_head_on_standoff_by_the_lower_priority_first() -> None:
    truck = AGENT_TYPES["pallet_truck"].footprint_m
    a = Intent("robot_agent_1", 1, (0.0, 0.0, 0.0), truck, np.array([[0.0, 0.0], [8.0, 0.0]]))
    b = Intent("robot_agent_2", 2, (3.5, 0.0, np.pi), truck, np.array([[3.5, 0.0], [-5.0, 0.0]]))
    c = Coordinator(safety_distance_m=0.6, horizon_m=3.0, deadlock_after_s=3.0)
    second = 1_000_000_000
    for t in range(0, 3 * second, second // 20):
        out = c.decide(t, [a, b])
        assert out["robot_agent_1"].speed_limit_mps == 0.0 and out["robot_agent_2"].speed_limit_mps == 0.0
        assert not out["robot_agent_1"].replan and not out["robot_agent_2"].replan
    out = c.decide(3 * second, [a, b])
    assert out["robot_agent_2"].replan and not out["robot_agent_1"].replan
    out = c.decide(6 * second, [a, b])  # robot 2 found no way round: robot 1 tries as well
    assert out["robot_agent_1"].replan


def _dry_run(*overrides: str):
    cfg = to_config(compose_config(*overrides))
    inputs = load_inputs(cfg)
    plans = [
        AgentPlan(
            a.namespace,
            a.number,
            inputs.agent_types[a.namespace],
            a.marker_id,
            [list(g) for g in a.goals],
            a.speed_mps,
            a.loop,
            (float(a.pose[0]), float(a.pose[1]), float(a.pose[2])),
        )
        for a in cfg.agent_list
    ]
    n = cfg.navigation
    params = NavigationParams(
        n.clearance_m,
        n.lookahead_m,
        n.goal_tolerance_m,
        n.max_yaw_rate_rps,
        n.coordination,
        n.safety_distance_m,
    )
    return dry_run(plans, inputs.grid, params, duration_s=cfg.duration_s), cfg


def test_four_robots_with_crossing_routes_all_arrive_without_touching() -> None:
    """The multi_robot scenario on the real warehouse grid with ideal robots: head-on meetings in
    the main aisle, a Jackal crossing both lanes, a forklift turning back into a busy lane."""
    result, cfg = _dry_run("scenario=multi_robot")
    assert result.all_goals_reached, (result.goals_reached, result.goals_total)
    assert max(t for t in result.finished_s.values() if t is not None) < cfg.duration_s - 5
    assert result.min_gap_m >= 0.4, (result.min_gap_m, result.min_gap_pair)
    assert sum(result.waits_s.values()) > 0  # they did meet


def test_without_coordination_the_same_routes_come_too_close() -> None:
    result, _ = _dry_run("scenario=multi_robot", "navigation.coordination=false")
    assert result.min_gap_m < 0.1  # the coordinator is what keeps them apart


def test_simlan_nav2_map_loads_and_plans_the_main_aisle() -> None:
    grid = grid_from_nav2_map(MAPS_DIR / "warehouse.yaml", resolution_m=0.1)
    assert grid.occupied.mean() < 0.9
    plan = GridPlanner(grid, radius_m=0.8).plan((-10.0, 0.4), (20.0, 0.4))
    assert plan.length_m < 32.0


def test_a_navigator_waits_at_the_end_of_a_coordinator_route_that_stops_short_of_its_goal() -> None:
    # a fleet coordinator's windowed or queued route ends before the goal: done with it, the robot
    # stands there, waiting for the next, and counts no goal
    grid = _room_with_wall()
    nav = Navigator(
        "robot_agent_1", [(3.5, 1.5)], GridPlanner(grid, radius_m=0.4), PursuitParams(max_speed_mps=1.0)
    )
    nav.adopt(Plan(np.array([[1.5, 1.5], [2.5, 1.5]]), 1.0, 0))
    x, y, yaw, dt = 1.5, 1.5, 0.0, 0.05
    for _ in range(200):
        v, w = nav.step((x, y, yaw), dt)
        x, y, yaw = x + v * np.cos(yaw) * dt, y + v * np.sin(yaw) * dt, yaw + w * dt
    assert abs(x - 2.5) < 0.35 and nav.status.goals_reached == 0 and nav.status.state == "waiting"
    nav.adopt(Plan(np.array([[x, y], [3.5, 1.5]]), 1.0, 0))  # the next window: to the goal
    for _ in range(200):
        v, w = nav.step((x, y, yaw), dt)
        x, y, yaw = x + v * np.cos(yaw) * dt, y + v * np.sin(yaw) * dt, yaw + w * dt
    assert nav.status.goals_reached == 1


def test_a_navigator_with_every_goal_done_drives_only_the_way_aside_it_is_given() -> None:
    grid = _room_with_wall()
    nav = Navigator("robot_agent_1", [], GridPlanner(grid, radius_m=0.4), PursuitParams(max_speed_mps=1.0))
    x, y, yaw, dt = 1.5, 1.5, 0.0, 0.05
    assert nav.step((x, y, yaw), dt) == (0.0, 0.0)  # done: it stands
    nav.move_aside(np.array([[1.5, 1.5], [3.5, 1.5]]))  # a fleet coordinator moves it out of the way
    for _ in range(int(10 / dt)):
        v, w = nav.step((x, y, yaw), dt, Decision(None))
        x, y, yaw = x + v * np.cos(yaw) * dt, y + v * np.sin(yaw) * dt, yaw + w * dt
    assert np.hypot(x - 3.5, y - 1.5) < 0.3
    assert nav.status.state == "done" and nav.status.goals_reached == 0  # no goal counted
    assert nav.step((x, y, yaw), dt, Decision(0.0)) == (0.0, 0.0)


def test_a_robot_held_without_turning_stands_still_while_a_waiting_one_may_face_its_path() -> None:
    """Held at speed 0, a navigator whose path lies behind it turns in place towards it (the `gpss`
    coordinator's waiting robots do), unless the decision forbids it (``turn_in_place=False``: a
    fleet plan reserves a turn's swept circle only where it plans the turn; a forklift held so
    turned anyway and swept its forks to 0.10 m of a pallet truck)."""
    grid = _room_with_wall()
    nav = Navigator(
        "robot_agent_1", [[1.0, 1.5]], GridPlanner(grid, radius_m=0.4), PursuitParams(max_speed_mps=1.0)
    )
    pose = (3.0, 1.5, 0.0)  # facing away from its goal
    v, w = nav.step(pose, 0.05, Decision(0.0))
    assert v == 0.0 and abs(w) > 0.1  # waits, turning towards its path
    assert nav.step(pose, 0.05, Decision(0.0, turn_in_place=False)) == (0.0, 0.0)
    assert nav.status.state == "waiting"
    v, w = nav.step(pose, 0.05, Decision(None, turn_in_place=False))
    assert v == 0.0 and abs(w) > 0.1  # free: the turn is its plan's first move
