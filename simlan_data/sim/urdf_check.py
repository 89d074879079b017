"""Check an agent type's URDF before PyBullet sees it (PyBullet prints to stderr and raises a bare
``error`` on bad files; a half-loaded robot fails much later).

Checked: the file exists and is small; it is well-formed XML with a ``<robot>`` root; joints
name links that exist; a robot that carries a marker has the marker placeholder; a
differential-drive robot has its two wheel joints (continuous or revolute) and its caster links.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pybullet_data

from simlan_data.constants import URDF_DIR
from simlan_data.errors import AssetError
from simlan_data.world.agent_types import AgentType

MARKER_PLACEHOLDER = "<!-- ARUCO_MARKER -->"
MAX_URDF_BYTES = 10 << 20
WHEEL_JOINT_TYPES = ("continuous", "revolute")


def urdf_path(kind: AgentType, urdf_dir: Path = URDF_DIR) -> Path:
    if kind.urdf.startswith("pybullet_data:"):
        return Path(pybullet_data.getDataPath()) / kind.urdf.split(":", 1)[1]
    return urdf_dir / kind.urdf


def check_urdf(kind: AgentType, urdf_dir: Path = URDF_DIR) -> Path:
    """Return the URDF path of ``kind`` after checking it.

    Raises:
        AssetError: one line naming the file and what is wrong with it.
    """
    path = urdf_path(kind, urdf_dir)

    def bad(what: str, why: str, fix: str = "restore the packaged URDF") -> AssetError:
        return AssetError(what, f"{path} (agent type {kind.name})", why, fix)

    if not path.is_file():
        raise bad("URDF file missing", "no such file")
    if path.stat().st_size > MAX_URDF_BYTES:
        raise bad("URDF file too large", f"over {MAX_URDF_BYTES} bytes")
    try:
        text = path.read_bytes().decode("utf-8")
        root = ET.fromstring(text)
    except UnicodeDecodeError as err:
        raise bad("URDF file unreadable", f"not UTF-8 text ({err.reason})") from None
    except ET.ParseError as err:
        line, col = err.position
        raise bad(
            "URDF file is not valid XML", f"{str(err).split(':')[0]} at line {line}, column {col}"
        ) from None
    if root.tag != "robot":
        raise bad("URDF file has no <robot> root", f"the root element is <{root.tag}>")
    links = {link.get("name") for link in root.iter("link")}
    if not links:
        raise bad("URDF file has no links", "a robot needs at least one <link>")
    joints = {j.get("name"): j for j in root.iter("joint")}
    for name, joint in joints.items():
        for end in ("parent", "child"):
            node = joint.find(end)
            ref = node.get("link") if node is not None else None
            if ref not in links:
                raise bad(
                    f"URDF joint '{name}' names an unknown {end} link",
                    f"{end} link {ref!r} is not defined",
                    "fix the joint or add the link",
                )
    if kind.marker_xyz is not None and MARKER_PLACEHOLDER not in text:
        raise bad(
            "URDF lacks the marker placeholder",
            f"no {MARKER_PLACEHOLDER} line, so the robot would carry no ArUco marker",
            "put the placeholder inside the link that carries the marker",
        )
    if kind.drive == "diff":
        for name in kind.wheel_joints:
            wheel = joints.get(name)
            if wheel is None:
                raise bad(
                    f"URDF lacks wheel joint '{name}'",
                    f"a {kind.drive}-drive robot is driven through {' and '.join(kind.wheel_joints)}",
                    "add the joint or restore the packaged URDF",
                )
            if wheel.get("type") not in WHEEL_JOINT_TYPES:
                raise bad(
                    f"URDF wheel joint '{name}' cannot turn",
                    f"its type is {wheel.get('type')!r}",
                    f"make it one of {', '.join(WHEEL_JOINT_TYPES)}",
                )
        missing = [c for c in kind.caster_links if c not in links]
        if missing:
            raise bad("URDF lacks caster links", ", ".join(missing), "add them or restore the packaged URDF")
    return path
