"""Build the warehouse in a PyBullet client from layout placements and model specs."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from simlan_data.geometry.rotations import quat_from_rpy
from simlan_data.geometry.transforms import Transform
from simlan_data.world._pybullet import pb
from simlan_data.world.labels import label_id
from simlan_data.world.layout import Placement
from simlan_data.world.mesh import MeshBuilder
from simlan_data.world.models import ModelSpec, Part, model_spec
from simlan_data.world.physics import PhysicsParams

MAX_SHAPES_PER_ARRAY = 16  # PyBullet's createVisualShapeArray/createCollisionShapeArray limit


@dataclass
class WorldBodies:
    """What was built: body ids by name, their semantic class and whether they can move."""

    names: dict[int, str] = field(default_factory=dict)
    labels: dict[int, int] = field(default_factory=dict)
    movable: set[int] = field(default_factory=set)
    floor: set[int] = field(default_factory=set)
    visual_only: set[int] = field(default_factory=set)
    # visual-only body -> (its visual shape, colour): to create the body again after removing it
    visual_shapes: dict[int, tuple[int, tuple[float, ...]]] = field(default_factory=dict)
    layout_conflicts: list[str] = field(default_factory=list)
    skipped_models: dict[str, int] = field(default_factory=dict)


def _shape_arrays(parts: Sequence[Part]) -> dict[str, list]:
    arrays: dict[str, list] = {
        "shapeTypes": [],
        "halfExtents": [],
        "radii": [],
        "lengths": [],
        "framePositions": [],
        "frameOrientations": [],
    }
    for part in parts:
        if part.shape == "box":
            arrays["shapeTypes"].append(pb.GEOM_BOX)
            arrays["halfExtents"].append(list(part.size))
            arrays["radii"].append(0.0)
            arrays["lengths"].append(0.0)
        elif part.shape == "cylinder":
            arrays["shapeTypes"].append(pb.GEOM_CYLINDER)
            arrays["halfExtents"].append([0.0, 0.0, 0.0])
            arrays["radii"].append(part.size[0])
            arrays["lengths"].append(part.size[1])
        else:  # pragma: no cover - specs are package data
            raise ValueError(f"unknown part shape {part.shape!r}")
        arrays["framePositions"].append(list(part.xyz))
        arrays["frameOrientations"].append(list(quat_from_rpy(*part.rpy)))
    return arrays


def create_body(
    client: int,
    parts: Sequence[Part],
    *,
    position: Sequence[float],
    orientation: Iterable[float],
    mass_kg: float,
    visual: int = -1,
) -> int:
    """Create one multibody made of ``parts`` and return its id.

    PyBullet's EGL renderer merges all visual shapes of a link into one mesh with one colour, so
    parts are grouped by colour: the base carries the first colour group and the whole collision
    compound, every further colour group is a massless fixed link without collision.
    """
    by_colour: dict[tuple[float, ...], list[Part]] = {}
    for part in parts:
        if part.visual:
            by_colour.setdefault(tuple(part.rgba), []).append(part)
    # a shape array holds at most MAX_SHAPES_PER_ARRAY shapes: split larger colour groups
    groups = [
        (colour, group[i : i + MAX_SHAPES_PER_ARRAY])
        for colour, group in by_colour.items()
        for i in range(0, len(group), MAX_SHAPES_PER_ARRAY)
    ]
    collide = [p for p in parts if p.collide]
    if len(collide) > MAX_SHAPES_PER_ARRAY:  # pragma: no cover - specs are package data
        raise ValueError(f"a body can collide with at most {MAX_SHAPES_PER_ARRAY} parts, got {len(collide)}")
    col = -1
    if [p.shape for p in collide] == ["plane"]:
        col = pb.createCollisionShape(pb.GEOM_PLANE, planeNormal=[0, 0, 1], physicsClientId=client)
    elif collide:
        a = _shape_arrays(collide)
        col = pb.createCollisionShapeArray(
            shapeTypes=a["shapeTypes"],
            halfExtents=a["halfExtents"],
            radii=a["radii"],
            lengths=a["lengths"],
            collisionFramePositions=a["framePositions"],
            collisionFrameOrientations=a["frameOrientations"],
            physicsClientId=client,
        )
    visuals = []
    for _, group in groups:
        a = _shape_arrays(group)
        visuals.append(
            pb.createVisualShapeArray(
                shapeTypes=a["shapeTypes"],
                halfExtents=a["halfExtents"],
                radii=a["radii"],
                lengths=a["lengths"],
                visualFramePositions=a["framePositions"],
                visualFrameOrientations=a["frameOrientations"],
                physicsClientId=client,
            )
        )
    n_links = max(0, len(visuals) - 1)
    link_mass = 1e-3 if mass_kg > 0 else 0.0
    body = pb.createMultiBody(
        baseMass=mass_kg,
        baseCollisionShapeIndex=col,
        baseVisualShapeIndex=visuals[0] if visuals else visual,
        basePosition=list(position),
        baseOrientation=list(orientation),
        linkMasses=[link_mass] * n_links,
        linkCollisionShapeIndices=[-1] * n_links,
        linkVisualShapeIndices=visuals[1:],
        linkPositions=[[0.0, 0.0, 0.0]] * n_links,
        linkOrientations=[[0.0, 0.0, 0.0, 1.0]] * n_links,
        linkInertialFramePositions=[[0.0, 0.0, 0.0]] * n_links,
        linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * n_links,
        linkParentIndices=[0] * n_links,
        linkJointTypes=[pb.JOINT_FIXED] * n_links,
        linkJointAxis=[[0.0, 0.0, 1.0]] * n_links,
        physicsClientId=client,
    )
    for link, (colour, _) in enumerate(groups):
        pb.changeVisualShape(body, link - 1, rgbaColor=list(colour), physicsClientId=client)
    return body


def apply_physics(client: int, body: int, params: PhysicsParams) -> None:
    pb.changeDynamics(
        body,
        -1,
        lateralFriction=params.lateral_friction,
        rollingFriction=params.rolling_friction,
        spinningFriction=params.spinning_friction,
        restitution=params.restitution,
        linearDamping=params.linear_damping,
        angularDamping=params.angular_damping,
        physicsClientId=client,
    )


def _null_visual(client: int, mesh_dir: Path) -> int:
    """A shared, invisible visual shape for collision-only bodies.

    Without a visual shape PyBullet draws a body's collision shapes; with this one (one tiny
    triangle 1 km below the body, a mesh file so that all bodies share one instanced draw call)
    nothing is seen and rendering stays cheap.
    """
    path = mesh_dir / "null.obj"
    path.write_text("v 0 0 -1000\nv 0.001 0 -1000\nv 0 0.001 -1000\nvn 0 0 1\nf 1//1 2//1 3//1\n")
    return pb.createVisualShape(pb.GEOM_MESH, fileName=str(path), physicsClientId=client)


PENETRATION_TOLERANCE_M = 0.005


def _fix_interpenetrating(client: int, world: WorldBodies) -> None:
    """Make movable objects that start inside fixed geometry fixed themselves.

    Physics would otherwise eject them violently on the first step. They are reported in
    ``world.layout_conflicts``.
    """
    for body in sorted(world.movable):
        lo, hi = pb.getAABB(body, -1, physicsClientId=client)
        for other, _ in pb.getOverlappingObjects(lo, hi, physicsClientId=client) or []:
            if other == body or other in world.movable or other in world.floor or other not in world.names:
                continue
            points = pb.getClosestPoints(body, other, 0.0, physicsClientId=client)
            depth = min((p[8] for p in points), default=0.0)
            if depth < -PENETRATION_TOLERANCE_M:
                pb.changeDynamics(body, -1, mass=0.0, physicsClientId=client)
                world.movable.discard(body)
                world.layout_conflicts.append(
                    f"{world.names[body]} starts {-depth * 100:.1f} cm inside {world.names[other]}: fixed in place"
                )
                break


def build_world(
    client: int, placements: Sequence[Placement], physics: Mapping[str, PhysicsParams], *, mesh_dir: Path
) -> WorldBodies:
    """Create the world: static geometry merged into one mesh per (class, colour), collision
    bodies per placement (named, invisible), movable objects as ordinary bodies.

    Models without a spec are counted in ``skipped_models``. OBJ files go to ``mesh_dir``.
    """
    out = WorldBodies()
    meshes: dict[tuple[str, tuple[float, ...]], MeshBuilder] = {}
    mesh_dir.mkdir(parents=True, exist_ok=True)
    null_visual = _null_visual(client, mesh_dir)
    for pl in placements:
        spec: ModelSpec | None = model_spec(pl.model)
        if spec is None:
            out.skipped_models[pl.model] = out.skipped_models.get(pl.model, 0) + 1
            continue
        if not spec.parts:
            continue
        params = physics.get(spec.physics, PhysicsParams())
        dynamic = spec.movable and not pl.static and params.mass_kg > 0
        x, y, z = (0.0, 0.0, 0.0) if spec.world_frame else pl.xyz_m
        rpy = (0.0, 0.0, 0.0) if spec.world_frame else pl.rpy_rad
        position, orientation = (x, y, z + spec.z_offset_m), quat_from_rpy(*rpy)
        if dynamic:
            body = create_body(
                client, spec.parts, position=position, orientation=orientation, mass_kg=params.mass_kg
            )
            # settled objects fall asleep (a resting stack of ten pallets otherwise costs 1 ms per
            # physics step) and wake up when something touches them
            pb.changeDynamics(
                body, -1, activationState=pb.ACTIVATION_STATE_ENABLE_SLEEPING, physicsClientId=client
            )
            out.movable.add(body)
        else:
            pose = Transform.from_quat(position, orientation)
            for part in spec.parts:
                if part.visual:
                    mesh = meshes.setdefault((spec.semantic, tuple(part.rgba)), MeshBuilder())
                    part_pose = pose @ Transform.from_xyz_rpy(part.xyz, part.rpy)
                    if part.shape == "box":
                        mesh.add_box(part.size, part_pose)
                    else:
                        mesh.add_cylinder(part.size[0], part.size[1], part_pose)
            collide = [p for p in spec.parts if p.collide]
            if not collide:
                continue
            body = create_body(
                client,
                [replace(p, visual=False) for p in collide],
                position=position,
                orientation=orientation,
                mass_kg=0.0,
                visual=null_visual,
            )
        apply_physics(client, body, params)
        out.names[body] = pl.name
        out.labels[body] = label_id(spec.semantic)
        if spec.semantic in ("floor", "floor_marking"):
            out.floor.add(body)
    _fix_interpenetrating(client, out)
    for i, ((semantic, rgba), mesh) in enumerate(sorted(meshes.items())):
        path = mesh.write_obj(mesh_dir / f"static_{i:03d}_{semantic}.obj")
        vis = pb.createVisualShape(
            pb.GEOM_MESH, fileName=str(path), rgbaColor=list(rgba), physicsClientId=client
        )
        body = pb.createMultiBody(
            baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=vis, physicsClientId=client
        )
        pb.changeVisualShape(body, -1, rgbaColor=list(rgba), physicsClientId=client)
        out.labels[body] = label_id(semantic)
        out.visual_only.add(body)
        out.visual_shapes[body] = (vis, tuple(rgba))
    return out
