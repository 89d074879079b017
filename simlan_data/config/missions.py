"""Seeded fleet missions on the real layout (``scenario=fleet``): robots, homes, tasks, shared docks.

The ``fleet`` section says what to generate; the config resolver ``${fleet_missions:agents}``
turns it, with ``seed``, the layout and ``navigation.clearance_m``, into the ``agents`` section,
so the run proceeds as any run and its recorded config holds the generated poses and goals::

    fleet section + seed + layout (occupancy grid, clearance per cell)
        -> spots on free floor reachable from each other (one connected free region)
        -> docks and chargers (shared: several robots visit them, the coordinator queues them)
        -> homes (spawn poses, footprints apart) -> per robot: tasks, then home

Every task is two goals: a delivery goes to a pickup by a rack (or a wall), then to one of the docks; a
charge (every ``charge_every``-th task) goes to one of the chargers, then back home. After its
tasks a robot returns home, so no robot ends on a shared spot. The fleet metrics count goals
``2k, 2k+1`` as task ``k`` and a last unpaired goal as the return home.

People (``fleet.people``, the dataset scenarios): each a humanoid that walks a loop, from its home
through ``PERSON_STOPS`` other spots and back, for the whole run, along collision-free paths the
grid planner finds on the layout (walkers follow straight lines between their waypoints, so the
waypoints are the path's corners). People have no tasks: the fleet metrics count robots only.

Reachable means: every spot lies in the largest connected region of floor whose clearance to the
layout's obstacles is at least the largest footprint's circumscribed radius in the mix plus
``MARGIN_M`` (so a robot can turn in place on it, and the planner, which keeps half a width plus
``navigation.clearance_m``, has a path between any two).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.coverage import connected_seen, seen_by_all, seen_floor
from simlan_data.algorithms.markers import markers_in_view
from simlan_data.algorithms.occupancy import OccupancyGrid, grid_from_world
from simlan_data.algorithms.planner import GridPlanner, PlanningError
from simlan_data.errors import CalibrationError, ConfigError
from simlan_data.geometry.calibration import load_calibration
from simlan_data.geometry.camera import CameraModel
from simlan_data.world.agent_types import AGENT_TYPES, MARKER_SIZE_M, AgentType
from simlan_data.world.layout import load_layout

__all__ = ["GOALS_PER_TASK", "Missions", "MissionsConfig", "generate_missions", "resolve"]

GOALS_PER_TASK = 2  # pickup -> drop-off (charger -> home for a charge)
MARGIN_M = 0.15  # spots keep the circumscribed radius plus this from obstacles
RACK_BAND_M = 0.8  # pickups lie within this of the closest spot to a rack
SPACING_M = 0.5  # free floor between two homes' (or a home's and a dock's) circumscribed circles
MAX_ROBOTS = 200
DRAWS = 20  # draws per seed until the homes, docks and a pickup fit apart
MAX_PEOPLE = 50
PERSON_STOPS = 3  # a person walks from home through this many spots and back, again and again
PERSON = "humanoid"
ROBOT_TYPES = tuple(name for name, t in AGENT_TYPES.items() if t.drive == "diff")
_bad = ConfigError.invalid


@dataclass
class MissionsConfig:
    """The ``fleet`` section: what ``scenario=fleet`` generates from ``seed`` (0 robots: nothing)."""

    robots: int = 0  # robots generated (scenario=fleet sets 4); 0: no fleet
    types: list[str] = field(
        default_factory=lambda: ["pallet_truck", "jackal", "forklift"]
    )  # robot i: types[i % n]
    tasks: int = 2  # tasks per robot (each two goals), then home
    docks: int = 2  # shared drop-off spots
    chargers: int = 1  # shared charging spots
    charge_every: int = 3  # every n-th task of a robot is a charge (0: never)
    speed_mps: float = 1.0  # every robot's speed
    people: int = 0  # people (humanoids) walking loops between spots on the floor (0: none)
    people_speed_mps: float = 1.2  # their walking speed
    area_m: list[float] = field(
        default_factory=lambda: [-8.0, 34.0, -10.0, 10.0]
    )  # x0, x1, y0, y1: all spots

    def __post_init__(self) -> None:
        if not 0 <= self.people <= MAX_PEOPLE:
            raise _bad(
                "fleet.people", self.people, f"must be within 0..{MAX_PEOPLE}", "use e.g. fleet.people=2"
            )
        if not 0 < self.people_speed_mps <= 2.0:
            raise _bad(
                "fleet.people_speed_mps", self.people_speed_mps, "must be within (0, 2] m/s", "use 1.2"
            )
        if not 0 <= self.robots <= MAX_ROBOTS:
            raise _bad(
                "fleet.robots",
                self.robots,
                f"must be within 0..{MAX_ROBOTS} (0: no fleet)",
                "use e.g. fleet.robots=4",
            )
        if not self.types:
            raise _bad(
                "fleet.types", list(self.types), "no robot type", f"list some of {', '.join(ROBOT_TYPES)}"
            )
        for name in self.types:
            if name not in ROBOT_TYPES:
                raise _bad(
                    "fleet.types[]",
                    name,
                    f"not a robot type ({', '.join(ROBOT_TYPES)})",
                    "use e.g. pallet_truck",
                )
        for key, low, high in (
            ("tasks", 1, 100),
            ("docks", 1, 20),
            ("chargers", 0, 20),
            ("charge_every", 0, 100),
        ):
            if not low <= getattr(self, key) <= high:
                raise _bad(
                    f"fleet.{key}", getattr(self, key), f"must be within {low}..{high}", "see docs/fleet.md"
                )
        if self.charge_every and not self.chargers:
            raise _bad(
                "fleet.charge_every",
                self.charge_every,
                "there are no chargers",
                "set fleet.chargers=1 or charge_every=0",
            )
        if not 0 < self.speed_mps <= 3.0:
            raise _bad("fleet.speed_mps", self.speed_mps, "must be within (0, 3] m/s", "use 1.0")
        if len(self.area_m) != 4 or not (self.area_m[0] < self.area_m[1] and self.area_m[2] < self.area_m[3]):
            raise _bad(
                "fleet.area_m",
                list(self.area_m),
                "expected [x0, x1, y0, y1] with x0 < x1, y0 < y1",
                "use [-8, 34, -10, 10]",
            )


@dataclass(frozen=True)
class Missions:
    """What was generated: the ``agents`` section and the shared spots (map frame, metres)."""

    agents: dict[str, dict[str, Any]]
    docks: list[list[float]]
    chargers: list[list[float]]


@functools.lru_cache(maxsize=4)
def _floor(layout: str, fidelity: str, resolution_m: float) -> tuple[OccupancyGrid, NDArray[np.float32]]:
    """The layout's occupancy grid and clearance (cached: the resolver runs several times a run)."""
    grid = grid_from_world(load_layout(layout, fidelity), resolution_m=resolution_m)
    return grid, grid.clearance_m()


