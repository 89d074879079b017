"""The humanoid's skeleton as data: 47 joints, dressed link geometry, the 33 landmarks, numpy FK.

One table drives everything that needs the body: the URDF (``world/humanoid_urdf.py`` writes
``assets/urdf/humanoid.urdf`` from it), the projection pose estimator (landmarks attached to
links), the re-posing metric (MPJPE) and the drive. Pure numpy, no simulator.

Kinematics follow SIMLAN's human model (robotology's human-gazebo ``humanSubject01``, the
Xsens-style 48-DoF body, reduced by SIMLAN to 44 revolute joints: the lumbar joints L4L3 and
L1T12 are fixed), hung from SIMLAN's 3-joint support arm (``link1_link2_joint`` about x,
``link2_link3_joint`` about y, ``link3_link4_joint`` about z, all within +-pi/2): 47 joint
targets in all, in SIMLAN's order (the order of its motion files and its ``movable_joint_names``).

Frames: every link frame is parallel to the pelvis in the zero pose (x forward, y to the person's
left, z up); the zero pose is a T-pose. The support arm's base (``base_link``) stands on the floor
0.2 m behind the pelvis, which hangs 1.52 m up as in SIMLAN (the humanoid-capture cameras 500-503
look horizontally from 2 m: the body spans about 0.6-2.3 m, centred in their view).

One departure from SIMLAN, on purpose: SIMLAN's arm pivots 0.52 m above the floor with the pelvis
1 m above the pivot, so at the random +-72 degrees (0.8 x +-pi/2) the body swings down through
the floor and out of the cameras' view (measured with that geometry: 52 % of the landmarks
visible). Here the same three joints (names, axes, limits, order) pivot 0.22 m from the pelvis
(a 1.3 m pole behind the person): they are the body's global orientation, the body stays in view.

Joint limits are the human-gazebo URDF's ``lower < upper``. SIMLAN's ``pose_to_motion`` config
lists the same numbers with the two lists swapped for the 44 human joints (its
``movable_joint_upper`` holds the lower limits); :func:`limits_from_simlan_lists` undoes that.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

SUPPORT_JOINTS = ("link1_link2_joint", "link2_link3_joint", "link3_link4_joint")
HALF_PI = 1.5707  # SIMLAN's support-arm limit (its config writes 1.5707)


@dataclass(frozen=True)
class Joint:
    """One URDF joint: ``revolute`` (axis, limits) or ``fixed``."""

    name: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    axis: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lower: float = 0.0
    upper: float = 0.0

    @property
    def revolute(self) -> bool:
        return any(self.axis)


@dataclass(frozen=True)
class Visual:
    """One primitive of a link: ``box`` (size x y z), ``cylinder`` (radius, length) or ``sphere`` (radius)."""

    shape: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Link:
    name: str
    material: str
    visuals: tuple[Visual, ...] = ()


@dataclass(frozen=True)
class Landmark:
    """A MediaPipe Pose landmark attached to a link; ``inside_m``: how deep under the body's surface it lies."""

    name: str
    link: str
    xyz: tuple[float, float, float]
    inside_m: float


MATERIALS = {
    "skin": (0.87, 0.68, 0.55, 1.0),
    "hair": (0.18, 0.12, 0.08, 1.0),
    "eyes": (0.05, 0.05, 0.05, 1.0),
    "shirt": (0.15, 0.35, 0.75, 1.0),
    "trousers": (0.20, 0.20, 0.25, 1.0),
    "shoes": (0.08, 0.06, 0.05, 1.0),
    "metal": (0.55, 0.57, 0.60, 1.0),
}

_ALONG_Y = (1.5707963267948966, 0.0, 0.0)  # a URDF cylinder (along z) turned to lie along y


def _side(name: str, sign: float) -> str:
    return name.replace("Side", "Right" if sign < 0 else "Left")


class _Body:
    """The joints and links of the body in the order they are declared (the URDF's order)."""

    def __init__(self) -> None:
        self.joints: list[Joint] = []
        self.links: list[Link] = []

    def rev(
        self,
        name: str,
        parent: str,
        child: str,
        xyz: tuple[float, float, float],
        axis: str,
        lo: float,
        hi: float,
    ) -> None:
        """Add a revolute joint about the parent's x, y or z axis."""
        vec = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}[axis]
        self.joints.append(Joint(name, parent, child, xyz, vec, lo, hi))

    def frame(self, name: str) -> None:
        """Add a massless frame between two joints of one anatomical joint."""
        self.links.append(Link(name, "", ()))


