"""Domain randomization (``randomize``, issue 24; docs/sensors.md "Domain randomization").

Scene-level effects are applied once while the scene is built; the lighting effects after each
render, on the colour image, before the camera stage (``sim/sensors.py``), so they hold with
``sensors=ideal`` too::

    layout placements --placement--> build world --materials--> --distractors--> settle, static layers
    spawn agents --agents (paint; marker links untouched)
    each camera frame: render --light (per-channel LUT)--> --time_of_day (sunlit floor patches)-->
                       camera stage --> recorder, algorithms

Every effect draws from its own stream ``run_rng(seed, "randomize", <effect>)``, so turning one
off leaves the others' values alone. What was drawn is kept in ``Randomizer.drawn`` (plain JSON
values) and published once, latched, on ``/simlan/randomization``. With every effect off nothing
is drawn, added or changed: the run is byte for byte the run without the group.

Time of day. PyBullet's EGL renderer ignores the light direction and colour, so the sun is added
after rendering: its direction follows from the hour drawn, ``day_of_year`` and
``latitude_deg`` (map x taken as east, y as north); the skylights (``SKYLIGHTS``: SIMLAN's world
has no roof, these strips are the twin's assumption) project along it onto the floor as sunlit
rectangles. Each camera's floor point per pixel (the ray through its true, possibly drifted, lens
model meeting z = 0) is computed once; a pixel is sunlit when its floor point lies in a patch and
the pixel shows floor (the label image; without labels, depth equal to the floor's; without
either, the patch shows on whatever stands in it). Shadows of shelves inside a patch are not
modelled.
"""

from __future__ import annotations

import colorsys
import itertools
import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray
from shapely import affinity
from shapely.geometry import LineString, Point, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from simlan_data.algorithms.occupancy import OccupancyGrid
from simlan_data.algorithms.planner import GridPlanner, PlanningError
from simlan_data.config.randomize import RandomizeConfig
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import quat_from_rpy
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording.writer import RecordingWriter
from simlan_data.seeding import run_rng
from simlan_data.sim.rendering import Aabb, CameraImages, CameraRenderer
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import WorldBodies, create_body
from simlan_data.world.labels import SEMANTIC_CLASSES
from simlan_data.world.layout import Placement
from simlan_data.world.models import BUILDING_HEIGHT_M, BUILDING_X_M, BUILDING_Y_M, Part, model_spec

if TYPE_CHECKING:
    from simlan_data.config.schema import Config
    from simlan_data.sim.agents import Agent
    from simlan_data.world.agent_types import AgentType

log = logging.getLogger(__name__)

# Skylights in the roof (z = BUILDING_HEIGHT_M): strips 1.6 m (x) by 6 m (y) on a 7.5 m x 10 m
# pitch over the whole building, a common layout for a warehouse of this size (about 5 % of the
# roof glazed). SIMLAN models no roof; these are the twin's, documented in docs/sensors.md.
SKYLIGHT_SIZE_M = (1.6, 6.0)
SKYLIGHT_PITCH_M = (7.5, 10.0)
SKYLIGHT_FIRST_M = (-26.0, -34.0)  # lower-left corner of the first strip
SKYLIGHT_COUNT = (10, 5)
MIN_SUN_ELEVATION = 0.05  # sin(elevation) below which (3 degrees) no patch is drawn
FLOOR, SHELF = SEMANTIC_CLASSES["floor"], SEMANTIC_CLASSES["shelf"]
FLOOR_LABELS = (FLOOR, SEMANTIC_CLASSES["floor_marking"])
_FLOOR_TABLE = np.isin(np.arange(256), FLOOR_LABELS)  # label id -> shows the floor
DISTRACTOR_LABEL = "furniture"  # an existing class: the recorded label table stays as it was
MARKER_LINK_PREFIX = "aruco_marker"  # sim/markers.py: the marker's links keep their colours
ROUTE_MARGIN_M = 0.3  # what an agent's corridor keeps beyond its half width and clearance
SUN_GRID_PX = 4  # floor points of the sun's patches: intersected every 4 pixels, interpolated between
FLOOR_TOLERANCE_M = 0.05  # depth within this (plus 1 %) of the floor's: the floor is seen


