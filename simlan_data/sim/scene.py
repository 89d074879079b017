"""Assemble a scene from a config: world, cameras, agents. All input checks happen here first.

``load_inputs`` reads and validates every file the config names (calibrations, layout) without
touching PyBullet or the disk's outputs; ``Scene.build`` then creates the PyBullet world, renders
the cameras' static layers (movable bodies hidden) and spawns the agents.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from shapely.geometry import Polygon

from simlan_data.algorithms.occupancy import OccupancyGrid, grid_from_nav2_map, grid_from_world
from simlan_data.config.schema import AgentConfig, Config
from simlan_data.constants import MAPS_DIR
from simlan_data.errors import CalibrationError, ConfigError
from simlan_data.geometry.calibration import Calibration, available_camera_ids, load_calibration
from simlan_data.geometry.camera import CameraModel
from simlan_data.sim.agents import Agent, spawn_agent
from simlan_data.sim.dynamic_layer import MovedAgents, StaticMeshes
from simlan_data.sim.instances import INSTANCE_STREAM, InstanceObject, instance_objects
from simlan_data.sim.posemap_drive import DriveInputs, load_drive_inputs
from simlan_data.sim.pybullet_client import Client, connect
from simlan_data.sim.randomize import LitRenderer, Randomizer, keep_clear
from simlan_data.sim.rendering import CameraRenderer, LabelTable
from simlan_data.sim.sensors import drifted
from simlan_data.sim.urdf_check import check_urdf
from simlan_data.world._pybullet import pb
from simlan_data.world.agent_types import AgentType, agent_type
from simlan_data.world.builder import WorldBodies, build_world
from simlan_data.world.layout import Placement, load_layout
from simlan_data.world.models import BUILDING_X_M, BUILDING_Y_M

log = logging.getLogger(__name__)

# m (or quaternion units): a world object this far from its baked pose is re-rendered; 2 mm is
# under 0.2 px at the cameras' distances
MOVED_TOLERANCE = 2e-3


@dataclass(frozen=True)
class Inputs:
    """Everything read from files for a run, already validated."""

    cameras: list[CameraModel]
    calibration_issues: list[str]
    placements: list[Placement]
    agent_types: dict[str, AgentType]
    grid: OccupancyGrid
    posemap: DriveInputs | None = None  # posed humanoid: motion keyframes or the drive's predictions


def load_cameras(cfg: Config) -> tuple[list[CameraModel], list[str]]:
    """Load and scale the configured cameras; unknown ids and bad files raise ConfigError."""
    cam_cfg = cfg.cameras
    directory = Path(cam_cfg.calibration_dir) if cam_cfg.calibration_dir else None
    available = available_camera_ids(directory)
    cameras: list[CameraModel] = []
    issues: list[str] = []
    for cid in cam_cfg.ids:
        if str(cid) not in available:
            where = str(directory) if directory else "the packaged calibrations"
            raise ConfigError(
                f"unknown camera id {cid} in cameras.ids",
                where,
                "no intrinsic/extrinsic calibration pair with that id",
                f"use one of {', '.join(available) or '(none found)'}",
            )
        cal: Calibration = load_calibration(cid, directory)
        if cal.issues and cam_cfg.calibration_check == "error":
            raise CalibrationError(
                "calibration files disagree",
                f"camera {cid}",
                "; ".join(cal.issues),
                "fix the files or set cameras.calibration_check=warn",
            )
        issues.extend(cal.issues)
        native = cal.camera
        if abs(native.width / native.height - cam_cfg.width / cam_cfg.height) > 0.02:
            raise ConfigError(
                f"invalid cameras.width x height={cam_cfg.width}x{cam_cfg.height}",
                "config",
                f"camera {cid} is {native.width}x{native.height}; scaling would change its aspect ratio",
                f"keep the aspect ratio, e.g. {native.width // 4}x{native.height // 4}",
            )
        cameras.append(native.scaled(cam_cfg.width, cam_cfg.height))
    return cameras, issues


def load_inputs(cfg: Config) -> Inputs:
    cameras, issues = load_cameras(cfg)
    placements = load_layout(cfg.world.layout, cfg.world.fidelity)
    types = {a.namespace: agent_type(a.type, where=f"agents.{a.namespace}.type") for a in cfg.agent_list}
    for kind in sorted({t.name: t for t in types.values()}.values(), key=lambda t: t.name):
        check_urdf(kind)
    for a in cfg.agent_list:
        check_spawn_pose(a, types[a.namespace], cfg.world.fidelity)
    if not cfg.trajectory.file:  # a tracker's objects spawn where it first saw them, at different times
        check_agents_apart(cfg.agent_list, types)
    nav = cfg.navigation
    if nav.map == "simlan":
        grid = grid_from_nav2_map(MAPS_DIR / "warehouse.yaml", resolution_m=nav.resolution_m)
    else:
        grid = grid_from_world(placements, resolution_m=nav.resolution_m)
    for a in cfg.agent_list:
        kind = types[a.namespace]
        if kind.drive != "diff":
            continue
        clearance = grid.clearance_m()
        for i, goal in enumerate(a.goals):
            cell = grid.to_cell((goal[0], goal[1]))
            if not grid.inside(cell) or clearance[cell] < kind.half_width_m:
                raise ConfigError(
                    f"invalid agents.{a.namespace}.goals[{i}]={list(goal)}",
                    "config",
                    "the goal is inside an obstacle or outside the map",
                    "pick a goal on free floor (see the occupancy grid in report.md)",
                )
    return Inputs(cameras, issues, placements, types, grid, load_drive_inputs(cfg))


def footprint_corners(kind: AgentType, pose: list[float]) -> np.ndarray:
    x0, x1, y0, y1 = kind.footprint_m
    x, y, yaw = pose
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    return local @ np.array([[c, s], [-s, c]]) + [x, y]


def check_agents_apart(agents: list[AgentConfig], types: dict[str, AgentType]) -> None:
    """Refuse two agents whose footprints overlap at spawn."""
    shapes = {a.namespace: Polygon(footprint_corners(types[a.namespace], list(a.pose))) for a in agents}
    for i, a in enumerate(agents):
        for b in agents[:i]:
            if shapes[a.namespace].intersects(shapes[b.namespace]):
                raise ConfigError(
                    f"invalid agents.{a.namespace}.pose={list(a.pose)}",
                    "config",
                    f"its footprint overlaps {b.namespace}'s (at {list(b.pose)})",
                    "spawn every agent on its own spot of the floor",
                )


def check_spawn_pose(agent: AgentConfig, kind: AgentType, fidelity: str) -> None:
    """Refuse a spawn pose whose footprint leaves the building (obstacles: ``Scene.build``)."""
    if fidelity == "empty":
        return
    corners = footprint_corners(kind, list(agent.pose))
    (bx0, bx1), (by0, by1) = BUILDING_X_M, BUILDING_Y_M
    if (
        corners[:, 0].min() < bx0
        or corners[:, 0].max() > bx1
        or corners[:, 1].min() < by0
        or corners[:, 1].max() > by1
    ):
        raise ConfigError(
            f"invalid agents.{agent.namespace}.pose={list(agent.pose)}",
            "config",
            f"the robot's footprint leaves the building (x {bx0}..{bx1}, y {by0}..{by1} m)",
            "move it inside the building",
        )


@dataclass
class Scene:
    """The live PyBullet scene of a run."""

    client: Client
    world: WorldBodies
    cameras: list[CameraModel]
    renderers: list[CameraRenderer]
    agents: list[Agent]
    labels: LabelTable
    names: dict[int, str] = field(default_factory=dict)
    meshes: StaticMeshes | None = None  # layered: the warehouse meshes, removed between static layers
    moved: MovedAgents | None = None
    randomizer: Randomizer | None = None  # domain randomization (sim/randomize.py): post_render per image
    instances: list[InstanceObject] = field(default_factory=list)  # stream instance: the instance table
    _baked: dict[int, tuple] = field(default_factory=dict)

    @staticmethod
    def build(cfg: Config, inputs: Inputs) -> Scene:
        client = connect(cfg.render.backend, software_gl_threads=cfg.render.software_gl_threads)
        try:
            return Scene._build(cfg, inputs, client)
        except BaseException:
            client.disconnect()
            raise

    @staticmethod
    def _build(cfg: Config, inputs: Inputs, client: Client) -> Scene:
        cid = client.id
        pb.setGravity(0.0, 0.0, -cfg.world.gravity_mps2, physicsClientId=cid)
        pb.setTimeStep(1.0 / cfg.world.physics_hz, physicsClientId=cid)
        pb.setPhysicsEngineParameter(deterministicOverlappingPairs=1, physicsClientId=cid)
        physics = dict(cfg.world.physics)
        randomizer = Randomizer(cfg.randomize, cfg.seed)  # (randomize=off: changes nothing)
        clear = keep_clear(cfg, inputs.agent_types, inputs.grid) if randomizer.moves_objects else Polygon()
        placements = randomizer.jitter_placements(inputs.placements, clear)
        with tempfile.TemporaryDirectory(prefix="simlan_world_") as mesh_dir:
            world = build_world(cid, placements, physics, mesh_dir=Path(mesh_dir))
        randomizer.paint_world(cid, world)
        randomizer.add_distractors(cid, world, cameras=inputs.cameras, grid=inputs.grid, clear=clear)
        if world.skipped_models:
            log.info("layout models without geometry in this twin: %s", world.skipped_models)
        for conflict in world.layout_conflicts:
            log.debug("layout: %s", conflict)
        # let movable objects settle (SIMLAN's poses leave gaps and small overlaps) before the
        # cameras bake their static layers
        for _ in range(round(cfg.world.settle_s * cfg.world.physics_hz)):
            pb.stepSimulation(physicsClientId=cid)
        labels = LabelTable()
        for body, label in world.labels.items():
            labels.set(body, label)
        for agent_cfg in (
            [] if cfg.trajectory.file else cfg.agent_list
        ):  # (a tracker's agents are where it saw them)
            _check_spawn_clear(cid, agent_cfg, inputs.agent_types[agent_cfg.namespace], world)
        cam_cfg = cfg.cameras
        # (light and sun from randomize: applied to each rendered colour image)
        make = functools.partial(LitRenderer, randomizer=randomizer) if randomizer.lights else CameraRenderer
        instance_ids = LabelTable(np.uint16)  # body id -> instance id, filled once the agents exist
        renderers = [
            make(
                client,
                drifted(cam, cfg.sensors.drift, cfg.seed),  # drawn from where it truly hangs
                labels,
                distort=cam_cfg.distortion,
                near_m=cam_cfg.near_m,
                far_m=cam_cfg.far_m,
                layered=cfg.render.layered,
                streams=cam_cfg.streams,
                instances=instance_ids,
            )
            for cam in inputs.cameras
        ]
        if cfg.render.layered:  # static layers: the world as it stands, before any agent exists
            for r in renderers:
                r.render_static()
        agents: list[Agent] = []
        for a in cfg.agent_list:
            agent = spawn_agent(
                cid, a.namespace, inputs.agent_types[a.namespace], pose=list(a.pose), marker_id=a.marker_id
            )
            agent.apply_command(0.0, 0.0)
            labels.set(agent.body, agent.label)
            agents.append(agent)
        randomizer.paint_agents(cid, agents)
        names = dict(world.names)
        names.update({a.body: a.namespace for a in agents})
        scene = Scene(client, world, inputs.cameras, renderers, agents, labels, names, randomizer=randomizer)
        if INSTANCE_STREAM in cam_cfg.streams:
            scene.instances = instance_objects(agents, world)
            for obj in scene.instances:
                instance_ids.set(obj.body, obj.id)
        if cfg.render.layered:  # region renders draw only what moves (see sim/dynamic_layer.py)
            scene.meshes = StaticMeshes(client.id, world, labels)
            scene.meshes.remove()
            scene.moved = MovedAgents(agents)
        scene._baked = {b: scene._body_state(b) for b in sorted(world.movable)}
        return scene

    def _body_state(self, body: int) -> tuple[np.ndarray, tuple]:
        pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=self.client.id)
        return np.array(pos + orn), pb.getAABB(body, -1, physicsClientId=self.client.id)

    def agent_aabbs(self) -> list[tuple]:
        """AABBs of every agent link."""
        boxes: list[tuple] = []
        for agent in self.agents:
            boxes.extend(agent.aabbs())
        return boxes

    def moved_boxes(self) -> list[tuple]:
        """What the cameras must draw again: boxes of the agents that moved (then and now).

        In layered mode only agents that moved since they were last drawn count; otherwise
        every agent.
        """
        return self.moved.boxes() if self.moved is not None else self.agent_aabbs()

    def refresh_static_layers(self) -> int:
        """Re-render the static layers that show a world object which moved (pushed pallets...).

        Static layers hold the world without agents; agents are moved out of sight while the
        affected cameras re-render. Returns the number of layers re-rendered.
        """
        moved: list[tuple] = []
        for body, (state, box) in self._baked.items():
            now, now_box = self._body_state(body)
            if np.abs(now - state).max() > MOVED_TOLERANCE:
                moved += [box, now_box]
                self._baked[body] = (now, now_box)
        if not moved:
            return 0
        stale = [r for r in self.renderers if r.layered and r.canvas_rects(moved)]
        if stale:
            shown = self.meshes.shown() if self.meshes is not None else contextlib.nullcontext()
            with shown, _Hidden(self.client.id, [a.body for a in self.agents]):
                for r in stale:
                    r.render_static()
        return len(stale)

    def close(self) -> None:
        self.client.disconnect()


class _Hidden:
    """Move bodies 1 km below the floor for the duration of a block, then restore pose and velocity."""

    def __init__(self, client: int, bodies: list[int]) -> None:
        self.client, self.bodies = client, sorted(bodies)
        self.saved: list[tuple] = []

    def __enter__(self) -> None:
        for b in self.bodies:
            pos, orn = pb.getBasePositionAndOrientation(b, physicsClientId=self.client)
            lin, ang = pb.getBaseVelocity(b, physicsClientId=self.client)
            self.saved.append((b, pos, orn, lin, ang))
            pb.resetBasePositionAndOrientation(
                b, [pos[0], pos[1], pos[2] - 1000.0], orn, physicsClientId=self.client
            )

    def __exit__(self, *exc: object) -> None:
        for b, pos, orn, lin, ang in self.saved:
            pb.resetBasePositionAndOrientation(b, pos, orn, physicsClientId=self.client)
            pb.resetBaseVelocity(b, lin, ang, physicsClientId=self.client)


def _check_spawn_clear(client: int, agent: AgentConfig, kind: AgentType, world: WorldBodies) -> None:
    """Refuse a spawn pose whose footprint (0.05-1.5 m high) overlaps a non-floor object."""
    x0, x1, y0, y1 = kind.footprint_m
    x, y, yaw = (float(v) for v in agent.pose)
    centre_local = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    c, s = np.cos(yaw), np.sin(yaw)
    centre = [
        x + c * centre_local[0] - s * centre_local[1],
        y + s * centre_local[0] + c * centre_local[1],
        0.8,
    ]
    probe = pb.createCollisionShape(
        pb.GEOM_BOX, halfExtents=[(x1 - x0) / 2, (y1 - y0) / 2, 0.7], physicsClientId=client
    )
    orn = [0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2))]
    # (the probe shape is left in place: removing a collision shape makes PyBullet print a warning)
    for body in sorted(world.names):
        if body in world.floor:
            continue
        hits = pb.getClosestPoints(
            bodyA=-1,
            bodyB=body,
            distance=0.0,
            collisionShapeA=probe,
            collisionShapePositionA=centre,
            collisionShapeOrientationA=orn,
            physicsClientId=client,
        )
        if hits:
            raise ConfigError(
                f"invalid agents.{agent.namespace}.pose={list(agent.pose)}",
                "config",
                f"the robot's footprint overlaps '{world.names[body]}'",
                "move it to a free spot of the floor",
            )
