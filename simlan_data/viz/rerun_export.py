"""Export a recording to Rerun: the warehouse, cameras, images, trajectories, errors, events.

Entity tree (timeline ``sim_time``: the simulated clock)::

    world                                  z up, metres, the map frame
      layout/<class>                       static geometry of the layout (Boxes3D, Cylinders3D)
      cameras                              AnnotationContext: semantic class ids -> names, colours
      cameras/<id>                         Transform3D (map <- optical) + Pinhole of the
                                           undistorted camera: a frustum
        undistorted                        EncodedImage: the colour image undistorted (remapped to
                                           that pinhole; the 3D view shows it, so 3D overlays land
                                           on the image content)
        image                              EncodedImage (the recorded JPEG/PNG, kept compressed;
                                           distorted like the real camera: the 2D views)
        depth                              DepthImage, millimetres (meter = 1000; 0 = no return), distorted
        semantic                           SegmentationImage of class ids, distorted
        detections                         LineStrips2D: marker outlines the localizer found (distorted pixels)
      agents/<ns>/truth                    Transform3D from ground truth + footprint box
      agents/<ns>/truth_path               LineStrips3D: the whole ground-truth trajectory
      agents/<ns>/estimate                 Transform3D of the camera estimate + footprint box
      agents/<ns>/estimate_path            LineStrips3D: the estimated trajectory
      agents/<ns>/goal, plan               Points3D, LineStrips3D (on change)
      markers/<topic>                      any visualization_msgs/MarkerArray (zones, ...)
    birdseye/image                         the recorded bird's-eye view, if any
    metrics/<ns>/xy_error_cm, yaw_error_deg, fix_age_s     Scalars
    events/<topic>                         TextLog of every other simlan_msgs topic (safety events, ...)

Topics are matched generically where they can be: a new MarkerArray or custom-message topic
shows up without a change here.

Lens distortion: Rerun's Pinhole (0.41) has no distortion model, and the recorded images are
strongly distorted (k1 about -0.4). The pinhole logged is therefore that of an undistorted image
(:func:`rectification`: the same principal point, the focal length scaled so that the image keeps
the recorded field of view along its axes) and the 3D view shows the colour image remapped to it
(``undistorted``); the recorded images, depth and labels stay as recorded in the 2D views, with
the detections in their distorted pixels.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import polars as pl
import rerun as rr

from simlan_data.constants import NS_PER_S
from simlan_data.errors import ConfigError
from simlan_data.evaluation.metrics import estimates_from_recording, ground_truth
from simlan_data.evaluation.replay import ReplayContext
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import wrap_angle
from simlan_data.geometry.transforms import Transform
from simlan_data.recording import schema
from simlan_data.recording.codecs import decode_compressed, decode_raw, depth_to_mm
from simlan_data.recording.reader import RecordingReader
from simlan_data.viz.blueprint import build_blueprint
from simlan_data.world.agent_types import agent_type
from simlan_data.world.labels import LABEL_COLOURS, LABEL_NAMES
from simlan_data.world.layout import load_layout
from simlan_data.world.models import model_spec

TIMELINE = "sim_time"
APP_ID = "simlan_data"
IMAGE_SUFFIXES = ("/image_raw/compressed",)
DEPTH_SUFFIXES = ("/depth/image_raw/compressedDepth", "/depth/image_raw")
SEMANTIC_SUFFIXES = ("/semantic/image_raw/compressed", "/semantic/image_raw")
UNDISTORTED_JPEG_QUALITY = 85
HANDLED_TYPES = {
    schema.CLOCK_TYPE,
    schema.TF_TYPE,
    schema.CAMERA_INFO_TYPE,
    schema.COMPRESSED_IMAGE_TYPE,
    schema.IMAGE_TYPE,
    schema.TWIST_STAMPED_TYPE,
    schema.PATH_TYPE,
    schema.POSE_COV_TYPE,
    schema.POSE_STAMPED_TYPE,
    schema.MARKER_DETECTIONS_TYPE,
    schema.RUN_INFO_TYPE,
    schema.SEMANTIC_LABELS_TYPE,
    schema.LOCALIZATION_STATUS_TYPE,
    schema.COLLISION_STATE_TYPE,
    "visualization_msgs/msg/MarkerArray",
}
MARKER_ARRAY_TYPE = "visualization_msgs/msg/MarkerArray"


def _rgba(c: Iterable[float]) -> list[int]:
    return [round(255 * max(0.0, min(1.0, float(v)))) for v in c]


def _seconds(stamps_ns: Any) -> np.ndarray:
    return np.asarray(stamps_ns, dtype=np.float64) / NS_PER_S


def _set_time(rec: rr.RecordingStream, stamp_ns: int) -> None:
    rec.set_time(TIMELINE, duration=stamp_ns / NS_PER_S)


def log_layout(rec: rr.RecordingStream, config: dict[str, Any]) -> int:
    """The layout's static geometry, one entity per semantic class; returns the number of parts."""
    world = config.get("world") or {}
    placements = load_layout(world.get("layout", "warehouse_layout.csv"), world.get("fidelity", "default"))
    boxes: dict[str, dict[str, list]] = {}
    cylinders: dict[str, dict[str, list]] = {}
    for pl_ in placements:
        spec = model_spec(pl_.model)
        if spec is None:
            continue
        base = (
            Transform.identity()
            if spec.world_frame
            else Transform.from_xyz_rpy(
                [pl_.xyz_m[0], pl_.xyz_m[1], pl_.xyz_m[2] + spec.z_offset_m], pl_.rpy_rad
            )
        )
        for part in spec.parts:
            if not part.visual or part.shape not in ("box", "cylinder"):
                continue
            pose = base @ Transform.from_xyz_rpy(part.xyz, part.rpy)
            into = boxes if part.shape == "box" else cylinders
            entry = into.setdefault(spec.semantic, {"centers": [], "quats": [], "sizes": [], "colors": []})
            entry["centers"].append(pose.translation)
            entry["quats"].append(pose.quat())
            entry["sizes"].append(part.size)
            entry["colors"].append(_rgba(part.rgba))
    count = 0
    for semantic, e in boxes.items():
        rec.log(
            f"world/layout/{semantic}",
            rr.Boxes3D(
                centers=e["centers"],
                half_sizes=e["sizes"],
                quaternions=[rr.Quaternion(xyzw=q) for q in e["quats"]],
                colors=e["colors"],
                fill_mode="solid",
            ),
            static=True,
        )
        count += len(e["centers"])
    for semantic, e in cylinders.items():
        rec.log(
            f"world/layout/{semantic}/cylinders",
            rr.Cylinders3D(
                centers=e["centers"],
                radii=[s[0] for s in e["sizes"]],
                lengths=[s[1] for s in e["sizes"]],
                quaternions=[rr.Quaternion(xyzw=q) for q in e["quats"]],
                colors=e["colors"],
                fill_mode="solid",
            ),
            static=True,
        )
        count += len(e["centers"])
    return count


