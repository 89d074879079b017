"""The floor the cameras see (issue 23): robots that steer on the cameras plan on it.

A GPSS robot has no odometry: driven where no camera sees its marker, it is stopped by the safety
layer after 0.5 s and never localized again. So the grid planner pays ``unseen_cost`` per metre of
floor not seen at the heading driven, the fleet's route graph keeps only edges seen both ways,
and the visibility test behind it (``markers_in_view``, which projects only rays near each image)
agrees with projecting every corner through OpenCV.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from simlan_data.algorithms.coverage import HEADINGS, SeenFloor, heading_index, seen_floor
from simlan_data.algorithms.fleet.graph import build_route_graph
from simlan_data.algorithms.markers import MIN_SIDE_PX, marker_corners_in_marker_frame, markers_in_view
from simlan_data.algorithms.occupancy import OccupancyGrid, grid_from_world
from simlan_data.algorithms.planner import GridPlanner
from simlan_data.config.validation import compose_config
from simlan_data.errors import ConfigError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.world.agent_types import AGENT_TYPES, MARKER_SIZE_M
from simlan_data.world.layout import load_layout

RES = 0.1


def _open_floor() -> OccupancyGrid:
    """A 20 m x 10 m hall with walls around it."""
    occ = np.zeros((100, 200), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return OccupancyGrid(occ, (0.0, 0.0), RES)


def _seen_but(grid: OccupancyGrid, box: tuple[float, float, float, float], headings: range) -> np.ndarray:
    """Seen everywhere except in ``box`` (x0, x1, y0, y1) at ``headings``."""
    seen = np.ones((HEADINGS, *grid.shape), dtype=bool)
    x0, x1, y0, y1 = box
    r0, c0 = grid.to_cell((x0, y0))
    r1, c1 = grid.to_cell((x1, y1))
    for k in headings:
        seen[k, r0:r1, c0:c1] = False
    return seen


def test_the_planner_goes_round_floor_no_camera_sees() -> None:
    grid = _open_floor()
    seen = _seen_but(grid, (8.0, 12.0, 0.0, 7.0), range(HEADINGS))  # a blind band with a way round at y > 7
    blind = GridPlanner(grid, radius_m=0.5, seen=seen, unseen_cost=25.0).plan((2.0, 3.0), (18.0, 3.0))
    plain = GridPlanner(grid, radius_m=0.5).plan((2.0, 3.0), (18.0, 3.0))
    assert plain.points_xy[:, 1].max() < 3.5  # straight through
    inside = [
        p for p in _samples(blind.points_xy) if 8.0 <= p[0] <= 12.0 and p[1] < 7.0
    ]  # the planned way never enters the band
    assert not inside, inside[:3]
    assert blind.length_m > plain.length_m + 2.0
    # nothing seen at all: the planner still finds the straight way (no other way exists)
    none = GridPlanner(grid, radius_m=0.5, seen=np.zeros_like(seen), unseen_cost=25.0)
    assert none.plan((2.0, 3.0), (18.0, 3.0)).length_m == pytest.approx(plain.length_m, abs=0.3)


def test_the_planner_reads_the_seen_floor_per_heading() -> None:
    """A band unseen only facing east (the marker off-centre leaves the view one way): eastbound
    robots go round it, westbound ones drive through."""
    grid = _open_floor()
    seen = _seen_but(grid, (8.0, 12.0, 0.0, 7.0), range(HEADINGS))
    seen[HEADINGS // 2] = True  # facing west (k = 4): seen everywhere
    planner = GridPlanner(grid, radius_m=0.5, seen=seen, unseen_cost=25.0)
    east = planner.plan((2.0, 3.0), (18.0, 3.0))
    west = planner.plan((18.0, 3.0), (2.0, 3.0))
    assert east.points_xy[:, 1].max() > 7.0
    assert west.points_xy[:, 1].max() < 3.5
    assert heading_index(math.pi) == HEADINGS // 2 and heading_index(-0.3) == 0


def _samples(points: np.ndarray, step: float = 0.05) -> list[np.ndarray]:
    out = []
    for a, b in itertools.pairwise(points):
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / step)))
        out += [a + t * (b - a) for t in np.linspace(0.0, 1.0, n)]
    return out


def test_the_route_guide_counts_floor_no_camera_sees_as_longer() -> None:
    """Arcs driven where no camera sees the robot that way weigh 1 + unseen_cost times their unseen
    share in the route guide (per direction), so the guide goes round a blind band and still
    reaches a goal inside it."""
    grid = _open_floor()
    east_blind = _seen_but(grid, (8.0, 12.0, 0.0, 7.0), range(1))  # unseen facing east only
    full = build_route_graph(grid, radius_m=0.7, spacing_m=1.0)
    weighted = build_route_graph(grid, radius_m=0.7, spacing_m=1.0, seen=east_blind, unseen_cost=25.0)
    assert full.arc_bias is None and weighted.arc_bias is not None
    np.testing.assert_array_equal(weighted.edges, full.edges)  # nothing removed
    arcs, bias = weighted.arcs, weighted.arc_bias
    mid = 0.5 * (weighted.xy[arcs[:, 0]] + weighted.xy[arcs[:, 1]])
    d = weighted.xy[arcs[:, 1]] - weighted.xy[arcs[:, 0]]
    in_band = (mid[:, 0] > 8.6) & (mid[:, 0] < 11.4) & (mid[:, 1] < 6.4)
    east, west = (
        in_band & (d[:, 0] > 0.5) & (abs(d[:, 1]) < 1e-9),
        in_band & (d[:, 0] < -0.5) & (abs(d[:, 1]) < 1e-9),
    )
    assert east.any() and np.allclose(bias[east], 26.0) and np.allclose(bias[west], 1.0)
    assert np.allclose(bias[~in_band & (mid[:, 1] > 7.6)], 1.0)
    # the guide from the west end to the east end goes round the band (y > 7)
    start = weighted.nearest((2.0, 3.0), within_m=1.0)
    goal = weighted.nearest((18.0, 3.0), within_m=1.0)
    assert start is not None and goal is not None
    to = weighted.turns(0.8, math.radians(50)).to_goal(goal, forward=False)
    plain = full.turns(0.8, math.radians(50)).to_goal(goal, forward=False)
    assert to.node[start] > plain.node[start] + 1.0  # round the band (through it: 4 m at 26x)
    assert to.node[start] < plain.node[start] + 25.0
    back = weighted.turns(0.8, math.radians(50)).to_goal(start, forward=False)
    # a robot turns in place only where every heading is seen (not in the band)
    band_nodes = (weighted.xy[:, 0] > 8.2) & (weighted.xy[:, 0] < 11.8) & (weighted.xy[:, 1] < 6.8)
    assert full.turnable(0.8)[band_nodes].any() and not weighted.turnable(0.8)[band_nodes].any()
    assert weighted.turnable(0.8)[~band_nodes & full.turnable(0.8)].all()
    plain_back = full.turns(0.8, math.radians(50)).to_goal(start, forward=False)
    assert back.node[goal] == pytest.approx(plain_back.node[goal])  # westbound: seen, straight through


def _reference_in_view(cameras, marker_xyz, poses, size_m) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Every corner projected through OpenCV (markers_in_view before its near-the-image test)."""
    local = marker_corners_in_marker_frame(size_m) + np.asarray(marker_xyz)
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    corners = np.stack(
        [
            poses[:, :1] + c * local[:, 0] - s * local[:, 1],
            poses[:, 1:2] + s * local[:, 0] + c * local[:, 1],
            np.broadcast_to(local[:, 2], (len(poses), 4)),
        ],
        axis=-1,
    )
    out = np.zeros(len(poses), dtype=bool)
    for cam in cameras:
        uv, ok = cam.project(corners.reshape(-1, 3))
        uv = uv.reshape(-1, 4, 2)
        inside = (
            ok.reshape(-1, 4).all(axis=1)
            & (uv >= 0).all(axis=(1, 2))
            & (uv[..., 0] <= cam.width - 1).all(axis=1)
            & (uv[..., 1] <= cam.height - 1).all(axis=1)
        )
        for i in np.flatnonzero(inside):
            _, ok_px = cam.undistort_pixels(uv[i])
            side = np.linalg.norm(uv[i] - np.roll(uv[i], 1, axis=0), axis=1).mean()
            out[i] |= bool(ok_px.all() and side >= MIN_SIDE_PX)
    return out


