"""Occupancy grids of the warehouse: from the world's geometry or from SIMLAN's Nav2 map.

Pure numpy/OpenCV over plain data (layout placements, model specs, a PGM image).
Cell (row, col) covers x = origin_x + (col + 0.5) * resolution, y = origin_y + (row + 0.5) * res.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from simlan_data.errors import AssetError
from simlan_data.geometry.transforms import Transform
from simlan_data.world.layout import Placement
from simlan_data.world.models import BUILDING_X_M, BUILDING_Y_M, model_spec

ROBOT_BAND_M = (0.03, 2.2)  # obstacles matter if they reach into this height band


@dataclass(frozen=True)
class OccupancyGrid:
    """Boolean occupancy on a regular grid in the map frame."""

    occupied: NDArray[np.bool_]  # (rows, cols)
    origin_xy_m: tuple[float, float]
    resolution_m: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape

    def to_cell(self, xy: NDArray[np.float64] | tuple[float, float]) -> tuple[int, int]:
        x, y = float(xy[0]), float(xy[1])
        return int(np.floor((y - self.origin_xy_m[1]) / self.resolution_m)), int(
            np.floor((x - self.origin_xy_m[0]) / self.resolution_m)
        )

    def to_xy(self, cells: NDArray[np.int64]) -> NDArray[np.float64]:
        """(N, 2) rows, cols -> (N, 2) x, y of the cell centres."""
        cells = np.asarray(cells)
        return np.stack(
            [
                self.origin_xy_m[0] + (cells[:, 1] + 0.5) * self.resolution_m,
                self.origin_xy_m[1] + (cells[:, 0] + 0.5) * self.resolution_m,
            ],
            axis=1,
        )

    def inside(self, cell: tuple[int, int]) -> bool:
        return 0 <= cell[0] < self.shape[0] and 0 <= cell[1] < self.shape[1]

    def clearance_m(self) -> NDArray[np.float32]:
        """Distance from every cell to the nearest occupied cell, in metres."""
        free = (~self.occupied).astype(np.uint8)
        return cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * np.float32(self.resolution_m)


def _footprint_polygon(pose: Transform, half: tuple[float, ...]) -> NDArray[np.float64] | None:
    """The xy outline of a box's footprint, or None if the box misses the robot height band."""
    hx, hy, hz = half
    corners = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    world = pose.apply(corners)
    if world[:, 2].max() < ROBOT_BAND_M[0] or world[:, 2].min() > ROBOT_BAND_M[1]:
        return None
    return cv2.convexHull(world[:, :2].astype(np.float32)).reshape(-1, 2).astype(np.float64)


def grid_from_world(
    placements: list[Placement], *, resolution_m: float, margin_m: float = 1.0
) -> OccupancyGrid:
    """Rasterize every colliding, non-floor part of the layout that reaches the robots' height."""
    x0, x1 = BUILDING_X_M[0] - margin_m, BUILDING_X_M[1] + margin_m
    y0, y1 = BUILDING_Y_M[0] - margin_m, BUILDING_Y_M[1] + margin_m
    cols, rows = int(np.ceil((x1 - x0) / resolution_m)), int(np.ceil((y1 - y0) / resolution_m))
    img = np.zeros((rows, cols), dtype=np.uint8)
    for pl in placements:
        spec = model_spec(pl.model)
        if spec is None or spec.semantic in ("floor", "floor_marking"):
            continue
        base = (
            Transform.identity()
            if spec.world_frame
            else Transform.from_xyz_rpy([pl.xyz_m[0], pl.xyz_m[1], pl.xyz_m[2] + spec.z_offset_m], pl.rpy_rad)
        )
        for part in spec.parts:
            if not part.collide or part.shape == "plane":
                continue
            pose = base @ Transform.from_xyz_rpy(part.xyz, part.rpy)
            half = part.size if part.shape == "box" else (part.size[0], part.size[0], part.size[1] / 2)
            poly = _footprint_polygon(pose, half)
            if poly is None:
                continue
            px = np.stack([(poly[:, 0] - x0) / resolution_m, (poly[:, 1] - y0) / resolution_m], axis=1)
            cv2.fillConvexPoly(img, np.round(px * 16).astype(np.int32), 1, lineType=cv2.LINE_8, shift=4)
    return OccupancyGrid(img.astype(bool), (x0, y0), resolution_m)


def grid_from_nav2_map(yaml_path: Path, *, resolution_m: float) -> OccupancyGrid:
    """SIMLAN's Nav2 map (trinary PGM + YAML); unknown counts as occupied; resampled conservatively."""
    try:
        meta = yaml.safe_load(yaml_path.read_text())
        image = cv2.imread(str(yaml_path.parent / meta["image"]), cv2.IMREAD_GRAYSCALE)
        res, (ox, oy, _) = float(meta["resolution"]), meta["origin"]
        free_thresh, negate = float(meta.get("free_thresh", 0.25)), int(meta.get("negate", 0))
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError) as err:
        raise AssetError(
            "occupancy map unreadable",
            str(yaml_path),
            f"{type(err).__name__}: {err}",
            "point navigation to a Nav2 map YAML",
        ) from err
    if image is None:
        raise AssetError(
            "occupancy map image unreadable", str(yaml_path), "the PGM does not load", "restore the map image"
        )
    p = image.astype(np.float32) / 255.0 if negate else (255.0 - image.astype(np.float32)) / 255.0
    occupied = (p >= free_thresh).astype(np.float32)[::-1]  # PGM row 0 is the top (largest y)
    scale = res / resolution_m
    resized = cv2.resize(occupied, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return OccupancyGrid(resized > 0.0, (float(ox), float(oy)), resolution_m)
