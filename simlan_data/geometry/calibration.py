"""Load SIMLAN's OpenCV FileStorage calibration files with OpenCV itself, and check them.

Layout (``assets/calibration`` or any directory with the same layout)::

    intrinsic/<id>.yaml   K (3x3), D (5x1: k1 k2 p1 p2 k3), xi (0), image_shape [rows, cols, ch]
    extrinsic/<id>.yaml   rot_mat (world -> camera), t_vec, camera_matrix_p = K[R|t], position

K, D, R and t are authoritative. ``camera_matrix_p`` and ``position`` are derived copies; when they
disagree with K[R|t] and -R^T t the loader reports the file (SIMLAN's 500-503 carry stale copies).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from simlan_data.constants import CALIBRATION_DIR
from simlan_data.errors import CalibrationError
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.rotations import is_rotation_matrix
from simlan_data.geometry.transforms import Transform

MAX_CALIBRATION_BYTES = 1 << 20  # a calibration file is a few hundred bytes; refuse huge inputs
P_REL_TOL = 1e-4  # relative tolerance for P == K[R|t] (files store 17 significant digits)
POSITION_TOL_M = 1e-3
ROTATION_TOL = 1e-4
# plausibility bounds: finite values outside them are typos or corruption, and would only fail
# later (and less clearly) in projection and rendering
MAX_FOCAL_PX = 1e6
MAX_DISTORTION = 1e3
MAX_DISTANCE_M = 1e4
# OpenCV's YAML parser recurses per [ or { and crashes the process (segfault, measured at 50000
# levels); SIMLAN's files nest 1 deep
MAX_FLOW_DEPTH = 32
MATRIX_TYPES = ("d", "f", "i", "u", "c", "s", "w")  # OpenCV's element type letters


@dataclass(frozen=True)
class Calibration:
    """A loaded camera and what did not agree in its files."""

    camera: CameraModel
    issues: tuple[str, ...]


def _read_storage(path: Path) -> cv2.FileStorage:
    if not path.is_file():
        raise CalibrationError(
            "calibration file missing",
            str(path),
            "no such file",
            "check the camera id in cameras.ids and cameras.calibration_dir",
        )
    if path.stat().st_size > MAX_CALIBRATION_BYTES:
        raise CalibrationError(
            "calibration file too large",
            str(path),
            f"over {MAX_CALIBRATION_BYTES} bytes",
            "point to SIMLAN's YAML files",
        )
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise CalibrationError(
            "calibration file unreadable",
            str(path),
            f"not UTF-8 text ({err.reason})",
            "point to an OpenCV FileStorage YAML file",
        ) from err
    depth = _flow_depth(text)
    if depth > MAX_FLOW_DEPTH:
        raise CalibrationError(
            "calibration file unreadable",
            str(path),
            f"brackets nested {depth} deep (more than {MAX_FLOW_DEPTH}; OpenCV's parser would crash)",
            "point to SIMLAN's calibration YAML",
        )
    if not text.lstrip().startswith("%YAML"):
        raise CalibrationError(
            "calibration file unreadable",
            str(path),
            "not an OpenCV FileStorage YAML file (no %YAML header)",
            "point to SIMLAN's calibration YAML",
        )
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as err:
        # OpenCV 5's binding reports some parse errors as SystemError with the cv2.error as cause
        cause = err.__cause__ if isinstance(err, SystemError) and err.__cause__ is not None else err
        msg = str(cause).strip().splitlines()[-1] if str(cause).strip() else "parse error"
        raise CalibrationError(
            "calibration file unreadable",
            str(path),
            f"OpenCV cannot parse it ({msg})",
            "fix the YAML or restore the original file",
        ) from err
    if not fs.isOpened():
        raise CalibrationError(
            "calibration file unreadable",
            str(path),
            "OpenCV cannot open it",
            "fix the YAML or restore the original file",
        )
    return fs


def _flow_depth(text: str) -> int:
    """Deepest nesting of [ and { in ``text`` (YAML flow collections)."""
    depth = deepest = 0
    for ch in re.sub(r"[^\[\]{}]", "", text):
        depth = depth + 1 if ch in "[{" else max(0, depth - 1)
        deepest = max(deepest, depth)
    return deepest


def _matrix_header_problem(node: cv2.FileNode, size: int) -> str:
    """Why an !!opencv-matrix node must not reach ``FileNode.mat()``, or "".

    OpenCV 5 corrupts the heap (the process aborts later, at some free) on a matrix with a
    negative ``cols`` (found by fuzzing), so the header is checked field by field first.
    """
    rows, cols, dt, data = (node.getNode(k) for k in ("rows", "cols", "dt", "data"))
    if not (rows.isInt() and cols.isInt() and dt.isString() and data.isSeq()):
        return "not an !!opencv-matrix with rows, cols, dt and data"
    r, c = rows.real(), cols.real()
    if not (1 <= r <= 64 and 1 <= c <= 64) or r * c != size:
        return f"rows x cols is {r:g} x {c:g}, expected {size} values"
    if dt.string() not in MATRIX_TYPES:
        return f"dt {dt.string()!r} is not one of {', '.join(MATRIX_TYPES)}"
    if data.size() != size:
        return f"data has {data.size()} values, expected {size}"
    return ""


def _matrix(fs: cv2.FileStorage, key: str, shape: tuple[int, ...], path: Path) -> np.ndarray:
    try:
        node = fs.getNode(key)
        problem = (
            "" if node.empty() or not node.isMap() else _matrix_header_problem(node, int(np.prod(shape)))
        )
        if problem:
            raise CalibrationError(
                f"calibration key '{key}' has the wrong shape",
                str(path),
                problem,
                "fix the matrix: rows, cols, dt and as many data values as rows x cols",
            )
        mat = None if node.empty() or not node.isMap() else node.mat()
    except (cv2.error, SystemError):
        mat = None
    if mat is None:
        raise CalibrationError(
            f"calibration key '{key}' missing",
            str(path),
            "the file has no such matrix",
            f"add '{key}' as an !!opencv-matrix",
        )
    mat = np.asarray(mat, dtype=np.float64)
    if mat.size != int(np.prod(shape)):
        raise CalibrationError(
            f"calibration key '{key}' has the wrong shape",
            str(path),
            f"got {mat.shape}, expected {shape}",
            "fix the rows/cols of the matrix",
        )
    mat = mat.reshape(shape)
    if not np.all(np.isfinite(mat)):
        raise CalibrationError(
            f"calibration key '{key}' is not finite",
            str(path),
            "NaN or inf inside",
            "restore the original values",
        )
    return mat


def load_calibration(camera_id: str | int, directory: Path | str | None = None) -> Calibration:
    """Load camera ``camera_id`` at its native resolution and report inconsistent fields.

    Raises:
        CalibrationError: a file is missing, unreadable, lacks a key, or has invalid values.
    """
    cam = str(camera_id)
    root = Path(directory) if directory else CALIBRATION_DIR
    ipath, epath = root / "intrinsic" / f"{cam}.yaml", root / "extrinsic" / f"{cam}.yaml"
    fs = _read_storage(ipath)
    K = _matrix(fs, "K", (3, 3), ipath)
    D = _matrix(fs, "D", (5,), ipath)
    shape = _matrix(fs, "image_shape", (3,), ipath)
    fs.release()
    fs = _read_storage(epath)
    R = _matrix(fs, "rot_mat", (3, 3), epath)
    t = _matrix(fs, "t_vec", (3,), epath)
    P_file = _matrix(fs, "camera_matrix_p", (3, 4), epath)
    pos_file = _matrix(fs, "position", (3,), epath)
    fs.release()

    height, width = round(shape[0]), round(shape[1])
    if not (0 < width <= 100_000 and 0 < height <= 100_000) or shape[0] != height or shape[1] != width:
        raise CalibrationError(
            "calibration image_shape invalid",
            str(ipath),
            f"got {shape.tolist()}",
            "use [rows, cols, channels], e.g. [2160, 3840, 3]",
        )
    if not (
        K[0, 0] > 0 and K[1, 1] > 0 and K[2, 2] == 1.0 and K[1, 0] == 0 and K[2, 0] == 0 and K[2, 1] == 0
    ):
        raise CalibrationError(
            "calibration K invalid",
            str(ipath),
            f"not an upper-triangular camera matrix with fx, fy > 0 and K[2,2] = 1: {K.tolist()}",
            "restore the calibrated K",
        )
    if not (K[0, 0] <= MAX_FOCAL_PX and K[1, 1] <= MAX_FOCAL_PX and abs(K[0, 1]) <= MAX_FOCAL_PX) or not (
        -width <= K[0, 2] <= 2 * width and -height <= K[1, 2] <= 2 * height
    ):
        raise CalibrationError(
            "calibration K implausible",
            str(ipath),
            f"focal lengths must be within (0, {MAX_FOCAL_PX:g}] px and the principal point near the "
            f"{width}x{height} image: {K.tolist()}",
            "restore the calibrated K",
        )
    if np.abs(D).max() > MAX_DISTORTION:
        raise CalibrationError(
            "calibration D implausible",
            str(ipath),
            f"distortion coefficients beyond +-{MAX_DISTORTION:g}: {D.tolist()}",
            "restore the calibrated D (k1 k2 p1 p2 k3)",
        )
    if np.abs(t).max() > MAX_DISTANCE_M:
        raise CalibrationError(
            "calibration t_vec implausible",
            str(epath),
            f"the camera would be over {MAX_DISTANCE_M:g} m from the origin: {t.tolist()}",
            "restore the calibrated t_vec (metres)",
        )
    if not is_rotation_matrix(R, tol=ROTATION_TOL):
        err = float(np.abs(R.T @ R - np.eye(3)).max())
        raise CalibrationError(
            "calibration rot_mat is not a rotation",
            str(epath),
            f"R^T R deviates from I by {err:.2e} (det {np.linalg.det(R):.4f})",
            "restore an orthonormal rot_mat with det +1",
        )

    camera = CameraModel(cam, width, height, K, D, Transform(R, t))
    issues: list[str] = []
    P = camera.projection_matrix
    if not np.allclose(P_file, P, rtol=P_REL_TOL, atol=P_REL_TOL * np.abs(P).max()):
        issues.append(f"{epath.name}: {_explain_p(P_file, K, R, t)}")
    pos_err = float(np.linalg.norm(pos_file - camera.position))
    if pos_err > POSITION_TOL_M:
        issues.append(f"{epath.name}: position disagrees with -R^T t by {pos_err:.3f} m")
    return Calibration(camera, tuple(issues))


def _explain_p(P_file: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> str:
    """Say how a camera_matrix_p that is not K[R|t] relates to the camera, if it does."""
    K_other = P_file[:, :3] @ R.T
    scale = np.abs(K_other).max()
    lower = np.array([K_other[1, 0], K_other[2, 0], K_other[2, 1]])
    is_camera_matrix = (
        np.all(np.abs(lower) < 1e-6 * scale)
        and abs(K_other[2, 2] - 1.0) < 1e-6
        and np.allclose(K_other @ t, P_file[:, 3], rtol=1e-6, atol=1e-6 * np.abs(P_file[:, 3]).max())
    )
    if is_camera_matrix:
        return (
            "camera_matrix_p disagrees with K[R|t]: it is K'[R|t] with another camera matrix "
            f"(fx'={K_other[0, 0]:.1f} vs fx={K[0, 0]:.1f}, cx'={K_other[0, 2]:.1f} vs cx={K[0, 2]:.1f}, "
            "an ideal undistorted camera matrix); using K"
        )
    return "camera_matrix_p disagrees with K[R|t] and is no camera matrix times [R|t] (stale copy); using K, R, t"


def available_camera_ids(directory: Path | str | None = None) -> list[str]:
    """Return the ids that have both an intrinsic and an extrinsic file, sorted numerically."""
    root = Path(directory) if directory else CALIBRATION_DIR
    intr = {p.stem for p in (root / "intrinsic").glob("*.yaml")}
    extr = {p.stem for p in (root / "extrinsic").glob("*.yaml")}
    return sorted(intr & extr, key=lambda s: (len(s), s))