def _in_area(xy: NDArray[np.float64], area: list[float]) -> NDArray[np.bool_]:
    """Which points ``xy`` (..., 2) lie in ``area`` (x0, x1, y0, y1; edges included)."""
    x, y = xy[..., 0], xy[..., 1]
    return np.asarray((x >= area[0]) & (x <= area[1]) & (y >= area[2]) & (y <= area[3]), dtype=bool)


def _largest_region(free: NDArray[np.bool_]) -> NDArray[np.int64]:
    """(N, 2) cells of the largest 8-connected region of ``free`` (none when nothing is free)."""
    count, labels = cv2.connectedComponents(free.astype(np.uint8), connectivity=8)
    if count < 2:
        return np.zeros((0, 2), dtype=np.int64)
    largest = int(np.argmax(np.bincount(labels.ravel())[1:])) + 1  # (label 0: not free)
    return np.argwhere(labels == largest)


def _spots(
    grid: OccupancyGrid, clearance: NDArray[np.float32], need_m: float, area: list[float]
) -> NDArray[np.float64]:
    """(N, 3) x, y, clearance of the cells in ``area`` with ``need_m`` clearance, in the largest
    connected region of such floor (over the whole map: a region may leave the area between spots)."""
    cells = _largest_region(clearance >= need_m)
    xy = grid.to_xy(cells)
    inside = _in_area(xy, area)
    return np.column_stack([xy[inside], clearance[cells[inside, 0], cells[inside, 1]]])


