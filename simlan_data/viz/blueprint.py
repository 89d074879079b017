"""The Rerun blueprint of an inspected recording: 3D warehouse, camera grid, time series, logs.

+---------------------------------+---------------------------+
| world (3D): layout, frustums,   | camera grid (2D views:    |
| truth and estimates, zones      | image + detections)       |
|                                 +---------------------------+
+---------------------------------+ bird's-eye | events (log) |
| errors over time (time series)  |                           |
+---------------------------------+---------------------------+
"""

from __future__ import annotations

import math

import rerun.blueprint as rrb


def build_blueprint(
    cameras: list[str], namespaces: list[str], *, has_birdseye: bool, has_events: bool
) -> rrb.Blueprint:
    cols = max(1, math.ceil(math.sqrt(len(cameras))))
    camera_views = [rrb.Spatial2DView(origin=f"world/cameras/{cid}", name=f"camera {cid}") for cid in cameras]
    series = [rrb.TimeSeriesView(origin=f"metrics/{ns}", name=f"{ns} errors") for ns in namespaces] or [
        rrb.TimeSeriesView(origin="metrics", name="errors")
    ]
    left = rrb.Vertical(
        rrb.Spatial3DView(origin="world", name="warehouse"),
        rrb.Tabs(*series, name="errors over time"),
        row_shares=[3, 1],
    )
    lower: list[rrb.View] = []
    if has_birdseye:
        lower.append(rrb.Spatial2DView(origin="birdseye", name="bird's-eye view"))
    if has_events:
        lower.append(rrb.TextLogView(origin="events", name="events"))
    right_parts: list[rrb.Container | rrb.View] = [
        rrb.Grid(*camera_views, grid_columns=cols, name="cameras")
        if camera_views
        else rrb.TextDocumentView(origin="world/recording")
    ]
    if lower:
        right_parts.append(rrb.Horizontal(*lower))
    right = rrb.Vertical(*right_parts, row_shares=[3, 1][: len(right_parts)])
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[3, 2]),
        rrb.TimePanel(state="expanded"),
        collapse_panels=False,
    )