@dataclasses.dataclass(frozen=True, eq=False)
class Rectification:
    """An undistorted view of a camera: its pinhole K (the same image size) and the remap
    tables from the recorded, distorted image (fixed point, ``cv2.remap``'s fast path); pixels
    whose ray lies beyond the camera model's valid radius stay black."""

    K: np.ndarray
    map1: np.ndarray
    map2: np.ndarray

    def apply(self, image: np.ndarray) -> np.ndarray:
        """``image`` (as recorded: distorted) undistorted, bilinear."""
        return cv2.remap(image, self.map1, self.map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def rectified_intrinsics(cam: CameraModel) -> np.ndarray:
    """The intrinsics of an undistorted image of ``cam`` of the same size: the same principal
    point, the focal lengths scaled by one factor so that the undistorted image reaches the
    recorded image's edges along its axes (where they lie within the model's valid radius)."""
    K = np.asarray(cam.K, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    edges = np.array([[0.0, cy], [cam.width - 1.0, cy], [cx, 0.0], [cx, cam.height - 1.0]])
    xy, ok = cam.undistort_pixels(edges)
    limit = cam.valid_radius
    reach = np.where(ok, np.abs(np.where(np.arange(4)[:, None] < 2, xy[:, :1], xy[:, 1:2]))[:, 0], limit)
    reach = np.minimum(reach, limit)  # normalized coordinate each edge midpoint shows
    room = np.array([cx, cam.width - 1.0 - cx, cy, cam.height - 1.0 - cy])  # pixels to that edge
    focal = np.array([fx, fx, fy, fy])
    scale = float(np.min(room / (reach * focal)))
    out = K.copy()
    out[0, 0], out[1, 1] = fx * scale, fy * scale
    return out


_RECTIFICATIONS: dict[tuple, Rectification] = {}


def rectification(cam: CameraModel) -> Rectification:
    """The undistorted view of ``cam`` (:func:`rectified_intrinsics`), its maps cached per camera
    model (intrinsics, distortion and size)."""
    key = (cam.width, cam.height, cam.K.tobytes(), np.asarray(cam.D, dtype=np.float64).tobytes())
    cached = _RECTIFICATIONS.get(key)
    if cached is not None:
        return cached
    K_new = rectified_intrinsics(cam)
    size = (cam.width, cam.height)
    map_x, map_y = cv2.initUndistortRectifyMap(cam.K, cam.D, None, K_new, size, cv2.CV_32FC1)
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
    r = np.hypot((u - K_new[0, 2]) / K_new[0, 0], (v - K_new[1, 2]) / K_new[1, 1])
    beyond = r > cam.valid_radius  # the model folds back there: no valid ray (black)
    map_x[beyond], map_y[beyond] = -1.0, -1.0
    map1, map2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
    out = Rectification(K_new, map1, map2)
    _RECTIFICATIONS[key] = out
    return out


def log_annotations(rec: rr.RecordingStream) -> None:
    """Semantic class ids -> names and colours (``world/labels.py``) for every camera's labels."""
    rec.log(
        "world/cameras",
        rr.AnnotationContext(
            [
                rr.AnnotationInfo(id=i, label=LABEL_NAMES[i], color=LABEL_COLOURS[i])
                for i in sorted(LABEL_NAMES)
            ]
        ),
        static=True,
    )


def log_cameras(rec: rr.RecordingStream, ctx: ReplayContext) -> list[str]:
    """A frustum per camera: static Transform3D (map <- optical frame) and the Pinhole of its
    undistorted image (:func:`rectification`)."""
    log_annotations(rec)
    for cid, cam in ctx.cameras.items():
        wfc = cam.world_from_camera
        path = f"world/cameras/{cid}"
        rec.log(path, rr.Transform3D(translation=wfc.translation, mat3x3=wfc.rotation), static=True)
        rec.log(
            path,
            rr.Pinhole(
                image_from_camera=rectification(cam).K,
                resolution=[cam.width, cam.height],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=1.0,
            ),
            static=True,
        )
    return sorted(ctx.cameras, key=lambda c: (len(c), c))


def _camera_of(topic: str, suffixes: tuple[str, ...], camera_ids: Iterable[str]) -> str | None:
    for cid in camera_ids:
        if any(topic == f"/camera_{cid}{s}" for s in suffixes):
            return cid
    return None


def _decoded(m: Any) -> np.ndarray:
    if m.msgtype.endswith("CompressedImage"):
        return decode_compressed(m.msg.format, m.msg.data)
    return decode_raw(m.msg.encoding, m.msg.height, m.msg.width, m.msg.step, m.msg.data)


class _Undistorter:
    """The undistorted colour image of each camera, re-encoded as JPEG; an image whose recorded
    bytes equal the camera's last is not logged again (Rerun shows the latest image anyway)."""

    def __init__(self, rec: rr.RecordingStream, cameras: dict[str, CameraModel]) -> None:
        self.rec, self.cameras = rec, cameras
        self._last: dict[str, bytes] = {}
        self.logged = 0

    def log(self, cid: str, data: bytes, fmt: str) -> None:
        cam = self.cameras.get(cid)
        if cam is None:
            return
        digest = hashlib.blake2b(data, digest_size=16).digest()
        if self._last.get(cid) == digest:
            return
        self._last[cid] = digest
        rgb = decode_compressed(fmt, data)
        if rgb.shape[:2] != (cam.height, cam.width):
            return  # (a camera info of another size: nothing to undistort it with)
        bgr = rectification(cam).apply(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        ok, jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, UNDISTORTED_JPEG_QUALITY])
        if ok:
            self.rec.log(
                f"world/cameras/{cid}/undistorted",
                rr.EncodedImage(contents=jpeg.tobytes(), media_type="image/jpeg"),
            )
            self.logged += 1


def log_images(
    rec: rr.RecordingStream,
    reader: RecordingReader,
    camera_ids: list[str],
    *,
    every: int = 1,
    cameras: dict[str, CameraModel] | None = None,
    counts: dict[str, int] | None = None,
) -> int:
    """Each camera's colour images as EncodedImage (compressed bytes as recorded), and each
    colour image undistorted to the camera's pinhole (``cameras``: those with a model); depth
    as DepthImage (millimetres), semantic labels as SegmentationImage; detections. ``every``
    thins each image stream. Depth, labels and undistorted images are logged when they differ
    from the camera's last (a static camera's mostly do not; Rerun shows the latest one).
    ``counts`` receives the number of images logged per kind; returns the colour images'."""
    topics = {f"/camera_{c}/image_raw/compressed": c for c in camera_ids}
    detections = {f"/camera_{c}/marker_detections": c for c in camera_ids}
    depth = {t: c for t in reader.topics if (c := _camera_of(t, DEPTH_SUFFIXES, camera_ids)) is not None}
    semantic = {
        t: c for t in reader.topics if (c := _camera_of(t, SEMANTIC_SUFFIXES, camera_ids)) is not None
    }
    birdseye = schema.BIRDSEYE_IMAGE if schema.BIRDSEYE_IMAGE in reader.topics else None
    wanted = [*[t for t in topics if t in reader.topics], *[t for t in detections if t in reader.topics]]
    wanted += [*depth, *semantic]
    if birdseye:
        wanted.append(birdseye)
    undistorter = _Undistorter(rec, cameras or {})
    last: dict[str, bytes] = {}  # topic -> digest of its last logged depth or label image
    seen: dict[str, int] = {}
    logged = {"image": 0, "depth": 0, "semantic": 0}
    for m in reader.messages(wanted):
        _set_time(rec, m.stamp_ns)
        if m.topic in topics or m.topic in depth or m.topic in semantic:
            n = seen.get(m.topic, 0)
            seen[m.topic] = n + 1
            if n % every:
                continue
        if m.topic in depth or m.topic in semantic:
            digest = hashlib.blake2b(bytes(m.msg.data), digest_size=16).digest()
            if last.get(m.topic) == digest:
                continue
            last[m.topic] = digest
        if m.topic in topics:
            media = "image/png" if "png" in m.msg.format else "image/jpeg"
            rec.log(
                f"world/cameras/{topics[m.topic]}/image",
                rr.EncodedImage(contents=bytes(m.msg.data), media_type=media),
            )
            logged["image"] += 1
            undistorter.log(topics[m.topic], bytes(m.msg.data), m.msg.format)
        elif m.topic in depth:
            rec.log(
                f"world/cameras/{depth[m.topic]}/depth", rr.DepthImage(depth_to_mm(_decoded(m)), meter=1000.0)
            )
            logged["depth"] += 1
        elif m.topic in semantic:
            rec.log(f"world/cameras/{semantic[m.topic]}/semantic", rr.SegmentationImage(_decoded(m)))
            logged["semantic"] += 1
        elif m.topic in detections:
            corners = np.asarray(m.msg.corners_px, dtype=np.float32).reshape(-1, 4, 2)
            strips = [np.vstack([c, c[:1]]) for c in corners]
            rec.log(
                f"world/cameras/{detections[m.topic]}/detections",
                rr.LineStrips2D(
                    strips,
                    labels=[f"id {i}" for i in m.msg.ids],
                    colors=[[255, 60, 40]] * len(strips),
                    radii=1.5,
                ),
            )
        else:
            media = "image/png" if "png" in m.msg.format else "image/jpeg"
            rec.log("birdseye/image", rr.EncodedImage(contents=bytes(m.msg.data), media_type=media))
    if counts is not None:
        counts.update(logged, undistorted=undistorter.logged)
    return logged["image"]


def _footprint(kind_name: str) -> tuple[list[float], list[float]]:
    x0, x1, y0, y1 = agent_type(kind_name).footprint_m
    return [(x0 + x1) / 2, (y0 + y1) / 2, 0.05], [(x1 - x0) / 2, (y1 - y0) / 2, 0.05]


def _log_poses(
    rec: rr.RecordingStream, path: str, table: pl.DataFrame, colour: list[int], kind: str, z: float
) -> None:
    if table.height == 0:
        return
    t = _seconds(table["stamp_ns"].to_numpy())
    x, y, yaw = (table[c].to_numpy() for c in ("x", "y", "yaw"))
    quats = np.stack([np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2), np.cos(yaw / 2)], axis=1)
    translations = np.stack([x, y, np.full_like(x, z)], axis=1)
    rec.send_columns(
        path,
        indexes=[rr.TimeColumn(TIMELINE, duration=t)],
        columns=rr.Transform3D.columns(translation=translations, quaternion=quats),
    )
    centre, half = _footprint(kind)
    rec.log(path, rr.Boxes3D(centers=[centre], half_sizes=[half], colors=[colour]), static=True)
    rec.log(f"{path}_path", rr.LineStrips3D([translations], colors=[colour], radii=0.03), static=True)


