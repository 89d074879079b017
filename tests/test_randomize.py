"""Domain randomization (issue 24 item 2, ``randomize``): real PyBullet scenes and real runs.

Scenes are built the way a run builds them (``Scene.build``) and inspected in PyBullet; runs go
through the public CLI and are read back with the independent mcap + mcap_ros2 decoder. The
multi-robot scenario (robot_agent_2 moved into the cameras' view) shows every robot's marker.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from omegaconf import OmegaConf
from shapely.geometry import LineString, box

from conftest import compose_config, made_once, run_cli
from simlan_data.algorithms.planner import GridPlanner
from simlan_data.config.randomize import (
    AgentPaintConfig,
    DistractorsConfig,
    LightConfig,
    MaterialsConfig,
    PlacementConfig,
    RandomizeConfig,
    TimeOfDayConfig,
)
from simlan_data.errors import ConfigError
from simlan_data.sim.randomize import Randomizer, gain_lut, in_patches, sun_direction
from simlan_data.sim.rendering import CameraImages
from simlan_data.sim.scene import Scene, load_cameras, load_inputs
from simlan_data.world._pybullet import pb
from simlan_data.world.labels import SEMANTIC_CLASSES

SCENE = (
    "scenario=multi_robot",
    "agents.robot_agent_2.pose=[12.0,-0.7,3.14159]",  # (at 24 m no camera sees its marker)
    "cameras.ids=[160,162,163,164]",  # the cameras that see the four robots' markers
    "cameras.width=480",
    "cameras.height=270",
)
ON = (*SCENE, "randomize=on", "seed=2")
MATERIALS = ("randomize.materials.floor=0.2", "randomize.materials.shelf=0.3")
EFFECTS = ("light", "time_of_day", "materials", "placement", "distractors", "agents")
FURNITURE = SEMANTIC_CLASSES["furniture"]


def _config(*overrides: str) -> Any:
    return OmegaConf.to_object(compose_config(*overrides))


def _scene_facts(*overrides: str) -> dict[str, Any]:
    """Build a scene as a run does, render every camera once and read back what PyBullet holds.

    (One scene at a time: PyBullet's EGL plug-in serves one client per process.)
    """
    # (render.layered=false: a layered scene removes the warehouse's merged meshes once the static
    # layers are drawn, after which PyBullet reports other bodies' visual data for some ids)
    cfg = _config(*overrides, "render.layered=false")
    inputs = load_inputs(cfg)
    scene = Scene.build(cfg, inputs)
    try:
        cid = scene.client.id
        images = [r.render(scene.agent_aabbs()) for r in scene.renderers]
        bodies = {name: body for body, name in scene.world.names.items()}
        drawn = scene.randomizer.drawn if scene.randomizer else {}
        distractors = {
            d["name"]: (
                pb.getBasePositionAndOrientation(bodies[d["name"]], physicsClientId=cid),
                pb.getAABB(bodies[d["name"]], -1, physicsClientId=cid),
                min(
                    (
                        p[8]
                        for a in scene.agents
                        for p in pb.getClosestPoints(bodies[d["name"]], a.body, 5.0, physicsClientId=cid)
                    ),
                    default=5.0,
                ),
            )
            for d in drawn.get("distractors", [])
        }
        agent_links = {}
        for a in scene.agents:
            names = {-1: "base"} | {
                j: pb.getJointInfo(a.body, j, physicsClientId=cid)[12].decode()
                for j in range(pb.getNumJoints(a.body, physicsClientId=cid))
            }
            agent_links[a.namespace] = [
                (names[s[1]], tuple(s[7])) for s in pb.getVisualShapeData(a.body, physicsClientId=cid)
            ]
        return {
            "cfg": cfg,
            "inputs": inputs,
            "images": images,
            "cameras": [r.camera for r in scene.renderers],
            "drawn": drawn,
            "record": scene.randomizer.record() if scene.randomizer else "",
            "distractors": distractors,
            "agent_links": agent_links,
        }
    finally:
        scene.close()


@pytest.fixture(scope="module")
def scenes() -> dict[str, dict[str, Any]]:
    return {
        "on": _scene_facts(*ON),
        "again": _scene_facts(*ON),
        "other_seed": _scene_facts(*SCENE, "randomize=on", "seed=3"),
        "off": _scene_facts(*SCENE, "seed=2"),
        "materials": _scene_facts(*SCENE, "seed=2", "randomize.materials.enabled=true", *MATERIALS),
        "paint": _scene_facts(
            *SCENE, "seed=2", "randomize.agents.enabled=true", "randomize.agents.hue_deg=180"
        ),
    }


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    short = (
        "duration_s=1",
        "progress=false",
        "cameras.ids=[162,163]",
        "cameras.width=480",
        "cameras.height=270",
    )
    disabled = ["randomize=on"] + [f"randomize.{e}.enabled=false" for e in EFFECTS]

    def make(root: Path) -> None:
        for name, extra in (
            ("on", (*ON, "duration_s=1", "progress=false", "cameras.streams=[rgb]")),
            ("default", short),
            ("disabled", (*short, *disabled)),
        ):
            proc = run_cli(*extra, f"hydra.run.dir={root / name}")
            assert proc.returncode == 0, proc.stderr

    root = made_once(tmp_path_factory, "randomize_runs", make)
    return {name: root / name for name in ("on", "default", "disabled")}


def _messages(run: Path) -> dict[str, list[tuple[bytes, Any]]]:
    """topic -> [(raw CDR, decoded)], read with the independent mcap + mcap_ros2 decoder."""
    out: dict[str, list[tuple[bytes, Any]]] = defaultdict(list)
    (bag,) = (run / "recording").glob("*.mcap")
    with bag.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            out[channel.topic].append((message.data, decoded))
    return out


# ---------------------------------------------------------------------------------- config
@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: LightConfig(intensity=-0.2), r"randomize\.light\.intensity=-0\.2.*use 0\.3"),
        (lambda: LightConfig(colour=1.0), r"randomize\.light\.colour=1\.0"),
        (lambda: TimeOfDayConfig(hours=[18.0, 7.0]), r"randomize\.time_of_day\.hours"),
        (lambda: TimeOfDayConfig(day_of_year=0), r"randomize\.time_of_day\.day_of_year=0"),
        (lambda: TimeOfDayConfig(latitude_deg=91.0), r"randomize\.time_of_day\.latitude_deg=91"),
        (lambda: TimeOfDayConfig(sun_strength=-1.0), r"randomize\.time_of_day\.sun_strength=-1"),
        (lambda: MaterialsConfig(floor=-0.1), r"randomize\.materials\.floor=-0\.1"),
        (lambda: MaterialsConfig(shelf=1.5), r"randomize\.materials\.shelf=1\.5"),
        (lambda: PlacementConfig(xy_m=-0.01), r"randomize\.placement\.xy_m=-0\.01"),
        (lambda: PlacementConfig(yaw_deg=90.0), r"randomize\.placement=.*at most 0\.5 m and 45 degrees"),
        (lambda: DistractorsConfig(count=-1), r"randomize\.distractors\.count=-1"),
        (lambda: DistractorsConfig(min_size_m=1.0, max_size_m=0.5), r"min_size_m <= max_size_m"),
        (lambda: DistractorsConfig(clearance_m=-1.0), r"randomize\.distractors\.clearance_m=-1"),
        (lambda: AgentPaintConfig(hue_deg=200.0), r"randomize\.agents\.hue_deg=200"),
        (lambda: AgentPaintConfig(value=-0.5), r"randomize\.agents\.value=-0\.5"),
    ],
)
def test_every_check_names_the_field_the_value_and_the_fix(make: Any, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        make()


def test_bad_input_is_one_line_exit_2_and_nothing_is_written(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = run_cli("randomize=on", "randomize.light.intensity=-0.2", f"hydra.run.dir={out}")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines == [
        "error: invalid randomize.light.intensity=-0.2 in config: must be within 0..1 (1 would allow black); use 0.3"
    ]
    assert not out.exists()


def test_off_draws_nothing_and_on_draws_every_effect() -> None:
    assert not RandomizeConfig().active
    on = _config("randomize=on").randomize
    assert on.active and all(getattr(on, e).enabled for e in EFFECTS)
    off = Randomizer(RandomizeConfig(), 0)
    image = np.arange(48, dtype=np.uint8).reshape(4, 4, 3)
    frame = CameraImages(image, None, None)
    assert off.drawn == {} and not off.lights and off.post_render(0, frame) is frame


# ------------------------------------------------------------------------------- lighting
def test_the_sun_stands_where_the_almanac_puts_it() -> None:
    east, north, up = sun_direction(12.0, 172, 57.7)  # midsummer noon in Gothenburg: due south
    assert abs(east) < 1e-9 and north < 0
    assert np.degrees(np.arcsin(up)) == pytest.approx(90 - 57.7 + 23.44, abs=0.1)
    morning = sun_direction(8.0, 172, 57.7)
    assert morning[0] > 0 and morning[2] > 0  # in the east, up
    # a patch is a skylight moved along the sun: a point under a skylight's centre is lit, and
    # with the patch moved 3 m east the same point is lit no longer but its neighbour 3 m east is
    under = np.array([[-26.0 + 0.8, -34.0 + 3.0]])
    assert in_patches(under, [0.0, 0.0])[0]
    assert not in_patches(under, [3.0, 0.0])[0] and in_patches(under + [3.0, 0.0], [3.0, 0.0])[0]


def test_light_is_applied_with_the_recorded_gains() -> None:
    cfg = RandomizeConfig(light=LightConfig(enabled=True, intensity=0.3, colour=0.1))
    rz = Randomizer(cfg, 5)
    (camera,), _issues = load_cameras(_config("cameras.ids=[163]"))
    rz.attach_camera(camera, distorted=True)
    gains = rz.drawn["light"]["gains"]
    levels = np.arange(256, dtype=np.uint8)
    image = np.stack([levels, levels[::-1], levels], axis=1).reshape(16, 16, 3)
    out = rz.post_render(0, CameraImages(image, None, None)).rgb
    assert out is not None
    expected = np.clip(255.0 * (((image / 255.0) ** 2.2) * gains) ** (1 / 2.2), 0, 255)
    assert np.abs(out.astype(float) - expected).max() <= 0.5 + 1e-9
    assert gain_lut([1.0, 1.0, 1.0]).ravel()[::3].tolist() == list(range(256))  # gain 1: unchanged


# ---------------------------------------------------------------------------------- scenes
def test_same_seed_same_images_another_seed_other_colours_and_places(scenes: dict[str, Any]) -> None:
    on, again, other = scenes["on"], scenes["again"], scenes["other_seed"]
    assert on["record"] == again["record"]
    for a, b in zip(on["images"], again["images"], strict=True):
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.labels, b.labels)
    assert other["drawn"]["light"]["gains"] != on["drawn"]["light"]["gains"]
    assert other["drawn"]["materials"] != on["drawn"]["materials"]
    assert [d["xy_m"] for d in other["drawn"]["distractors"]] != [
        d["xy_m"] for d in on["drawn"]["distractors"]
    ]
    assert other["drawn"]["placement"]["moved"] != on["drawn"]["placement"]["moved"]
    differ = [not np.array_equal(a.rgb, b.rgb) for a, b in zip(on["images"], other["images"], strict=True)]
    assert all(differ)


def test_what_is_applied_is_what_was_drawn(scenes: dict[str, Any]) -> None:
    on, off = scenes["on"], scenes["off"]
    drawn = on["drawn"]
    # floor and shelves (materials alone): the rendered colour is the modelled one times the
    # drawn tint (PyBullet shades albedo linearly), everything else as it was
    painted = scenes["materials"]
    tints = painted["drawn"]["materials"]
    for label, tint in (
        (SEMANTIC_CLASSES["floor"], tints["floor_tint"]),
        (SEMANTIC_CLASSES["shelf"], tints["shelf_tint"]),
    ):
        ratios = []
        for a, b in zip(off["images"], painted["images"], strict=True):
            mask = (
                (a.labels == label)
                & (b.labels == label)
                & (a.rgb.min(axis=2) > 40)
                & (b.rgb.max(axis=2) < 250)
            )
            ratios.append(b.rgb[mask].astype(float) / a.rgb[mask])
        ratio = np.median(np.concatenate(ratios), axis=0)
        assert np.allclose(ratio, tint, atol=0.03), (label, ratio, tint)
    for a, b in zip(off["images"], painted["images"], strict=True):
        other = ~np.isin(a.labels, [SEMANTIC_CLASSES["floor"], SEMANTIC_CLASSES["shelf"], 0])
        # (2 px from a floor or shelf pixel: the lens remap blends neighbours)
        inner = cv2.erode(other.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        assert inner.sum() > 500
        assert (a.rgb == b.rgb).all(axis=2)[inner].mean() > 0.99
    # distractors: where and what colour they were drawn
    assert len(on["distractors"]) == on["cfg"].randomize.distractors.count
    for d in drawn["distractors"]:  # (not their colour: PyBullet reports a shape's, not a body's)
        (pos, _orn), (_lo, hi), _gap = on["distractors"][d["name"]]
        assert np.allclose(pos[:2], d["xy_m"], atol=1e-6)
        assert hi[2] == pytest.approx(d["size_m"][2], abs=0.01)
    # agents (paint alone): their pixels change, nothing else does; every link but the marker's
    # has a drawn colour (the marker keeps its code: test_markers_are_still_detected_for_every_robot)
    robots = [SEMANTIC_CLASSES[k] for k in ("forklift", "pallet_truck", "jackal")]
    changed = unchanged = 0
    for a, b in zip(off["images"], scenes["paint"]["images"], strict=True):
        agent = np.isin(a.labels, robots)
        inner = cv2.erode(agent.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        changed += int((a.rgb != b.rgb).any(axis=2)[inner].sum())
        rest = cv2.erode((~agent).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        unchanged += int((a.rgb != b.rgb).any(axis=2)[rest].sum())
    assert changed > 200 and unchanged == 0
    for ns, links in off["agent_links"].items():
        names = {name for name, _ in links}
        painted_links = set(scenes["paint"]["drawn"]["agents"][ns]["links"])
        assert painted_links == {n for n in names if not n.startswith("aruco_marker")}, ns
    # placement: every offset within the configured jitter, most boxes and pallets moved
    jitter = on["cfg"].randomize.placement
    moved = drawn["placement"]["moved"]
    assert len(moved) > 20
    for dx, dy, dyaw in moved.values():
        assert max(abs(dx), abs(dy)) <= jitter.xy_m and abs(dyaw) <= jitter.yaw_deg


def test_distractors_keep_off_routes_and_agents_and_are_labelled(scenes: dict[str, Any]) -> None:
    on = scenes["on"]
    cfg, inputs = on["cfg"], on["inputs"]
    nav = cfg.navigation
    for a in cfg.agent_list:  # the route each robot's planner takes between its start and goals
        kind = inputs.agent_types[a.namespace]
        radius = round(kind.half_width_m + nav.clearance_m, 3)
        planner = GridPlanner(inputs.grid, radius_m=radius)
        stops = [tuple(a.pose[:2]), *[tuple(g) for g in a.goals]]
        for start, goal in itertools.pairwise(stops):
            path = LineString(planner.plan(start, goal).points_xy)
            for name, (_pose, (lo, hi), _gap) in on["distractors"].items():
                gap = path.distance(box(lo[0], lo[1], hi[0], hi[1]))
                assert gap >= radius, f"{name} is {gap:.2f} m from {a.namespace}'s route"
    for name, (*_, agent_gap) in on["distractors"].items():
        assert agent_gap > 0.5, f"{name} is {agent_gap:.2f} m from an agent"
    # every camera pixel that shows a distractor's top centre (depth as expected) is labelled
    seen = 0
    for images, cam in zip(on["images"], on["cameras"], strict=True):
        for d in on["drawn"]["distractors"]:
            top = np.array([[*d["xy_m"], d["size_m"][2]]])
            uv, ok = cam.project(top)
            u, v = (round(c) for c in uv[0])
            if not ok[0] or not (0 <= u < cam.width and 0 <= v < cam.height):
                continue
            depth = cam.world_to_camera(top)[0, 2]
            if abs(float(images.depth_m[v, u]) - depth) < 0.03:
                assert images.labels[v, u] == FURNITURE, d["name"]
                seen += 1
    assert seen >= 1


def test_the_sun_lights_floor_patches_only(scenes: dict[str, Any]) -> None:
    """Floor pixels in a sunlit patch are brighter than the other floor pixels by the sun's gain
    (against the same scene without randomization); boxes standing in a patch are not."""
    on, off = scenes["on"], scenes["off"]
    sun = on["drawn"]["time_of_day"]
    assert "patch_offset_m" in sun, sun  # hours 7-18 at midsummer: the sun is up
    gains, sun_gains = np.array(on["drawn"]["light"]["gains"]), np.array(sun["sun_gains"])
    ratios: dict[str, list[np.ndarray]] = defaultdict(list)
    for a, b, cam in zip(off["images"], on["images"], on["cameras"], strict=True):
        u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
        points, ok = cam.intersect_plane_z(np.stack([u.ravel(), v.ravel()], axis=1), 0.0)
        lit = (ok & in_patches(points[:, :2], sun["patch_offset_m"])).reshape(cam.height, cam.width)
        lit = cv2.erode(lit.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        floor = (a.labels == SEMANTIC_CLASSES["floor"]) & (b.labels == SEMANTIC_CLASSES["floor"])
        usable = (a.rgb.min(axis=2) > 40) & (b.rgb.max(axis=2) < 250)
        for name, mask in (
            ("lit", lit & floor),
            ("shade", ~lit & floor),
            ("box_lit", lit & (a.labels == 11)),
        ):
            ratios[name].append(b.rgb[mask & usable].astype(float) / a.rgb[mask & usable])
    lit_ratio, shade_ratio = (np.median(np.concatenate(ratios[k]), axis=0) for k in ("lit", "shade"))
    assert sum(len(r) for r in ratios["lit"]) > 500
    # display values scale with gain^(1/2.2); the floor's tint is in both
    assert np.allclose(lit_ratio / shade_ratio, (sun_gains / gains) ** (1 / 2.2), rtol=0.04)
    boxes = np.concatenate(ratios["box_lit"])
    if len(boxes) > 50:  # a box in a patch has the lamps' light only
        assert np.allclose(np.median(boxes, axis=0), gains ** (1 / 2.2), rtol=0.04)


# ------------------------------------------------------------------------------------ runs
def test_markers_are_still_detected_for_every_robot(runs: dict[str, Path]) -> None:
    seen: set[int] = set()
    for topic, msgs in _messages(runs["on"]).items():
        if topic.endswith("/marker_detections"):
            for _raw, det in msgs:
                seen.update(int(i) for i in det.ids)
    robots = {a.marker_id for a in _config(*ON).agent_list}
    assert robots == {1, 2, 3, 4} and robots <= seen


def test_the_recorded_values_are_the_applied_ones(runs: dict[str, Path], scenes: dict[str, Any]) -> None:
    msgs = _messages(runs["on"])
    ((_raw, recorded),) = msgs["/simlan/randomization"]
    values = json.loads(recorded.data)
    assert values == json.loads(scenes["on"]["record"])  # what the scene of the same config applied
    assert values["seed"] == 2 and set(EFFECTS) <= set(values)
    ((_raw, config),) = msgs["/simlan/config"]
    assert "randomize:" in config.data and "name: 'on'" in config.data


def test_every_effect_disabled_is_byte_identical_to_no_group(runs: dict[str, Path]) -> None:
    default, disabled = _messages(runs["default"]), _messages(runs["disabled"])
    assert "/simlan/randomization" not in disabled
    assert set(default) == set(disabled)
    for topic in default:
        if topic == "/simlan/config":  # (it says randomize: on with every effect off)
            continue
        a = hashlib.sha256(b"".join(raw for raw, _ in default[topic])).hexdigest()
        b = hashlib.sha256(b"".join(raw for raw, _ in disabled[topic])).hexdigest()
        assert a == b, topic
    frame = cv2.imdecode(np.frombuffer(default["/camera_163/image_raw/compressed"][0][1].data, np.uint8), 1)
    assert frame is not None and frame.mean() > 10  # (real images were compared)


def test_replay_reproduces_the_live_estimates_of_a_randomized_run(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """The recorded images are the randomized ones: the replay's localizer sees what the live one saw."""
    proc = run_cli(str(runs["on"]), "--out", str(tmp_path / "replay"), module="simlan_data.replay")
    assert proc.returncode == 0, proc.stderr
    line = next(x for x in proc.stdout.splitlines() if "replay.localization.max_diff_to_live_m" in x)
    assert float(line.split()[1]) <= 1e-9
