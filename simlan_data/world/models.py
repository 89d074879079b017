"""Geometry of SIMLAN's warehouse models as coloured primitives (no meshes, no textures).

Every model is a list of boxes and cylinders in its own frame, with a semantic class and a physics
class (which set of mass/friction/damping parameters from the config applies). Textures are avoided
on purpose: PyBullet's EGL renderer is used in its projective-texture mode (no shadow-map pass, ten
times faster for small regions), where only untextured, coloured geometry renders faithfully. The
floor gets its visual texture from concrete slabs of varying shade with dark joints.

Sizes follow SIMLAN (box 1.185 x 0.785 x 1.01 m; shelf 2.7 x 1.2 m, decks at 1 and 2 m; EUR pallet
1.2 x 0.8 x 0.144 m; building walls x -30.1..45.1, y -38.1..12.1, 8 m high). Where SIMLAN's model
origin is not documented it was inferred from the layout (a shelf's boxes sit 0.85 m from its
origin in x and y) and is stated next to the model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

Rgba = tuple[float, float, float, float]

CONCRETE: Rgba = (0.60, 0.60, 0.58, 1.0)
JOINT: Rgba = (0.30, 0.30, 0.30, 1.0)
WALL: Rgba = (0.86, 0.86, 0.82, 1.0)
RACK_BLUE: Rgba = (0.10, 0.25, 0.60, 1.0)
RACK_ORANGE: Rgba = (0.95, 0.45, 0.08, 1.0)
DECK_GREY: Rgba = (0.55, 0.57, 0.60, 1.0)
CARDBOARD: Rgba = (0.66, 0.50, 0.32, 1.0)
WOOD: Rgba = (0.78, 0.64, 0.44, 1.0)
SAFETY_YELLOW: Rgba = (0.96, 0.80, 0.08, 1.0)
BLACK: Rgba = (0.08, 0.08, 0.08, 1.0)
STEEL: Rgba = (0.45, 0.47, 0.50, 1.0)

BUILDING_X_M = (-30.1, 45.1)
BUILDING_Y_M = (-38.1, 12.1)
BUILDING_HEIGHT_M = 8.0
WALL_THICKNESS_M = 0.3
DOOR_X_M = (25.0, 29.0)  # opening in the north wall between the door poles at x 24.87 and 29.2
YARD_Y_M = (12.1, 30.0)  # outdoor yard north of the building (SIMLAN's truck and pallet stack)
ASPHALT: Rgba = (0.32, 0.33, 0.34, 1.0)
SLAB_M = 5.0
JOINT_WIDTH_M = 0.03


@dataclass(frozen=True)
class Part:
    """A primitive in a model's frame: box (half extents), cylinder (radius, length along z), or
    the infinite floor plane z = 0 (collision only)."""

    shape: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rgba: Rgba = CONCRETE
    collide: bool = True
    visual: bool = True


# The floor collides as Bullet's infinite static plane: wheels rolling on one large box, or on a
# compound of boxes, drifted sideways (measured: 3 cm over 3 m of straight driving).
FLOOR_PLANE = Part("plane", (), visual=False)


@dataclass(frozen=True)
class ModelSpec:
    """What a layout model name becomes in the simulator."""

    semantic: str
    physics: str
    parts: tuple[Part, ...]
    movable: bool = False
    # layout z of SIMLAN's origin is not the bottom for boxes: shift the whole model by this much
    z_offset_m: float = 0.0
    # parts are given in world coordinates (the building shell and floor, whose measured extents
    # are known in the world while SIMLAN's model origin is not)
    world_frame: bool = False
    extra: dict[str, float] = field(default_factory=dict)


def _box(
    hx: float,
    hy: float,
    hz: float,
    x: float = 0.0,
    y: float = 0.0,
    z: float = 0.0,
    rgba: Rgba = CONCRETE,
    *,
    collide: bool = True,
    yaw: float = 0.0,
) -> Part:
    return Part("box", (hx, hy, hz), (x, y, z), (0.0, 0.0, yaw), rgba, collide)


def _cyl(
    radius: float,
    length: float,
    x: float = 0.0,
    y: float = 0.0,
    z: float = 0.0,
    rgba: Rgba = STEEL,
    *,
    collide: bool = True,
) -> Part:
    return Part("cylinder", (radius, length), (x, y, z), (0.0, 0.0, 0.0), rgba, collide)


def shelf_parts() -> tuple[Part, ...]:
    """Pallet rack 2.7 x 1.2 m, 3 m uprights, beams and decks at 1 and 2 m.

    SIMLAN's shelf origin sits at one corner: its boxes are placed 0.2 and 1.5 m along x and
    0.8-0.9 m along y from it, so the rack is centred at (0.85, 0.85) in the model frame.
    """
    cx, cy, lx, ly = 0.85, 0.85, 2.7, 1.2
    parts: list[Part] = []
    post = 0.04
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append(
                _box(post, post, 1.5, cx + sx * (lx / 2 - post), cy + sy * (ly / 2 - post), 1.5, RACK_BLUE)
            )
    # beams run between the posts and decks sit 2 mm below the beams' tops with 1 mm gaps: parts of
    # different colours never share a face (the 16-bit depth buffer would let either win)
    beam_half = lx / 2 - 2 * post - 0.001
    for level in (1.0, 2.0):
        for sy in (-1, 1):
            parts.append(
                _box(beam_half, 0.03, 0.05, cx, cy + sy * (ly / 2 - 0.03), level - 0.05, RACK_ORANGE)
            )
        parts.append(_box(beam_half, ly / 2 - 0.061, 0.015, cx, cy, level - 0.017, DECK_GREY))
    return tuple(parts)


def box_parts() -> tuple[Part, ...]:
    """Cardboard box 1.185 x 0.785 x 1.01 m with a darker tape stripe on top (bottom at z = 0)."""
    return (
        _box(1.185 / 2, 0.785 / 2, 1.01 / 2, z=1.01 / 2, rgba=CARDBOARD),
        # the tape stands 1 cm proud: the 16-bit depth buffer cannot separate a thinner layer
        _box(1.185 / 2 + 0.001, 0.04, 0.005, z=1.01 + 0.005, rgba=(0.55, 0.40, 0.25, 1.0), collide=False),
    )


def pallet_parts() -> tuple[Part, ...]:
    """EUR pallet 1.2 x 0.8 x 0.144 m: top deck on three stringer blocks (bottom at z = 0)."""
    parts = [_box(0.6, 0.4, 0.011, z=0.144 - 0.011, rgba=WOOD)]
    for y in (-0.345, 0.0, 0.345):
        parts.append(_box(0.6, 0.05, 0.061, y=y, z=0.061, rgba=(0.70, 0.56, 0.38, 1.0)))
    return tuple(parts)


def floor_marking_parts(length_m: float, width_m: float, *, striped: bool) -> tuple[Part, ...]:
    """Painted floor line along x, 2 cm proud (16-bit depth buffer); striped alternate with black."""
    hz, z = 0.01, 0.01
    if not striped:
        return (_box(length_m / 2, width_m / 2, hz, z=z, rgba=SAFETY_YELLOW, collide=False),)
    n = max(1, round(length_m / 0.5))
    seg = length_m / n
    return tuple(
        _box(
            seg / 2,
            width_m / 2,
            hz,
            x=-length_m / 2 + (i + 0.5) * seg,
            z=z,
            rgba=SAFETY_YELLOW if i % 2 == 0 else BLACK,
            collide=False,
        )
        for i in range(n)
    )


def railing_parts() -> tuple[Part, ...]:
    """Yellow guard rail segment 1.2 m long: two posts, top and knee rails."""
    return (
        _box(0.03, 0.03, 0.55, x=-0.57, z=0.55, rgba=SAFETY_YELLOW),
        _box(0.03, 0.03, 0.55, x=0.57, z=0.55, rgba=SAFETY_YELLOW),
        _box(0.6, 0.025, 0.025, z=1.08, rgba=SAFETY_YELLOW),
        _box(0.6, 0.025, 0.025, z=0.55, rgba=SAFETY_YELLOW),
    )


def support_pole_parts() -> tuple[Part, ...]:
    """Steel column 0.3 x 0.3 m to the roof with a yellow-black guard sleeve at its foot."""
    return (
        _box(0.15, 0.15, BUILDING_HEIGHT_M / 2, z=BUILDING_HEIGHT_M / 2, rgba=STEEL),
        _box(0.17, 0.17, 0.25, z=0.25, rgba=SAFETY_YELLOW, collide=False),
        _box(0.171, 0.171, 0.1, z=0.6, rgba=BLACK, collide=False),
    )


def wall_parts() -> tuple[Part, ...]:
    """Building shell: four walls, the north one with a door opening (SIMLAN's 'factory')."""
    (x0, x1), (y0, y1), h, t = BUILDING_X_M, BUILDING_Y_M, BUILDING_HEIGHT_M, WALL_THICKNESS_M
    dl, dr = DOOR_X_M
    return (
        _box((x1 - x0) / 2 + t, t / 2, h / 2, (x0 + x1) / 2, y0 - t / 2, h / 2, WALL),
        _box((dl - x0) / 2 + t / 2, t / 2, h / 2, (x0 - t + dl) / 2, y1 + t / 2, h / 2, WALL),
        _box((x1 - dr) / 2 + t / 2, t / 2, h / 2, (dr + x1 + t) / 2, y1 + t / 2, h / 2, WALL),
        _box(t / 2, (y1 - y0) / 2, h / 2, x0 - t / 2, (y0 + y1) / 2, h / 2, WALL),
        _box(t / 2, (y1 - y0) / 2, h / 2, x1 + t / 2, (y0 + y1) / 2, h / 2, WALL),
    )


def floor_parts(
    x_range: tuple[float, float], y_range: tuple[float, float], *, slabs: bool
) -> tuple[Part, ...]:
    """Concrete floor as slabs of varying shade with dark joints (slab tops at z = 0).

    The shade of each slab is a fixed function of its index, so every run looks the same.
    """
    (x0, x1), (y0, y1) = x_range, y_range
    thickness = 0.1
    if not slabs:
        return (
            FLOOR_PLANE,
            _box(
                (x1 - x0) / 2,
                (y1 - y0) / 2,
                thickness / 2,
                (x0 + x1) / 2,
                (y0 + y1) / 2,
                -thickness / 2,
                CONCRETE,
                collide=False,
            ),
        )
    # PyBullet's EGL depth buffer has 16 bits: overlapping coplanar surfaces flicker. The collision
    # plane is invisible, the visual slabs do not overlap, and the dark plane that shows through
    # the joints lies 3 cm lower.
    parts: list[Part] = [
        FLOOR_PLANE,
        Part(
            "box",
            ((x1 - x0) / 2, (y1 - y0) / 2, 0.005),
            ((x0 + x1) / 2, (y0 + y1) / 2, -0.035),
            rgba=JOINT,
            collide=False,
        ),
    ]
    nx, ny = int(np.ceil((x1 - x0) / SLAB_M)), int(np.ceil((y1 - y0) / SLAB_M))
    rng = np.random.default_rng(20240531)
    # eight shades: the renderer draws one colour per link, so few distinct colours keep it cheap
    shades = rng.integers(-4, 4, size=(nx, ny)) * 0.018
    for i in range(nx):
        for j in range(ny):
            sx0, sx1 = x0 + i * SLAB_M, min(x1, x0 + (i + 1) * SLAB_M)
            sy0, sy1 = y0 + j * SLAB_M, min(y1, y0 + (j + 1) * SLAB_M)
            s = float(shades[i, j])
            rgba = (CONCRETE[0] + s, CONCRETE[1] + s, CONCRETE[2] + s * 0.9, 1.0)
            parts.append(
                _box(
                    (sx1 - sx0 - JOINT_WIDTH_M) / 2,
                    (sy1 - sy0 - JOINT_WIDTH_M) / 2,
                    0.005,
                    (sx0 + sx1) / 2,
                    (sy0 + sy1) / 2,
                    -0.005,
                    rgba,
                    collide=False,
                )
            )
    return tuple(parts)


def _generic(hx: float, hy: float, hz: float, rgba: Rgba) -> tuple[Part, ...]:
    return (_box(hx, hy, hz, z=hz, rgba=rgba),)


MODEL_SPECS: dict[str, ModelSpec] = {
    # Gazebo's infinite ground plane: a plain floor under the whole site
    "ground_plane": ModelSpec(
        "floor", "floor", floor_parts((-35.0, 50.0), (-45.0, 30.0), slabs=False), world_frame=True
    ),
    "ground_collision": ModelSpec("floor", "floor", ()),
    "ground_visual_updated": ModelSpec(
        "floor",
        "floor",
        (
            *floor_parts(BUILDING_X_M, BUILDING_Y_M, slabs=True),
            _box(
                (BUILDING_X_M[1] - BUILDING_X_M[0]) / 2 + 5.0,
                (YARD_Y_M[1] - YARD_Y_M[0]) / 2,
                0.05,
                (BUILDING_X_M[0] + BUILDING_X_M[1]) / 2,
                (YARD_Y_M[0] + YARD_Y_M[1]) / 2,
                -0.05,
                ASPHALT,
                collide=False,
            ),
        ),
    ),
    "concrete_ground": ModelSpec(
        "floor", "floor", (_box(10.0, 5.0, 0.0075, z=0.0075, rgba=(0.50, 0.50, 0.49, 1.0), collide=False),)
    ),
    "factory": ModelSpec("wall", "structure", wall_parts(), world_frame=True),
    "shelf": ModelSpec("shelf", "shelf", shelf_parts()),
    # SIMLAN's box origin is 0.4 m above its bottom (boxes at z 0.4 / 1.4 stand on the floor / 1 m deck)
    "box_1185x785x1010": ModelSpec("box", "box", box_parts(), movable=True, z_offset_m=-0.4),
    "eur_pallet": ModelSpec("pallet", "pallet", pallet_parts(), movable=True),
    "hazard_lines": ModelSpec("floor_marking", "floor", floor_marking_parts(6.0, 0.1, striped=False)),
    "hazard_lines_striped": ModelSpec(
        "floor_marking", "floor", floor_marking_parts(12.0, 0.15, striped=True)
    ),
    "hazard_lines_striped_scaled": ModelSpec(
        "floor_marking", "floor", floor_marking_parts(6.0, 0.15, striped=True)
    ),
    "railing": ModelSpec("railing", "structure", railing_parts()),
    "support_pole": ModelSpec("pole", "structure", support_pole_parts()),
    "truck": ModelSpec(
        "vehicle",
        "structure",
        (
            _box(6.0, 1.25, 1.9, z=2.0, rgba=(0.92, 0.92, 0.95, 1.0)),
            _box(1.0, 1.25, 1.4, x=7.0, z=1.5, rgba=(0.15, 0.3, 0.7, 1.0)),
        ),
    ),
    "electrical_box": ModelSpec("furniture", "structure", _generic(0.3, 0.2, 0.9, (0.5, 0.52, 0.55, 1.0))),
    "blue_cabinet": ModelSpec("furniture", "structure", _generic(0.5, 0.25, 1.0, (0.12, 0.3, 0.75, 1.0))),
    "table": ModelSpec(
        "furniture",
        "structure",
        (
            _box(0.8, 0.4, 0.025, z=0.875, rgba=(0.7, 0.6, 0.45, 1.0)),
            *(
                _box(0.03, 0.03, 0.425, x=sx * 0.75, y=sy * 0.35, z=0.425, rgba=STEEL)
                for sx in (-1, 1)
                for sy in (-1, 1)
            ),
        ),
    ),
    "robot_arm_beam": ModelSpec(
        "furniture",
        "structure",
        (
            _box(0.15, 0.15, 1.5, x=-1.5, z=1.5, rgba=RACK_ORANGE),
            _box(0.15, 0.15, 1.5, x=1.5, z=1.5, rgba=RACK_ORANGE),
            _box(1.65, 0.15, 0.15, z=3.15, rgba=RACK_ORANGE),
        ),
    ),
    "flow_rack": ModelSpec("shelf", "shelf", _generic(1.2, 0.6, 0.9, (0.35, 0.55, 0.35, 1.0))),
    "stacking_crate": ModelSpec("box", "structure", _generic(0.3, 0.2, 0.15, (0.2, 0.35, 0.75, 1.0))),
    "truck_part_hose": ModelSpec("furniture", "structure", (_cyl(0.04, 0.5, z=0.25, rgba=BLACK),)),
    "truck_part_gold_bar": ModelSpec(
        "furniture", "structure", _generic(0.15, 0.05, 0.03, (0.85, 0.7, 0.2, 1.0))
    ),
}


def model_spec(model: str) -> ModelSpec | None:
    """Return the spec of a layout model name, or None for models this twin does not build."""
    return MODEL_SPECS.get(model)