def log_agents(rec: rr.RecordingStream, reader: RecordingReader, config: dict[str, Any]) -> list[str]:
    """Ground truth and estimates of every agent (poses, paths), goals, plans and error curves."""
    agents = config.get("agents") or {}
    truth = ground_truth(reader)
    namespaces = [ns for ns in sorted(agents) if ns in truth]
    with_estimates = [
        ns for ns in namespaces if schema.agent_topics(ns)["pose_estimate"].name in reader.topics
    ]
    estimates = estimates_from_recording(reader, with_estimates) if with_estimates else {}
    for ns in namespaces:
        kind = (agents[ns] or {}).get("type", "pallet_truck")
        _log_poses(rec, f"world/agents/{ns}/truth", truth[ns], [40, 160, 60], kind, 0.0)
        est = estimates.get(ns)
        if est is None:
            continue
        valid = est.filter(pl.col("x").is_not_null())
        _log_poses(
            rec,
            f"world/agents/{ns}/estimate",
            valid.select("stamp_ns", "x", "y", "yaw"),
            [230, 120, 20],
            kind,
            0.02,
        )
        joined = valid.join(
            truth[ns].rename({"x": "gx", "y": "gy", "yaw": "gyaw"}), on="stamp_ns", how="inner"
        )
        if joined.height:
            t = _seconds(joined["stamp_ns"].to_numpy())
            err_cm = 100 * np.hypot(
                (joined["x"] - joined["gx"]).to_numpy(), (joined["y"] - joined["gy"]).to_numpy()
            )
            yaw_deg = np.degrees(np.abs(wrap_angle((joined["yaw"] - joined["gyaw"]).to_numpy())))
            for name, values in (("xy_error_cm", err_cm), ("yaw_error_deg", yaw_deg)):
                rec.send_columns(
                    f"metrics/{ns}/{name}",
                    indexes=[rr.TimeColumn(TIMELINE, duration=t)],
                    columns=rr.Scalars.columns(scalars=values),
                )
        ages = est.filter(pl.col("age_s") >= 0)
        if ages.height:
            rec.send_columns(
                f"metrics/{ns}/fix_age_s",
                indexes=[rr.TimeColumn(TIMELINE, duration=_seconds(ages["stamp_ns"].to_numpy()))],
                columns=rr.Scalars.columns(scalars=ages["age_s"].to_numpy()),
            )
        topics = schema.agent_topics(ns)
        for m in reader.messages([topics["goal"].name, topics["plan"].name]):
            _set_time(rec, m.stamp_ns)
            if m.topic == topics["goal"].name:
                p = m.msg.pose.position
                rec.log(
                    f"world/agents/{ns}/goal",
                    rr.Points3D([[p.x, p.y, 0.05]], radii=0.15, colors=[[60, 90, 230]]),
                )
            else:
                pts = [[ps.pose.position.x, ps.pose.position.y, 0.03] for ps in m.msg.poses]
                if pts:
                    rec.log(
                        f"world/agents/{ns}/plan", rr.LineStrips3D([pts], colors=[[60, 90, 230]], radii=0.02)
                    )
    return namespaces