def _support_arm(b: _Body) -> None:
    """Add SIMLAN's three-joint support arm (x, y, z, +-pi/2), its pivot just behind the pelvis."""
    J, L, rev = b.joints, b.links, b.rev
    L.append(Link("base_link", "metal", (Visual("box", (0.3, 0.3, 0.02), (0.0, 0.0, 0.01)),)))
    L.append(Link("link1", "metal", (Visual("cylinder", (0.025, 1.3), (0.0, 0.0, 0.65)),)))
    J.append(Joint("base_link1_joint", "base_link", "link1", (0.0, 0.0, 0.02)))
    L.append(Link("link2", "metal", (Visual("cylinder", (0.025, 0.05), (0.0, 0.0, 0.025)),)))
    L.append(Link("link3", "metal", (Visual("cylinder", (0.025, 0.05), (0.0, 0.0, 0.025)),)))
    L.append(
        Link(
            "link4",
            "metal",
            (
                Visual("cylinder", (0.02, 0.1), (0.0, 0.0, 0.05)),
                Visual("box", (0.14, 0.03, 0.03), (0.07, 0.0, 0.1)),
            ),
        )
    )
    rev("link1_link2_joint", "link1", "link2", (0.0, 0.0, 1.3), "x", -HALF_PI, HALF_PI)
    rev("link2_link3_joint", "link2", "link3", (0.0, 0.0, 0.05), "y", -HALF_PI, HALF_PI)
    rev("link3_link4_joint", "link3", "link4", (0.0, 0.0, 0.05), "z", -HALF_PI, HALF_PI)
    J.append(Joint("arm_human_joint", "link4", "Pelvis", (0.2, 0.0, 0.1)))


def _trunk(b: _Body) -> None:
    """Add the pelvis, abdomen, chest, neck and head (hair and eyes as links of their own)."""
    J, L, rev, frame = b.joints, b.links, b.rev, b.frame
    L.append(Link("Pelvis", "trousers", (Visual("box", (0.18, 0.31, 0.16), (0.0, 0.0, 0.03)),)))
    frame("L5_f1")
    rev("jL5S1_rotx", "Pelvis", "L5_f1", (-0.000206, 0.0, 0.098478), "x", -0.610865, 0.610865)
    rev("jL5S1_roty", "L5_f1", "L5", (0.0, 0.0, 0.0), "y", -0.523599, 1.309)
    # abdomen up to T9T8 (L4L3 and L1T12 are fixed in SIMLAN's model: one link here)
    L.append(Link("L5", "shirt", (Visual("box", (0.19, 0.30, 0.27), (0.0, 0.0, 0.13)),)))
    frame("T8_f1")
    frame("T8_f2")
    rev("jT9T8_rotx", "L5", "T8_f1", (0.000374, 0.0, 0.266936), "x", -0.349066, 0.349066)
    rev("jT9T8_roty", "T8_f1", "T8_f2", (0.0, 0.0, 0.0), "y", -0.261799, 0.698132)
    rev("jT9T8_rotz", "T8_f2", "T8", (0.0, 0.0, 0.0), "z", -0.610865, 0.610865)
    L.append(Link("T8", "shirt", (Visual("box", (0.21, 0.33, 0.16), (0.0, 0.0, 0.045)),)))
    frame("Neck_f1")
    frame("Neck_f2")
    rev("jT1C7_rotx", "T8", "Neck_f1", (0.0, 0.0, 0.11975), "x", -0.610865, 0.610865)
    rev("jT1C7_roty", "Neck_f1", "Neck_f2", (0.0, 0.0, 0.0), "y", -0.959931, 1.5708)
    rev("jT1C7_rotz", "Neck_f2", "Neck", (0.0, 0.0, 0.0), "z", -1.22173, 1.22173)
    L.append(Link("Neck", "skin", (Visual("cylinder", (0.05, 0.1), (0.0, 0.0, 0.045)),)))
    frame("Head_f1")
    rev("jC1Head_rotx", "Neck", "Head_f1", (0.000152, 0.0, 0.089252), "x", -0.610865, 0.610865)
    rev("jC1Head_roty", "Head_f1", "Head", (0.0, 0.0, 0.0), "y", -0.436332, 0.174533)
    L.append(Link("Head", "skin", (Visual("sphere", (0.1,), (0.0, 0.0, 0.1)),)))
    # one colour per link (PyBullet's EGL renderer): hair and eyes are links of their own
    L.append(Link("Hair", "hair", (Visual("sphere", (0.1,), (-0.025, 0.0, 0.125)),)))
    J.append(Joint("jHair", "Head", "Hair", (0.0, 0.0, 0.0)))
    L.append(
        Link(
            "Eyes",
            "eyes",
            (
                Visual("sphere", (0.013,), (0.087, 0.035, 0.12)),
                Visual("sphere", (0.013,), (0.087, -0.035, 0.12)),
            ),
        )
    )
    J.append(Joint("jEyes", "Head", "Eyes", (0.0, 0.0, 0.0)))


