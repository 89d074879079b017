"""Instance ground truth (issue 25): which object each pixel shows, 2D and 3D boxes, keypoints, recorded.

Data flow per camera tick (stream ``instance``)::

    PyBullet poses + collision shapes --> 3D boxes in map (one per instance) --> /ground_truth/boxes
                                               |
    renderer's segmentation pass               | project through each camera (with distortion)
      body id image --LabelTable--> instance ids (uint16 PNG) --> /camera_<id>/instances/image_raw
                          |                    |
                          v                    v
                 visible boxes (mask) + amodal boxes, visible fraction, truncation
                                               --> /camera_<id>/instances/boxes
    people's 33 landmarks --camera + the render's depth--> /camera_<id>/instances/keypoints
                                                           (sim/keypoints.py; scenes with people)

Instance ids: 1..A for the agents in config order, then the world's movable objects (pallets,
boxes) by body id; the same in every camera for the whole run: they are the track ids.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from simlan_data.geometry.boxes import clip_box, project_box, visible_boxes
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import yaw_from_quat
from simlan_data.recording import messages as M
from simlan_data.recording import schema
from simlan_data.recording import standard_instances as standard
from simlan_data.recording.writer import RecordingWriter
from simlan_data.sim.agent_base import Agent
from simlan_data.sim.keypoints import DepthSource, frame_keypoints
from simlan_data.sim.rendering import CameraImages, LabelTable
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import WorldBodies
from simlan_data.world.labels import LABEL_NAMES

INSTANCE_STREAM = "instance"


class InstanceObject(NamedTuple):
    """One row of the instance table."""

    id: int
    body: int
    namespace: str  # the agent's namespace, "" for a world object
    name: str
    class_id: int


def instance_objects(agents: Sequence[Agent], world: WorldBodies) -> list[InstanceObject]:
    """The instance table: agents in config order, then the world's movable objects by body id."""
    rows = [
        InstanceObject(i, a.body, a.namespace, a.kind.name, a.label) for i, a in enumerate(agents, start=1)
    ]
    for body in sorted(world.movable):
        rows.append(
            InstanceObject(len(rows) + 1, body, "", world.names.get(body, ""), world.labels.get(body, 0))
        )
    return rows


def people_instances(agents: Sequence[Agent], objects: Sequence[InstanceObject]) -> list[tuple[int, Agent]]:
    """(instance id, agent) of every person among the agents (those with body landmarks)."""
    ids = {obj.body: obj.id for obj in objects}
    return [(ids[a.body], a) for a in agents if a.body in ids and a.landmarks() is not None]


def instance_lut(objects: Sequence[InstanceObject]) -> LabelTable:
    """Body id -> instance id, for the renderers."""
    table = LabelTable(np.uint16)
    for obj in objects:
        table.set(obj.body, obj.id)
    return table


def _shape_corners(geometry: int, dims: Sequence[float]) -> NDArray[np.float64] | None:
    """Corners (8, 3) of the box around a primitive collision shape in its own frame (None: a mesh
    or plane, bounded by the link's AABB instead)."""
    if geometry == pb.GEOM_BOX:
        half = np.asarray(dims[:3]) / 2
    elif geometry == pb.GEOM_SPHERE:
        half = np.full(3, dims[0])
    elif geometry in (pb.GEOM_CYLINDER, pb.GEOM_CAPSULE):  # dims: (length, radius)
        length, radius = dims[0], dims[1]
        half = np.array([radius, radius, length / 2 + (radius if geometry == pb.GEOM_CAPSULE else 0.0)])
    else:
        return None
    signs = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], dtype=float) * 2 - 1
    return signs * half


