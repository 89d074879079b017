"""Pose estimators behind one interface, all returning MediaPipe Pose's output per camera image.

Output per view: float32 (33, 4) = x, y (normalised by the image width and height, as MediaPipe),
z (depth relative to the hips' midpoint, in the same scale as x: smaller is closer to the camera)
and visibility (0..1). A view where no person was found is all zeros.

- :class:`ProjectionEstimator` (``projection``): the 33 landmarks attached to the humanoid's links
  (``skeleton.LANDMARKS``), projected by the calibrated camera model with its lens distortion;
  a landmark is visible when it lies in the image and the rendered depth at its pixel shows no
  surface more than ``inside_m + depth_tolerance_m`` in front of it (self-occlusion by an arm,
  occlusion by the world). Pixel noise is Gaussian (``noise_px``); landmarks that are not
  visible are reported with ``hidden_noise_px`` (MediaPipe guesses hidden landmarks: their
  positions are reported, less exactly). Deterministic for a seed.
- :class:`MediaPipeEstimator` (``mediapipe``): MediaPipe Pose 0.10.14 (``model_complexity=1``),
  run in its own Python environment (it needs numpy<2 and its own OpenCV) as a worker process
  fed RGB images over a pipe; see ``mediapipe_worker.py``.
"""

from __future__ import annotations

import json
import os
import subprocess
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simlan_data.errors import ConfigError, RunError
from simlan_data.geometry.camera import CameraModel
from simlan_data.world.skeleton import LANDMARK_INSIDE_M, LANDMARK_NAMES, NUM_LANDMARKS

ESTIMATORS = ("projection", "mediapipe")
LEFT_HIP, RIGHT_HIP = LANDMARK_NAMES.index("left_hip"), LANDMARK_NAMES.index("right_hip")
WORKER = Path(__file__).with_name("mediapipe_worker.py")
PIPE_WINDOW = 8  # images sent ahead of their answers (an answer is about 3 kB of JSON)


@dataclass
class CameraView:
    """What an estimator may look at for one camera: the image, and for the projection estimator
    the landmarks' true world positions and what hides them (the rendered depth image, or
    ``hidden``: landmarks a ray cast found something in front of)."""

    camera: CameraModel
    rgb: NDArray[np.uint8] | None = None
    depth_m: NDArray[np.float32] | None = None
    landmarks_world: NDArray[np.float64] | None = None
    hidden: NDArray[np.bool_] | None = None
    # (u0, v0, u1, v1): the person's region of ``rgb``; MediaPipe looks at it alone (None: all)
    crop: tuple[int, int, int, int] | None = None


