"""A Foxglove layout for the twin: camera grids, a 3D view of the warehouse, error and speed plots.

Built from the topic names a recording has, so it fits any camera set and any agents; the same
layout serves a live run (``live.foxglove=true``, which writes it into the run directory) and its
recording, whose topics are the same. The format is the one Foxglove's "Import from file" reads (``configById``,
``layout`` as a mosaic tree, ``userNodes``, ``globalVariables``, ``playbackConfig``).

    +-----------------------------+----------------------+
    | 3D: map, TF, camera frusta, | tabs: RGB | depth |  |
    | estimates, plans, zones     | labels (camera grids)|
    +--------------+--------------+                      |
    | xy error (m) | speed (m/s)  |                      |
    +--------------+--------------+----------------------+

The localization error is computed in Foxglove by a user script per agent (ground truth at the
estimate's log time); no recorded topic carries it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from simlan_data.recording import schema

LAYOUT_FILENAME = "foxglove_layout.json"  # in a live run's directory
PACKAGED_LAYOUT = Path(__file__).with_name("foxglove_layout.json")  # a default run's (all 11 cameras)
SCRIPT_PREFIX = "/foxglove_script/"  # where Foxglove's user scripts publish

_CAMERA_INFO = re.compile(r"^/camera_([^/]+)/camera_info$")
_POSE_ESTIMATE = re.compile(r"^/([^/]+)/pose_estimate$")


def _id_key(value: str) -> tuple[int, str]:
    return (int(value), "") if value.isdigit() else (1 << 30, value)


def _first(topics: set[str], candidates: Iterable[str]) -> str | None:
    return next((t for t in candidates if t in topics), None)


def _stream(topics: set[str], camera_id: str, stream: str) -> str | None:
    """The one image topic of a camera's depth or semantic stream, whatever its encoding."""
    prefix = f"/camera_{camera_id}/{stream}/"
    found = sorted(t for t in topics if t.startswith(prefix))
    return found[0] if found else None


class _Panels:
    """Panel configs by id (``Type!suffix``, as Foxglove names them)."""

    def __init__(self) -> None:
        self.by_id: dict[str, dict[str, Any]] = {}

    def add(self, kind: str, config: dict[str, Any]) -> str:
        panel_id = f"{kind}!{len(self.by_id):x}simlan"
        self.by_id[panel_id] = config
        return panel_id


def _grid(ids: list[str], direction: str = "row") -> Any:
    """A balanced mosaic of panels: halves side by side, then stacked, and so on."""
    if len(ids) == 1:
        return ids[0]
    half = (len(ids) + 1) // 2
    other = "column" if direction == "row" else "row"
    return {
        "first": _grid(ids[:half], other),
        "second": _grid(ids[half:], other),
        "direction": direction,
        "splitPercentage": 100.0 * half / len(ids),
    }


# 16UC1 depth in millimetres: Foxglove's default grey range (0-65535) shows it almost black;
# a turbo colour map over 0-20 m (the hall's depths) shows it as distance
DEPTH_COLOURS = {"colorMode": "colormap", "colorMap": "turbo", "minValue": 0, "maxValue": 20000}


def _image(title: str, topic: str, calibration: str | None) -> dict[str, Any]:
    mode: dict[str, Any] = {"imageTopic": topic}
    if "/depth/" in topic:
        mode.update(DEPTH_COLOURS)
    if calibration is not None:
        mode["calibrationTopic"] = calibration
    return {"foxglovePanelTitle": title, "imageMode": mode}


def _plot(title: str, series: list[tuple[str, str]], unit: str) -> dict[str, Any]:
    return {
        "foxglovePanelTitle": title,
        "paths": [
            {"value": path, "label": label, "enabled": True, "timestampMethod": "receiveTime"}
            for path, label in series
        ],
        "showLegend": True,
        "legendDisplay": "floating",
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "isSynced": True,
        "xAxisVal": "timestamp",
        "followingViewWidth": 30,
        "sidebarDimension": 240,
        "yAxisLabel": unit,
    }


def error_script(namespace: str) -> tuple[str, str]:
    """A Foxglove user script: the xy distance between an agent's estimate and its ground truth.

    Returns (output topic, TypeScript source). Ground truth (``/ground_truth/poses``, at a rate
    that the control rate divides) is taken at the estimate's log time.
    """
    estimate = schema.agent_topics(namespace)["pose_estimate"].name
    output = f"{SCRIPT_PREFIX}{namespace}/localization_error"
    source = f"""// {namespace}: xy error of the camera-based pose estimate against the ground truth (simlan_data)
import {{ Input }} from "./types";

type Output = {{ error_xy_m: number; error_x_m: number; error_y_m: number }};

export const inputs = ["{schema.GROUND_TRUTH_POSES}", "{estimate}"];
export const output = "{output}";

const TRUTH_FRAME = "{schema.ground_truth_frame(namespace)}";
let truth: {{ x: number; y: number }} | undefined;

export default function script(
  event: Input<"{schema.GROUND_TRUTH_POSES}"> | Input<"{estimate}">,
): Output | undefined {{
  if (event.topic === "{schema.GROUND_TRUTH_POSES}") {{
    const poses = event.message as Input<"{schema.GROUND_TRUTH_POSES}">["message"];
    for (const t of poses.transforms) {{
      if (t.child_frame_id === TRUTH_FRAME) {{
        truth = {{ x: t.transform.translation.x, y: t.transform.translation.y }};
      }}
    }}
    return undefined;
  }}
  if (truth === undefined) {{
    return undefined;
  }}
  const estimate = event.message as Input<"{estimate}">["message"];
  const dx = estimate.pose.pose.position.x - truth.x;
  const dy = estimate.pose.pose.position.y - truth.y;
  return {{ error_xy_m: Math.hypot(dx, dy), error_x_m: dx, error_y_m: dy }};
}}
"""
    return output, source