def _arm(b: _Body, s: float) -> None:
    """Add one arm, shoulder to hand: the right one for ``s = -1`` (-y), the left one for ``s = 1``."""
    L, rev, frame = b.links, b.rev, b.frame
    side = "Right" if s < 0 else "Left"
    # SIMLAN's names: jC7RightShoulder_rotx (human-gazebo: jRightC7Shoulder_rotx)
    lo, hi = (-0.785398, 0.0872665) if s < 0 else (-0.0872665, 0.785398)
    rev(f"jC7{side}Shoulder_rotx", "T8", f"{side}Shoulder", (0.0, s * 0.026313, 0.067052), "x", lo, hi)
    L.append(
        Link(
            f"{side}Shoulder",
            "shirt",
            (Visual("cylinder", (0.05, 0.13), (0.0, s * 0.065, 0.0), _ALONG_Y),),
        )
    )
    frame(f"{side}UpperArm_f1")
    frame(f"{side}UpperArm_f2")
    lo, hi = (-2.35619, 1.5708) if s < 0 else (-1.5708, 2.35619)
    rev(
        f"j{side}Shoulder_rotx",
        f"{side}Shoulder",
        f"{side}UpperArm_f1",
        (0.0, s * 0.13047, 0.0),
        "x",
        lo,
        hi,
    )
    rev(
        f"j{side}Shoulder_roty",
        f"{side}UpperArm_f1",
        f"{side}UpperArm_f2",
        (0.0, 0.0, 0.0),
        "y",
        -1.5708,
        1.5708,
    )
    lo, hi = (-0.785398, 3.14159) if s < 0 else (-3.14159, 0.785398)
    rev(f"j{side}Shoulder_rotz", f"{side}UpperArm_f2", f"{side}UpperArm", (0.0, 0.0, 0.0), "z", lo, hi)
    L.append(
        Link(
            f"{side}UpperArm",
            "shirt",
            (Visual("cylinder", (0.045, 0.27), (0.0, s * 0.135, 0.0), _ALONG_Y),),
        )
    )
    frame(f"{side}ForeArm_f1")
    rev(
        f"j{side}Elbow_roty",
        f"{side}UpperArm",
        f"{side}ForeArm_f1",
        (0.0, s * 0.26994, 0.0),
        "y",
        -1.5708,
        1.48353,
    )
    lo, hi = (0.0, 2.53073) if s < 0 else (-2.53073, 0.0)
    rev(f"j{side}Elbow_rotz", f"{side}ForeArm_f1", f"{side}ForeArm", (0.0, 0.0, 0.0), "z", lo, hi)
    L.append(
        Link(
            f"{side}ForeArm",
            "skin",
            (Visual("cylinder", (0.034, 0.222), (0.0, s * 0.111, 0.0), _ALONG_Y),),
        )
    )
    frame(f"{side}Hand_f1")
    lo, hi = (-0.872665, 1.0472) if s < 0 else (-1.0472, 0.872665)
    rev(f"j{side}Wrist_rotx", f"{side}ForeArm", f"{side}Hand_f1", (7.7e-05, s * 0.22247, 0.0), "x", lo, hi)
    lo, hi = (-0.523599, 0.349066) if s < 0 else (-0.349066, 0.523599)
    rev(f"j{side}Wrist_rotz", f"{side}Hand_f1", f"{side}Hand", (0.0, 0.0, 0.0), "z", lo, hi)
    L.append(Link(f"{side}Hand", "skin", (Visual("box", (0.095, 0.17, 0.035), (0.0, s * 0.085, 0.0)),)))