def skylights() -> list[tuple[float, float, float, float]]:
    """The skylight rectangles (x0, x1, y0, y1) in the map frame."""
    (w, h), (px, py), (x0, y0), (nx, ny) = SKYLIGHT_SIZE_M, SKYLIGHT_PITCH_M, SKYLIGHT_FIRST_M, SKYLIGHT_COUNT
    return [
        (x0 + i * px, x0 + i * px + w, y0 + j * py, y0 + j * py + h) for i in range(nx) for j in range(ny)
    ]


def sun_direction(hour: float, day_of_year: int, latitude_deg: float) -> NDArray[np.float64]:
    """Unit vector towards the sun (east, north, up) at local solar ``hour``."""
    decl = np.radians(-23.44) * np.cos(2 * np.pi * (day_of_year + 10) / 365.0)
    h = np.radians(15.0 * (hour - 12.0))
    lat = np.radians(latitude_deg)
    return np.array(
        [
            -np.cos(decl) * np.sin(h),
            np.cos(lat) * np.sin(decl) - np.sin(lat) * np.cos(decl) * np.cos(h),
            np.sin(lat) * np.sin(decl) + np.cos(lat) * np.cos(decl) * np.cos(h),
        ]
    )


def in_patches(xy: NDArray[np.float64], offset_xy: Sequence[float]) -> NDArray[np.bool_]:
    """Which floor points (N, 2) lie in a skylight's sunlit patch (the skylights moved by ``offset_xy``)."""
    (w, h), (px, py), (x0, y0), (nx, ny) = SKYLIGHT_SIZE_M, SKYLIGHT_PITCH_M, SKYLIGHT_FIRST_M, SKYLIGHT_COUNT
    u = xy[:, 0] - x0 - offset_xy[0]
    v = xy[:, 1] - y0 - offset_xy[1]
    i, j = np.floor(u / px), np.floor(v / py)
    return (
        (i >= 0) & (i < nx) & (j >= 0) & (j < ny) & (u - i * px <= w) & (v - j * py <= h)
    )  # fmt: skip


def gain_lut(gains: Sequence[float], *, gamma: float = 2.2) -> NDArray[np.uint8]:
    """A per-channel table (1, 256, 3) scaling display-referred values by ``gains`` in linear light."""
    levels = np.arange(256, dtype=np.float64) / 255.0
    linear = levels**gamma
    out = np.stack([np.clip(linear * g, 0.0, 1.0) ** (1.0 / gamma) for g in gains], axis=1)
    return np.round(out * 255.0).astype(np.uint8).reshape(1, 256, 3)


def _tint(rng: np.random.Generator, spread: float) -> list[float]:
    """Per-channel gains: a brightness within 1 +- ``spread``, each channel within 1 +- ``spread`` / 3
    of it (a real floor or paint varies more in lightness than in hue)."""
    brightness = rng.uniform(1.0 - spread, 1.0 + spread)
    return [float(brightness * c) for c in rng.uniform(1.0 - spread / 3, 1.0 + spread / 3, 3)]


def _painted(rgba: Sequence[float], tint: Sequence[float]) -> list[float]:
    return [float(np.clip(c * t, 0.0, 1.0)) for c, t in zip(rgba[:3], tint, strict=True)] + [float(rgba[3])]


def _agent_footprint(pose: Sequence[float], footprint_m: Sequence[float]) -> Polygon:
    x0, x1, y0, y1 = footprint_m
    shape = affinity.rotate(box(x0, y0, x1, y1), float(pose[2]), origin=(0, 0), use_radians=True)
    return affinity.translate(shape, float(pose[0]), float(pose[1]))


