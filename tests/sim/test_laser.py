"""RaycastLaser against an independent shapely reference, noise model, intensities, determinism."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from robots.lasers import LMS100, POST_INTENSITY_THRESHOLD, S300, LaserSpec
from sim.client import SimClient
from sim.ground_truth import obstacle_footprints, reference_ranges
from sim.laser import RaycastLaser
from sim.world_builder import TAG_POST, SimWorld
from tests.sim.random_scenes import free_pose, random_world, room_walls, simple_path
from worlds import bundled_worlds, load_world
from worlds.spec import PostSpec, WallSpec, WorldSpec

RANGE_TOLERANCE = 1e-3  # the acceptance line: noise-free ranges within 1 mm of the reference
SENSOR_HEIGHT = 0.3
SCENE_SEEDS = range(20)


def wall_world(distance: float) -> WorldSpec:
    """Return a long wall crossing the x axis at ``distance`` (its near face there)."""
    x = distance + 0.05
    return WorldSpec("wall", (WallSpec((x, -30.0), (x, 30.0)),), (), (), (), simple_path())


@pytest.fixture
def sim():
    with SimClient() as client:
        yield client


@pytest.mark.parametrize("seed", SCENE_SEEDS)
def test_noise_free_ranges_match_shapely_reference(sim, seed):
    rng = np.random.default_rng(seed)
    spec = random_world(rng, walls=seed % 2 == 0)
    world = SimWorld(sim, spec)
    laser = RaycastLaser(sim, LMS100, world, np.random.default_rng(0), noise_free=True)
    pose = free_pose(rng, spec, SENSOR_HEIGHT)

    scan = laser.scan(pose, stamp=1.0)
    expected = reference_ranges(obstacle_footprints(spec), pose, LMS100.angles(), LMS100.range_max)

    assert np.array_equal(np.isinf(scan.ranges), np.isinf(expected))
    hit = np.isfinite(expected)
    assert hit.any()
    np.testing.assert_allclose(scan.ranges[hit], expected[hit], rtol=0.0, atol=RANGE_TOLERANCE)


def test_scan_carries_the_true_sensor_pose_and_the_spec(sim):
    world = SimWorld(sim, wall_world(3.0))
    laser = RaycastLaser(sim, S300, world, np.random.default_rng(0))
    scan = laser.scan((0.5, -0.25, 0.15, 3.0 * math.pi), stamp=2.5)
    np.testing.assert_allclose(scan.pose, [0.5, -0.25, math.pi])
    assert scan.stamp == 2.5
    assert len(scan) == S300.num_beams == 541
    assert scan.angle_min == S300.angle_min
    assert scan.angle_increment == S300.angular_resolution
    assert (scan.range_min, scan.range_max) == (S300.range_min, S300.range_max)


def test_intensity_separates_posts_from_everything_else(sim):
    rng = np.random.default_rng(7)
    spec = random_world(rng, walls=True)
    world = SimWorld(sim, spec)
    laser = RaycastLaser(sim, LMS100, world, np.random.default_rng(1))
    post_beams = other_beams = 0
    for _ in range(5):
        pose = free_pose(rng, spec, SENSOR_HEIGHT)
        _, body_ids = laser.cast(pose)
        on_post = np.array([world.tag_of(b) == TAG_POST for b in body_ids])
        scan = laser.scan(pose)
        assert np.all(scan.intensities[on_post] > POST_INTENSITY_THRESHOLD)
        assert np.all(scan.intensities[~on_post] < POST_INTENSITY_THRESHOLD)
        post_beams += int(on_post.sum())
        other_beams += int((~on_post).sum())
    assert post_beams >= 10
    assert other_beams >= 100


def test_noisy_scans_have_no_nan_and_respect_range_semantics(sim):
    rng = np.random.default_rng(3)
    spec = random_world(rng, walls=False)
    lossy = dataclasses.replace(LMS100, dropout_prob=0.1)
    laser = RaycastLaser(sim, lossy, SimWorld(sim, spec), np.random.default_rng(2))
    for _ in range(5):
        scan = laser.scan(free_pose(rng, spec, SENSOR_HEIGHT))
        assert not np.isnan(scan.ranges).any()
        assert not np.isnan(scan.intensities).any()
        finite = np.isfinite(scan.ranges)
        assert np.all(scan.ranges[finite] >= 0.0)
        assert np.all(scan.ranges[finite] <= lossy.range_max)
        assert np.all(scan.intensities[~finite] == 0.0)
        assert np.all(scan.intensities >= 0.0)


def test_dropout_removes_about_the_requested_fraction(sim):
    lossy = dataclasses.replace(S300, dropout_prob=0.2)
    room = WorldSpec("room", room_walls(half=4.0), (), (), (), simple_path())
    laser = RaycastLaser(sim, lossy, SimWorld(sim, room), np.random.default_rng(5))
    dropped = np.mean([np.isinf(laser.scan((0.0, 0.0, 0.2, 0.0)).ranges) for _ in range(20)])
    # 20 x 541 Bernoulli(0.2) draws: the fraction's sigma is 0.004
    assert dropped == pytest.approx(0.2, abs=0.02)


def test_range_noise_has_the_data_sheet_sigma_and_a_per_instance_bias(sim):
    world = SimWorld(sim, wall_world(5.0))
    lasers = [RaycastLaser(sim, LMS100, world, np.random.default_rng(seed)) for seed in range(4)]
    biases = [laser.bias for laser in lasers]
    assert all(abs(b) <= LMS100.range_bias_max for b in biases)
    assert len(set(biases)) == len(biases)
    for laser in lasers:
        errors = np.concatenate(
            [
                laser.scan((0.0, 0.0, 0.3, 0.0)).ranges[265:276]
                - 5.0 / np.cos(LMS100.angles()[265:276])
                for _ in range(100)
            ]
        )
        # 1100 samples: the mean's sigma is 0.4 mm, the std's about 0.3 mm
        assert errors.mean() == pytest.approx(laser.bias, abs=2e-3)
        assert errors.std() == pytest.approx(LMS100.range_sigma, rel=0.1)


def test_no_return_beyond_range_max_and_near_returns_below_range_min(sim):
    far = RaycastLaser(sim, LMS100, SimWorld(sim, wall_world(25.0)), np.random.default_rng(0))
    assert np.all(np.isinf(far.scan((0.0, 0.0, 0.3, 0.0)).ranges))
    with SimClient() as other:
        near = RaycastLaser(
            other, LMS100, SimWorld(other, wall_world(0.3)), np.random.default_rng(0)
        )
        scan = near.scan((0.0, 0.0, 0.3, 0.0))
    # a surface closer than range_min is reported as measured, so Scan.valid_mask drops it
    assert scan.ranges[270] == pytest.approx(0.3, abs=0.1)
    assert not scan.valid_mask()[270]


def test_readings_past_range_max_are_clipped_not_lost(sim):
    edge = dataclasses.replace(LMS100, range_sigma=0.05, range_bias_max=0.0)
    world = SimWorld(sim, wall_world(19.99))
    laser = RaycastLaser(sim, edge, world, np.random.default_rng(0))
    ranges = laser.scan((0.0, 0.0, 0.3, 0.0)).ranges[268:273]
    assert np.all(np.isfinite(ranges))
    assert np.all(ranges <= edge.range_max)
    assert np.any(ranges == edge.range_max)


def test_robot_body_is_invisible_to_its_lasers_but_still_collides(sim):
    world = SimWorld(sim, wall_world(3.0))
    bullet = sim.bullet
    robot = bullet.createMultiBody(
        10.0,
        bullet.createCollisionShape(bullet.GEOM_BOX, halfExtents=[0.4, 0.3, 0.2]),
        -1,
        [0.0, 0.0, 0.2],
    )
    blind = RaycastLaser(sim, S300, world, np.random.default_rng(0), noise_free=True)
    _, blind_ids = blind.cast((0.45, 0.0, 0.15, 0.0))
    assert robot in blind_ids  # beams towards the back end on the robot itself

    RaycastLaser(sim, S300, world, np.random.default_rng(0), ignore_body_ids=(robot,))
    _, ids = blind.cast((0.45, 0.0, 0.15, 0.0))
    assert robot not in ids
    # the robot still rests on the floor and is stopped by the wall
    bullet.resetBaseVelocity(robot, [1.5, 0.0, 0.0])
    sim.step(480)
    (x, _, z), _ = bullet.getBasePositionAndOrientation(robot)
    assert z == pytest.approx(0.2, abs=0.01)
    assert x < 3.0 - 0.4 + 0.01


def test_same_seed_gives_bitwise_identical_scans():
    def run(seed):
        rng = np.random.default_rng(11)
        spec = random_world(rng, walls=True)
        poses = [free_pose(rng, spec, SENSOR_HEIGHT) for _ in range(3)]
        with SimClient() as client:
            laser = RaycastLaser(
                client, LMS100, SimWorld(client, spec), np.random.default_rng(seed)
            )
            scans = [laser.scan(pose, stamp=i) for i, pose in enumerate(poses)]
        return [(s.ranges, s.intensities) for s in scans]

    first, again, other = run(0), run(0), run(1)
    for (r1, i1), (r2, i2) in zip(first, again, strict=True):
        assert np.array_equal(r1, r2)
        assert np.array_equal(i1, i2)
    assert not np.array_equal(first[0][0], other[0][0])


def test_threads_do_not_change_the_result(sim):
    rng = np.random.default_rng(4)
    spec = random_world(rng, walls=True)
    world = SimWorld(sim, spec)
    pose = free_pose(rng, spec, SENSOR_HEIGHT)
    single = RaycastLaser(sim, LMS100, world, np.random.default_rng(0), num_threads=1)
    pooled = RaycastLaser(sim, LMS100, world, np.random.default_rng(0), num_threads=0)
    for a, b in zip(single.cast(pose), pooled.cast(pose), strict=True):
        assert np.array_equal(a, b)


def test_bad_arguments_are_rejected(sim):
    world = SimWorld(sim, wall_world(3.0))
    with pytest.raises(ValueError, match="num_threads"):
        RaycastLaser(sim, LMS100, world, np.random.default_rng(0), num_threads=-1)
    laser = RaycastLaser(sim, LMS100, world, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"\(x, y, z, yaw\)"):
        laser.scan((0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"\(x, y, z, yaw\)"):
        laser.scan((0.0, np.nan, 0.3, 0.0))


@pytest.mark.parametrize("name", bundled_worlds())
def test_every_bundled_world_builds_and_scans_without_nan(sim, name):
    spec = load_world(name)
    world = SimWorld(sim, spec)
    (x0, y0), (x1, y1) = spec.path.knots[:2]
    pose = (x0, y0, SENSOR_HEIGHT, math.atan2(y1 - y0, x1 - x0))
    for laser_spec in (LMS100, S300):
        scan = RaycastLaser(sim, laser_spec, world, np.random.default_rng(0)).scan(pose)
        assert not np.isnan(scan.ranges).any()
        assert not np.isnan(scan.intensities).any()
        assert np.isfinite(scan.ranges).sum() > laser_spec.num_beams // 4
    exact = RaycastLaser(sim, LMS100, world, np.random.default_rng(0), noise_free=True)
    expected = reference_ranges(
        obstacle_footprints(world, scan_height=SENSOR_HEIGHT),
        pose,
        LMS100.angles(),
        LMS100.range_max,
    )
    ranges = exact.scan(pose).ranges
    assert np.array_equal(np.isinf(ranges), np.isinf(expected))
    hit = np.isfinite(expected)
    np.testing.assert_allclose(ranges[hit], expected[hit], rtol=0.0, atol=RANGE_TOLERANCE)


def test_posts_of_the_default_spec_are_far_above_the_threshold():
    spec = LaserSpec(**{**dataclasses.asdict(LMS100), "name": "check"})
    post = PostSpec(0.0, 0.0)
    assert post.remission - POST_INTENSITY_THRESHOLD > 5 * spec.intensity_sigma
    assert POST_INTENSITY_THRESHOLD - WallSpec((0, 0), (1, 0)).remission > 5 * spec.intensity_sigma


def footprint_remissions(spec: WorldSpec) -> dict[str, float]:
    """Return the remission of every footprint ``obstacle_footprints`` names, from the spec."""
    remissions = {f"wall_{i}": wall.remission for i, wall in enumerate(spec.walls)}
    remissions.update({f"post_{i}": post.remission for i, post in enumerate(spec.posts)})
    remissions.update({box.name: box.remission for box in spec.boxes})
    return remissions


def nearest_footprints(spec, pose, angles, range_max):
    """Return GEOS's true range of every beam, the footprint it meets first and the margin.

    The margin is the gap to the second-nearest footprint along the beam (``inf`` with
    one): below the engine's accuracy the two engines may disagree about what is hit.
    """
    footprints = obstacle_footprints(spec)
    names = list(footprints)
    per_footprint = np.array(
        [reference_ranges({name: footprints[name]}, pose, angles, range_max) for name in names]
    )
    order = np.sort(per_footprint, axis=0)
    margin = order[1] - order[0] if len(names) > 1 else np.full(angles.size, np.inf)
    return order[0], np.array(names)[np.argmin(per_footprint, axis=0)], margin


@pytest.mark.parametrize("laser_spec", [LMS100, S300], ids=["lms100", "s300"])
def test_noisy_scans_are_geos_ranges_plus_the_documented_noise(sim, laser_spec):
    # The noise model against GEOS ray casts on random scenes: a bias drawn once per
    # laser (uniform within range_bias_max), then per scan Gaussian range noise, Gaussian
    # intensity noise and dropouts, drawn in that order for every beam (hit or not) from
    # the laser's stream; readings clipped to [0, range_max], intensities floored at 0
    # and zeroed with the range (inf) where nothing came back.
    spec = dataclasses.replace(laser_spec, dropout_prob=0.05, range_max=5.0, range_sigma=0.05)
    angles = spec.angles()
    scene = np.random.default_rng(21)
    dropped = clipped = compared = 0
    for _ in range(4):
        world_spec = random_world(scene, walls=True)
        draws = np.random.default_rng(3)  # the laser's stream, drawn as documented
        bias = draws.uniform(-spec.range_bias_max, spec.range_bias_max)
        with SimClient() as client:
            laser = RaycastLaser(
                client, spec, SimWorld(client, world_spec), np.random.default_rng(3)
            )
            assert laser.bias == bias
            remissions = footprint_remissions(world_spec)
            for _ in range(5):
                pose = free_pose(scene, world_spec, SENSOR_HEIGHT)
                scan = laser.scan(pose, stamp=1.0)
                true, names, margin = nearest_footprints(world_spec, pose, angles, 40.0)
                range_noise = draws.normal(0.0, spec.range_sigma, angles.size)
                intensity_noise = draws.normal(0.0, spec.intensity_sigma, angles.size)
                lost = draws.random(angles.size) < spec.dropout_prob
                hit = (true <= spec.range_max) & ~lost
                expected = np.where(
                    hit, np.clip(true + bias + range_noise, 0.0, spec.range_max), np.inf
                )
                remission = np.array([remissions.get(name, 0.0) for name in names])
                brightness = np.where(hit, np.maximum(remission + intensity_noise, 0.0), 0.0)
                # Beams the two engines may see differently: ending within a millimetre
                # of range_max, or meeting two footprints within a millimetre (a corner).
                clear = (np.abs(true - spec.range_max) > RANGE_TOLERANCE) & (
                    margin > RANGE_TOLERANCE
                )
                assert clear.mean() > 0.95
                np.testing.assert_array_equal(np.isinf(scan.ranges)[clear], ~hit[clear])
                both = clear & hit
                np.testing.assert_allclose(
                    scan.ranges[both], expected[both], rtol=0.0, atol=RANGE_TOLERANCE
                )
                np.testing.assert_allclose(
                    scan.intensities[clear], brightness[clear], rtol=0.0, atol=1e-12
                )
                # The true sensor pose (yaw wrapped: to the ulp, as wrap_angle rounds).
                np.testing.assert_allclose(
                    scan.pose, [pose[0], pose[1], pose[3]], rtol=0.0, atol=1e-15
                )
                dropped += np.count_nonzero(lost & (true <= spec.range_max))
                clipped += np.count_nonzero(both & (expected == spec.range_max))
                compared += np.count_nonzero(both)
    # Both branches of the noise model were exercised, and most beams were compared.
    assert dropped > 0
    assert clipped > 0
    assert compared > 1000
