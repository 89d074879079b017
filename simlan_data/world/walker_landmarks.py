"""The walking person's 33 body landmarks (MediaPipe Pose's order), fixed in its ``base_link``.

The walker (``assets/urdf/walker.urdf``) is one rigid dressed body: legs and hips (trousers),
torso and upper arms (shirt), head, neck and forearms (skin), shoes, all fixed to ``base_link``
(on the floor between the feet, x forward, y to the person's left, z up). Its landmarks are
therefore fixed points of that frame, placed on or in the boxes and sphere the URDF draws:
joints at the centre of the limb box they join (``inside_m``: how deep under the surface),
face and foot points on the surface. The articulated humanoid's landmarks hang from its links
instead (``skeleton.LANDMARKS``); both feed the same keypoint ground truth.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from simlan_data.world.skeleton import LANDMARK_NAMES

HEAD_CENTRE_M = (0.0, 0.0, 1.63)  # the URDF's head sphere (radius 0.115)
HEAD_RADIUS_M = 0.115

# name -> (x, y, z) in base_link for the person's left side and the midline; the right side mirrors y
_LEFT_AND_MIDLINE: dict[str, tuple[tuple[float, float, float], float]] = {
    "nose": ((0.115, 0.0, 1.63), 0.0),
    "left_eye_inner": ((0.104, 0.02, 1.665), 0.0),
    "left_eye": ((0.1, 0.035, 1.665), 0.0),
    "left_eye_outer": ((0.094, 0.05, 1.665), 0.0),
    "left_ear": ((0.0, 0.115, 1.63), 0.0),
    "mouth_left": ((0.105, 0.03, 1.595), 0.0),
    "left_shoulder": ((0.0, 0.26, 1.48), 0.04),  # top of the upper-arm box (z 1.08..1.52)
    "left_elbow": ((0.0, 0.26, 1.1), 0.04),  # where the upper arm meets the forearm (z 0.8..1.1)
    "left_wrist": ((0.0, 0.26, 0.84), 0.04),
    "left_pinky": ((-0.045, 0.26, 0.8), 0.0),  # hand corners at the forearm box's lower end
    "left_index": ((0.045, 0.26, 0.8), 0.0),
    "left_thumb": ((0.045, 0.22, 0.84), 0.0),
    "left_hip": ((0.0, 0.1, 0.92), 0.1),  # in the hip box (z 0.87..1.03), over the leg
    "left_knee": ((0.0, 0.1, 0.48), 0.08),  # leg box 0.16 x 0.15, z 0.02..0.88
    "left_ankle": ((0.0, 0.1, 0.08), 0.08),
    "left_heel": ((-0.09, 0.1, 0.03), 0.0),  # shoe box x -0.09..0.17, z 0..0.06
    "left_foot_index": ((0.17, 0.1, 0.03), 0.0),
}


def _table() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    points, inside = [], []
    for name in LANDMARK_NAMES:
        if name in _LEFT_AND_MIDLINE:
            xyz, depth = _LEFT_AND_MIDLINE[name]
        else:  # the person's right: the left's mirror image
            (x, y, z), depth = _LEFT_AND_MIDLINE[name.replace("right", "left")]
            xyz = (x, -y, z)
        points.append(xyz)
        inside.append(depth)
    return np.array(points, dtype=np.float64), np.array(inside, dtype=np.float64)


WALKER_LANDMARKS_M, WALKER_INSIDE_M = _table()  # (33, 3) in base_link, (33,)