def keep_clear(cfg: Config, agent_types: Mapping[str, AgentType], grid: OccupancyGrid) -> BaseGeometry:
    """Where nothing may be moved or put: every agent's start and goals and its route corridor.

    A robot's route is what the planner finds between its start and goals on the run's occupancy
    grid (the straight leg where none is found), widened by its half width, the navigation
    clearance and ``ROUTE_MARGIN_M``; a walker's is the straight legs between its goals.
    """
    shapes: list[BaseGeometry] = []
    planners: dict[float, GridPlanner] = {}
    for a in cfg.agent_list:
        if not a.pose:
            continue
        kind = agent_types[a.namespace]
        shapes.append(_agent_footprint(a.pose, kind.footprint_m).buffer(ROUTE_MARGIN_M))
        width = kind.half_width_m + cfg.navigation.clearance_m + ROUTE_MARGIN_M
        stops = [(float(a.pose[0]), float(a.pose[1]))] + [(float(g[0]), float(g[1])) for g in a.goals]
        if a.loop and len(a.goals) > 1:
            stops.append(stops[1])
        shapes += [Point(p).buffer(width) for p in stops[1:]]
        for start, goal in itertools.pairwise(stops):
            points: Any = [start, goal]
            if kind.drive == "diff":
                radius = round(kind.half_width_m + cfg.navigation.clearance_m, 3)
                planner = planners.setdefault(radius, GridPlanner(grid, radius_m=radius))
                try:
                    points = [start, *map(tuple, planner.plan(start, goal).points_xy), goal]
                except PlanningError:  # the robot will not get there either: its straight leg
                    points = [start, goal]
            shapes.append(LineString(points).buffer(width))
    return unary_union(shapes) if shapes else Polygon()


def moved_placements(
    placements: Sequence[Placement], moved: Mapping[str, Sequence[float]]
) -> list[Placement]:
    """``placements`` with the named ones moved by ``[dx_m, dy_m, dyaw_deg]``."""
    out = []
    for pl in placements:
        if pl.name not in moved:
            out.append(pl)
            continue
        dx, dy, dyaw = (float(v) for v in moved[pl.name])
        (x, y, z), (roll, pitch, yaw) = pl.xyz_m, pl.rpy_rad
        out.append(
            replace(pl, xyz_m=(x + dx, y + dy, z), rpy_rad=(roll, pitch, yaw + float(np.radians(dyaw))))
        )
    return out


def tint_world(client: int, world: WorldBodies, materials: Mapping[str, Sequence[float]]) -> None:
    """Tint the floor's and the shelves' merged meshes (``world.visual_shapes`` too: restored so)."""
    tints = {
        SEMANTIC_CLASSES["floor"]: materials["floor_tint"],
        SEMANTIC_CLASSES["shelf"]: materials["shelf_tint"],
    }
    for body in sorted(world.visual_shapes):
        tint = tints.get(world.labels[body])
        if tint is None:
            continue
        visual, rgba = world.visual_shapes[body]
        colour = _painted(rgba, tint)
        world.visual_shapes[body] = (visual, tuple(colour))
        pb.changeVisualShape(body, -1, rgbaColor=colour, physicsClientId=client)


def add_bodies(client: int, world: WorldBodies, distractors: Sequence[Mapping[str, Any]]) -> list[int]:
    """Create the distractors (static, colliding, labelled) as recorded; their body ids."""
    bodies = []
    for d in distractors:
        sx, sy, height = (float(v) for v in d["size_m"])
        rgba = tuple(float(c) for c in d["rgba"])
        half = (sx / 2, height) if d["shape"] == "cylinder" else (sx / 2, sy / 2, height / 2)
        part = Part(str(d["shape"]), half, (0.0, 0.0, height / 2), rgba=rgba)  # type: ignore[arg-type]
        x, y = (float(v) for v in d["xy_m"])
        orientation = quat_from_rpy(0.0, 0.0, float(d["yaw_rad"]))
        body = create_body(client, [part], position=(x, y, 0.0), orientation=orientation, mass_kg=0.0)
        world.names[body] = str(d["name"])
        world.labels[body] = SEMANTIC_CLASSES[str(d["label"])]
        bodies.append(body)
    return bodies