class Boxes3D:
    """Yaw-aligned 3D boxes of bodies from their collision shapes and current link poses.

    A box's yaw is the body base's; its extent bounds every shape's own box (PyBullet reports
    collision shapes relative to each link's centre of mass, as it reports link poses), so a
    rotated pallet gets its true size, not its axis-aligned bounds. Mesh shapes fall back to the
    link's world AABB.
    """

    def __init__(self, client: int) -> None:
        self.client = client
        self._shapes: dict[int, list[tuple[int, NDArray[np.float64] | None, tuple, tuple]]] = {}

    def _body_shapes(self, body: int) -> list[tuple[int, NDArray[np.float64] | None, tuple, tuple]]:
        if body not in self._shapes:
            links = range(-1, pb.getNumJoints(body, physicsClientId=self.client))
            self._shapes[body] = [
                (link, _shape_corners(geom, dims), pos, orn)
                for link in links
                for (_, _, geom, dims, _, pos, orn) in pb.getCollisionShapeData(
                    body, link, physicsClientId=self.client
                )
            ]
        return self._shapes[body]

    def _link_pose(self, body: int, link: int) -> tuple[Any, Any]:
        if link < 0:
            return pb.getBasePositionAndOrientation(body, physicsClientId=self.client)
        state = pb.getLinkState(body, link, physicsClientId=self.client)
        return state[0], state[1]

    def box(self, body: int) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """(centre (3,), size (3,), yaw_rad) of one body in map."""
        _, base_orn = pb.getBasePositionAndOrientation(body, physicsClientId=self.client)
        yaw = float(yaw_from_quat(base_orn))
        points = []
        for link, corners, pos, orn in self._body_shapes(body):
            if corners is None:
                lo, hi = pb.getAABB(body, link, physicsClientId=self.client)
                bits = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], dtype=bool)
                points.append(np.where(bits, hi, lo))
                continue
            link_pos, link_orn = self._link_pose(body, link)
            wpos, worn = pb.multiplyTransforms(link_pos, link_orn, pos, orn)
            rot = np.asarray(pb.getMatrixFromQuaternion(worn)).reshape(3, 3)
            points.append(corners @ rot.T + np.asarray(wpos))
        if not points:  # (no collision shape: the body's AABB)
            lo, hi = pb.getAABB(body, -1, physicsClientId=self.client)
            return (np.asarray(lo) + hi) / 2, np.asarray(hi) - lo, yaw
        pts = np.vstack(points)
        c, s = np.cos(yaw), np.sin(yaw)
        to_box = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # map -> box axes
        local = pts @ to_box.T
        lo, hi = local.min(axis=0), local.max(axis=0)
        return ((lo + hi) / 2) @ to_box, hi - lo, yaw


