"""What the tracking metrics compare (issue 25): a recording's tracking ground truth, and a
tracker's output read from a user's file or made from the recording's localizer estimates.

Ground truth, from the instance stream's annotated frames (:mod:`~simlan_data.evaluation.instance_truth`,
the reader the exports use, so frame numbers are the exports'):

- per camera and frame: the objects seen (at least one pixel) and their 2D boxes, visible (the
  mask's bounds, the MOT export's default) or amodal (the 3D box projected, clipped);
- world, per camera tick: every object seen by at least one camera, at its 3D box centre's floor
  position (x, y in ``map``), as the AI City export writes it.

Tracker output:

- a MOTChallenge folder: ``camera_<id>.txt`` per camera (or TrackEval's ``<tracker>/data/``
  holding them), rows ``frame,id,left,top,width,height[,...]``, frames from 1: per-camera boxes;
- an AI City file (``camera_id obj_id frame_id xmin ymin width height xworld yworld``, frames
  from 0, as ``export --format aicity`` writes): per-camera boxes and world positions (an object
  seen by several cameras at one tick: the mean of its rows);
- the recording's localizer estimates (``/<ns>/pose_estimate`` while its status is valid; the
  newest at or before each camera tick, so an online tracker's view): a track per namespace at
  the estimated 3D box centre (the box's offset from ``base_link`` measured once from the ground
  truth, a rigid body), and per camera that box (true size, estimated pose) projected and clipped
  like the amodal ground truth.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simlan_data.errors import ConfigError
from simlan_data.evaluation.instance_truth import camera_topics, frames
from simlan_data.evaluation.metrics import estimates_from_recording, ground_truth
from simlan_data.geometry.boxes import clip_box, project_box
from simlan_data.geometry.camera import CameraModel
from simlan_data.recording import schema
from simlan_data.recording.reader import RecordingReader

MAX_TRACK_ROWS = 10_000_000  # a tracker file's rows (a 10-minute 12-camera run at 5 Hz has ~1e6)
Boxes = tuple[NDArray[np.int64], NDArray[np.float64]]  # ids (N,), x y w h (N, 4)
Points = dict[int, tuple[float, float]]  # track id -> floor position


@dataclass
class CameraTruth:
    """One camera's ground truth: per frame (index from 0) its stamp and its boxes."""

    width: int
    height: int
    stamps: list[int] = field(default_factory=list)
    boxes: list[Boxes] = field(default_factory=list)


@dataclass
class Truth:
    cameras: dict[str, CameraTruth]
    world: dict[int, Points]  # camera tick -> objects seen by any camera


@dataclass
class Tracks:
    """A tracker's output in the ground truth's frames (missing frames: no detections)."""

    cameras: dict[str, dict[int, Boxes]] = field(default_factory=dict)  # camera -> frame index -> boxes
    world: dict[int, Points] | None = None  # None: the tracker gives no world positions


def read_truth(reader: RecordingReader, *, box: str, keep: Callable[[int], bool]) -> Truth:
    """The ground truth of the objects ``keep`` accepts (see the module docstring)."""
    cameras: dict[str, CameraTruth] = {}
    world: dict[int, Points] = defaultdict(dict)
    for frame in frames(reader, camera_topics(reader), images=False):
        cam = cameras.setdefault(frame.camera_id, CameraTruth(frame.width, frame.height))
        rows = [k for k, i in enumerate(frame.ids.tolist()) if keep(i)]
        source = frame.visible if box == "visible" else frame.amodal
        xyxy = np.asarray(source, dtype=np.float64)[rows].reshape(-1, 4)
        xywh = np.column_stack([xyxy[:, :2], xyxy[:, 2:] - xyxy[:, :2]])
        cam.stamps.append(frame.log_ns)  # (the estimates' clock: header stamps may carry an epoch)
        cam.boxes.append((np.asarray(frame.ids, dtype=np.int64)[rows], xywh))
        positions = world[frame.log_ns]
        centres = {int(i): c for i, c in zip(frame.world_ids.tolist(), frame.world_centers)}
        for i in frame.ids[rows].tolist():
            if i in centres:
                positions[i] = (float(centres[i][0]), float(centres[i][1]))
    return Truth(cameras, dict(world))


# ----------------------------------------------------------------------------- tracker files
def _bad(where: str, what: str, why: str, fix: str) -> ConfigError:
    return ConfigError(what, where, why, fix)


