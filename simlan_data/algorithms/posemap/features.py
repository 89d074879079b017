"""Model inputs from landmarks: per-camera image features, and multi-view features in the rig's frame.

``image`` (SIMLAN's input, per camera): x, y, z as the estimator gives them (SIMLAN's MLP reads
these 99 numbers of one camera) plus visibility.

``rig`` (multi-view fusion, ours): for every camera, each landmark's pixel is turned into a unit
ray through the calibrated camera model (lens distortion undone) and expressed in the frame of
the humanoid's support base; the rays of all cameras are intersected per landmark (least
squares, weighted by visibility) into a 3D point in that frame, with how well the rays agree.
The network then reads geometry instead of having to learn each camera's projection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform

MIN_WEIGHT = 0.05  # a landmark the estimator marks hidden still pulls a little (its guess)


@dataclass(frozen=True)
class Rig:
    """The cameras a model reads (in feature order) and where the humanoid's support base stands."""

    cameras: tuple[CameraModel, ...]
    world_from_base: NDArray[np.float64]  # 4x4

    @staticmethod
    def from_meta(camera_models: list[dict], camera_ids: list[str], position: list[float]) -> Rig:
        by_id = {str(m["id"]): m for m in camera_models}
        cams = []
        for cid in camera_ids:
            m = by_id[str(cid)]
            world_from_camera = np.asarray(m["world_from_camera"], dtype=np.float64)
            cams.append(
                CameraModel(
                    str(cid),
                    int(m["width"]),
                    int(m["height"]),
                    np.asarray(m["K"], dtype=np.float64),
                    np.asarray(m["D"], dtype=np.float64),
                    Transform.from_matrix(world_from_camera).inverse(),
                )
            )
        x, y, yaw = (float(v) for v in position)
        return Rig(tuple(cams), Transform.from_pose2d(x, y, yaw).matrix())


def image_features(landmarks: NDArray[np.float32], *, visibility: bool = True) -> NDArray[np.float32]:
    """(N, C, 33, 4) -> (N, C * 33 * k): x, y, z (and visibility) per camera and landmark."""
    keep = 4 if visibility else 3
    return landmarks[..., :keep].reshape(len(landmarks), -1).astype(np.float32)


def rays_in_base(landmarks: NDArray[np.float32], rig: Rig) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit rays (N, C, 33, 3) through each landmark's pixel and camera centres (C, 3), base frame."""
    n, c = landmarks.shape[:2]
    base_from_world = np.linalg.inv(rig.world_from_base)
    rays = np.zeros((n, c, landmarks.shape[2], 3))
    centres = np.zeros((c, 3))
    for k, cam in enumerate(rig.cameras):
        uv = landmarks[:, k, :, :2].reshape(-1, 2).astype(np.float64) * [cam.width, cam.height]
        d_cam, ok = cam.pixel_rays(uv)
        d_cam[~ok] = [0.0, 0.0, 1.0]  # beyond the lens model: along the axis (weight drops below)
        base_from_cam = base_from_world @ cam.world_from_camera.matrix()
        rays[:, k] = (d_cam @ base_from_cam[:3, :3].T).reshape(n, -1, 3)
        centres[k] = base_from_cam[:3, 3]
    return rays, centres


def triangulate(
    rays: NDArray[np.float64], centres: NDArray[np.float64], weights: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Weighted least-squares intersection of the cameras' rays per landmark.

    Args:
        rays: (N, C, L, 3) unit directions; centres: (C, 3); weights: (N, C, L).
    Returns:
        points (N, L, 3) and the weighted RMS distance of the rays from each point (N, L).
    """
    eye = np.eye(3)
    P = eye - rays[..., :, None] * rays[..., None, :]  # (N, C, L, 3, 3) projectors orthogonal to the rays
    W = weights[..., None, None]
    A = (W * P).sum(axis=1) + 1e-9 * eye
    b = (W * (P @ centres[None, :, None, :, None])).sum(axis=1)[..., 0]
    pts = np.linalg.solve(A, b[..., None])[..., 0]
    off = pts[:, None] - centres[None, :, None, :]
    resid = np.einsum("nclij,nclj->ncli", P, off)
    rms = np.sqrt((weights * (resid**2).sum(-1)).sum(1) / np.maximum(weights.sum(1), 1e-9))
    return pts, rms


def rig_features(landmarks: NDArray[np.float32], rig: Rig) -> NDArray[np.float32]:
    """Image features + rays in the base frame + triangulated 3D landmarks and their ray spread."""
    rays, centres = rays_in_base(landmarks, rig)
    detected = (landmarks[..., 3] > 0).any(axis=2, keepdims=True)
    weights = np.where(detected, np.maximum(landmarks[..., 3], MIN_WEIGHT), 0.0).astype(np.float64)
    pts, rms = triangulate(rays, centres, weights)
    n = len(landmarks)
    return np.concatenate(
        [
            image_features(landmarks),
            rays.reshape(n, -1),
            pts.reshape(n, -1),
            np.minimum(rms, 1.0).reshape(n, -1),
        ],
        axis=1,
    ).astype(np.float32)


def build_features(landmarks: NDArray[np.float32], kind: str, rig: Rig | None) -> NDArray[np.float32]:
    if kind == "simlan":
        return image_features(landmarks, visibility=False)
    if kind == "image":
        return image_features(landmarks)
    if rig is None:
        raise ValueError("rig features need the camera models")
    return rig_features(landmarks, rig)