def _leg(b: _Body, s: float) -> None:
    """Add one leg, hip to toe: the right one for ``s = -1`` (-y), the left one for ``s = 1``."""
    L, rev, frame = b.links, b.rev, b.frame
    side = "Right" if s < 0 else "Left"
    frame(f"{side}UpperLeg_f1")
    frame(f"{side}UpperLeg_f2")
    lo, hi = (-0.785398, 0.523599) if s < 0 else (-0.523599, 0.785398)
    rev(
        f"j{side}Hip_rotx",
        "Pelvis",
        f"{side}UpperLeg_f1",
        (0.000103, s * 0.081614, 0.001009),
        "x",
        lo,
        hi,
    )
    rev(
        f"j{side}Hip_roty",
        f"{side}UpperLeg_f1",
        f"{side}UpperLeg_f2",
        (0.0, 0.0, 0.0),
        "y",
        -2.0944,
        0.261799,
    )
    rev(
        f"j{side}Hip_rotz",
        f"{side}UpperLeg_f2",
        f"{side}UpperLeg",
        (0.0, 0.0, 0.0),
        "z",
        -0.785398,
        0.785398,
    )
    L.append(Link(f"{side}UpperLeg", "trousers", (Visual("cylinder", (0.07, 0.449), (0.0, 0.0, -0.2245)),)))
    frame(f"{side}LowerLeg_f1")
    rev(
        f"j{side}Knee_roty",
        f"{side}UpperLeg",
        f"{side}LowerLeg_f1",
        (3.6e-05, 0.0, -0.44898),
        "y",
        0.0,
        2.35619,
    )
    lo, hi = (-0.698132, 0.523599) if s < 0 else (-0.523599, 0.698132)
    rev(f"j{side}Knee_rotz", f"{side}LowerLeg_f1", f"{side}LowerLeg", (0.0, 0.0, 0.0), "z", lo, hi)
    L.append(Link(f"{side}LowerLeg", "trousers", (Visual("cylinder", (0.05, 0.406), (0.0, 0.0, -0.203)),)))
    frame(f"{side}Foot_f1")
    frame(f"{side}Foot_f2")
    lo, hi = (-0.610865, 0.785398) if s < 0 else (-0.785398, 0.610865)
    rev(f"j{side}Ankle_rotx", f"{side}LowerLeg", f"{side}Foot_f1", (0.000205, 0.0, -0.40608), "x", lo, hi)
    rev(
        f"j{side}Ankle_roty",
        f"{side}Foot_f1",
        f"{side}Foot_f2",
        (0.0, 0.0, 0.0),
        "y",
        -0.523599,
        0.872665,
    )
    lo, hi = (-0.436332, 0.872665) if s < 0 else (-0.872665, 0.436332)
    rev(f"j{side}Ankle_rotz", f"{side}Foot_f2", f"{side}Foot", (0.0, 0.0, 0.0), "z", lo, hi)
    L.append(Link(f"{side}Foot", "shoes", (Visual("box", (0.19, 0.09, 0.08), (0.05, 0.0, -0.04)),)))
    rev(
        f"j{side}BallFoot_roty",
        f"{side}Foot",
        f"{side}Toe",
        (0.14456, 0.0, -0.064752),
        "y",
        -0.174533,
        1.5708,
    )
    L.append(Link(f"{side}Toe", "shoes", (Visual("box", (0.07, 0.09, 0.03), (0.03, 0.0, 0.0)),)))


def _build() -> tuple[tuple[Joint, ...], tuple[Link, ...]]:
    """Declare the whole body: support arm, trunk, both arms, both legs, in the URDF's order."""
    b = _Body()
    _support_arm(b)
    _trunk(b)
    for s in (-1.0, 1.0):
        _arm(b, s)
    for s in (-1.0, 1.0):
        _leg(b, s)
    return tuple(b.joints), tuple(b.links)


JOINTS_ALL, LINKS = _build()

# SIMLAN's order of the 47 joint targets (its motion files and movable_joint_names)
JOINT_NAMES: tuple[str, ...] = (
    "jL5S1_rotx", "jL5S1_roty", "jT9T8_rotx", "jT9T8_roty", "jT9T8_rotz",
    "jC7RightShoulder_rotx", "jC7LeftShoulder_rotx", "jT1C7_rotx", "jT1C7_roty", "jT1C7_rotz",
    "jC1Head_rotx", "jC1Head_roty",
    "jRightShoulder_rotx", "jRightShoulder_roty", "jRightShoulder_rotz", "jRightElbow_roty",
    "jRightElbow_rotz", "jRightWrist_rotx", "jRightWrist_rotz",
    "jLeftShoulder_rotx", "jLeftShoulder_roty", "jLeftShoulder_rotz", "jLeftElbow_roty",
    "jLeftElbow_rotz", "jLeftWrist_rotx", "jLeftWrist_rotz",
    "jRightHip_rotx", "jRightHip_roty", "jRightHip_rotz", "jRightKnee_roty", "jRightKnee_rotz",
    "jRightAnkle_rotx", "jRightAnkle_roty", "jRightAnkle_rotz", "jRightBallFoot_roty",
    "jLeftHip_rotx", "jLeftHip_roty", "jLeftHip_rotz", "jLeftKnee_roty", "jLeftKnee_rotz",
    "jLeftAnkle_rotx", "jLeftAnkle_roty", "jLeftAnkle_rotz", "jLeftBallFoot_roty",
    *SUPPORT_JOINTS,
)  # fmt: skip
HUMAN_JOINT_NAMES = JOINT_NAMES[:44]
NUM_JOINTS = len(JOINT_NAMES)

