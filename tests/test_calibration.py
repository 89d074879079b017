"""SIMLAN calibration files: loading with OpenCV, consistency checks, clear errors."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from simlan_data.constants import CALIBRATION_DIR
from simlan_data.errors import CalibrationError
from simlan_data.geometry.calibration import available_camera_ids, load_calibration
from simlan_data.geometry.rotations import is_rotation_matrix

ALL_IDS = [
    str(i) for i in [*range(160, 172), *range(264, 269), *range(364, 369), *range(464, 469), *range(500, 504)]
]


def test_all_31_simlan_files_are_shipped_and_load() -> None:
    assert available_camera_ids() == ALL_IDS
    for cid in ALL_IDS:
        cal = load_calibration(cid)
        cam = cal.camera
        assert (cam.width, cam.height) == (3840, 2160)
        assert is_rotation_matrix(cam.camera_from_world.rotation, tol=1e-4)
        # the loader reads exactly what OpenCV reads
        fs = cv2.FileStorage(str(CALIBRATION_DIR / "intrinsic" / f"{cid}.yaml"), cv2.FILE_STORAGE_READ)
        np.testing.assert_array_equal(cam.K, fs.getNode("K").mat())
        np.testing.assert_array_equal(cam.D, fs.getNode("D").mat().ravel())


def test_positions_agree_with_minus_rt_t_except_the_stale_humanoid_cameras() -> None:
    for cid in ALL_IDS:
        issues = load_calibration(cid).issues
        stale_position = any("position disagrees" in i for i in issues)
        assert stale_position == cid.startswith("50"), (cid, issues)
    # the derived centres of 500-503 are the ring SIMLAN describes: 2 m high, 3 m around (5.5, -10)
    for cid in ("500", "501", "502", "503"):
        c = load_calibration(cid).camera.position
        assert c[2] == pytest.approx(2.0, abs=1e-6)
        assert np.hypot(c[0] - 5.5, c[1] + 10.0) == pytest.approx(3.0, abs=1e-6)


def test_camera_matrix_p_is_explained() -> None:
    # 160-171: P = K'[R|t] with an ideal camera matrix (principal point at the image centre)
    issues = load_calibration("160").issues
    assert len(issues) == 1
    assert "K'[R|t]" in issues[0] and "cx'=1919.5" in issues[0]
    # 500-503: stale
    assert any("stale" in i for i in load_calibration("501").issues)


def _copy_camera(tmp_path: Path, cid: str = "163") -> Path:
    for kind in ("intrinsic", "extrinsic"):
        (tmp_path / kind).mkdir(parents=True, exist_ok=True)
        shutil.copy(CALIBRATION_DIR / kind / f"{cid}.yaml", tmp_path / kind / f"{cid}.yaml")
    return tmp_path


def test_missing_file_is_named(tmp_path: Path) -> None:
    root = _copy_camera(tmp_path)
    (root / "extrinsic" / "163.yaml").unlink()
    with pytest.raises(CalibrationError, match=r"calibration file missing in .*extrinsic/163.yaml"):
        load_calibration("163", root)


def test_missing_key_is_named(tmp_path: Path) -> None:
    root = _copy_camera(tmp_path)
    path = root / "intrinsic" / "163.yaml"
    text = path.read_text().replace("D: !!opencv-matrix", "E: !!opencv-matrix")
    path.write_text(text)
    with pytest.raises(CalibrationError, match=r"calibration key 'D' missing in .*163.yaml"):
        load_calibration("163", root)


def test_non_orthonormal_rotation_is_refused(tmp_path: Path) -> None:
    root = _copy_camera(tmp_path)
    path = root / "extrinsic" / "163.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    R, t, P, pos = (fs.getNode(k).mat() for k in ("rot_mat", "t_vec", "camera_matrix_p", "position"))
    fs.release()
    out = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in (("rot_mat", R * 1.01), ("t_vec", t), ("camera_matrix_p", P), ("position", pos)):
        out.write(key, value)
    out.release()
    with pytest.raises(CalibrationError, match=r"rot_mat is not a rotation"):
        load_calibration("163", root)


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (b"\x00\x01garbage", r"not UTF-8|no %YAML header"),
        (b"K: [1, 2, 3]\n", r"no %YAML header"),
        (
            b"%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [1, 2]\n",
            r"unreadable|missing|wrong shape",
        ),
    ],
)
def test_garbage_files_get_one_clear_error(tmp_path: Path, content: bytes, match: str) -> None:
    root = _copy_camera(tmp_path)
    (root / "intrinsic" / "163.yaml").write_bytes(content)
    with pytest.raises(CalibrationError, match=match):
        load_calibration("163", root)