def _pick_apart(
    rng: np.random.Generator,
    candidates: NDArray[np.float64],
    radii_m: list[float],
    taken: list[tuple[float, float, float]],
) -> list[tuple[float, float]]:
    """Pick one candidate per radius in seeded order, each circle of ``radii_m[k]`` clear of every
    taken (x, y, radius) circle (``taken`` grows); fewer when the floor has no room left."""
    picked: list[tuple[float, float]] = []
    for i in rng.permutation(len(candidates)):
        if len(picked) == len(radii_m):
            break
        x, y = float(candidates[i, 0]), float(candidates[i, 1])
        radius = radii_m[len(picked)]
        if taken:
            t = np.asarray(taken)
            if np.any(np.hypot(t[:, 0] - x, t[:, 1] - y) < t[:, 2] + radius):
                continue
        picked.append((round(x, 2), round(y, 2)))
        taken.append((x, y, radius))
    return picked


def generate_missions(
    spec: MissionsConfig,
    *,
    seed: int,
    layout: str = "warehouse_layout.csv",
    fidelity: str = "default",
    resolution_m: float = 0.1,
    clearance_m: float = 0.4,
    cameras: tuple[CameraModel, ...] = (),
) -> Missions:
    """The fleet's agents (type, home pose, goals, speed) from ``spec`` and ``seed``, deterministically.

    With ``cameras`` (robots that steer on the cameras' estimates), every spot lies in one connected
    part of the floor where each robot type of the mix is seen by a camera at every heading
    (``_seen_spots``): a robot that drives, starts or stops where no camera sees its marker is
    stopped by the safety layer and never localized again. Under the GPSS cameras that part is
    mostly the main aisle, so it holds fewer robots than the whole floor.

    Raises:
        ConfigError: no robots, or the area's floor cannot hold the robots, docks and chargers apart.
    """
    if spec.robots < 1:
        raise _bad(
            "fleet.robots",
            spec.robots,
            f"must be within 1..{MAX_ROBOTS} for scenario=fleet",
            "use e.g. fleet.robots=4",
        )
    kinds: list[AgentType] = [AGENT_TYPES[spec.types[i % len(spec.types)]] for i in range(spec.robots)]
    widest = max(k.radius_m for k in kinds)
    planner_m = max(k.half_width_m for k in kinds) + clearance_m
    grid, clearance = _floor(layout, fidelity, resolution_m)
    need = max(widest + MARGIN_M, planner_m)
    shared = spec.docks + spec.chargers
    spots = (
        _seen_spots(grid, clearance, need, planner_m, cameras, kinds, spec.area_m)
        if cameras
        else _spots(grid, clearance, need, spec.area_m)
    )
    rack_band = spots[spots[:, 2] <= spots[:, 2].min() + RACK_BAND_M] if len(spots) else spots
    # a draw that leaves no room (homes, docks, a pickup) is drawn again from the same seed:
    # every seed of a sweep gets missions where the floor holds them at all
    for attempt in range(DRAWS):
        # (23: the issue; any constant keeps seeds independent; the first draw as it always was)
        rng = np.random.default_rng([seed, 23] if attempt == 0 else [seed, 23, attempt])
        taken: list[tuple[float, float, float]] = []
        stations = _pick_apart(rng, spots, [widest + SPACING_M] * shared, taken)
        homes = _pick_apart(rng, spots, [k.radius_m + SPACING_M / 2 for k in kinds], taken)
        near_rack = rack_band
        for x, y, r in taken:  # a pickup keeps clear of homes (robots park there) and shared spots
            near_rack = near_rack[
                np.hypot(near_rack[:, 0] - x, near_rack[:, 1] - y) >= r + widest + SPACING_M
            ]
        if len(stations) == shared and len(homes) == spec.robots and len(near_rack):
            break
    if len(stations) < shared or len(homes) < spec.robots:
        raise _bad(
            "fleet.robots",
            spec.robots,
            f"the free floor of fleet.area_m={list(spec.area_m)} holds only {len(homes)} of these robots apart"
            f" beside {spec.docks} docks and {spec.chargers} chargers"
            + (
                " where the cameras see them (robots steer on the cameras: localization.source=camera)"
                if cameras
                else ""
            ),
            "use fewer robots (or smaller types, or a larger fleet.area_m"
            + (", or more cameras)" if cameras else ")"),
        )
    if not len(near_rack):
        raise _bad(
            "fleet.area_m",
            list(spec.area_m),
            "no pickup spot left clear of the homes and docks",
            "use fewer robots or a larger area",
        )
    docks, chargers = stations[: spec.docks], stations[spec.docks :]
    agents: dict[str, dict[str, Any]] = {}
    for i, (kind, home) in enumerate(zip(kinds, homes, strict=True)):
        goals: list[list[float]] = []
        for t in range(spec.tasks):
            if spec.charge_every and (t + 1) % spec.charge_every == 0:
                goals += [list(chargers[int(rng.integers(len(chargers)))]), list(home)]
            else:
                x, y, _ = near_rack[int(rng.integers(len(near_rack)))]
                goals += [
                    [round(float(x), 2), round(float(y), 2)],
                    list(docks[int(rng.integers(len(docks)))]),
                ]
        if goals[-1] != list(home):
            goals.append(list(home))
        yaw = round(_seen_heading(float(rng.uniform(-math.pi, math.pi)), home, kind, cameras), 4)
        agents[f"robot_agent_{i + 1}"] = {
            "type": kind.name,
            "pose": [home[0], home[1], yaw],
            "goals": goals,
            "speed_mps": float(spec.speed_mps),
        }
    walks = _walks(spec, grid, clearance, seed=seed, area=spec.area_m, taken=taken)
    for k, (home, goals) in enumerate(walks):
        agents[f"robot_agent_{spec.robots + k + 1}"] = {
            "type": PERSON,
            "pose": [home[0], home[1], _heading(home, goals[0])],
            "goals": goals,
            "speed_mps": float(spec.people_speed_mps),
            "loop": True,
        }
    return Missions(agents, [list(d) for d in docks], [list(c) for c in chargers])