def replay_placements(placements: Sequence[Placement], record: Mapping[str, Any]) -> list[Placement]:
    """The layout as a recorded run moved it (``record``: the JSON of ``/simlan/randomization``)."""
    return moved_placements(placements, record.get("placement", {}).get("moved", {}))


def replay_world(client: int, world: WorldBodies, record: Mapping[str, Any]) -> None:
    """Colours and distractors of a recorded run, on a world built from ``replay_placements``."""
    if "materials" in record:
        tint_world(client, world, record["materials"])
    add_bodies(client, world, record.get("distractors", []))


@dataclass
class _CameraSun:
    """One camera's sunlit floor pixels (fixed for the run) and the floor's depth there."""

    lit: NDArray[np.intp]  # flat indices of the pixels whose floor point is in a patch
    floor_depth_m: NDArray[np.float32]  # the floor's depth (camera z) at those pixels


class _Reuse:
    """A camera's last input arrays (compared by identity) and the output made of them."""

    __slots__ = ("depth_m", "labels", "out", "rgb")

    def __init__(self, rgb: Any, labels: Any, depth_m: Any, out: NDArray[np.uint8]) -> None:
        self.rgb, self.labels, self.depth_m, self.out = rgb, labels, depth_m, out

    def same(self, images: CameraImages) -> bool:
        return self.rgb is images.rgb and self.labels is images.labels and self.depth_m is images.depth_m


