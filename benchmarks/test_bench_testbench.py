"""Benchmark: one lap of pal1 on the bare testbench (physics, wheels, encoders, LMS100).

Issue 3's figure: 240 Hz physics, the LMS100 at 50 Hz, the robot driven along the path by
the chained-form follower on its true pose (no EKF, no mapper: the testbench alone).
Reports the real-time factor and wall time over time inside PyBullet (goal <= 1.3).

Run: ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_testbench.py``
"""

import time

import numpy as np
import pytest

from robots.follower import ChainedFormFollower, FollowerParams
from robots.path import SplinePath
from robots.presets import PIONEER3DX
from scenarios.bench.clock import Schedule
from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.encoders import WheelEncoders
from sim.laser import RaycastLaser
from sim.ugv import SimUGV
from sim.world_builder import SimWorld
from worlds.load import load_world


def one_lap(world_name="pal1", physics_hz=240.0, laser_hz=50.0, control_hz=50.0):
    world_spec = load_world(world_name)
    path = SplinePath(world_spec.path.knots)
    rng = np.random.default_rng(0)
    started = time.perf_counter()
    with SimClient(time_step=1.0 / physics_hz) as sim:
        world = SimWorld(sim, world_spec)
        robot = SimUGV(sim, PIONEER3DX, path.pose(0.0))
        mount = PIONEER3DX.localization_laser
        laser = RaycastLaser(sim, mount.laser, world, rng, ignore_body_ids=(robot.body_id,))
        encoders = WheelEncoders(PIONEER3DX, rng)
        encoders.reset(robot.wheel_angles())
        contacts = ContactMonitor(sim, robot.body_id, world)
        follower = ChainedFormFollower(path, FollowerParams(speed=world_spec.path.speed))
        laser_due, control_due = Schedule(laser_hz, physics_hz), Schedule(control_hz, physics_hz)
        scans, step = 0, 0
        while not follower.done and sim.sim_time < 120.0:
            step += 1
            if laser_due.due(step):
                laser.scan(robot.sensor_pose(mount), stamp=sim.sim_time)
                scans += 1
            if control_due.due(step):
                encoders.odometry_increment(robot.wheel_angles())
                robot.command(*follower.command(robot.true_pose(), 1.0 / control_hz))
            sim.step()
            contacts.check()
        wall = time.perf_counter() - started
        return {
            "sim_time_s": sim.sim_time,
            "wall_time_s": wall,
            "engine_time_s": sim.engine_time_s,
            "scans": scans,
            "collisions": contacts.collisions,
        }


@pytest.mark.bench
def test_one_lap_of_pal1_on_the_bare_testbench():
    result = one_lap()
    rtf = result["sim_time_s"] / result["wall_time_s"]
    ratio = result["wall_time_s"] / result["engine_time_s"]
    print(
        f"\npal1 lap: {result['sim_time_s']:.1f} s simulated in {result['wall_time_s']:.2f} s wall "
        f"(real-time x{rtf:.1f}); inside PyBullet {result['engine_time_s']:.2f} s "
        f"({100 * result['engine_time_s'] / result['wall_time_s']:.0f}% of wall); "
        f"wall/engine {ratio:.2f} (goal <= 1.3); {result['scans']} LMS100 scans, "
        f"{result['collisions']} collisions"
    )
    assert result["collisions"] == 0