def _marker_entities(msg: Any) -> tuple[list, list, list, list]:
    """MarkerArray -> line strips (+colours) and boxes (centres, half sizes, colours) in map."""
    strips, strip_colours, boxes, box_colours = [], [], [], []
    for mk in msg.markers:
        colour = _rgba([mk.color.r, mk.color.g, mk.color.b, mk.color.a or 1.0])
        pose = Transform.from_quat(
            [mk.pose.position.x, mk.pose.position.y, mk.pose.position.z],
            [
                mk.pose.orientation.x,
                mk.pose.orientation.y,
                mk.pose.orientation.z,
                mk.pose.orientation.w or 1.0,
            ],
        )
        pts = pose.apply(np.array([[p.x, p.y, p.z] for p in mk.points], dtype=float).reshape(-1, 3))
        if mk.type in (4, 5, 11) and len(pts) >= 2:  # LINE_STRIP, LINE_LIST, TRIANGLE_LIST (outline)
            strips.append(pts)
            strip_colours.append(colour)
        elif mk.type == 1:  # CUBE
            boxes.append((pose.translation, [mk.scale.x / 2, mk.scale.y / 2, mk.scale.z / 2]))
            box_colours.append(colour)
        elif len(pts):
            strips.append(pts)
            strip_colours.append(colour)
    return strips, strip_colours, boxes, box_colours