_BY_NAME = {j.name: j for j in JOINTS_ALL}
JOINTS: tuple[Joint, ...] = tuple(_BY_NAME[n] for n in JOINT_NAMES)
LOWER = np.array([j.lower for j in JOINTS])
UPPER = np.array([j.upper for j in JOINTS])

# MediaPipe Pose's 33 landmarks, in its order; "left" is the person's left (+y here)
LANDMARK_NAMES: tuple[str, ...] = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
    "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
    "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel", "right_heel",
    "left_foot_index", "right_foot_index",
)  # fmt: skip
NUM_LANDMARKS = len(LANDMARK_NAMES)


def _landmarks() -> tuple[Landmark, ...]:
    head = {
        "nose": ((0.108, 0.0, 0.085), 0.005),
        "left_eye_inner": ((0.094, 0.018, 0.12), 0.01),
        "left_eye": ((0.093, 0.035, 0.12), 0.01),
        "left_eye_outer": ((0.086, 0.052, 0.12), 0.01),
        "left_ear": ((0.0, 0.1, 0.1), 0.01),
        "mouth_left": ((0.092, 0.028, 0.055), 0.01),
    }
    out: dict[str, Landmark] = {}
    for name, (xyz, inside) in head.items():
        out[name] = Landmark(name, "Head", xyz, inside)
        mirror = name.replace("left", "right") if "left" in name else None
        if mirror:
            out[mirror] = Landmark(mirror, "Head", (xyz[0], -xyz[1], xyz[2]), inside)
    for side, s in (("left", 1.0), ("right", -1.0)):
        S = side.capitalize()
        out[f"{side}_shoulder"] = Landmark(f"{side}_shoulder", f"{S}UpperArm", (0.0, 0.0, 0.0), 0.06)
        out[f"{side}_elbow"] = Landmark(f"{side}_elbow", f"{S}ForeArm", (0.0, 0.0, 0.0), 0.05)
        out[f"{side}_wrist"] = Landmark(f"{side}_wrist", f"{S}Hand", (0.0, 0.0, 0.0), 0.04)
        # palms face down in the zero pose, thumbs forward: knuckles of the hand box
        out[f"{side}_pinky"] = Landmark(f"{side}_pinky", f"{S}Hand", (-0.035, s * 0.1, 0.0), 0.025)
        out[f"{side}_index"] = Landmark(f"{side}_index", f"{S}Hand", (0.03, s * 0.11, 0.0), 0.025)
        out[f"{side}_thumb"] = Landmark(f"{side}_thumb", f"{S}Hand", (0.055, s * 0.05, 0.0), 0.025)
        out[f"{side}_hip"] = Landmark(f"{side}_hip", f"{S}UpperLeg", (0.0, 0.0, 0.0), 0.09)
        out[f"{side}_knee"] = Landmark(f"{side}_knee", f"{S}LowerLeg", (0.0, 0.0, 0.0), 0.06)
        out[f"{side}_ankle"] = Landmark(f"{side}_ankle", f"{S}Foot", (0.0, 0.0, 0.0), 0.06)
        out[f"{side}_heel"] = Landmark(f"{side}_heel", f"{S}Foot", (-0.04, 0.0, -0.06), 0.03)
        out[f"{side}_foot_index"] = Landmark(f"{side}_foot_index", f"{S}Toe", (0.06, 0.0, -0.005), 0.03)
    return tuple(out[n] for n in LANDMARK_NAMES)


LANDMARKS = _landmarks()


def limits_from_simlan_lists(
    names: list[str], upper_list: list[float], lower_list: list[float]
) -> dict[str, tuple[float, float]]:
    """Read SIMLAN's ``movable_joint_upper`` / ``movable_joint_lower`` lists as ``(lower, upper)``.

    SIMLAN's config swaps them for the human joints (its "upper" list holds the smaller number);
    for the support arm they are in order. Whatever the order, the smaller number is the lower limit.
    """
    return {n: (min(a, b), max(a, b)) for n, a, b in zip(names, upper_list, lower_list)}


