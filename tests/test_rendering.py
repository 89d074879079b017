"""Rendering geometry on a real PyBullet world: pixels where the camera model says, layered == full."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from simlan_data._pybullet import pb
from simlan_data.geometry.calibration import load_calibration
from simlan_data.sim.agents import AGENT_TYPES, DiffDriveAgent
from simlan_data.sim.pybullet_client import connect
from simlan_data.sim.rendering import CameraRenderer, LabelTable, merge_rects
from simlan_data.world.builder import build_world, create_body
from simlan_data.world.layout import load_layout
from simlan_data.world.models import Part

SQUARE_LABEL0 = 100


def _scene(backend: str, camera_id: str = "163", width: int = 960, height: int = 540):
    """Floor, 30 small coloured squares at known places seen by the camera, a label per square."""
    client = connect(backend)
    with tempfile.TemporaryDirectory() as tmp:
        world = build_world(client.id, load_layout("warehouse_layout.csv", "empty"), {}, mesh_dir=Path(tmp))
    labels = LabelTable()
    for body, label in world.labels.items():
        labels.set(body, label)
    cam = load_calibration(camera_id).camera.scaled(width, height)
    rng = np.random.default_rng(7)
    uv = rng.uniform([0.12 * width, 0.12 * height], [0.88 * width, 0.88 * height], size=(30, 2))
    centres, ok = cam.intersect_plane_z(uv, 0.01)
    squares = []
    for i, c in enumerate(centres[ok]):
        body = create_body(
            client.id,
            [Part("box", (0.06, 0.06, 0.005), rgba=(0.9, 0.1, 0.1, 1.0), collide=False)],
            position=c - [0, 0, 0.005],
            orientation=[0, 0, 0, 1],
            mass_kg=0.0,
        )
        labels.set(body, SQUARE_LABEL0 + i)
        squares.append(c)
    return client, cam, labels, np.array(squares)


def _centroid_errors(labels_img: np.ndarray, cam, squares: np.ndarray, *, distort: bool) -> np.ndarray:
    uv, _ = cam.project(squares, distort=distort)
    errs = []
    for i, expected in enumerate(uv):
        ys, xs = np.nonzero(labels_img == SQUARE_LABEL0 + i)
        if len(xs) < 12:
            continue
        errs.append(np.hypot(xs.mean() - expected[0], ys.mean() - expected[1]))
    return np.array(errs)


@pytest.mark.parametrize("backend", ["egl", "tiny"])
def test_known_points_land_within_one_pixel(backend: str) -> None:
    size = (960, 540) if backend == "egl" else (480, 270)
    client, cam, labels, squares = _scene(backend, width=size[0], height=size[1])
    try:
        for distort in (False, True):
            renderer = CameraRenderer(client, cam, labels, distort=distort, layered=False)
            out = renderer.render()
            errs = _centroid_errors(out.labels, cam, squares, distort=distort)
            assert len(errs) >= 15, f"only {len(errs)} squares seen"
            assert errs.max() < 1.0, (backend, distort, errs.max())
            assert np.median(errs) < 0.35
    finally:
        client.disconnect()


def test_distorted_image_masks_pixels_without_a_ray() -> None:
    client, cam, labels, _ = _scene("egl")
    try:
        renderer = CameraRenderer(client, cam, labels, distort=True, layered=False)
        out = renderer.render()
        invalid = ~renderer.valid_mask
        assert invalid[0, 0] and invalid[-1, -1] and not invalid[270, 480]
        assert (
            np.all(out.rgb[invalid] == 0)
            and np.all(out.depth_m[invalid] == 0)
            and np.all(out.labels[invalid] == 0)
        )
        # everything valid sees the floor (or a square) at a plausible depth
        d = out.depth_m[renderer.valid_mask]
        assert d.min() > 5.0 and d.max() < 60.0
    finally:
        client.disconnect()


def test_depth_is_metric_z_depth() -> None:
    client, cam, labels, squares = _scene("egl")
    try:
        out = CameraRenderer(client, cam, labels, distort=True, layered=False).render()
        uv, _ = cam.project(squares)
        z_expected = cam.world_to_camera(squares)[:, 2]
        got = np.array([out.depth_m[round(v), round(u)] for u, v in uv])
        # 16-bit depth buffer: the step at ~8 m with near = 1 m is about 1 mm
        np.testing.assert_allclose(got, z_expected, atol=0.01)
    finally:
        client.disconnect()


def test_layered_render_equals_full_render_with_a_moving_agent() -> None:
    client = connect("egl")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            world = build_world(
                client.id, load_layout("warehouse_layout.csv", "default"), {}, mesh_dir=Path(tmp)
            )
        labels = LabelTable()
        for body, label in world.labels.items():
            labels.set(body, label)
        cam = load_calibration("162").camera.scaled(960, 540)
        layered = CameraRenderer(client, cam, labels, distort=True, layered=True)
        full = CameraRenderer(client, cam, labels, distort=True, layered=False)
        layered.render_static()
        agent = DiffDriveAgent(
            client.id, "robot_agent_3", AGENT_TYPES["pallet_truck"], pose=[-8.0, 0.4, 0.0], marker_id=3
        )
        labels.set(agent.body, agent.label)
        agent.apply_command(1.2, 0.3)
        seen = 0
        for _ in range(8):
            for _ in range(48):
                pb.stepSimulation(physicsClientId=client.id)
            a = layered.render(agent.aabbs())
            b = full.render()
            seen += int((b.labels == agent.label).sum() > 100)
            assert np.mean(a.labels == b.labels) >= 0.995
            valid = layered.valid_mask
            assert np.mean(np.abs(a.depth_m[valid] - b.depth_m[valid]) <= 0.01) >= 0.995
            assert np.mean(np.all(a.rgb == b.rgb, axis=-1)) >= 0.99
        assert seen >= 6, "the agent should be in view while the renders are compared"
    finally:
        client.disconnect()


def test_merge_rects() -> None:
    assert merge_rects([(0, 0, 10, 10), (5, 5, 20, 20), (100, 100, 110, 110)]) == [
        (0, 0, 20, 20),
        (100, 100, 110, 110),
    ]
    # close regions are cheaper rendered as one
    assert merge_rects([(0, 0, 10, 10), (12, 0, 20, 10)], slack_px=100) == [(0, 0, 20, 10)]
    assert merge_rects([(0, 0, 10, 10), (200, 200, 210, 210)], slack_px=100) == [
        (0, 0, 10, 10),
        (200, 200, 210, 210),
    ]
