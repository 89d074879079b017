"""The Rerun blueprint of an inspected recording: 3D warehouse, camera grids, time series, logs.

+---------------------------------+---------------------------+
| world (3D): layout, frustums    | tabs of camera grids (2D, |
| with the undistorted images,    | as recorded: distorted):  |
| truth and estimates, zones      | colour + detections |     |
|                                 | depth | semantic labels   |
+---------------------------------+---------------------------+
| errors over time (time series)  | bird's-eye | events (log) |
+---------------------------------+---------------------------+

Which image is where: the 3D view shows each camera's ``undistorted`` colour image under its
pinhole (an undistorted camera: Rerun's Pinhole has no lens distortion), so that 3D overlays line
up with the image; the 2D views show the images as recorded (distorted like the real camera),
with the marker detections in those pixels. The recorded images, depth and labels are left out
of the 3D view: projected through a distortion-free pinhole they would not line up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import rerun.blueprint as rrb

# the children of world/cameras/<id> that are distorted pixels: 2D views only
DISTORTED = ("image", "depth", "semantic", "detections")


def _grid(views: Sequence[rrb.View], name: str) -> rrb.Grid:
    return rrb.Grid(*views, grid_columns=max(1, math.ceil(math.sqrt(len(views)))), name=name)


def build_blueprint(
    cameras: list[str],
    namespaces: list[str],
    *,
    has_birdseye: bool,
    has_events: bool,
    depth_cameras: list[str] | None = None,
    semantic_cameras: list[str] | None = None,
) -> rrb.Blueprint:
    """The layout above for ``cameras`` (colour), ``depth_cameras`` and ``semantic_cameras``
    (those recording the stream) and the agents ``namespaces``."""
    camera_views = [
        rrb.Spatial2DView(
            origin=f"world/cameras/{cid}",
            name=f"camera {cid}",
            contents=["$origin/image", "$origin/detections"],
        )
        for cid in cameras
    ]
    depth_views = [
        rrb.Spatial2DView(origin=f"world/cameras/{cid}", name=f"depth {cid}", contents=["$origin/depth"])
        for cid in depth_cameras or []
    ]
    semantic_views = [
        rrb.Spatial2DView(
            origin=f"world/cameras/{cid}", name=f"semantic {cid}", contents=["$origin/semantic"]
        )
        for cid in semantic_cameras or []
    ]
    series = [rrb.TimeSeriesView(origin=f"metrics/{ns}", name=f"{ns} errors") for ns in namespaces] or [
        rrb.TimeSeriesView(origin="metrics", name="errors")
    ]
    hidden = [f"- world/cameras/{cid}/{child}" for cid in cameras for child in DISTORTED]
    left = rrb.Vertical(
        rrb.Spatial3DView(origin="world", name="warehouse", contents=["+ world/**", *hidden]),
        rrb.Tabs(*series, name="errors over time"),
        row_shares=[3, 1],
    )
    lower: list[rrb.View] = []
    if has_birdseye:
        lower.append(rrb.Spatial2DView(origin="birdseye", name="bird's-eye view"))
    if has_events:
        lower.append(rrb.TextLogView(origin="events", name="events"))
    grids = [
        _grid(views, name)
        for views, name in (
            (camera_views, "cameras"),
            (depth_views, "depth"),
            (semantic_views, "semantic labels"),
        )
        if views
    ]
    top: rrb.Container | rrb.View = (
        (rrb.Tabs(*grids, name="cameras") if len(grids) > 1 else grids[0])
        if grids
        else rrb.TextDocumentView(origin="world/recording")
    )
    right_parts: list[rrb.Container | rrb.View] = [top]
    if lower:
        right_parts.append(rrb.Horizontal(*lower))
    right = rrb.Vertical(*right_parts, row_shares=[3, 1][: len(right_parts)])
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[3, 2]),
        rrb.TimePanel(state="expanded"),
        collapse_panels=False,
    )