def sample_joints(rng: np.random.Generator, n: int, *, limit_scale: float = 0.8) -> FloatArray:
    """``n`` random configurations (n, 47), uniform within ``limit_scale`` x the limits (as SIMLAN).

    Scaling is about zero (SIMLAN's ``limit * 0.8``); a range that does not contain zero (none
    here) would be scaled about its middle instead.
    """
    lo, hi = sampling_box(limit_scale)
    return rng.uniform(lo, hi, size=(n, NUM_JOINTS))


def sampling_box(limit_scale: float = 0.8) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) of :func:`sample_joints`: the limits scaled about zero, or about the middle
    for a range that does not contain zero."""
    straddle = (LOWER <= 0) & (UPPER >= 0)
    mid = (LOWER + UPPER) / 2
    lo = np.where(straddle, LOWER * limit_scale, mid + (LOWER - mid) * limit_scale)
    hi = np.where(straddle, UPPER * limit_scale, mid + (UPPER - mid) * limit_scale)
    return lo, hi


# ------------------------------------------------------------------------------ forward kinematics
@cache
def _chain() -> tuple[tuple[str, ...], tuple[tuple[int, int, int, FloatArray, FloatArray], ...]]:
    """Links in topological order and per joint (parent index, child index, q index or -1, xyz, axis)."""
    order = ["base_link"]
    steps = []
    index = {"base_link": 0}
    pending = list(JOINTS_ALL)
    q_index = {n: i for i, n in enumerate(JOINT_NAMES)}
    while pending:
        rest = []
        for j in pending:
            if j.parent in index:
                index[j.child] = len(order)
                order.append(j.child)
                steps.append(
                    (
                        index[j.parent],
                        index[j.child],
                        q_index.get(j.name, -1),
                        np.array(j.xyz),
                        np.array(j.axis),
                    )
                )
            else:
                rest.append(j)
        if len(rest) == len(pending):
            raise ValueError(f"skeleton joints without a parent link: {[j.name for j in rest]}")
        pending = rest
    return tuple(order), tuple(steps)


def link_names() -> tuple[str, ...]:
    return _chain()[0]


def _axis_rotations(axis: FloatArray, q: FloatArray) -> FloatArray:
    """Rotation matrices (N, 3, 3) about a unit axis by angles q (N,) (Rodrigues)."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    s, c = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def forward_kinematics(q: FloatArray, world_from_base: FloatArray | None = None) -> FloatArray:
    """World poses (N, n_links, 4, 4) of every link for joint vectors q (N, 47) in JOINT_NAMES order."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    if q.shape[1] != NUM_JOINTS:
        raise ValueError(f"expected {NUM_JOINTS} joint values per row, got {q.shape[1]}")
    order, steps = _chain()
    n = len(q)
    T = np.zeros((n, len(order), 4, 4))
    T[:, 0] = np.eye(4) if world_from_base is None else world_from_base
    for parent, child, qi, xyz, axis in steps:
        local = np.tile(np.eye(4), (n, 1, 1))
        local[:, :3, 3] = xyz
        if qi >= 0:
            local[:, :3, :3] = _axis_rotations(axis, q[:, qi])
        T[:, child] = T[:, parent] @ local
    return T


@cache
def _landmark_links() -> tuple[NDArray[np.int64], FloatArray]:
    index = {name: i for i, name in enumerate(link_names())}
    return np.array([index[lm.link] for lm in LANDMARKS]), np.array([lm.xyz for lm in LANDMARKS])


def landmark_positions(q: FloatArray, world_from_base: FloatArray | None = None) -> FloatArray:
    """World positions (N, 33, 3) of the 33 landmarks for joint vectors q (N, 47)."""
    return landmarks_of_links(forward_kinematics(q, world_from_base))


def landmarks_of_links(T: FloatArray) -> FloatArray:
    """Positions (N, 33, 3) of the 33 landmarks, given every link's pose T (N, links, 4, 4)."""
    links, offsets = _landmark_links()
    at = T[:, links]  # (N, 33, 4, 4)
    return np.einsum("nkij,kj->nki", at[..., :3, :3], offsets) + at[..., :3, 3]


LANDMARK_INSIDE_M = np.array([lm.inside_m for lm in LANDMARKS])
