"""People walking kinematically: the pure route function and the bodies in the engine."""

from __future__ import annotations

import numpy as np
import pytest

from robots.lasers import S300
from robots.presets import PIONEER3DX
from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.ground_truth import people_positions
from sim.laser import RaycastLaser
from sim.people import PARKED_Z, People, person_position
from sim.ugv import SimUGV
from sim.world_builder import SimWorld
from tests.sim.random_scenes import simple_path
from worlds.spec import PersonSpec, WorldSpec

L_ROUTE = ((0.0, 0.0), (3.0, 0.0), (3.0, 4.0))  # 7 m long


def test_before_the_start_a_person_is_absent():
    person = PersonSpec("p", L_ROUTE, start_time=2.0)
    assert person_position(person, 0.0) is None
    assert person_position(person, 1.999) is None
    assert person_position(person, 2.0).tolist() == [0.0, 0.0]


@pytest.mark.parametrize(
    ("t", "expected"),
    [
        (0.0, (0.0, 0.0)),
        (1.0, (1.0, 0.0)),
        (3.0, (3.0, 0.0)),
        (5.0, (3.0, 2.0)),
        (7.0, (3.0, 4.0)),
        (100.0, (3.0, 4.0)),
    ],
)
def test_walks_at_speed_along_the_polyline_and_stays_at_the_end(t, expected):
    person = PersonSpec("p", L_ROUTE, speed=1.0)
    np.testing.assert_allclose(person_position(person, t), expected, atol=1e-12)


def test_speed_scales_the_walk():
    slow = PersonSpec("p", L_ROUTE, speed=0.5)
    np.testing.assert_allclose(person_position(slow, 10.0), (3.0, 2.0))