@pytest.mark.parametrize("size", [(960, 540), (480, 270), (3840, 2160)])
def test_the_near_image_test_changes_no_answer(size: tuple[int, int]) -> None:
    cams = [load_calibration(i).camera.scaled(*size) for i in (160, 162, 164, 166, 171)]
    rng = np.random.default_rng(4)
    poses = np.column_stack(
        [rng.uniform(-10, 36, 3000), rng.uniform(-12, 12, 3000), rng.uniform(-np.pi, np.pi, 3000)]
    )
    for kind in ("pallet_truck", "jackal"):
        marker = AGENT_TYPES[kind].marker_xyz
        got = markers_in_view(cams, marker, poses, size_m=MARKER_SIZE_M)
        want = _reference_in_view(cams, marker, poses, MARKER_SIZE_M)
        assert want.sum() > 100
        np.testing.assert_array_equal(got, want)


def test_the_seen_floor_of_the_real_cameras_matches_the_marker_test() -> None:
    """On the real layout under the GPSS cameras: every sampled cell of the seen floor says what
    ``markers_in_view`` says at that pose, and the floor seen at every heading is a strict part of
    the floor seen at some heading (the marker sits 0.8 m off a pallet truck's centre)."""
    grid = grid_from_world(load_layout("warehouse_layout.csv", "default"), resolution_m=RES)
    cams = [load_calibration(i).camera.scaled(960, 540) for i in range(160, 171)]
    marker = AGENT_TYPES["pallet_truck"].marker_xyz
    free = grid.clearance_m() >= 0.8
    floor = seen_floor(grid, cams, marker, marker_size_m=MARKER_SIZE_M, free=free)
    assert isinstance(floor, SeenFloor) and floor.by_heading.shape == (HEADINGS, *grid.shape)
    assert seen_floor(grid, cams, marker, marker_size_m=MARKER_SIZE_M, free=free) is floor  # cached
    rng = np.random.default_rng(1)
    cells = np.argwhere(free[::2, ::2]) * 2
    cells = cells[rng.choice(len(cells), 400, replace=False)]
    xy = grid.to_xy(cells)
    for k in (0, 3, 6):
        want = markers_in_view(
            cams, marker, np.column_stack([xy, np.full(len(xy), k * math.pi / 4)]), size_m=MARKER_SIZE_M
        )
        np.testing.assert_array_equal(floor.by_heading[k][cells[:, 0], cells[:, 1]], want)
    every, some = floor.every_heading.sum(), floor.by_heading.any(axis=0).sum()
    assert 0 < every < some


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            "navigation.unseen_cost=-1",
            "invalid navigation.unseen_cost=-1.0 in config: must be a finite number >= 0",
        ),
        (
            "algorithms.coordinator.unseen_cost=-3",
            "invalid algorithms.coordinator.unseen_cost=-3.0 in config: must be within 0.0..1000.0;",
        ),
    ],
)
def test_a_bad_unseen_cost_is_refused_naming_the_key(override: str, message: str) -> None:
    extra = ["algorithms/coordinator=fleet"] if override.startswith("algorithms") else []
    with pytest.raises(ConfigError) as err:
        compose_config([*extra, override])
    assert message in str(err.value)
