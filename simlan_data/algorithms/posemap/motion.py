"""SIMLAN motion files: one pose as a JSON object ``{joint name: radians}`` over the 47 joints."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simlan_data.constants import MOTIONS_DIR
from simlan_data.errors import AssetError
from simlan_data.world.skeleton import JOINT_NAMES, LOWER, UPPER


def resolve_motion_path(name: str) -> Path:
    """A motion file by path, or by name in the packaged ``assets/motions``."""
    path = Path(name)
    if path.is_file():
        return path
    packaged = MOTIONS_DIR / (name if name.endswith(".json") else f"{name}.json")
    if packaged.is_file():
        return packaged
    known = ", ".join(sorted(p.stem for p in MOTIONS_DIR.glob("*.json")))
    raise AssetError(
        "motion file not found",
        name,
        f"no such file, and no packaged motion of that name (packaged: {known})",
        "give a path to a JSON motion file",
    )


def joints_from_mapping(values: Mapping[str, object], where: str) -> NDArray[np.float64]:
    """The 47-vector (SIMLAN's order) of a ``{joint: radians}`` mapping; unknown or missing joints are errors.

    Values outside the joint limits are refused (a motion the body cannot take).
    """
    unknown = sorted(set(values) - set(JOINT_NAMES))
    if unknown:
        raise AssetError(
            f"unknown joint{'s' if len(unknown) > 1 else ''} {', '.join(unknown[:3])}{' ...' if len(unknown) > 3 else ''}",
            where,
            f"the humanoid's 47 joints are SIMLAN's ({JOINT_NAMES[0]}, ..., {JOINT_NAMES[-1]})",
            "rename or remove them",
        )
    missing = [n for n in JOINT_NAMES if n not in values]
    if missing:
        raise AssetError(
            f"missing joint{'s' if len(missing) > 1 else ''} {', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''}",
            where,
            "a motion gives a target for each of the 47 joints",
            "add them (0.0 is the T-pose)",
        )
    q = np.empty(len(JOINT_NAMES))
    for i, name in enumerate(JOINT_NAMES):
        v = values[name]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(float(v)):
            raise AssetError(
                f"invalid value {v!r} of joint {name}", where, "expected a number of radians", "fix the file"
            )
        q[i] = float(v)
    bad = np.flatnonzero((q < LOWER - 1e-6) | (q > UPPER + 1e-6))
    if len(bad):
        i = int(bad[0])
        raise AssetError(
            f"joint {JOINT_NAMES[i]}={q[i]:.4f} rad outside its limits",
            where,
            f"the limits are [{LOWER[i]:.4f}, {UPPER[i]:.4f}] rad",
            "clip it to the limits",
        )
    return q


def load_motion(name: str) -> NDArray[np.float64]:
    """Read a SIMLAN motion file into the 47-vector of joint targets (one clear error line if bad)."""
    path = resolve_motion_path(name)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise AssetError(
            "cannot read motion file", str(path), str(err), "give a JSON object {joint: radians}"
        ) from err
    if not isinstance(data, dict):
        raise AssetError(
            "invalid motion file", str(path), "expected a JSON object {joint: radians}", "fix the file"
        )
    return joints_from_mapping(data, str(path))