def test_a_looping_person_walks_back_to_the_start_and_again():
    person = PersonSpec("p", L_ROUTE, speed=1.0, loop=True)  # closed route: 7 + 5 = 12 m
    np.testing.assert_allclose(person_position(person, 9.5), (1.5, 2.0))  # on the way back
    np.testing.assert_allclose(person_position(person, 12.0), (0.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(person_position(person, 13.0), person_position(person, 1.0))


def test_a_single_waypoint_and_repeated_waypoints_are_harmless():
    still = PersonSpec("p", ((2.0, 1.0),))
    assert person_position(still, 5.0).tolist() == [2.0, 1.0]
    repeated = PersonSpec("p", ((0.0, 0.0), (1.0, 0.0), (1.0, 0.0), (1.0, 1.0)))
    np.testing.assert_allclose(person_position(repeated, 1.5), (1.0, 0.5))
    assert np.all(np.isfinite(person_position(repeated, 1.0)))


def world_with(*people: PersonSpec) -> WorldSpec:
    return WorldSpec("people", (), (), (), people, simple_path())


def test_update_moves_the_bodies_and_parks_absent_people():
    late = PersonSpec("late", ((0.0, 2.0), (4.0, 2.0)), start_time=5.0, per_lap=False)
    with SimClient() as sim:
        world = SimWorld(sim, world_with(late))
        people = People(world)
        assert people.update(1.0)["late"] is None
        (_, _, z), _ = sim.bullet.getBasePositionAndOrientation(world.person_id("late"))
        assert z == PARKED_Z
        assert people_positions(world) == {}

        people.update(7.0)
        (x, y, z), _ = sim.bullet.getBasePositionAndOrientation(world.person_id("late"))
        assert (x, y, z) == pytest.approx((2.0, 2.0, 0.0))
        np.testing.assert_allclose(people_positions(world)["late"], (2.0, 2.0))


def test_per_lap_people_follow_the_lap_clock_and_others_the_run_clock():
    lap_walker = PersonSpec("lap", ((0.0, 0.0), (10.0, 0.0)), per_lap=True)
    run_walker = PersonSpec("run", ((0.0, 5.0), (10.0, 5.0)), per_lap=False)
    with SimClient() as sim:
        people = People(SimWorld(sim, world_with(lap_walker, run_walker)))
        positions = people.update(t=103.0, lap_start=100.0)
    np.testing.assert_allclose(positions["lap"], (3.0, 0.0))
    np.testing.assert_allclose(positions["run"], (10.0, 5.0))


def test_lasers_see_a_present_person_and_not_a_parked_one():
    walker = PersonSpec("w", ((2.0, -1.0), (2.0, 1.0)), speed=1.0, start_time=1.0, per_lap=False)
    with SimClient() as sim:
        world = SimWorld(sim, world_with(walker))
        people = People(world)
        laser = RaycastLaser(sim, S300, world, np.random.default_rng(0), noise_free=True)
        people.update(0.0)
        assert np.all(np.isinf(laser.scan((0.0, 0.0, 0.2, 0.0)).ranges))
        people.update(2.0)  # at (2, 0): the beam straight ahead meets its front at 1.75 m
        ranges = laser.scan((0.0, 0.0, 0.2, 0.0)).ranges
    assert ranges[S300.num_beams // 2] == pytest.approx(2.0 - walker.radius, abs=1e-5)


# ------------------------------------------- the per-step fast path and skipped teleports

class CountingBullet:
    """Forward to a BulletClient, counting the teleports."""

    def __init__(self, bullet):
        self.bullet, self.teleports = bullet, 0

    def __getattr__(self, name):
        return getattr(self.bullet, name)

    def resetBasePositionAndOrientation(self, *args):  # PyBullet's name
        self.teleports += 1
        return self.bullet.resetBasePositionAndOrientation(*args)


def test_bodies_are_teleported_only_when_their_position_changes():
    walker = PersonSpec("w", ((0.0, 2.0), (1.0, 2.0)), speed=1.0, start_time=1.0)
    with SimClient() as sim:
        people = People(SimWorld(sim, world_with(walker)))
        counting = people._bullet = CountingBullet(sim.bullet)
        people.update(0.0)  # first update: parked
        people.update(0.5)  # still parked: no engine call
        assert counting.teleports == 1
        people.update(1.5)
        people.update(2.5)  # arrived at the end
        people.update(3.5)
        people.update(90.0)
        assert counting.teleports == 3
        (x, y, z), _ = sim.bullet.getBasePositionAndOrientation(people._ids["w"])
        assert (x, y, z) == pytest.approx((1.0, 2.0, 0.0))
        people.update(100.0, lap_start=100.0)  # a new lap: parked again
        assert counting.teleports == 4


def test_skipping_unchanged_teleports_leaves_the_physics_bit_identical():
    # A robot pushes into a person standing at the end of their walk; the reference
    # teleports every person at every step, as People did before it skipped no-ops.
    walker = PersonSpec("w", ((1.5, 2.0), (1.5, 0.0)), speed=2.0, start_time=0.2)

    def drive(update_people):
        with SimClient() as sim:
            world = SimWorld(sim, world_with(walker))
            robot = SimUGV(sim, PIONEER3DX, (0.0, 0.0, 0.0))
            contacts = ContactMonitor(sim, robot.body_id, world)
            update = update_people(sim, world)
            robot.command(0.6, 0.0)
            poses = []
            for step in range(720):
                update(step * sim.time_step)
                sim.step()
                contacts.check()
                poses.append(robot.true_pose())
            return np.array(poses), contacts.collisions

    def fast(sim, world):
        return People(world).update

    def every_step(sim, world):
        upright = sim.bullet.getQuaternionFromEuler([0.0, 0.0, 0.0])

        def update(t):
            for person in world.people:
                xy = person_position(person, t)
                xyz = [*person.waypoints[0], PARKED_Z] if xy is None else [*xy.tolist(), 0.0]
                sim.bullet.resetBasePositionAndOrientation(
                    world.person_id(person.name), xyz, upright
                )

        return update

    poses, collisions = drive(fast)
    reference_poses, reference_collisions = drive(every_step)
    assert collisions == reference_collisions == 1  # the robot did run into the person
    assert np.array_equal(poses, reference_poses)
