"""Triangle meshes of primitives, merged and written as Wavefront OBJ.

The static warehouse is drawn as one mesh per (semantic class, colour): PyBullet's renderer pays a
fixed cost per visual shape on every camera image, which with thousands of shelf and floor parts
dominated small-region renders (12 ms per call against 2 ms with merged meshes).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from simlan_data.geometry.rotations import FloatArray
from simlan_data.geometry.transforms import Transform

_BOX_FACES = [
    # normal, then four corners as signs of the half extents (counter-clockwise seen from outside)
    ((1, 0, 0), [(1, -1, -1), (1, 1, -1), (1, 1, 1), (1, -1, 1)]),
    ((-1, 0, 0), [(-1, 1, -1), (-1, -1, -1), (-1, -1, 1), (-1, 1, 1)]),
    ((0, 1, 0), [(1, 1, -1), (-1, 1, -1), (-1, 1, 1), (1, 1, 1)]),
    ((0, -1, 0), [(-1, -1, -1), (1, -1, -1), (1, -1, 1), (-1, -1, 1)]),
    ((0, 0, 1), [(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]),
    ((0, 0, -1), [(-1, 1, -1), (1, 1, -1), (1, -1, -1), (-1, -1, -1)]),
]
CYLINDER_SEGMENTS = 16


class MeshBuilder:
    """Accumulates triangles (positions + per-vertex normals) in world coordinates."""

    def __init__(self) -> None:
        self._vertices: list[FloatArray] = []
        self._normals: list[FloatArray] = []
        self._faces: list[np.ndarray] = []
        self._count = 0

    @property
    def empty(self) -> bool:
        return self._count == 0

    def _add(self, verts: FloatArray, normals: FloatArray, faces: np.ndarray, pose: Transform) -> None:
        self._vertices.append(pose.apply(verts))
        self._normals.append(normals @ pose.rotation.T)
        self._faces.append(faces + self._count)
        self._count += len(verts)

    def add_box(self, half_extents: Iterable[float], pose: Transform) -> None:
        h = np.asarray(list(half_extents), dtype=float)
        verts: list[FloatArray] = []
        normals: list[Any] = []
        faces: list[tuple[int, int, int]] = []
        for normal, corners in _BOX_FACES:
            base = len(verts)
            for c in corners:
                verts.append(np.asarray(c, dtype=float) * h)
                normals.append(normal)
            faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
        self._add(np.array(verts), np.array(normals, dtype=float), np.array(faces), pose)

    def add_cylinder(self, radius: float, length: float, pose: Transform) -> None:
        n = CYLINDER_SEGMENTS
        ang = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        ring = np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], axis=1)
        hz = length / 2.0
        side_v = np.concatenate([ring * radius + [0, 0, -hz], ring * radius + [0, 0, hz]])
        side_n = np.concatenate([ring, ring])
        side_f = np.array(
            [f for i in range(n) for f in ((i, (i + 1) % n, n + (i + 1) % n), (i, n + (i + 1) % n, n + i))]
        )
        self._add(side_v, side_n, side_f, pose)
        for sign in (1.0, -1.0):
            cap_v = np.concatenate([[[0.0, 0.0, sign * hz]], ring * radius + [0, 0, sign * hz]])
            cap_n = np.tile([0.0, 0.0, sign], (n + 1, 1))
            cap_f = np.array(
                [(0, 1 + i, 1 + (i + 1) % n) if sign > 0 else (0, 1 + (i + 1) % n, 1 + i) for i in range(n)]
            )
            self._add(cap_v, cap_n, cap_f, pose)

    def write_obj(self, path: Path) -> Path:
        """Write the mesh as OBJ (positions, normals, triangles); deterministic text."""
        v = np.concatenate(self._vertices)
        vn = np.concatenate(self._normals)
        f = np.concatenate(self._faces) + 1
        lines = ["# simlan_data merged static geometry"]
        lines += [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in v]
        lines += [f"vn {x:.5f} {y:.5f} {z:.5f}" for x, y, z in vn]
        lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in f]
        path.write_text("\n".join(lines) + "\n")
        return path
