"""Humanoid keypoint ground truth (issue 25): the 33 body landmarks of every person, per camera.

Data flow per camera frame (stream ``instance``, scenes with people)::

    person agents --landmarks()--> 33 points in map + depth under the surface
        --camera model (extrinsics, distortion)--> pixels (u, v), camera z
        --the renderer's depth along each ray--> visibility v --> /camera_<id>/instances/keypoints

Visibility follows COCO's ``v``: 0 = not in the image (behind the camera, outside the model's
valid field or off the image), 1 = in the image but hidden, 2 = visible. A landmark in the image is
visible when the rendered surface along its ray lies no more than its depth under the body's
surface (``inside_m``) plus ``DEPTH_TOLERANCE_M`` in front of it: the projection pose
estimator's rule (``algorithms/posemap/estimators.py``), so another object in front hides it
and so does the person's own body (an arm, the head seen from behind). The depth is the render
the frame's images come from (the renderer's undistorted canvas, no extra render or remap).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from simlan_data.geometry.camera import CameraModel
from simlan_data.world.skeleton import NUM_LANDMARKS

DEPTH_TOLERANCE_M = 0.03  # as the projection estimator: a pixel's depth on a slanted surface
NOT_IN_IMAGE, HIDDEN, VISIBLE = 0, 1, 2  # COCO's keypoint visibility flags


class DepthSource(Protocol):
    """The camera an image was rendered from and that render's depth along rays (a renderer)."""

    camera: CameraModel

    def surface_depth_m(self, points_cam: NDArray[np.float64]) -> NDArray[np.float32]: ...


class FrameKeypoints(NamedTuple):
    """The keypoints of one camera frame (arrays of the InstanceKeypoints message)."""

    ids: NDArray[np.uint16]  # (N,) person instance ids
    uv: NDArray[np.float32]  # (N, 33, 2) pixels (OpenCV: pixel centres at integers)
    visibility: NDArray[np.uint8]  # (N, 33) NOT_IN_IMAGE | HIDDEN | VISIBLE


def landmark_pixels(
    camera: CameraModel,
    world: NDArray[np.float64],
    inside_m: NDArray[np.float64],
    depth: DepthSource,
) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
    """Pixels (33, 2) and COCO visibility (33,) of one person's landmarks in one camera."""
    pts = camera.world_to_camera(world)
    uv, ok = camera.project_camera_points(pts)
    inside = ok & (uv[:, 0] > -0.5) & (uv[:, 0] < camera.width - 0.5)
    inside &= (uv[:, 1] > -0.5) & (uv[:, 1] < camera.height - 0.5)
    seen = depth.surface_depth_m(pts)
    clear = (seen > 0) & (pts[:, 2] - seen <= inside_m + DEPTH_TOLERANCE_M)
    vis = np.where(inside, np.where(clear, VISIBLE, HIDDEN), NOT_IN_IMAGE).astype(np.uint8)
    uv = np.where(ok[:, None], uv, 0.0)  # (a point behind the camera has no pixel)
    return uv.astype(np.float32), vis


def frame_keypoints(
    camera: CameraModel,
    people: Sequence[tuple[int, tuple[NDArray[np.float64], NDArray[np.float64]]]],
    depth: DepthSource,
) -> FrameKeypoints:
    """Every person's landmarks in one camera frame; ``people``: (instance id, (world, inside_m))."""
    uv = np.zeros((len(people), NUM_LANDMARKS, 2), dtype=np.float32)
    vis = np.zeros((len(people), NUM_LANDMARKS), dtype=np.uint8)
    for n, (_, (world, inside_m)) in enumerate(people):
        uv[n], vis[n] = landmark_pixels(camera, world, inside_m, depth)
    return FrameKeypoints(np.array([i for i, _ in people], dtype=np.uint16), uv, vis)
