"""Where the cameras localize a robot: the floor on which its marker is in some camera's view, per
heading (the marker sits up to 0.8 m off the robot's centre, so a spot seen facing east may not
be seen facing west).

GPSS robots carry no odometry: a robot that drives where no camera sees its marker is stopped by
the safety layer within ``unobserved_timeout_s`` and, unseen, never moves again. So robots that
steer on the cameras must plan on this floor, and missions must lie in one connected part of it
(``connected_seen``). Pure numpy/OpenCV; the test per pose is ``markers.markers_in_view``.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.markers import markers_in_view
from simlan_data.algorithms.occupancy import OccupancyGrid
from simlan_data.geometry.camera import CameraModel
from simlan_data.world.agent_types import MARKER_SIZE_M, AgentType

HEADINGS = 8  # every 45 degrees: the grid planner's move directions
STEP_CELLS = 2  # tested on every 2nd cell (0.2 m at the default resolution), spread to its block


@dataclass(frozen=True)
class SeenFloor:
    """``by_heading[k, row, col]``: a robot with its centre in the cell, facing ``k * 45`` degrees
    (map frame, counter-clockwise from +x), has its marker in some camera's view."""

    by_heading: NDArray[np.bool_]  # (HEADINGS, rows, cols)

    @property
    def every_heading(self) -> NDArray[np.bool_]:
        """Cells seen at every heading (a robot may turn in place there and stay seen)."""
        return np.asarray(self.by_heading.all(axis=0))

    def __and__(self, other: SeenFloor) -> SeenFloor:
        return SeenFloor(self.by_heading & other.by_heading)


def robot_floors(
    grid: OccupancyGrid,
    cameras: Iterable[CameraModel],
    kinds: Iterable[AgentType],
    *,
    clearance_m: float,
) -> dict[tuple[float, float, float], SeenFloor]:
    """Per marker mount of the driving ``kinds``: the floor the cameras see it on, tested where the
    narrowest of them can drive (its half width + ``clearance_m`` from obstacles; the planners'
    radius). Empty when none of them carries a marker."""
    robots = [k for k in kinds if k.drive == "diff" and k.marker_xyz is not None]
    if not robots:
        return {}
    free = grid.clearance_m() >= min(k.half_width_m for k in robots) + clearance_m
    cams = tuple(cameras)
    return {
        m: seen_floor(grid, cams, m, marker_size_m=MARKER_SIZE_M, free=free)
        for m in sorted({k.marker_xyz for k in robots if k.marker_xyz is not None})
    }


def seen_by_all(floors: Iterable[SeenFloor]) -> SeenFloor:
    """The floor seen for every one of ``floors`` (a robot of each marker mount); at least one."""
    out: SeenFloor | None = None
    for f in floors:
        out = f if out is None else out & f
    if out is None:
        raise ValueError("seen_by_all needs at least one floor")
    return out


def heading_index(yaw_rad: float) -> int:
    """The heading bin ``k`` of ``yaw_rad`` (nearest multiple of 45 degrees)."""
    return round(yaw_rad / (2.0 * math.pi / HEADINGS)) % HEADINGS


_CACHE: dict[tuple[object, ...], SeenFloor] = {}


def seen_floor(
    grid: OccupancyGrid,
    cameras: Iterable[CameraModel],
    marker_xyz: Sequence[float],
    *,
    marker_size_m: float,
    free: NDArray[np.bool_] | None = None,
) -> SeenFloor:
    """The floor where a robot whose marker sits at ``marker_xyz`` (base_link) is seen, tested on
    every ``STEP_CELLS``-th cell of ``free`` (default: every cell not occupied) at ``HEADINGS``
    headings. Cached per grid, cameras and marker (every robot of a type, every seed asks the same)."""
    cams = tuple(cameras)
    free_mask = ~grid.occupied if free is None else free
    key = (
        grid.origin_xy_m,
        grid.resolution_m,
        zlib.crc32(np.packbits(free_mask).tobytes()),
        tuple(
            (c.camera_id, c.width, c.height, c.K.tobytes(), c.D.tobytes(), c.position.tobytes()) for c in cams
        ),
        tuple(float(v) for v in marker_xyz),
        float(marker_size_m),
    )
    if key not in _CACHE:
        if len(_CACHE) > 16:
            _CACHE.clear()
        _CACHE[key] = _compute(grid, cams, marker_xyz, marker_size_m, free_mask)
    return _CACHE[key]


def _compute(
    grid: OccupancyGrid,
    cameras: tuple[CameraModel, ...],
    marker_xyz: Sequence[float],
    marker_size_m: float,
    free: NDArray[np.bool_],
) -> SeenFloor:
    rows, cols = free.shape
    coarse = np.argwhere(free[::STEP_CELLS, ::STEP_CELLS]) * STEP_CELLS
    xy = grid.to_xy(coarse) if len(coarse) else np.zeros((0, 2))
    out = np.zeros((HEADINGS, rows, cols), dtype=bool)
    for k in range(HEADINGS):
        poses = np.column_stack([xy, np.full(len(xy), k * 2.0 * math.pi / HEADINGS)])
        seen = (
            markers_in_view(cameras, marker_xyz, poses, size_m=marker_size_m)
            if len(xy)
            else np.zeros(0, dtype=bool)
        )
        for dr in range(STEP_CELLS):
            for dc in range(STEP_CELLS):
                r, c = coarse[seen, 0] + dr, coarse[seen, 1] + dc
                inside = (r < rows) & (c < cols)
                out[k, r[inside], c[inside]] = True
    return SeenFloor(out & free[None])


def connected_seen(seen: SeenFloor, free: NDArray[np.bool_]) -> NDArray[np.int32]:
    """Labels (0: none) of the 8-connected parts of ``free`` floor seen at every heading: a robot
    can drive between two cells of one part and stay seen whatever way it turns."""
    _, labels = cv2.connectedComponents((free & seen.every_heading).astype(np.uint8), connectivity=8)
    return np.asarray(labels, dtype=np.int32)