def _describe(msg: Any, depth: int = 0) -> str:
    """One line from a decoded message's fields (headers and long arrays shortened)."""
    if not dataclasses.is_dataclass(msg) or depth > 2:
        text = str(msg)
        return text if len(text) < 80 else text[:77] + "..."
    parts = []
    for f in dataclasses.fields(msg):
        if f.name in ("header", "__msgtype__"):
            continue
        parts.append(f"{f.name}={_describe(getattr(msg, f.name), depth + 1)}")
    return " ".join(parts)


def log_generic(rec: rr.RecordingStream, reader: RecordingReader) -> tuple[list[str], list[str]]:
    """MarkerArray topics as 3D shapes, every other unhandled custom-type topic as a text log."""
    markers = [t.name for t in reader.topics.values() if t.msgtype == MARKER_ARRAY_TYPE]
    events = [
        t.name
        for t in reader.topics.values()
        if t.msgtype not in HANDLED_TYPES and t.msgtype != schema.STRING_TYPE and t.name.startswith("/")
    ]
    for m in reader.messages([*markers, *events]):
        _set_time(rec, m.stamp_ns)
        path = m.topic.strip("/")
        if m.topic in markers:
            strips, colours, boxes, box_colours = _marker_entities(m.msg)
            if strips:
                rec.log(f"world/markers/{path}", rr.LineStrips3D(strips, colors=colours, radii=0.04))
            if boxes:
                rec.log(
                    f"world/markers/{path}/boxes",
                    rr.Boxes3D(
                        centers=[b[0] for b in boxes], half_sizes=[b[1] for b in boxes], colors=box_colours
                    ),
                )
        else:
            rec.log(
                f"events/{path}",
                rr.TextLog(_describe(m.msg), level="WARN" if "safety" in m.topic else "INFO"),
            )
    return markers, events