def _seen_spots(
    grid: OccupancyGrid,
    clearance: NDArray[np.float32],
    need_m: float,
    drive_m: float,
    cameras: tuple[CameraModel, ...],
    kinds: list[AgentType],
    area: list[float],
) -> NDArray[np.float64]:
    """``_spots`` for robots that steer on the cameras: cells with ``need_m`` clearance in ``area``
    that lie in one connected part of the floor where every type of the mix is seen at every
    heading (``coverage.connected_seen``, driven with ``drive_m`` clearance: the widest robot's
    planner radius), the part that holds most of them. A robot driving between two spots of
    different parts would lose the cameras on the way and stand for good."""
    drive = clearance >= drive_m
    markers = sorted({k.marker_xyz for k in kinds if k.marker_xyz is not None})
    if not markers:  # no robot carries a marker: nothing to see
        return _spots(grid, clearance, need_m, area)
    seen = seen_by_all(seen_floor(grid, cameras, m, marker_size_m=MARKER_SIZE_M, free=drive) for m in markers)
    labels = connected_seen(seen, drive)
    cells = np.argwhere((clearance >= need_m) & (labels > 0))
    xy = grid.to_xy(cells) if len(cells) else np.zeros((0, 2))
    inside = _in_area(xy, area)
    cells, xy = cells[inside], xy[inside]
    if not len(cells):
        return np.zeros((0, 3))
    part = labels[cells[:, 0], cells[:, 1]]
    best = int(np.argmax(np.bincount(part)))
    keep = part == best
    return np.column_stack([xy[keep], clearance[cells[keep, 0], cells[keep, 1]]])


def _seen_heading(
    yaw: float, xy: tuple[float, float], kind: AgentType, cameras: tuple[CameraModel, ...]
) -> float:
    """``yaw``, or where a camera does not see the robot's marker at its home facing so, the
    nearest of 16 headings at which one does (a robot not seen at the start is never localized)."""
    if not cameras or kind.marker_xyz is None:
        return yaw
    turns = np.array([0.0, *[s * k * math.pi / 8 for k in range(1, 9) for s in (1, -1)]])
    poses = np.column_stack([np.full((len(turns), 2), xy), yaw + turns])
    seen = markers_in_view(cameras, kind.marker_xyz, poses, size_m=MARKER_SIZE_M)
    return float(math.remainder(yaw + turns[int(np.argmax(seen))], 2 * math.pi)) if seen.any() else yaw


