"""Rendering geometry on a real PyBullet world: pixels where the camera model says, layered == full."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from simlan_data.geometry.calibration import load_calibration
from simlan_data.sim.agents import AGENT_TYPES, spawn_agent
from simlan_data.sim.dynamic_layer import MovedAgents, StaticMeshes
from simlan_data.sim.pybullet_client import connect
from simlan_data.sim.rendering import CameraRenderer, LabelTable, merge_rects
from simlan_data.world._pybullet import pb
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


def _equal_fractions(a, b, valid: np.ndarray) -> tuple[float, float, float]:
    """Share of pixels with equal labels, depth within 1 cm (valid pixels), equal colour."""
    labels = float(np.mean(a.labels == b.labels))
    depth = float(np.mean(np.abs(a.depth_m[valid] - b.depth_m[valid]) <= 0.01))
    rgb = float(np.mean(np.all(a.rgb == b.rgb, axis=-1)))
    return labels, depth, rgb


def test_layered_render_equals_full_render_with_moving_agents() -> None:
    """Four agents drive (one stops for a while, then goes on) under two cameras: the layered
    renderer (static layer + region renders without the warehouse meshes, composited by depth,
    only moved agents redrawn) matches the plain full render of the whole scene at every frame."""
    client = connect("egl")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            world = build_world(
                client.id, load_layout("warehouse_layout.csv", "default"), {}, mesh_dir=Path(tmp)
            )
        labels = LabelTable()
        for body, label in world.labels.items():
            labels.set(body, label)
        cams = [load_calibration(c).camera.scaled(960, 540) for c in ("162", "163")]
        layered = [CameraRenderer(client, c, labels, distort=True, layered=True) for c in cams]
        full = [CameraRenderer(client, c, labels, distort=True, layered=False) for c in cams]
        for r in layered:
            r.render_static()
        centre, _ = cams[0].intersect_plane_z([[480.0, 270.0]], 0.0)
        x0, y0 = float(centre[0, 0]), float(centre[0, 1])
        specs = [  # type, pose, command (v, w)
            ("pallet_truck", [x0 - 3.0, y0 + 1.2, 0.0], (1.2, 0.3)),
            ("forklift", [x0 + 3.0, y0 - 1.0, np.pi], (0.9, -0.2)),
            ("jackal", [x0, y0 - 2.5, 0.8], (0.6, 0.5)),
            ("pallet_truck", [x0 + 1.0, y0 + 2.8, -0.5], (0.8, 0.0)),
        ]
        agents = []
        for n, (kind, pose, cmd) in enumerate(specs, start=1):
            agent = spawn_agent(client.id, f"robot_agent_{n}", AGENT_TYPES[kind], pose=pose, marker_id=n)
            labels.set(agent.body, agent.label)
            agent.apply_command(*cmd)
            agents.append(agent)
        meshes = StaticMeshes(client.id, world, labels)
        meshes.remove()
        moving = MovedAgents(agents)
        seen = 0
        for frame in range(8):
            if frame == 3:
                agents[0].apply_command(0.0, 0.0)  # stops: its region is no longer redrawn
            if frame == 6:
                agents[0].apply_command(1.0, -0.4)  # and drives on: no ghost where it stood
            for _ in range(48):
                pb.stepSimulation(physicsClientId=client.id)
            moved = moving.boxes()
            for lr, fr in zip(layered, full):
                a = lr.render(moved)
                with meshes.shown():
                    b = fr.render()
                seen += sum(int((b.labels == ag.label).sum() > 100) for ag in agents)
                same_labels, same_depth, same_rgb = _equal_fractions(a, b, lr.valid_mask)
                assert same_labels >= 0.995, (frame, lr.camera.camera_id, same_labels)
                assert same_depth >= 0.995, (frame, lr.camera.camera_id, same_depth)
                assert same_rgb >= 0.99, (frame, lr.camera.camera_id, same_rgb)
        assert seen >= 30, f"agents should be in view while the renders are compared ({seen})"
    finally:
        client.disconnect()


def test_layered_renderer_skips_what_did_not_move_and_streams_not_asked_for() -> None:
    client, cam, labels, _ = _scene("egl")
    try:
        layered = CameraRenderer(client, cam, labels, layered=True, streams=["rgb"])
        layered.render_static()
        centre, _ = cam.intersect_plane_z([[480.0, 270.0]], 0.0)
        agent = spawn_agent(
            client.id,
            "robot_agent_1",
            AGENT_TYPES["jackal"],
            pose=[float(centre[0, 0]), float(centre[0, 1]), 0.0],
            marker_id=1,
        )
        labels.set(agent.body, agent.label)
        moving = MovedAgents([agent])
        first = layered.render(moving.boxes())
        assert first.depth_m is None and first.labels is None and first.rgb is not None
        for _ in range(10):  # settles on its wheels
            pb.stepSimulation(physicsClientId=client.id)
        layered.render(moving.boxes())
        calls = layered.regions_rendered
        for _ in range(3):
            pb.stepSimulation(physicsClientId=client.id)
            again = layered.render(moving.boxes())
        assert moving.boxes() == []
        assert not again.changed
        assert layered.regions_rendered == calls  # nothing drawn again
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


def test_static_layer_follows_a_pushed_object_and_the_meshes_go_away_again() -> None:
    """A world object moved (a robot pushed it): the cameras that see it render their static layer
    again with the warehouse meshes back for that moment, then the meshes are removed again; the
    layered image still equals the full render."""
    from conftest import compose_config
    from simlan_data.config.validation import to_config
    from simlan_data.sim.scene import Scene, load_inputs

    cfg = to_config(compose_config("cameras=single", "world.settle_s=0.5", "progress=false"))
    scene = Scene.build(cfg, load_inputs(cfg))
    try:
        (renderer,) = scene.renderers
        assert scene.meshes is not None and not scene.meshes.present
        cam, cid = renderer.camera, scene.client.id
        assert scene.world.movable, "the default warehouse has movable boxes and pallets"
        body = sorted(scene.world.movable)[0]
        assert renderer._static is not None and renderer._static[2] is not None
        before = renderer._static[2].copy()
        pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        centre, _ = cam.intersect_plane_z([[300.0, 200.0]], 0.0)  # beside the truck's aisle
        pb.resetBasePositionAndOrientation(
            body, [float(centre[0, 0]), float(centre[0, 1]), pos[2]], orn, physicsClientId=cid
        )
        assert scene.refresh_static_layers() == 1
        assert (renderer._static[2] != before).sum() > 50  # the object shows at its new place
        assert not scene.meshes.present
        layered = renderer.render(scene.moved_boxes())
        full = CameraRenderer(scene.client, cam, scene.labels, layered=False)
        with scene.meshes.shown():
            reference = full.render()
        same_labels, same_depth, same_rgb = _equal_fractions(layered, reference, renderer.valid_mask)
        assert same_labels >= 0.995 and same_depth >= 0.995 and same_rgb >= 0.99
        assert not scene.meshes.present
    finally:
        scene.close()


def test_instance_stream_gives_the_same_labels_and_ids_from_one_segmentation_pass() -> None:
    """With ``instance`` the renderer keeps body ids in its layers and looks up both class labels
    and instance ids: the labels equal a semantic-only renderer's, the ids cover the agent's pixels
    exactly, and an unchanged frame hands out the same instance image again."""
    client, cam, labels, _ = _scene("egl")
    try:
        ids = LabelTable(np.uint16)
        plain = CameraRenderer(client, cam, labels, streams=["rgb", "semantic"])
        both = CameraRenderer(client, cam, labels, streams=["rgb", "semantic", "instance"], instances=ids)
        for r in (plain, both):
            r.render_static()
        centre, _ = cam.intersect_plane_z([[480.0, 270.0]], 0.0)
        pose = [float(centre[0, 0]), float(centre[0, 1]), 0.3]
        agent = spawn_agent(client.id, "robot_agent_1", AGENT_TYPES["jackal"], pose=pose, marker_id=1)
        labels.set(agent.body, agent.label)
        ids.set(agent.body, 7)
        boxes = [MovedAgents([agent]).boxes() for _ in range(2)]
        a, b = plain.render(boxes[0]), both.render(boxes[1])
        assert a.instances is None and b.instances is not None and b.instances.dtype == np.uint16
        assert np.array_equal(a.labels, b.labels)
        assert np.array_equal(b.instances == 7, b.labels == agent.label)
        assert (b.instances == 7).sum() > 500 and set(np.unique(b.instances)) == {0, 7}
        again = both.render([])
        assert not again.changed and again.instances is b.instances
    finally:
        client.disconnect()