def _numbers(parts: list[str], where: str, names: tuple[str, ...]) -> list[float]:
    """The first ``len(names)`` fields as finite numbers, or one error naming the field."""
    if len(parts) < len(names):
        raise _bad(where, f"{len(parts)} fields", f"expected {len(names)}: {' '.join(names)}", "fix the row")
    out = []
    for name, text in zip(names, parts):
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise _bad(where, f"invalid {name}={text.strip()!r}", "not a finite number", "fix the row")
        out.append(value)
    return out


def _frame(value: float, first: int, count: int, name: str, where: str) -> int:
    if value != int(value) or not first <= value < first + count:
        raise _bad(
            where,
            f"invalid {name}={value:g}",
            f"the recording's camera has frames {first}..{first + count - 1}",
            f"number frames from {first}, as the export does",
        )
    return int(value) - first


def _track_id(value: float, name: str, where: str) -> int:
    if value != int(value):
        raise _bad(where, f"invalid {name}={value:g}", "a track id is an integer", "give whole-number ids")
    return int(value)


def _lines(path: Path) -> list[tuple[str, str]]:
    """(where, text) of a file's non-empty lines."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise _bad(str(path), "unreadable tracks", str(err), "give a text file") from None
    rows = [(f"{path} line {n}", line) for n, line in enumerate(text.splitlines(), 1) if line.strip()]
    if len(rows) > MAX_TRACK_ROWS:
        raise _bad(str(path), "too many rows", f"more than {MAX_TRACK_ROWS}", "split the recording")
    return rows


def _collect(rows: dict[int, list[tuple[int, list[float]]]]) -> dict[int, Boxes]:
    return {
        f: (np.array([r[0] for r in rs], dtype=np.int64), np.array([r[1] for r in rs]).reshape(-1, 4))
        for f, rs in rows.items()
    }


def read_mot(path: Path, truth: Truth) -> Tracks:
    """A MOTChallenge tracker folder (``camera_<id>.txt`` per camera of the recording)."""
    folder = path / "data" if (path / "data").is_dir() else path
    files = {p.stem.removeprefix("camera_"): p for p in sorted(folder.glob("camera_*.txt"))}
    unknown = sorted(set(files) - set(truth.cameras))
    if not files or unknown:
        raise _bad(
            str(folder),
            f"no tracks of camera {unknown[0]}" if unknown else "no camera_<id>.txt",
            f"the recording's cameras with instance ground truth: {', '.join(sorted(truth.cameras))}",
            "give one camera_<id>.txt per camera (MOTChallenge rows frame,id,left,top,width,height)",
        )
    missing = sorted(set(truth.cameras) - set(files))
    if missing:
        raise _bad(
            str(folder / f"camera_{missing[0]}.txt"),
            "missing tracks file",
            "every camera of the recording is scored",
            "write an empty file for a camera without tracks",
        )
    tracks = Tracks()
    for cid, file in files.items():
        rows: dict[int, list[tuple[int, list[float]]]] = defaultdict(list)
        count = len(truth.cameras[cid].stamps)
        for where, line in _lines(file):
            frame, track, *box = _numbers(
                line.split(","), where, ("frame", "id", "left", "top", "width", "height")
            )
            index = _frame(frame, 1, count, "frame", where)
            rows[index].append((_track_id(track, "id", where), box))
        tracks.cameras[cid] = _collect(rows)
    return tracks


AICITY_FIELDS = ("camera_id", "obj_id", "frame_id", "xmin", "ymin", "width", "height", "xworld", "yworld")


def read_aicity(path: Path, truth: Truth) -> Tracks:
    """An AI City multi-camera tracking file: boxes per camera and positions in the world."""
    boxes: dict[str, dict[int, list[tuple[int, list[float]]]]] = defaultdict(lambda: defaultdict(list))
    world: dict[int, dict[int, list[tuple[float, float]]]] = defaultdict(lambda: defaultdict(list))
    for where, line in _lines(path):
        parts = line.split()
        cid = parts[0] if parts else ""
        if cid not in truth.cameras:
            raise _bad(
                where,
                f"invalid camera_id={cid!r}",
                f"the recording's cameras with instance ground truth: {', '.join(sorted(truth.cameras))}",
                "a file is read as AI City rows (space-separated, camera_id first); give a "
                "MOTChallenge tracker as a folder of camera_<id>.txt",
            )
        _, track, frame, *rest = _numbers(["0", *parts[1:]], where, AICITY_FIELDS)
        index = _frame(frame, 0, len(truth.cameras[cid].stamps), "frame_id", where)
        obj = _track_id(track, "obj_id", where)
        boxes[cid][index].append((obj, rest[:4]))
        world[truth.cameras[cid].stamps[index]][obj].append((rest[4], rest[5]))
    tracks = Tracks({cid: _collect(rows) for cid, rows in boxes.items()}, {})
    assert tracks.world is not None
    for stamp, objects in world.items():
        tracks.world[stamp] = {i: tuple(np.mean(xy, axis=0).tolist()) for i, xy in objects.items()}
    return tracks


# ------------------------------------------------------------------------ localizer estimates
@dataclass(frozen=True)
class _Body:
    """A tracked agent: its track id, its 3D box in base_link (offset x y, z, yaw) and size."""

    track: int
    offset_xy: NDArray[np.float64]
    z: float
    dyaw: float
    size: NDArray[np.float64]


def localized_namespaces(reader: RecordingReader, agents: list[str]) -> list[str]:
    """The agents whose pose estimates the recording holds."""
    return [ns for ns in agents if schema.agent_topics(ns)["pose_estimate"].name in reader.topics]


def _bodies(reader: RecordingReader, ids: dict[str, int]) -> dict[str, _Body]:
    """Each agent's 3D box relative to its base_link, from the first camera tick's ground truth."""
    reader.require_topics([schema.INSTANCE_BOXES_3D])
    first = reader.first(schema.INSTANCE_BOXES_3D)
    if first is None:  # (an empty topic: no tick to measure at, so no track)
        return {}
    msg, t = first.msg, first.stamp_ns
    row = {int(i): k for k, i in enumerate(msg.ids)}
    centres, sizes = np.asarray(msg.centers).reshape(-1, 3), np.asarray(msg.sizes).reshape(-1, 3)
    poses = ground_truth(reader)
    out = {}
    for ns, iid in ids.items():
        if iid not in row or ns not in poses:
            continue
        table = poses[ns].filter(poses[ns]["stamp_ns"] <= t).tail(1)
        if table.height == 0:
            continue
        x, y, yaw = (float(table[c][0]) for c in ("x", "y", "yaw"))
        k = row[iid]
        c, s = math.cos(-yaw), math.sin(-yaw)
        d = centres[k, :2] - (x, y)
        out[ns] = _Body(
            iid,
            np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]]),
            float(centres[k, 2]),
            float(msg.yaw_rad[k]) - yaw,
            sizes[k],
        )
    return out


def _asof(stamps: NDArray[np.int64], t: int) -> int:
    return int(np.searchsorted(stamps, t, side="right")) - 1


def localizer_tracks(
    reader: RecordingReader, truth: Truth, ids: dict[str, int], cameras: dict[str, CameraModel]
) -> Tracks:
    """The localizer's estimates of the agents ``ids`` (namespace -> instance id) as tracks."""
    bodies = _bodies(reader, ids)
    estimates = {}
    for ns, table in estimates_from_recording(reader, list(bodies)).items():
        valid = table["valid"].fill_null(False).to_numpy() & table["x"].is_not_null().to_numpy()
        estimates[ns] = (
            table["stamp_ns"].to_numpy(),
            valid,
            table.select("x", "y", "yaw").fill_null(0.0).to_numpy(),
        )

    def at(t: int) -> dict[str, tuple[NDArray[np.float64], float]]:
        out = {}
        for ns, (stamps, valid, xyyaw) in estimates.items():
            k = _asof(stamps, t)
            if k >= 0 and valid[k]:
                x, y, yaw = xyyaw[k]
                c, s = math.cos(yaw), math.sin(yaw)
                off = bodies[ns].offset_xy
                out[ns] = (np.array([x + c * off[0] - s * off[1], y + s * off[0] + c * off[1]]), float(yaw))
        return out

    tracks = Tracks({}, {})
    assert tracks.world is not None
    for stamp in truth.world:
        tracks.world[stamp] = {
            bodies[ns].track: (float(p[0]), float(p[1])) for ns, (p, _) in at(stamp).items()
        }
    for cid, cam in truth.cameras.items():
        model = cameras.get(cid)
        per: dict[int, list[tuple[int, list[float]]]] = defaultdict(list)
        for index, stamp in enumerate(cam.stamps):
            for ns, (p, yaw) in at(stamp).items():
                body = bodies[ns]
                centre = np.array([p[0], p[1], body.z])
                proj = None if model is None else project_box(model, centre, body.size, yaw + body.dyaw)
                if proj is None:
                    continue
                (u0, v0, u1, v1), _ = clip_box(proj.bounds, cam.width, cam.height)
                if u1 > u0 and v1 > v0:
                    per[index].append((body.track, [u0, v0, u1 - u0, v1 - v0]))
        tracks.cameras[cid] = _collect(per)
    return tracks