def _walkable(
    grid: OccupancyGrid, clearance: NDArray[np.float32], need_m: float, area: list[float]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """People's spots: (N, 3) x, y, clearance of the largest connected region of floor with
    ``need_m`` clearance inside ``area`` (their paths stay in the area: under the cameras), and
    the cells outside the area."""
    rows, cols = np.indices(clearance.shape)
    xy = grid.to_xy(np.column_stack([rows.ravel(), cols.ravel()])).reshape(*clearance.shape, 2)
    outside = ~_in_area(xy, area)
    cells = _largest_region((clearance >= need_m) & ~outside)
    return np.column_stack([grid.to_xy(cells), clearance[cells[:, 0], cells[:, 1]]]), outside


def _heading(a: tuple[float, float], b: list[float]) -> float:
    return round(math.atan2(b[1] - a[1], b[0] - a[0]), 4)


def _walks(
    spec: MissionsConfig,
    grid: OccupancyGrid,
    clearance: NDArray[np.float32],
    *,
    seed: int,
    area: list[float],
    taken: list[tuple[float, float, float]],
) -> list[tuple[tuple[float, float], list[list[float]]]]:
    """Each person's home and the corners of its loop (home -> PERSON_STOPS spots -> home), planned
    on the grid with the person's radius plus ``MARGIN_M``; homes clear of ``taken`` (robots, docks)."""
    if not spec.people:
        return []
    person = AGENT_TYPES[PERSON]
    need = person.radius_m + MARGIN_M
    spots, outside = _walkable(grid, clearance, need, area)
    rng = np.random.default_rng([seed, 25])  # (25: the dataset issue; robots' draws stay as they were)
    homes = _pick_apart(rng, spots, [person.radius_m + SPACING_M / 2] * spec.people, taken)
    if len(homes) < spec.people:
        raise _bad(
            "fleet.people",
            spec.people,
            f"the free floor of fleet.area_m={list(area)} holds only {len(homes)} people apart beside the robots",
            "use fewer people or a larger fleet.area_m",
        )
    planner = GridPlanner(grid, radius_m=need)
    out = []
    for home in homes:
        stops = [tuple(spots[int(i), :2]) for i in rng.integers(len(spots), size=PERSON_STOPS)]
        corners: list[list[float]] = []
        here = home
        for there in [*stops, home]:
            try:
                path = planner.plan(here, there, blocked=outside).points_xy  # in the area
            except PlanningError:  # no way inside the area: the next stop
                continue
            corners += [[round(float(x), 2), round(float(y), 2)] for x, y in path[1:]]
            here = (float(path[-1, 0]), float(path[-1, 1]))
        out.append((home, corners or [list(home)]))
    return out


@functools.lru_cache(maxsize=8)
def _generated(
    section: str,
    seed: int,
    layout: str,
    fidelity: str,
    resolution_m: float,
    clearance_m: float,
    view: tuple[tuple[int, ...], str, int, int] | None,
) -> Missions:
    """``generate_missions`` of a JSON ``fleet`` section, in the view of the cameras ``view`` (ids,
    calibration directory, width, height) when robots steer on them (cached: the resolver runs
    several times a run, and the view and people's paths take a while)."""
    return generate_missions(
        MissionsConfig(**json.loads(section)),
        seed=seed,
        layout=layout,
        fidelity=fidelity,
        resolution_m=resolution_m,
        clearance_m=clearance_m,
        cameras=() if view is None else _cameras(*view),
    )


def _cameras(ids: tuple[int, ...], directory: str, width: int, height: int) -> tuple[CameraModel, ...]:
    """The run's cameras at its resolution; none where a calibration does not load (the scene
    refuses such a camera with its own message, before anything runs)."""
    try:
        return tuple(load_calibration(i, directory or None).camera.scaled(width, height) for i in ids)
    except (CalibrationError, ConfigError, OSError):
        return ()


def resolve(key: str, root: Mapping[Any, Any]) -> Any:
    """Value of ``${fleet_missions:KEY}`` (``agents``, ``docks``, ``chargers``) for a whole config."""
    section = dict(root.get("fleet") or {})
    world, nav = root.get("world") or {}, root.get("navigation") or {}
    cams = root.get("cameras") or {}
    steer_on_cameras = (root.get("localization") or {}).get("source", "camera") == "camera"
    view = (
        (
            tuple(cams.get("ids") or ()),
            str(cams.get("calibration_dir") or ""),
            int(cams.get("width", 960)),
            int(cams.get("height", 540)),
        )
        if steer_on_cameras
        else None
    )
    missions = _generated(
        json.dumps(section, sort_keys=True, default=list),
        int(root.get("seed", 0)),
        str(world.get("layout", "warehouse_layout.csv")),
        str(world.get("fidelity", "default")),
        float(nav.get("resolution_m", 0.1)),
        float(nav.get("clearance_m", 0.4)),
        view,
    )
    values = {"agents": missions.agents, "docks": missions.docks, "chargers": missions.chargers}
    if key not in values:
        raise KeyError(f"unknown fleet_missions key {key!r}; known: {', '.join(values)}")
    return values[key]
