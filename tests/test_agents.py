"""The pallet truck in a real PyBullet world: driving by velocity commands, collision sensing."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from simlan_data.sim.agents import AGENT_TYPES, DiffDriveAgent, urdf_with_marker
from simlan_data.sim.markers import marker_cells
from simlan_data.sim.pybullet_client import connect
from simlan_data.world._pybullet import pb
from simlan_data.world.builder import build_world
from simlan_data.world.layout import load_layout


@pytest.fixture
def warehouse():
    client = connect("tiny")
    pb.setGravity(0, 0, -9.81, physicsClientId=client.id)
    pb.setTimeStep(1 / 240, physicsClientId=client.id)
    with tempfile.TemporaryDirectory() as tmp:
        world = build_world(client.id, load_layout("warehouse_layout.csv", "default"), {}, mesh_dir=Path(tmp))
    yield client, world
    client.disconnect()


def _step(client, seconds: float) -> None:
    for _ in range(round(seconds * 240)):
        pb.stepSimulation(physicsClientId=client.id)


def test_velocity_commands_move_the_truck_through_physics(warehouse) -> None:
    client, world = warehouse
    truck = DiffDriveAgent(
        client.id, "robot_agent_2", AGENT_TYPES["pallet_truck"], pose=[-10.0, 0.4, 0.0], marker_id=2
    )
    truck.apply_command(1.0, 0.0)
    _step(client, 3.0)
    pose = truck.pose()
    assert pose.translation[0] - (-10.0) == pytest.approx(2.8, abs=0.35)  # accelerates, then 1 m/s
    assert abs(pose.translation[1] - 0.4) < 0.015
    assert abs(pose.yaw()) < 0.01
    v, _ = truck.twist()
    assert v == pytest.approx(1.0, abs=0.05)
    truck.apply_command(0.0, 0.5)
    _step(client, 1.0)
    yaw0 = truck.pose().yaw()
    _step(client, 2.0)
    assert truck.pose().yaw() - yaw0 == pytest.approx(1.0, abs=0.05)  # 0.5 rad/s for 2 s
    # driving on the floor is not a collision
    assert not truck.collisions(world.floor, world.names).in_collision


def test_collision_sensor_reports_what_was_hit(warehouse) -> None:
    client, world = warehouse
    # facing the shelf row at y = 2.6 (its front edge at y = 2.85) from the main aisle
    truck = DiffDriveAgent(
        client.id, "robot_agent_1", AGENT_TYPES["pallet_truck"], pose=[-6.0, 1.0, np.pi / 2], marker_id=1
    )
    truck.apply_command(0.8, 0.0)
    hits = []
    for _ in range(100):
        _step(client, 0.05)
        reading = truck.collisions(world.floor, world.names)
        if reading.in_collision:
            hits.append(reading)
    assert hits, "driving into the shelf must trigger the collision sensor"
    assert any(name.startswith(("shelf_wall_2_", "shelf_box_r2_")) for name in hits[-1].others), hits[
        -1
    ].others
    assert max(h.max_force_n for h in hits) > 1.0


def test_marker_cells_in_the_urdf_match_the_dictionary() -> None:
    text = urdf_with_marker(AGENT_TYPES["pallet_truck"], 42)
    assert '<link name="aruco_marker">' in text
    cells = marker_cells(42)
    assert cells.shape == (7, 7)
    assert not cells[0].any() and not cells[:, 0].any()  # black border
    # every black and white cell is drawn once: boxes cover the 7x7 grid plus the quiet zone
    assert text.count("<visual>") >= 4 + int(cells.sum() > 0)
