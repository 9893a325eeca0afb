"""ContactMonitor: pushing into a box is one collision, resting on the floor is none."""

from __future__ import annotations

import pytest

from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.world_builder import TAG_BOX, SimWorld
from tests.sim.random_scenes import simple_path
from worlds.spec import BoxSpec, WallSpec, WorldSpec

HALF = 0.2  # half size of the test "robot" cube


def arena() -> WorldSpec:
    return WorldSpec(
        "arena",
        walls=(WallSpec((-2.0, -2.0), (-2.0, 2.0)),),
        posts=(),
        boxes=(BoxSpec("crate", (0.6, 0.6, 0.5), (1.5, 0.0, 0.0)),),
        people=(),
        path=simple_path(),
    )


@pytest.fixture
def setup():
    with SimClient() as sim:
        world = SimWorld(sim, arena())
        bullet = sim.bullet
        robot = bullet.createMultiBody(
            5.0,
            bullet.createCollisionShape(bullet.GEOM_BOX, halfExtents=[HALF] * 3),
            -1,
            [0.0, 0.0, HALF],
        )
        yield sim, world, robot


def push(sim, robot, velocity, seconds):
    """Drive the body at ``velocity`` (x, y) for ``seconds``, checking every step."""
    for _ in range(round(seconds / sim.time_step)):
        sim.bullet.resetBaseVelocity(robot, [*velocity, 0.0], [0.0, 0.0, 0.0])
        sim.step()
        yield


def test_resting_on_the_floor_is_no_collision(setup):
    sim, world, robot = setup
    monitor = ContactMonitor(sim, robot, world)
    for _ in push(sim, robot, (0.0, 0.0), 2.0):
        assert monitor.check() == []
    assert monitor.collisions == 0
    assert sim.bullet.getContactPoints(bodyA=robot, bodyB=world.floor_id)  # it does touch the floor


def test_pushing_into_a_box_for_seconds_is_one_collision(setup):
    sim, world, robot = setup
    monitor = ContactMonitor(sim, robot, world)
    touching_steps = 0
    for _ in push(sim, robot, (1.0, 0.0), 3.0):
        contacts = monitor.check()
        touching_steps += bool(contacts)
    assert touching_steps > 100  # a long contact...
    assert monitor.collisions == 1  # ...counted once
    event = monitor.events[0]
    assert (event.name, event.tag, event.body_id) == ("crate", TAG_BOX, world.box_id("crate"))
    assert event.new
    assert event.position[0] == pytest.approx(1.2, abs=0.01)  # the crate's near face
    assert event.normal_force > 0.0


def test_leaving_and_coming_back_is_a_second_collision(setup):
    sim, world, robot = setup
    monitor = ContactMonitor(sim, robot, world)
    for _ in push(sim, robot, (1.0, 0.0), 1.5):
        monitor.check()
    for _ in push(sim, robot, (-1.0, 0.0), 0.5):
        monitor.check()
    assert monitor.collisions == 1
    for _ in push(sim, robot, (1.0, 0.0), 1.0):
        monitor.check()
    assert monitor.collisions == 2
    for _ in push(sim, robot, (-1.0, 0.0), 3.5):  # back across the arena into the wall
        monitor.check()
    assert [event.name for event in monitor.events] == ["crate", "crate", "wall_0"]


def test_reset_forgets_ongoing_contacts_but_not_the_count(setup):
    sim, world, robot = setup
    monitor = ContactMonitor(sim, robot, world)
    for _ in push(sim, robot, (1.0, 0.0), 1.5):
        monitor.check()
    monitor.reset()
    for _ in push(sim, robot, (1.0, 0.0), 0.1):
        monitor.check()
    assert monitor.collisions == 2


def test_negative_separation_time_is_rejected(setup):
    sim, world, robot = setup
    with pytest.raises(ValueError, match="separation_time"):
        ContactMonitor(sim, robot, world, separation_time=-1.0)