class Randomizer:
    """The run's domain randomization: scene hooks for ``Scene.build``, the post-render step, the record."""

    def __init__(self, cfg: RandomizeConfig, seed: int) -> None:
        self.cfg, self.seed = cfg, seed
        self.drawn: dict[str, Any] = {}
        self._base_lut: NDArray[np.uint8] | None = None
        self._sun_lut: NDArray[np.uint8] | None = None
        self._offset_xy: list[float] | None = None
        self._suns: list[_CameraSun | None] = []
        self._last: list[_Reuse | None] = []
        self._draw_lighting()

    @property
    def active(self) -> bool:
        return self.cfg.active

    @property
    def moves_objects(self) -> bool:
        """True when objects are moved or added (they need ``keep_clear``'s area)."""
        return self.cfg.placement.enabled or (self.cfg.distractors.enabled and self.cfg.distractors.count > 0)

    def _rng(self, *what: str) -> np.random.Generator:
        return run_rng(self.seed, "randomize", *what)

    # ------------------------------------------------------------------------------ lighting
    def _draw_lighting(self) -> None:
        light, sun = self.cfg.light, self.cfg.time_of_day
        gains = [1.0, 1.0, 1.0]
        if light.enabled:
            rng = self._rng("light")
            intensity = float(rng.uniform(1.0 - light.intensity, 1.0 + light.intensity))
            colour = [float(v) for v in rng.uniform(1.0 - light.colour, 1.0 + light.colour, 3)]
            gains = [intensity * c for c in colour]
            self.drawn["light"] = {"intensity": intensity, "colour": colour, "gains": gains}
            self._base_lut = gain_lut(gains)
        if not sun.enabled:
            return
        hour = float(self._rng("time_of_day").uniform(float(sun.hours[0]), float(sun.hours[1])))
        east, north, up = (float(v) for v in sun_direction(hour, sun.day_of_year, sun.latitude_deg))
        record: dict[str, Any] = {
            "hour": hour,
            "sun_direction_enu": [east, north, up],
            "sun_elevation_deg": float(np.degrees(np.arcsin(np.clip(up, -1.0, 1.0)))),
            "sun_azimuth_deg": float(np.degrees(np.arctan2(east, north)) % 360.0),
            "skylights": skylights(),
        }
        if up > MIN_SUN_ELEVATION:
            self._offset_xy = [-east * BUILDING_HEIGHT_M / up, -north * BUILDING_HEIGHT_M / up]
            warm = [1.0, 0.9 + 0.1 * up, 0.75 + 0.25 * up]  # a low sun is warmer
            sun_gains = [g * (1.0 + sun.sun_strength * up) * w for g, w in zip(gains, warm, strict=True)]
            self._sun_lut = gain_lut(sun_gains)
            self._base_lut = self._base_lut if self._base_lut is not None else gain_lut(gains)
            record.update(patch_offset_m=self._offset_xy, sun_gains=sun_gains)
        self.drawn["time_of_day"] = record

    @property
    def lights(self) -> bool:
        """True when rendered colour images change (light or sun): cameras need ``LitRenderer``."""
        return self._base_lut is not None

    def attach_camera(self, cam: CameraModel, *, distorted: bool) -> int:
        """Compute a camera's sunlit floor pixels (once, through its true lens model); its index."""
        self._suns.append(self._sun_pixels(cam, distorted=distorted))
        self._last.append(None)
        return len(self._suns) - 1

    def _sun_pixels(self, cam: CameraModel, *, distorted: bool) -> _CameraSun | None:
        """The pixels whose floor point lies in a patch: floor points (and depths) intersected on a
        grid every ``SUN_GRID_PX`` pixels, interpolated between (the lens model is smooth; a
        full-resolution intersection costs 0.7 s per 960x540 camera, this 16 times less)."""
        if self._offset_xy is None:
            return None
        step = SUN_GRID_PX
        gu = np.arange(0, cam.width + step - 1, step, dtype=np.float64)
        gv = np.arange(0, cam.height + step - 1, step, dtype=np.float64)
        u, v = np.meshgrid(gu, gv)
        points, ok = cam.intersect_plane_z(np.stack([u.ravel(), v.ravel()], axis=1), 0.0, distorted=distorted)
        depth = np.where(ok, cam.world_to_camera(points)[:, 2], 0.0)
        grid = np.stack([points[:, 0], points[:, 1], depth, ok], axis=1).astype(np.float32)
        grid = grid.reshape(len(gv), len(gu), 4)
        px, py = np.meshgrid(np.arange(cam.width, dtype=np.float32), np.arange(cam.height, dtype=np.float32))
        full = cv2.remap(grid, px / step, py / step, cv2.INTER_LINEAR).reshape(-1, 4)
        inside = full[:, 3] > 0.999  # (all four grid neighbours see the floor)
        lit = np.flatnonzero(inside & in_patches(full[:, :2].astype(np.float64), self._offset_xy))
        return _CameraSun(lit, full[lit, 2].astype(np.float32))

    def post_render(self, index: int, images: CameraImages) -> CameraImages:
        """Camera ``index``'s images under the drawn light and sun (the same object when both are off)."""
        if self._base_lut is None or images.rgb is None:
            return images
        last = self._last[index]
        if last is not None and last.same(images):
            return replace(images, rgb=last.out)  # the renderer reused its last images
        out: NDArray[np.uint8] = (
            np.asarray(cv2.LUT(images.rgb, self._base_lut), dtype=np.uint8)
            if "light" in self.drawn
            else images.rgb.copy()  # (the sun alone)
        )
        lit = self._sunlit(index, images)
        if lit is not None and self._sun_lut is not None and len(lit):
            # (only the patch pixels: about a tenth of the image, 3x cheaper than a masked copy)
            colours = images.rgb.reshape(-1, 3)[lit]
            out.reshape(-1, 3)[lit] = cv2.LUT(colours.reshape(-1, 1, 3), self._sun_lut).reshape(-1, 3)
        self._last[index] = _Reuse(images.rgb, images.labels, images.depth_m, out)
        return replace(images, rgb=out)

    def _sunlit(self, index: int, images: CameraImages) -> NDArray[np.intp] | None:
        """Flat indices of the pixels of this frame that show a sunlit floor patch."""
        sun = self._suns[index]
        if sun is None:
            return None
        if images.labels is not None:
            return sun.lit[_FLOOR_TABLE[images.labels.reshape(-1)[sun.lit]]]
        if images.depth_m is not None:
            tolerance = FLOOR_TOLERANCE_M + 0.01 * sun.floor_depth_m
            return sun.lit[np.abs(images.depth_m.reshape(-1)[sun.lit] - sun.floor_depth_m) <= tolerance]
        return sun.lit

    # ----------------------------------------------------------------------------- the scene
    def jitter_placements(self, placements: Sequence[Placement], clear: BaseGeometry) -> list[Placement]:
        """Boxes and pallets moved and turned by their draw, except those that could reach ``clear``.

        Every box and pallet draws (in layout order) whether it moves or not, so one object's
        fate does not change another's offset.
        """
        cfg = self.cfg.placement
        if not cfg.enabled:
            return list(placements)
        rng = self._rng("placement")
        moved: dict[str, list[float]] = {}
        kept = 0
        for pl in placements:
            spec = model_spec(pl.model)
            if spec is None or spec.semantic not in ("box", "pallet") or spec.world_frame:
                continue
            dx, dy = (float(v) for v in rng.uniform(-cfg.xy_m, cfg.xy_m, 2))
            dyaw = float(rng.uniform(-cfg.yaw_deg, cfg.yaw_deg))
            reach = max(
                (np.hypot(abs(p.xyz[0]) + p.size[0], abs(p.xyz[1]) + p.size[1]) for p in spec.parts),
                default=0.0,
            )
            x, y = pl.xyz_m[0], pl.xyz_m[1]
            if clear.intersects(Point(x, y).buffer(reach + cfg.xy_m * np.sqrt(2))):
                kept += 1
                continue
            moved[pl.name] = [dx, dy, dyaw]
        self.drawn["placement"] = {"moved": moved, "kept_near_routes": kept}
        return moved_placements(placements, moved)

    def paint_world(self, client: int, world: WorldBodies) -> None:
        """Tint the floor's and the shelves' colours (their merged meshes, as restored later too)."""
        cfg = self.cfg.materials
        if not cfg.enabled:
            return
        tints = {FLOOR: _tint(self._rng("floor"), cfg.floor), SHELF: _tint(self._rng("shelf"), cfg.shelf)}
        self.drawn["materials"] = {"floor_tint": tints[FLOOR], "shelf_tint": tints[SHELF]}
        tint_world(client, world, self.drawn["materials"])

    def add_distractors(
        self,
        client: int,
        world: WorldBodies,
        *,
        cameras: Sequence[CameraModel],
        grid: OccupancyGrid,
        clear: BaseGeometry,
    ) -> list[int]:
        """Put static primitives on free floor that a camera sees; returns their body ids."""
        cfg = self.cfg.distractors
        if not cfg.enabled or cfg.count == 0:
            return []
        rng = self._rng("distractors")
        grid_clearance = grid.clearance_m()
        (bx0, bx1), (by0, by1) = BUILDING_X_M, BUILDING_Y_M
        taken: list[BaseGeometry] = []
        placed: list[dict[str, Any]] = []
        for _ in range(cfg.count * 60):
            if len(placed) == cfg.count:
                break
            cam = cameras[int(rng.integers(len(cameras)))]
            uv = rng.uniform([0, 0], [cam.width, cam.height])
            shape = "cylinder" if rng.random() < 0.4 else "box"
            size = rng.uniform(cfg.min_size_m, cfg.max_size_m, 2)
            height = float(rng.uniform(0.4, 1.1))
            yaw = float(rng.uniform(-np.pi, np.pi))
            colour = [float(c) for c in rng.uniform(0.1, 0.9, 3)] + [1.0]
            point, ok = cam.intersect_plane_z(uv.reshape(1, 2), 0.0)
            x, y = float(point[0, 0]), float(point[0, 1])
            sx, sy = (float(size[0]),) * 2 if shape == "cylinder" else (float(size[0]), float(size[1]))
            footprint = (
                Point(x, y).buffer(sx / 2)
                if shape == "cylinder"
                else affinity.rotate(
                    box(x - sx / 2, y - sy / 2, x + sx / 2, y + sy / 2), yaw, use_radians=True
                )
            )
            reach = float(np.hypot(sx, sy) / 2)
            cell = grid.to_cell((x, y))
            if (
                not ok[0]
                or not (bx0 + reach < x < bx1 - reach and by0 + reach < y < by1 - reach)
                or not grid.inside(cell)
                or grid_clearance[cell] < reach + 0.15
                or footprint.buffer(cfg.clearance_m).intersects(clear)
                or any(footprint.buffer(cfg.clearance_m).intersects(t) for t in taken)
            ):
                continue
            taken.append(footprint)
            placed.append(
                {"name": f"distractor_{len(placed)}", "shape": shape, "xy_m": [x, y], "yaw_rad": yaw,
                 "size_m": [sx, sy, height], "rgba": colour, "label": DISTRACTOR_LABEL}
            )  # fmt: skip
        if len(placed) < cfg.count:
            log.info(
                "randomize.distractors: placed %d of %d (no more free floor in view)", len(placed), cfg.count
            )
        self.drawn["distractors"] = placed
        return add_bodies(client, world, placed)

    def paint_agents(self, client: int, agents: Sequence[Agent]) -> None:
        """Give every agent a paint: each link's colour turned in hue, saturation and value; the
        ArUco marker's links keep theirs (their black and white cells are the code)."""
        cfg = self.cfg.agents
        if not cfg.enabled:
            return
        record: dict[str, Any] = {}
        for agent in agents:
            rng = self._rng("agents", agent.namespace)
            dh = float(rng.uniform(-cfg.hue_deg, cfg.hue_deg)) / 360.0
            ds = float(rng.uniform(1.0 - cfg.saturation, 1.0 + cfg.saturation))
            dv = float(rng.uniform(1.0 - cfg.value, 1.0 + cfg.value))
            names = {-1: "base"} | {
                j: pb.getJointInfo(agent.body, j, physicsClientId=client)[12].decode()
                for j in range(pb.getNumJoints(agent.body, physicsClientId=client))
            }
            links: dict[str, list[float]] = {}
            for shape in pb.getVisualShapeData(agent.body, physicsClientId=client):
                link, rgba = shape[1], shape[7]
                name = names.get(link, str(link))
                if name.startswith(MARKER_LINK_PREFIX) or name in links:
                    continue  # (one colour per link: PyBullet's EGL renderer draws one)
                h, s, v = colorsys.rgb_to_hsv(*rgba[:3])
                r, g, b = colorsys.hsv_to_rgb((h + dh) % 1.0, min(1.0, s * ds), min(1.0, v * dv))
                links[name] = [float(r), float(g), float(b), float(rgba[3])]
                pb.changeVisualShape(agent.body, link, rgbaColor=links[name], physicsClientId=client)
            record[agent.namespace] = {"hue_turn": dh, "saturation": ds, "value": dv, "links": links}
        self.drawn["agents"] = record

    # ---------------------------------------------------------------------------- the record
    def publish(self, writer: RecordingWriter) -> None:
        """Record what was drawn, once (latched), when any effect is on."""
        if self.active:
            writer.write(RANDOMIZATION_TOPIC, 0, M.string(self.record()))

    def record(self) -> str:
        """The drawn values as JSON text (keys sorted: same draws, same bytes)."""
        return json.dumps({"seed": self.seed, "name": self.cfg.name, **self.drawn}, sort_keys=True)


class LitRenderer(CameraRenderer):
    """A camera renderer whose colour images carry the run's drawn light and sun
    (``Randomizer.post_render``), for every caller of ``render``: the one-render tick, the
    shutter's sub-frames, late cameras."""

    def __init__(self, *args: Any, randomizer: Randomizer, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.randomizer = randomizer
        self.index = randomizer.attach_camera(self.camera, distorted=self.distort)

    def render(self, moved_aabbs: Sequence[Aabb] = ()) -> CameraImages:
        return self.randomizer.post_render(self.index, super().render(moved_aabbs))


RANDOMIZATION_TOPIC = next(t for t in schema.GLOBAL_TOPICS if t.name == schema.RANDOMIZATION)