def export(
    recording: Path | str, *, save: Path | None = None, spawn: bool = False, image_every: int = 1
) -> dict[str, Any]:
    """Log a recording to Rerun (into ``save`` or a spawned viewer); returns what was logged.

    Raises:
        RecordingInputError: not a readable recording.
        ConfigError: bad arguments.
    """
    if image_every < 1:
        raise ConfigError(
            f"invalid --image-every {image_every}", "arguments", "must be >= 1", "e.g. 1 (every image)"
        )
    with RecordingReader(recording) as reader:
        reader.check_types_of(HANDLED_TYPES - {MARKER_ARRAY_TYPE} | {schema.STRING_TYPE})  # read by name
        rec = rr.RecordingStream(APP_ID, recording_id=str(reader.path.resolve()))
        rec.set_log_time_enabled(False)  # the simulated clock is the only time: same recording, same file
        rec.set_log_tick_enabled(False)
        ctx = ReplayContext(reader, Path("."))
        config = ctx.config
        cameras = sorted(ctx.cameras, key=lambda c: (len(c), c))
        namespaces = sorted(config.get("agents") or {})
        has_birdseye = schema.BIRDSEYE_IMAGE in reader.topics
        markers = [t.name for t in reader.topics.values() if t.msgtype == MARKER_ARRAY_TYPE]
        with_depth = sorted(
            {c for t in reader.topics if (c := _camera_of(t, DEPTH_SUFFIXES, cameras)) is not None},
            key=lambda c: (len(c), c),
        )
        with_semantic = sorted(
            {c for t in reader.topics if (c := _camera_of(t, SEMANTIC_SUFFIXES, cameras)) is not None},
            key=lambda c: (len(c), c),
        )
        blueprint = build_blueprint(
            cameras,
            namespaces,
            has_birdseye=has_birdseye,
            has_events=True,
            depth_cameras=with_depth,
            semantic_cameras=with_semantic,
        )
        if save is not None:
            rec.save(save, default_blueprint=blueprint)
        elif spawn:
            rec.spawn(default_blueprint=blueprint)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log("world/recording", rr.TextDocument(reader.summary()), static=True)
        parts = log_layout(rec, config)
        log_cameras(rec, ctx)
        counts: dict[str, int] = {}
        images = log_images(rec, reader, cameras, every=image_every, cameras=ctx.cameras, counts=counts)
        agents = log_agents(rec, reader, config)
        markers, events = log_generic(rec, reader)
        rec.flush()
        rec.disconnect()
    return {
        "layout_parts": parts,
        "cameras": cameras,
        "images": images,
        "depth_images": counts.get("depth", 0),
        "semantic_images": counts.get("semantic", 0),
        "undistorted_images": counts.get("undistorted", 0),
        "agents": agents,
        "birdseye": has_birdseye,
        "markers": markers,
        "events": events,
    }
