"""Test pieces in PyBullet: the laser reads the hand-computed ranges, a contact names them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robots.lasers import LMS100
from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.ground_truth import obstacle_footprints, reference_ranges
from sim.laser import RaycastLaser
from sim.world_builder import TAG_TEST_PIECE, SimWorld
from tests.sim.random_scenes import simple_path
from worlds.spec import TestPieceSpec, WorldSpec

RANGE_TOLERANCE = 1e-4  # the mesh strays 1 um from the circle; Bullet's rays are exact
ACROSS = math.pi / 2  # a lying piece's axis along y: across a scanner looking along +x
RADIUS_LYING, RADIUS_UPRIGHT = 0.1, 0.035  # the standard's 200 mm and 70 mm pieces


def world_of(*pieces: TestPieceSpec) -> WorldSpec:
    return WorldSpec("pieces", (), (), (), (), simple_path(), test_pieces=pieces)


def centre_beam() -> int:
    angles = LMS100.angles()
    index = int(np.argmin(np.abs(angles)))
    assert angles[index] == 0.0
    return index


@pytest.fixture
def sim():
    with SimClient() as client:
        yield client


def scan(sim, spec: WorldSpec, height: float, pose=(0.0, 0.0)) -> np.ndarray:
    world = SimWorld(sim, spec)
    laser = RaycastLaser(sim, LMS100, world, np.random.default_rng(0), noise_free=True)
    return laser.scan((*pose, height, 0.0)).ranges


@pytest.mark.parametrize("distance", [1.0, 2.5])
def test_the_centre_beam_reads_an_upright_piece_at_its_distance_less_its_radius(sim, distance):
    piece = TestPieceSpec("leg", "upright", (distance, 0.0, 0.0))
    ranges = scan(sim, world_of(piece), height=0.3)
    assert ranges[centre_beam()] == pytest.approx(distance - RADIUS_UPRIGHT, abs=RANGE_TOLERANCE)


@pytest.mark.parametrize("height", [0.02, 0.1, 0.15, 0.19])
def test_a_scanner_below_the_top_reads_the_lying_pieces_near_surface(sim, height):
    # The plane z = h cuts the lying cylinder (axis at z = r) in a strip whose near edge
    # lies sqrt(r^2 - (h - r)^2) before the axis.
    piece = TestPieceSpec("body", "lying", (2.0, 0.0, ACROSS))
    ranges = scan(sim, world_of(piece), height=height)
    near = 2.0 - math.sqrt(RADIUS_LYING**2 - (height - RADIUS_LYING) ** 2)
    assert ranges[centre_beam()] == pytest.approx(near, abs=RANGE_TOLERANCE)
    # Every beam that meets the 0.6 m long near face reads it at near / cos(angle).
    angles = LMS100.angles()
    on_face = np.abs(near * np.tan(angles)) < 0.3 - 1e-3
    on_face &= np.abs(angles) < math.pi / 2
    assert on_face.sum() > 20
    np.testing.assert_allclose(ranges[on_face], near / np.cos(angles[on_face]),
                               rtol=0.0, atol=RANGE_TOLERANCE)


def test_a_lying_piece_seen_end_on_reads_its_end_cap(sim):
    # Axis along the beam: the flat end 0.3 m before the centre.
    piece = TestPieceSpec("body", "lying", (2.0, 0.0, 0.0))
    ranges = scan(sim, world_of(piece), height=0.15)
    assert ranges[centre_beam()] == pytest.approx(2.0 - 0.3, abs=RANGE_TOLERANCE)


@pytest.mark.parametrize(
    ("kind", "height"),
    [("lying", 0.35), ("lying", 0.2 + 1e-3), ("upright", 0.45)],
    ids=["pioneer-lms100-over-lying", "just-over-lying", "over-upright"],
)
def test_a_scanner_above_the_top_gets_no_return(sim, kind, height):
    piece = TestPieceSpec("piece", kind, (1.5, 0.0, ACROSS))
    ranges = scan(sim, world_of(piece), height=height)
    assert np.all(np.isinf(ranges)), "a plane above the piece passes over it"


def test_pybullet_agrees_with_the_shapely_cross_section(sim):
    # A lying piece at an angle, an upright one beside it: the exact 2D section of each
    # (sim.ground_truth) against the ray casts, over the whole scan.
    pieces = (TestPieceSpec("body", "lying", (2.0, 0.4, 0.5)),
              TestPieceSpec("leg", "upright", (1.2, -0.8, 0.0)))
    spec = world_of(*pieces)
    pose = (0.1, -0.2, 0.12, 0.3)
    world = SimWorld(sim, spec)
    laser = RaycastLaser(sim, LMS100, world, np.random.default_rng(0), noise_free=True)
    measured = laser.scan(pose).ranges
    expected = reference_ranges(obstacle_footprints(spec, scan_height=pose[2]), pose,
                                LMS100.angles(), LMS100.range_max)
    assert np.array_equal(np.isinf(measured), np.isinf(expected))
    assert np.isfinite(expected).sum() > 15  # both pieces are in view
    hit = np.isfinite(expected)
    np.testing.assert_allclose(measured[hit], expected[hit], rtol=0.0, atol=1e-3)


def test_pieces_are_tagged_and_carry_their_remission(sim):
    spec = world_of(TestPieceSpec("body", "lying", (2.0, 0.0, 0.0), remission=0.05),
                    TestPieceSpec("leg", "upright", (3.0, 1.0, 0.0)))
    world = SimWorld(sim, spec)
    body, leg = world.body_id("body"), world.body_id("leg")
    assert (world.tag_of(body), world.tag_of(leg)) == (TAG_TEST_PIECE, TAG_TEST_PIECE)
    np.testing.assert_array_equal(world.remission_of([body, leg]), [0.05, 0.3])
    assert world.test_pieces == spec.test_pieces
    # Static: they stay where the spec puts them.
    sim.step(240)
    position, _ = sim.bullet.getBasePositionAndOrientation(body)
    assert position == pytest.approx((2.0, 0.0, 0.0))


@pytest.mark.parametrize("kind", ["lying", "upright"])
def test_touching_a_piece_is_a_contact_that_names_it(sim, kind):
    world = SimWorld(sim, world_of(TestPieceSpec("piece", kind, (1.0, 0.0, ACROSS))))
    bullet = sim.bullet
    half = 0.15
    cube = bullet.createMultiBody(
        5.0, bullet.createCollisionShape(bullet.GEOM_BOX, halfExtents=[half] * 3), -1,
        [0.0, 0.0, half])
    monitor = ContactMonitor(sim, cube, world)
    for _ in range(round(2.0 / sim.time_step)):
        bullet.resetBaseVelocity(cube, [0.5, 0.0, 0.0], [0.0, 0.0, 0.0])
        sim.step()
        monitor.check()
    assert monitor.collisions == 1
    event = monitor.events[0]
    assert (event.name, event.tag, event.body_id) == ("piece", TAG_TEST_PIECE,
                                                      world.body_id("piece"))
    # The cube's front face meets the piece's near side: 1 m less the piece's radius.
    radius = RADIUS_LYING if kind == "lying" else RADIUS_UPRIGHT
    assert event.position[0] == pytest.approx(1.0 - radius, abs=0.01)
