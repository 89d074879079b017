"""Warehouse layout table, fidelity levels, physics parameters, follower."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from simlan_data.algorithms.follower import FollowerParams, WaypointFollower
from simlan_data.errors import AssetError
from simlan_data.sim.pybullet_client import connect
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import PhysicsParams, build_world
from simlan_data.world.labels import SEMANTIC_CLASSES
from simlan_data.world.layout import load_layout


def test_fidelity_levels_nest() -> None:
    counts = {
        level: len(load_layout("warehouse_layout.csv", level))
        for level in ("empty", "light", "medium", "default")
    }
    assert counts["empty"] == 1
    assert counts["light"] < counts["medium"] < counts["default"]
    models = {p.model for p in load_layout("warehouse_layout.csv", "default")}
    assert {"shelf", "box_1185x785x1010", "eur_pallet", "factory"} <= models
    assert "box_1185x785x1010" not in {p.model for p in load_layout("warehouse_layout.csv", "medium")}


def test_simlan_labels() -> None:
    assert SEMANTIC_CLASSES["pallet_truck"] == 51 and SEMANTIC_CLASSES["forklift"] == 50


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("model,name\nshelf,a\n", "lacks columns"),
        (
            "model,name,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,static,world_setups\nshelf,a,1,2,nan,0,0,0,1,default\n",
            "layout row invalid",
        ),
        (
            "model,name,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,static,world_setups\nshelf,a,1,2,0,0,0,0,1,ultra\n",
            "unknown fidelity level",
        ),
    ],
)
def test_bad_layout_files(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "layout.csv"
    path.write_text(text)
    with pytest.raises(AssetError, match=match):
        load_layout(path, "default")
    with pytest.raises(AssetError, match="layout file missing"):
        load_layout(tmp_path / "nope.csv", "default")


def test_world_physics_parameters_and_movable_objects() -> None:
    client = connect("tiny")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            world = build_world(
                client.id,
                load_layout("warehouse_layout.csv", "default"),
                {"pallet": PhysicsParams(mass_kg=25.0, lateral_friction=0.55)},
                mesh_dir=Path(tmp),
            )
        pallets = [b for b in world.movable if world.names[b].startswith("pallet_stack2")]
        assert len(pallets) == 10
        info = pb.getDynamicsInfo(pallets[0], -1, physicsClientId=client.id)
        assert info[0] == pytest.approx(25.0) and info[1] == pytest.approx(0.55)
        # SIMLAN's pickup pallet starts inside a shelf: it is fixed in place and reported
        assert any("pallet_group_pickup" in c for c in world.layout_conflicts)
        # the building has walls: a ray along the main aisle hits the east wall at x = 45.1
        hit = pb.rayTest([0, 0.3, 1.0], [60, 0.3, 1.0], physicsClientId=client.id)[0]
        assert hit[0] >= 0 and hit[3][0] == pytest.approx(45.1, abs=0.01)
    finally:
        client.disconnect()


def test_follower_reaches_waypoints_on_a_unicycle() -> None:
    waypoints = [[5.0, 0.0], [5.0, 4.0], [0.0, 4.0]]
    follower = WaypointFollower(waypoints, FollowerParams(speed_mps=1.0))
    x, y, yaw, dt = 0.0, 0.0, 0.0, 0.05
    for _ in range(2000):
        cmd = follower.step(x, y, yaw, dt)
        if cmd.done:
            break
        x += cmd.linear_mps * np.cos(yaw) * dt
        y += cmd.linear_mps * np.sin(yaw) * dt
        yaw += cmd.angular_rps * dt
    assert follower.done and follower.reached == 3
    assert np.hypot(x - 0.0, y - 4.0) < 0.3
