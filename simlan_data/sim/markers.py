"""ArUco markers as coloured URDF geometry (no textures: see world/models.py for why).

The marker is a flat grid of non-overlapping boxes (black and white cells merged into row runs,
plus a white quiet zone one cell wide), so that a 16-bit depth buffer cannot make cells flicker.
In the marker frame x runs along the marker image's columns, y against its rows, z out of the
face; the face lies at z = 0. OpenCV's corner order (top-left, top-right, bottom-right,
bottom-left) is therefore (-s/2, +s/2), (+s/2, +s/2), (+s/2, -s/2), (-s/2, -s/2).
"""

from __future__ import annotations

import cv2
import numpy as np

ARUCO_DICTIONARY = cv2.aruco.DICT_5X5_1000
ARUCO_DICTIONARY_NAME = "DICT_5X5_1000"
MARKER_SIZE_M = 0.5
MARKER_BITS = 5
MARKER_THICKNESS_M = 0.025
_MAX_VISUALS_PER_LINK = 16

_WHITE = "0.97 0.97 0.97 1"
_BLACK = "0.02 0.02 0.02 1"


def marker_cells(marker_id: int) -> np.ndarray:
    """Return the (bits+2) x (bits+2) cell grid of ``marker_id``: True where the cell is white."""
    dictionary = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY)
    n = MARKER_BITS + 2
    image = cv2.aruco.generateImageMarker(dictionary, int(marker_id), n)
    return image > 127


def marker_object_points(size_m: float = MARKER_SIZE_M) -> np.ndarray:
    """Marker corners in the marker frame, in OpenCV's detection order (4, 3)."""
    h = size_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def _boxes(marker_id: int, size_m: float) -> list[tuple[float, float, float, float, bool]]:
    """Row runs of equal cells plus the quiet zone: (x, y, size_x, size_y, white)."""
    cells = marker_cells(marker_id)
    n = cells.shape[0]
    cell = size_m / n
    out: list[tuple[float, float, float, float, bool]] = []
    for r in range(n):
        c = 0
        while c < n:
            end = c
            while end + 1 < n and cells[r, end + 1] == cells[r, c]:
                end += 1
            x = (0.5 * (c + end) - (n - 1) / 2.0) * cell
            y = ((n - 1) / 2.0 - r) * cell
            out.append((x, y, (end - c + 1) * cell, cell, bool(cells[r, c])))
            c = end + 1
    outer = size_m + 2 * cell
    out += [
        (0.0, (size_m + cell) / 2, outer, cell, True),
        (0.0, -(size_m + cell) / 2, outer, cell, True),
        ((size_m + cell) / 2, 0.0, cell, size_m, True),
        (-(size_m + cell) / 2, 0.0, cell, size_m, True),
    ]
    return out


def marker_urdf(
    marker_id: int,
    *,
    parent: str = "base_link",
    xyz: tuple[float, float, float] = (-0.8, 0.0, 1.30),
    size_m: float = MARKER_SIZE_M,
) -> str:
    """URDF links and fixed joints drawing marker ``marker_id`` with its face at ``xyz`` of ``parent``.

    PyBullet's EGL renderer draws one colour per link and at most 16 shapes merge well, so cells
    are split into links of one colour with at most 16 boxes each. The first link is named
    ``aruco_marker`` and its frame is the marker frame.
    """
    boxes = _boxes(marker_id, size_m)
    t = MARKER_THICKNESS_M
    chunks: list[tuple[bool, list[tuple[float, float, float, float, bool]]]] = []
    for white in (True, False):
        same = [b for b in boxes if b[4] == white]
        chunks += [
            (white, same[i : i + _MAX_VISUALS_PER_LINK]) for i in range(0, len(same), _MAX_VISUALS_PER_LINK)
        ]
    parts: list[str] = []
    x0, y0, z0 = xyz
    for i, (white, chunk) in enumerate(chunks):
        name = "aruco_marker" if i == 0 else f"aruco_marker_cells_{i}"
        colour = _WHITE if white else _BLACK
        visuals = "".join(
            f'<visual><origin xyz="{x:.6f} {y:.6f} {-t / 2:.6f}"/><geometry><box size="{sx:.6f} {sy:.6f} {t:.6f}"/></geometry>'
            f'<material name="marker_{"white" if white else "black"}"><color rgba="{colour}"/></material></visual>'
            for x, y, sx, sy, _ in chunk
        )
        parts.append(
            f'<link name="{name}"><inertial><mass value="0.01"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>{visuals}</link>'
            f'<joint name="{name}_joint" type="fixed"><parent link="{parent}"/><child link="{name}"/>'
            f'<origin xyz="{x0:.6f} {y0:.6f} {z0:.6f}"/></joint>'
        )
    return "\n".join(parts)
