"""SimWorld: bodies, tags, remissions, box moves, and the box outlines of ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robots.lasers import S300
from sim.client import SimClient
from sim.ground_truth import box_outlines
from sim.laser import RaycastLaser
from sim.world_builder import (
    CIRCLE_SAGITTA,
    DEFAULT_REMISSION,
    NO_HIT_REMISSION,
    TAG_BOX,
    TAG_FLOOR,
    TAG_PERSON,
    TAG_POST,
    TAG_UNKNOWN,
    TAG_WALL,
    SimWorld,
    circle_footprint,
    prism_mesh,
)
from tests.sim.random_scenes import simple_path
from worlds.spec import BoxSpec, PersonSpec, PostSpec, WallSpec, WorldSpec

AABB_MARGIN = 1.5e-3
SENSOR = (0.0, 0.0, 0.2, 0.0)  # S300 at the origin looking along +x


def scene() -> WorldSpec:
    return WorldSpec(
        name="scene",
        walls=(WallSpec((6.0, -3.0), (6.0, 3.0), remission=0.15),),
        posts=(PostSpec(2.0, 2.0), PostSpec(-2.0, 1.0, radius=0.1)),
        boxes=(
            BoxSpec("crate", (0.5, 1.0, 0.6), (3.0, 0.0, 0.0), remission=0.4),
            BoxSpec("pallet", (1.2, 0.8, 0.2), (0.0, -3.0, math.pi / 2)),
        ),
        people=(
            PersonSpec("ann", ((0.0, 4.0), (1.0, 4.0))),
            PersonSpec("off", ((0.0, -5.0), (1.0, -5.0)), enabled=False),
        ),
        path=simple_path(),
    )


@pytest.fixture
def sim():
    with SimClient() as client:
        yield client


@pytest.fixture
def world(sim):
    return SimWorld(sim, scene())


def ahead(laser) -> float:
    """Return the noise-free range of the straight-ahead beam."""
    ranges, _ = laser.cast(SENSOR)
    return float(ranges[S300.num_beams // 2])


def test_every_object_becomes_one_tagged_body(world):
    names = {world.name_of(body): world.tag_of(body) for body in world.body_ids}
    assert names == {
        "floor": TAG_FLOOR,
        "wall_0": TAG_WALL,
        "post_0": TAG_POST,
        "post_1": TAG_POST,
        "crate": TAG_BOX,
        "pallet": TAG_BOX,
        "ann": TAG_PERSON,
    }
    assert world.tag_of(world.floor_id) == TAG_FLOOR
    assert [person.name for person in world.people] == ["ann"]  # disabled people are not built


def test_bodies_stand_where_the_spec_says(sim, world):
    bullet = sim.bullet
    (x, y, z), quaternion = bullet.getBasePositionAndOrientation(world.box_id("pallet"))
    assert (x, y, z) == pytest.approx((0.0, -3.0, 0.0))
    assert bullet.getEulerFromQuaternion(quaternion)[2] == pytest.approx(math.pi / 2)
    # the AABB carries the mesh's 1 mm collision margin
    low, high = bullet.getAABB(world.box_id("crate"))
    np.testing.assert_allclose(low, [2.75, -0.5, 0.0], atol=AABB_MARGIN)
    np.testing.assert_allclose(high, [3.25, 0.5, 0.6], atol=AABB_MARGIN)
    low, high = bullet.getAABB(world.body_id("wall_0"))
    np.testing.assert_allclose(low[:2], [5.95, -3.0], atol=AABB_MARGIN)
    np.testing.assert_allclose(high, [6.05, 3.0, 2.5], atol=AABB_MARGIN)


def test_remission_lookup_is_vectorised_and_handles_no_hit_and_strangers(world):
    ids = [world.body_id("post_0"), world.box_id("crate"), -1, world.body_id("wall_0"), 10_000]
    np.testing.assert_allclose(
        world.remission_of(ids), [0.95, 0.4, NO_HIT_REMISSION, 0.15, DEFAULT_REMISSION]
    )
    assert world.remission_of(np.array([], dtype=int)).shape == (0,)
    assert world.remission_of(np.full((2, 3), -1)).shape == (2, 3)
    assert world.tag_of(10_000) == TAG_UNKNOWN


def test_unknown_names_are_reported_with_the_known_ones(world):
    with pytest.raises(KeyError, match="crate"):
        world.box_id("crates")
    with pytest.raises(KeyError, match="known"):
        world.body_id("nobody")


def test_duplicate_names_are_rejected(world):
    with pytest.raises(ValueError, match="unique name"):
        world.add_box(BoxSpec("crate", (1.0, 1.0, 1.0), (0.0, 5.0, 0.0)))
    with pytest.raises(ValueError, match="unique name"):
        world.add_box(BoxSpec("ann", (1.0, 1.0, 1.0), (0.0, 5.0, 0.0)))


def test_moving_a_box_moves_its_body_and_its_outline(sim, world):
    laser = RaycastLaser(sim, S300, world, np.random.default_rng(0), noise_free=True)
    assert ahead(laser) == pytest.approx(2.75)
    world.move_box("crate", (4.0, 0.0, math.pi / 2))
    assert ahead(laser) == pytest.approx(3.5)  # turned: its 1.0 m side now faces the laser
    np.testing.assert_allclose(
        box_outlines(world)["crate"],
        [[4.5, 0.25], [3.5, 0.25], [3.5, -0.25], [4.5, -0.25]],
        atol=1e-12,
    )
    assert world.boxes[0].pose == (4.0, 0.0, math.pi / 2)
    assert box_outlines(world.spec)["crate"][0] == pytest.approx([3.25, -0.5])  # spec unchanged


def test_removing_and_adding_boxes(sim, world):
    laser = RaycastLaser(sim, S300, world, np.random.default_rng(0), noise_free=True)
    world.remove_box("crate")
    assert ahead(laser) == pytest.approx(5.95)  # the wall behind it
    assert "crate" not in box_outlines(world)
    with pytest.raises(KeyError):
        world.box_id("crate")

    body = world.add_box(BoxSpec("bin", (0.4, 0.4, 1.0), (1.2, 0.0, 0.0), remission=0.45))
    assert ahead(laser) == pytest.approx(1.0)
    assert world.tag_of(body) == TAG_BOX
    assert world.remission_of([body])[0] == pytest.approx(0.45)
    assert sorted(box_outlines(world)) == ["bin", "pallet"]


def test_box_outlines_of_the_spec(world):
    outlines = box_outlines(scene())
    assert sorted(outlines) == ["crate", "pallet"]
    np.testing.assert_allclose(
        outlines["pallet"], [[0.4, -2.4], [-0.4, -2.4], [-0.4, -3.6], [0.4, -3.6]], atol=1e-12
    )
    for name, outline in outlines.items():
        np.testing.assert_allclose(outline, box_outlines(world)[name])


def test_circle_footprint_stays_within_the_sagitta_of_the_circle():
    for radius in (0.03, 0.04, 0.25, 1.0):
        ring = circle_footprint(radius)
        mids = 0.5 * (ring + np.roll(ring, -1, axis=0))
        assert np.hypot(*mids.T).min() >= radius - CIRCLE_SAGITTA
        np.testing.assert_allclose(np.hypot(*ring.T), radius)


def test_prism_mesh_is_closed_and_wound_outwards():
    footprint = circle_footprint(0.5)
    vertices, indices = prism_mesh(footprint, 2.0)
    triangles = vertices[indices.reshape(-1, 3)]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    outward = triangles.mean(axis=1) - [0.0, 0.0, 1.0]
    assert np.all(np.einsum("ij,ij->i", normals, outward) > 0.0)
    # divergence theorem: the signed volume equals the prism's
    volume = np.einsum("ij,ij->i", triangles[:, 0], normals).sum() / 6.0
    area = 0.5 * np.sum(
        footprint[:, 0] * np.roll(footprint[:, 1], -1)
        - np.roll(footprint[:, 0], -1) * footprint[:, 1]
    )
    assert volume == pytest.approx(2.0 * area)


def test_building_twice_gives_the_same_ids_and_poses():
    def build():
        with SimClient() as client:
            world = SimWorld(client, scene())
            return {
                world.name_of(b): client.bullet.getBasePositionAndOrientation(b)
                for b in world.body_ids
            }, world.body_ids

    assert build() == build()