class InstanceRecorder:
    """Record the instance table once, then per camera tick the 3D boxes and per camera frame the
    instance image, its 2D boxes and the people's keypoints.

    ``people``: (instance id, agent) of every person (an agent whose ``landmarks()`` is not None);
    ``depth``: per camera id, the camera the image was rendered from and the render's depth (its
    renderer), for the keypoints' projection and occlusion test.
    """

    def __init__(
        self,
        writer: RecordingWriter,
        client: int,
        objects: Sequence[InstanceObject],
        *,
        people: Sequence[tuple[int, Agent]] = (),
        depth: Mapping[str, DepthSource] | None = None,
    ) -> None:
        self.writer, self.objects = writer, list(objects)
        self.people, self.depth = list(people), dict(depth or {})
        self._landmarks: list[tuple[int, tuple[NDArray[np.float64], NDArray[np.float64]]]] = []
        self._boxes3d = Boxes3D(client)
        self._now: tuple[int, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None = None
        self._topics: dict[str, dict[str, schema.Topic]] = {}
        self._last: dict[str, tuple[NDArray[np.uint16], Any, FrameBoxes]] = {}  # per camera
        self._class_of = {o.id: LABEL_NAMES.get(o.class_id, "") for o in self.objects}  # standard types
        writer.write(_global(schema.INSTANCES), 0, M.instance_table(self.objects))

    def tick(self, t: int) -> None:
        """Measure and record every instance's 3D box at camera tick ``t``."""
        boxes = [self._boxes3d.box(obj.body) for obj in self.objects]
        centers = np.array([b[0] for b in boxes]).reshape(-1, 3)
        sizes = np.array([b[1] for b in boxes]).reshape(-1, 3)
        yaws = np.array([b[2] for b in boxes], dtype=float)
        self._now = (t, centers, sizes, yaws)
        self._landmarks = [(i, lm) for i, agent in self.people if (lm := agent.landmarks()) is not None]
        ids = [obj.id for obj in self.objects]
        msg = M.instance_boxes_3d(self.writer.stamp_ns(t), ids, centers, sizes, yaws)
        self.writer.write(_global(schema.INSTANCE_BOXES_3D), t, msg)
        cubes = standard.box_markers(self.writer.stamp_ns(t), ids, centers, sizes, yaws, self._class_of)
        self.writer.write(_global(schema.INSTANCE_BOX_MARKERS), t, cubes)

    def record(self, t: int, camera: CameraModel, images: CameraImages, *, stamp_ns: int) -> None:
        """Queue one camera frame's instance image and boxes (encoded on the writer's workers)."""
        if images.instances is None or self._now is None:
            return
        cid = camera.camera_id
        if cid not in self._topics:
            self._topics[cid] = schema.instance_topics(cid)
        topics, stamp = self._topics[cid], self.writer.stamp_ns(stamp_ns)
        last = self._last.get(cid)
        if last is not None and last[0] is images.instances:
            # the renderer handed out its last image again: nothing in view moved (the objects it
            # shows, their boxes), so the encoded PNG and the boxes are reused with a new stamp
            _, png, boxes = last
        else:
            png = self.writer.run_async(encode_instances, images.instances)
            boxes = frame_boxes(camera, images.instances, self._now[1:], [o.id for o in self.objects])
            self._last[cid] = (images.instances, png, boxes)
        self.writer.submit(topics["instance"], t, functools.partial(_compressed, stamp, camera.frame_id, png))
        self.writer.write(topics["boxes_2d"], t, M.instance_boxes_2d(stamp, camera, boxes))
        detections = standard.detections_2d(stamp, camera, boxes.ids, boxes.visible, self._class_of)
        self.writer.write(topics["detections"], t, detections)
        if self.people and cid in self.depth:
            view = self.depth[cid]  # (its camera is the one the image was rendered from: drift)
            keypoints = frame_keypoints(view.camera, self._landmarks, view)
            self.writer.write(topics["keypoints"], t, M.instance_keypoints(stamp, camera, keypoints))


class FrameBoxes(NamedTuple):
    """The 2D boxes of one camera frame (arrays of the InstanceBoxes2D message)."""

    ids: NDArray[np.uint16]
    pixels: NDArray[np.uint32]
    visible: NDArray[np.int32]  # (N, 4)
    amodal: NDArray[np.float32]  # (N, 4), clipped
    visible_fraction: NDArray[np.float32]
    truncation: NDArray[np.float32]


def frame_boxes(
    camera: CameraModel,
    instances: NDArray[np.uint16],
    boxes3d: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    ids: Sequence[int],
) -> FrameBoxes:
    """Visible boxes from the instance image; amodal boxes, visible fraction and truncation from
    the 3D boxes projected through the camera (an instance seen by no pixel is left out)."""
    seen = visible_boxes(instances)
    row = {i: k for k, i in enumerate(ids)}
    centers, sizes, yaws = boxes3d
    amodal = np.zeros((len(seen.ids), 4), dtype=np.float32)
    fraction = np.zeros(len(seen.ids), dtype=np.float32)
    truncation = np.zeros(len(seen.ids), dtype=np.float32)
    for n, (iid, pixels, vis) in enumerate(zip(seen.ids, seen.pixels, seen.boxes, strict=True)):
        k = row.get(int(iid))
        proj = None if k is None else project_box(camera, centers[k], sizes[k], float(yaws[k]))
        if proj is None:  # (not projectable: the visible box stands in)
            amodal[n] = vis
            fraction[n] = 1.0
            continue
        clipped, truncation[n] = clip_box(proj.bounds, camera.width, camera.height)
        amodal[n] = clipped
        fraction[n] = min(1.0, float(pixels) / proj.outline_area) if proj.outline_area > 0 else 1.0
    return FrameBoxes(seen.ids, seen.pixels, seen.boxes, amodal, fraction, truncation)


def encode_instances(instances: NDArray[np.uint16]) -> tuple[str, bytes]:
    """A 16-bit PNG of an instance image (lossless; OpenCV's default compression)."""
    ok, data = cv2.imencode(".png", np.ascontiguousarray(instances, dtype=np.uint16))
    if not ok:
        raise RuntimeError("PNG encoding of an instance image failed")
    return schema.INSTANCE_PNG_FORMAT, data.tobytes()


def _compressed(stamp_ns: int, frame_id: str, encoded: Any) -> Any:
    return M.compressed_image(stamp_ns, frame_id, *encoded.result())


def _global(name: str) -> schema.Topic:
    return next(t for t in schema.GLOBAL_TOPICS if t.name == name)
