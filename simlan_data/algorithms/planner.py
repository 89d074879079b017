"""Grid path planning: A* on a clearance-weighted grid, then line-of-sight smoothing.

Pure numpy. A cell is traversable if its clearance (distance to the nearest obstacle) is at least
the robot's radius; within a comfort band the step cost grows, so paths keep to the middle of
aisles instead of hugging shelves. With the floor the cameras see (``coverage.SeenFloor``, per
heading), entering a cell facing a way no camera sees the robot's marker costs ``unseen_cost`` per
metre more: a robot that steers on the cameras keeps to the floor where they localize it, and
crosses unseen floor only where no other way exists.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simlan_data.algorithms.coverage import HEADINGS, heading_index
from simlan_data.algorithms.occupancy import OccupancyGrid

_SQRT2 = float(np.sqrt(2.0))
# the heading bin of a move (d_row, d_col): rows grow with y
_HEADING = {(dr, dc): heading_index(math.atan2(dr, dc)) for dr in (-1, 0, 1) for dc in (-1, 0, 1)}
_MOVES = [
    (-1, 0, 1.0),
    (1, 0, 1.0),
    (0, -1, 1.0),
    (0, 1, 1.0),
    (-1, -1, _SQRT2),
    (-1, 1, _SQRT2),
    (1, -1, _SQRT2),
    (1, 1, _SQRT2),
]


class PlanningError(Exception):
    """No path exists (the start or goal is blocked, or they are not connected)."""


@dataclass(frozen=True)
class Plan:
    points_xy: NDArray[np.float64]  # (N, 2) from start to goal
    length_m: float
    expanded: int
    reverse: tuple[bool, ...] | None = None  # per segment: driven backwards (a fleet plan's route)
    stops: tuple[int, ...] | None = None  # vertices where it stops to turn on the spot (a fleet plan's)


class GridPlanner:
    """A* for a robot of a given radius on a static occupancy grid."""

    def __init__(
        self,
        grid: OccupancyGrid,
        *,
        radius_m: float,
        comfort_m: float = 1.0,
        comfort_weight: float = 2.0,
        seen: NDArray[np.bool_] | None = None,
        unseen_cost: float = 0.0,
    ) -> None:
        self.grid = grid
        self.radius_m = radius_m
        clearance = grid.clearance_m()
        self.free = clearance >= radius_m
        # extra cost per metre walked near obstacles (0 beyond radius + comfort)
        self.penalty = np.clip((radius_m + comfort_m - clearance) / comfort_m, 0.0, 1.0) * comfort_weight
        self.clearance = clearance
        # (HEADINGS, rows, cols) SeenFloor.by_heading, or None: every cell counts as seen
        self.unseen = None if seen is None or unseen_cost <= 0 else ~np.asarray(seen, dtype=bool)
        # per heading bin: the cost per metre of entering a cell (1 + comfort penalty + unseen)
        base = 1.0 + self.penalty
        self._cost = (
            [base] * HEADINGS
            if self.unseen is None
            else [base + (unseen_cost * u).astype(base.dtype) for u in self.unseen]
        )

    def nearest_free(self, cell: tuple[int, int], max_radius_cells: int = 20) -> tuple[int, int] | None:
        """The closest traversable cell to ``cell`` (for starts/goals that touch the inflation)."""
        if self.grid.inside(cell) and self.free[cell]:
            return cell
        r0, c0 = cell
        for r in range(1, max_radius_cells + 1):
            best, best_d = None, None
            for dr in range(-r, r + 1):
                for dc in range(-r, r + 1):
                    if max(abs(dr), abs(dc)) != r:
                        continue
                    c = (r0 + dr, c0 + dc)
                    if self.grid.inside(c) and self.free[c]:
                        d = dr * dr + dc * dc
                        if best_d is None or d < best_d:
                            best, best_d = c, d
            if best is not None:
                return best
        return None

    def plan(
        self,
        start_xy: tuple[float, float],
        goal_xy: tuple[float, float],
        *,
        blocked: NDArray[np.bool_] | None = None,
        max_length_m: float = np.inf,
    ) -> Plan:
        """Shortest path (by clearance-weighted length) from start to goal; raises PlanningError.

        ``max_length_m`` bounds the search: no path is sought that is longer (a detour that
        would not be taken anyway costs nothing instead of a search of the whole building).
        """
        free = self.free if blocked is None else self.free & ~blocked
        start = self.nearest_free(self.grid.to_cell(start_xy))
        goal = self.grid.to_cell(goal_xy)
        if not self.grid.inside(goal) or not free[goal]:
            raise PlanningError(
                f"goal {tuple(round(v, 2) for v in goal_xy)} is inside an obstacle or outside the map"
            )
        if start is None or not free[start]:
            raise PlanningError(f"start {tuple(round(v, 2) for v in start_xy)} has no free cell nearby")
        rows, cols = free.shape
        g = np.full(free.shape, np.inf)
        parent = np.full((*free.shape, 2), -1, dtype=np.int32)
        g[start] = 0.0
        gr, gc = goal
        heap: list[tuple[float, float, int, int]] = [(0.0, 0.0, start[0], start[1])]
        closed = np.zeros(free.shape, dtype=bool)
        expanded = 0
        max_cost = max_length_m / self.grid.resolution_m
        moves = [(dr, dc, step, self._cost[_HEADING[dr, dc]]) for dr, dc, step in _MOVES]
        while heap:
            f, cost, r, c = heapq.heappop(heap)
            if f > max_cost:
                break
            if closed[r, c]:
                continue
            closed[r, c] = True
            expanded += 1
            if (r, c) == goal:
                break
            for dr, dc, step, cost_per_m in moves:
                nr, nc = r + dr, c + dc
                if nr < 0 or nc < 0 or nr >= rows or nc >= cols or closed[nr, nc] or not free[nr, nc]:
                    continue
                if dr and dc and not (free[r + dr, c] and free[r, c + dc]):
                    continue  # no corner cutting
                ng = cost + step * cost_per_m[nr, nc]
                if ng < g[nr, nc]:
                    g[nr, nc] = ng
                    parent[nr, nc] = (r, c)
                    ddr, ddc = abs(nr - gr), abs(nc - gc)
                    h = (ddr + ddc) + (_SQRT2 - 2.0) * min(ddr, ddc)
                    heapq.heappush(heap, (ng + h, ng, nr, nc))
        if not closed[goal]:
            raise PlanningError(
                f"no path from {tuple(round(v, 2) for v in start_xy)} to {tuple(round(v, 2) for v in goal_xy)}"
            )
        cells = [goal]
        while cells[-1] != start:
            pr, pc = parent[cells[-1]]
            cells.append((int(pr), int(pc)))
        cells.reverse()
        points = self.grid.to_xy(np.array(cells))
        points[0] = start_xy
        points[-1] = goal_xy
        points = self._smooth(points, free)
        length = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
        return Plan(points, length, expanded)

    def _segment_ok(
        self,
        a: NDArray[np.float64],
        b: NDArray[np.float64],
        free: NDArray[np.bool_],
        max_penalty: float,
        unseen_ok: bool = True,
    ) -> bool:
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / (0.5 * self.grid.resolution_m))))
        unseen = None
        if self.unseen is not None and not unseen_ok:
            unseen = self.unseen[heading_index(math.atan2(b[1] - a[1], b[0] - a[0]))]
        for t in np.linspace(0.0, 1.0, n):
            cell = self.grid.to_cell(a + t * (b - a))
            if not self.grid.inside(cell) or not free[cell] or self.penalty[cell] > max_penalty:
                return False
            if unseen is not None and t > 0.0 and unseen[cell]:
                return False
        return True

    def _unseen_points(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Per path point: is it entered (from the point before) facing a way no camera sees?"""
        out = np.zeros(len(points), dtype=bool)
        if self.unseen is None:
            return out
        for k in range(1, len(points)):
            d = points[k] - points[k - 1]
            cell = self.grid.to_cell(points[k])
            if self.grid.inside(cell):
                out[k] = self.unseen[heading_index(math.atan2(d[1], d[0]))][cell]
        return out

    def _smooth(self, points: NDArray[np.float64], free: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Drop intermediate points while the straight segment stays free and no closer to
        obstacles than the grid path it replaces (string pulling; a shortcut may not cut a corner
        the search kept away from, but may run straight through a narrow gap), nor onto floor the
        cameras do not see where the path it replaces is seen."""
        penalty = np.array([self.penalty[self.grid.to_cell(p)] for p in points])
        unseen = self._unseen_points(points)
        out = [points[0]]
        i = 0
        while i < len(points) - 1:
            j = len(points) - 1
            while j > i + 1 and not self._segment_ok(
                points[i],
                points[j],
                free,
                float(penalty[i : j + 1].max()) + 1e-6,
                bool(unseen[i + 1 : j + 1].any()),
            ):
                j = max(i + 1, (i + j) // 2) if j - i > 8 else j - 1
            out.append(points[j])
            i = j
        return np.array(out)