class PoseEstimator(ABC):
    """Landmarks of the person in each view: (n_views, 33, 4) float32, MediaPipe's layout.

    In two steps, so that a pool of workers can measure samples in any order and the dataset stays
    the same: :meth:`measure` depends on the views alone; :meth:`finish` (the seeded noise) runs
    in the parent, sample after sample.
    """

    name: str = ""
    version: str = ""

    @abstractmethod
    def measure(self, views: Sequence[CameraView]) -> NDArray[np.float64]:
        """The views' landmarks before :meth:`finish`: (n_views, 33, 4)."""

    def finish(self, measured: NDArray[np.float64], cameras: Sequence[CameraModel]) -> NDArray[np.float32]:
        """The landmarks of one sample's measurement (the default: as measured)."""
        del cameras  # (the projection estimator's noise needs them)
        return measured.astype(np.float32)

    def estimate(self, views: Sequence[CameraView]) -> NDArray[np.float32]:
        return self.finish(self.measure(views), [v.camera for v in views])

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release resources (worker processes)."""

    def __enter__(self) -> PoseEstimator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ProjectionEstimator(PoseEstimator):
    """Landmarks projected from the humanoid's links, occlusion from the rendered depth image."""

    name = "projection"

    def __init__(
        self,
        *,
        noise_px: float = 1.0,
        hidden_noise_px: float = 8.0,
        z_noise: float = 0.01,
        depth_tolerance_m: float = 0.03,
        seed: int = 0,
    ) -> None:
        self.noise_px, self.hidden_noise_px, self.z_noise = noise_px, hidden_noise_px, z_noise
        self.depth_tolerance_m = depth_tolerance_m
        self.rng = np.random.default_rng(seed)

    def visible(
        self, view: CameraView, uv: NDArray[np.float64], z_m: NDArray[np.float64], ok: NDArray[np.bool_]
    ) -> NDArray[np.bool_]:
        """Landmarks inside the image with no rendered surface in front of them."""
        cam = view.camera
        col, row = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
        inside = ok & (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
        if view.depth_m is None:
            return inside if view.hidden is None else inside & ~view.hidden
        seen = np.zeros(len(uv), dtype=np.float64)
        seen[inside] = view.depth_m[row[inside], col[inside]]
        return inside & (seen > 0) & (z_m - seen <= LANDMARK_INSIDE_M + self.depth_tolerance_m)

    def measure(self, views: Sequence[CameraView]) -> NDArray[np.float64]:
        """Per view: pixel u, v, MediaPipe's z (noise-free) and visibility; NaN where nothing is seen."""
        out = np.full((len(views), NUM_LANDMARKS, 4), np.nan)
        for i, view in enumerate(views):
            if view.landmarks_world is None:
                raise ValueError("the projection estimator needs the landmarks' world positions")
            cam = view.camera
            pts = cam.world_to_camera(view.landmarks_world)
            uv, ok = cam.project_camera_points(pts)
            vis = self.visible(view, uv, pts[:, 2], ok)
            if not vis.any():
                continue
            hips_z = 0.5 * (pts[LEFT_HIP, 2] + pts[RIGHT_HIP, 2])
            # MediaPipe's z: relative to the hips' midpoint, in image-width units like x
            out[i, :, :2] = uv
            out[i, :, 2] = (pts[:, 2] - hips_z) * cam.K[0, 0] / (max(hips_z, 1e-6) * cam.width)
            out[i, :, 3] = vis
        return out

    def finish(self, measured: NDArray[np.float64], cameras: Sequence[CameraModel]) -> NDArray[np.float32]:
        """Pixel noise (seeded, drawn view after view) and MediaPipe's normalised coordinates."""
        out = np.zeros((len(cameras), NUM_LANDMARKS, 4), dtype=np.float32)
        for i, cam in enumerate(cameras):
            if np.isnan(measured[i, 0, 0]):
                continue
            vis = measured[i, :, 3] > 0.5
            sigma = np.where(vis, self.noise_px, self.hidden_noise_px)[:, None]
            uv = measured[i, :, :2] + self.rng.normal(size=(NUM_LANDMARKS, 2)) * sigma
            z = measured[i, :, 2] + self.rng.normal(size=NUM_LANDMARKS) * self.z_noise
            out[i, :, 0] = uv[:, 0] / cam.width
            out[i, :, 1] = uv[:, 1] / cam.height
            out[i, :, 2] = z
            out[i, :, 3] = vis
        return out


class MediaPipeEstimator(PoseEstimator):
    """MediaPipe Pose (0.10.14, model_complexity=1) in a worker process of its own environment.

    Protocol (one request per image): a JSON line ``{"h": H, "w": W}`` and H*W*3 RGB bytes on the
    worker's stdin; it answers one JSON line ``{"landmarks": [[x, y, z, v], ...]}`` (33 rows, or
    an empty list when it finds no person).
    """

    name = "mediapipe"

    def __init__(self, python: str, *, min_detection_confidence: float = 0.5) -> None:
        exe = Path(python)
        if not exe.exists():
            raise ConfigError(
                "MediaPipe environment not found",
                f"posemap.mediapipe_python={python}",
                "the MediaPipe estimator runs in its own virtual environment (numpy<2, its own OpenCV)",
                "create it with `bash scripts/mediapipe_env.sh` (README: Pose mapping) or set posemap.mediapipe_python",
            )
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
        self.proc = subprocess.Popen(
            [str(exe), str(WORKER), "--min-detection-confidence", str(min_detection_confidence)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
        )
        ready = self._read()
        if ready.get("ready") is not True:
            raise RunError(
                "MediaPipe worker did not start",
                str(exe),
                str(ready.get("error", ready)),
                "check the environment",
            )
        self.version = str(ready.get("mediapipe", ""))

    def _read(self) -> dict:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            err = self.proc.stderr.read().decode(errors="replace") if self.proc.stderr else ""
            tail = err.strip().splitlines()[-1] if err.strip() else "no output"
            raise RunError("MediaPipe worker stopped", str(WORKER), tail, "run the worker by hand to see why")
        return dict(json.loads(line))

    def measure(self, views: Sequence[CameraView]) -> NDArray[np.float64]:
        """MediaPipe on each view's person crop (or whole image), in full-image coordinates."""
        if any(view.rgb is None for view in views):
            raise ValueError("the MediaPipe estimator needs the RGB image")
        crops = [view.crop or (0, 0, view.rgb.shape[1], view.rgb.shape[0]) for view in views]  # type: ignore[union-attr]
        images = [view.rgb[v0:v1, u0:u1] for view, (u0, v0, u1, v1) in zip(views, crops)]  # type: ignore[index]
        out = self.estimate_images(images).astype(np.float64)
        for lm, view, (u0, v0, u1, v1) in zip(out, views, crops):
            if not lm.any():
                continue
            h, w = view.rgb.shape[:2]  # type: ignore[union-attr]
            lm[:, 0] = (u0 + lm[:, 0] * (u1 - u0)) / w
            lm[:, 1] = (v0 + lm[:, 1] * (v1 - v0)) / h
            lm[:, 2] *= (u1 - u0) / w  # z: in the image width's scale, as x
        return out

    def estimate_images(self, images: Sequence[NDArray[np.uint8]]) -> NDArray[np.float32]:
        """Landmarks (n, 33, 4) of RGB images (H, W, 3) that need no camera model (video files).

        At most ``PIPE_WINDOW`` images wait for their answers: the answers queue in the worker's
        stdout pipe (64 KiB) while images are sent, and a full pipe would stop both sides.
        """
        assert self.proc.stdin is not None
        out = np.zeros((len(images), NUM_LANDMARKS, 4), dtype=np.float32)
        received = 0
        for sent, image in enumerate(images):
            if sent - received >= PIPE_WINDOW:
                received = self._receive(out, received)
            rgb = np.ascontiguousarray(image, dtype=np.uint8)
            self.proc.stdin.write(json.dumps({"h": rgb.shape[0], "w": rgb.shape[1]}).encode() + b"\n")
            self.proc.stdin.write(rgb.data)
            self.proc.stdin.flush()
        while received < len(images):
            received = self._receive(out, received)
        return out

    def _receive(self, out: NDArray[np.float32], i: int) -> int:
        """Read the answer for image ``i`` into ``out``; returns the next image's index."""
        rows = self._read()["landmarks"]
        if rows:
            out[i] = np.asarray(rows, dtype=np.float32)
        return i + 1

    def close(self) -> None:
        if self.proc.poll() is None:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def make_estimator(
    name: str,
    *,
    seed: int = 0,
    noise_px: float = 1.0,
    hidden_noise_px: float = 8.0,
    mediapipe_python: str = "",
) -> PoseEstimator:
    if name == "projection":
        return ProjectionEstimator(noise_px=noise_px, hidden_noise_px=hidden_noise_px, seed=seed)
    if name == "mediapipe":
        return MediaPipeEstimator(mediapipe_python)
    raise ConfigError(
        f"unknown pose estimator '{name}'",
        "posemap.estimator",
        f"expected one of {', '.join(ESTIMATORS)}",
        "use projection",
    )