def build_layout(topics: Iterable[str]) -> dict[str, Any]:
    """The layout for a recording with these topic names (cameras and agents found in them)."""
    names = set(topics)
    cameras = sorted((m.group(1) for t in names if (m := _CAMERA_INFO.match(t))), key=_id_key)
    agents = sorted((m.group(1) for t in names if (m := _POSE_ESTIMATE.match(t))), key=_id_key)
    panels = _Panels()
    grids: list[dict[str, Any]] = []
    for title, stream in (("RGB", None), ("Depth", "depth"), ("Labels", "semantic")):
        ids = []
        for cid in cameras:
            info = f"/camera_{cid}/camera_info"
            topic = (
                _first(names, (f"/camera_{cid}/image_raw/compressed", f"/camera_{cid}/image_raw"))
                if stream is None
                else _stream(names, cid, stream)
            )
            if topic is not None:
                ids.append(panels.add("Image", _image(f"camera {cid} {title.lower()}", topic, info)))
        if ids and stream == "semantic" and schema.SEMANTIC_LABELS in names:
            # the class names beside the label images (their colours are the PNGs' palette)
            legend = {
                "foxglovePanelTitle": "semantic classes (id, name)",
                "topicPath": schema.SEMANTIC_LABELS,
            }
            grids.append(
                {
                    "title": title,
                    "layout": {
                        "first": _grid(ids),
                        "second": panels.add("Table", legend),
                        "direction": "row",
                        "splitPercentage": 80.0,
                    },
                }
            )
        elif ids:
            grids.append({"title": title, "layout": _grid(ids)})
    tabs = panels.add("Tab", {"activeTabIdx": 0, "tabs": grids})
    three_d = panels.add("3D", _three_d(names, cameras, agents))
    scripts: dict[str, dict[str, str]] = {}
    error_series, speed_series = [], []
    for ns in agents:
        topics_of = schema.agent_topics(ns)
        output, source = error_script(ns)
        scripts[f"simlan-error-{ns}"] = {"name": f"{ns} localization error", "sourceCode": source}
        error_series.append((f"{output}.error_xy_m", f"{ns} xy error"))
        for key, label in (("velocity_estimate", "estimated"), ("cmd_vel", "commanded")):
            if topics_of[key].name in names:
                speed_series.append((f"{topics_of[key].name}.twist.linear.x", f"{ns} {label}"))
    error = panels.add("Plot", _plot("Localization error (m)", error_series, "m"))
    speed = panels.add("Plot", _plot("Speed (m/s)", speed_series, "m/s"))
    left = {
        "first": three_d,
        "second": {"first": error, "second": speed, "direction": "row", "splitPercentage": 50},
        "direction": "column",
        "splitPercentage": 62,
    }
    return {
        "configById": panels.by_id,
        "globalVariables": {},
        "userNodes": scripts,
        "playbackConfig": {"speed": 1},
        "layout": {"first": left, "second": tabs, "direction": "row", "splitPercentage": 58},
    }


def _three_d(names: set[str], cameras: list[str], agents: list[str]) -> dict[str, Any]:
    """The 3D panel: the map frame with every transform, camera frusta, the agents' estimates,
    plans and goals, restricted zones and detected people."""
    shown = [f"/camera_{cid}/camera_info" for cid in cameras]
    for ns in agents:
        topics_of = schema.agent_topics(ns)
        shown += [topics_of[k].name for k in ("pose_estimate", "plan", "goal")]
    shown += [schema.SAFETY_ZONES, schema.PEOPLE_DETECTIONS]
    return {
        "followTf": schema.MAP_FRAME,
        "followMode": "follow-pose",
        "scene": {"transforms": {"showLabel": True, "axisScale": 1.5}},
        "transforms": {},
        "topics": {t: {"visible": True} for t in shown if t in names},
        "layers": {
            "simlan-grid": {
                "layerId": "foxglove.Grid",
                "visible": True,
                "frameLocked": True,
                "label": "Grid (1 m)",
                "instanceId": "simlan-grid",
                "size": 60,
                "divisions": 60,
                "lineWidth": 0.5,
                "color": "#248eff40",
                "position": [0, 0, 0],
                "rotation": [0, 0, 0],
                "order": 1,
            }
        },
        "cameraState": {
            "perspective": True,
            "distance": 45,
            "phi": 50,
            "thetaOffset": 90,
            "target": [0, 0, 0],
            "targetOffset": [13, 0, 0],  # the middle of SIMLAN's warehouse
            "targetOrientation": [0, 0, 0, 1],
            "fovy": 45,
            "near": 0.5,
            "far": 5000,
        },
    }


def write_layout(path: Path, layout: dict[str, Any]) -> None:
    """Write the layout as indented JSON (a new file; parents made)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(layout, indent=2) + "\n")
