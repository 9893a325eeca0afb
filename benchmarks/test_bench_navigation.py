"""Per-tick hot paths of the navigation stack and the simulator glue.

Each benchmark times the current code on the ``pal1`` world and prints the median per
call in microseconds; where a plainer way to do the same exists (numpy or shapely
calls), it is timed beside it. The per-call clock is
the CPU time of the calling thread (``time.thread_time``): on a machine shared with
other jobs, wall-clock medians mostly measure the wait for a core. Calls into PyBullet,
whose ray casts use worker threads, are timed on the wall clock. One more benchmark
runs a whole lap of ``pal1`` and prints the wall / engine ratio and the real-time factor.

The SimUGV figures have no reference: before the float rewrite they were about 4, 12, 13
and 16 us (wheel angles, true pose, sensor pose, command) on this machine.

Run with ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_navigation.py``
(about 30 s; the lap alone about 10 s).
"""

from __future__ import annotations

import time
from operator import itemgetter

import numpy as np
import pytest
import shapely

from benchmarks.timing import median_us as timed_median_us
from robots.follower import ChainedFormFollower
from robots.landmarks import detect_landmarks
from robots.lasers import LMS100
from robots.path import SplinePath
from robots.presets import PIONEER3DX
from robots.safety import FieldSet, field_occupancy, scan_points_in_robot_frame
from scenarios.bench.runner import run_scenario
from scenarios.results.outputs import summarize
from scenarios.spec.scenario import ScenarioSpec
from semistatic.frames import transform_points
from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.encoders import WheelEncoders
from sim.laser import RaycastLaser
from sim.people import PARKED_Z, People, person_position
from sim.ugv import SimUGV
from sim.world_builder import SimWorld
from worlds.load import load_world

pytestmark = pytest.mark.bench

REPEATS = 2000


def median_us(run, repeats=REPEATS, clock=time.thread_time):
    """Return the median time of ``run()`` in microseconds (see ``benchmarks.timing``)."""
    return timed_median_us(run, repeats, clock)


def report(name, fast_us, reference_us=None):
    if reference_us is None:
        print(f"\n{name}: {fast_us:8.1f} us median")
        return
    print(
        f"\n{name}: {fast_us:8.1f} us median (reference {reference_us:8.1f} us, "
        f"{reference_us / fast_us:5.1f}x)"
    )


@pytest.fixture(scope="module")
def pal1():
    return load_world("pal1")


@pytest.fixture(scope="module")
def path(pal1):
    return SplinePath(pal1.path.knots)


def tracked_queries(path, count=REPEATS):
    """Poses near the path with the follower's hint: where the 50 Hz projection runs."""
    rng = np.random.default_rng(0)
    s = rng.uniform(0.0, path.length, count)
    points = path.point(s) + rng.normal(0.0, 0.05, (count, 2))
    return points, s + rng.normal(0.0, 0.01, count)


def median_over_queries(run, queries, clock=time.thread_time):
    """Return the median time of ``run(*query)`` over ``queries`` in microseconds."""
    run(*queries[0])
    times = np.empty(len(queries))
    for k, query in enumerate(queries):
        start = clock()
        run(*query)
        times[k] = clock() - start
    return float(np.median(times) * 1e6)


def test_projection_with_hint(path):
    points, hints = tracked_queries(path)
    queries = list(zip(points, hints.tolist(), strict=True))
    fast = median_over_queries(lambda p, h: path.project(p, s_hint=h, window=1.0), queries)
    report("SplinePath.project (one point, hint, 1 m window)", fast)


def test_pose_and_curvature(path):
    s = np.random.default_rng(1).uniform(0.0, path.length, REPEATS).tolist()
    queries = [(value,) for value in s]
    fast = median_over_queries(lambda v: (path.pose(v), path.curvature(v)), queries)
    report("SplinePath.pose + curvature (one s)", fast)


def test_follower_command(path):
    follower = ChainedFormFollower(path)
    pose = path.pose(0.0) + np.array([0.0, 0.05, 0.02])
    times = []
    for _ in range(REPEATS):
        start = time.thread_time()
        v, omega = follower.command(pose, 0.02)
        times.append(time.thread_time() - start)
        pose = pose + 0.02 * np.array([v * np.cos(pose[2]), v * np.sin(pose[2]), omega])
        if follower.done:
            follower.reset()
            pose = path.pose(0.0)
    report("ChainedFormFollower.command", 1e6 * float(np.median(times)))


@pytest.fixture(scope="module")
def pal1_scans(pal1, path):
    """Noisy LMS100 scans every 10 cm along the pal1 path, from the laser's height."""
    with SimClient() as sim:
        laser = RaycastLaser(sim, LMS100, SimWorld(sim, pal1), np.random.default_rng(2))
        s_values = np.arange(0.0, path.length, 0.1)
        return [laser.scan((*path.pose(s)[:2], 0.3, path.pose(s)[2])) for s in s_values]


def test_detect_landmarks(pal1_scans):
    options = {"post_radius": 0.04, "range_sigma": LMS100.range_sigma}
    queries = [(scan,) for scan in pal1_scans]
    fast = median_over_queries(lambda scan: detect_landmarks(scan, **options), queries)
    posts = np.mean([len(detect_landmarks(scan, **options)) for scan in pal1_scans])
    report(f"detect_landmarks ({LMS100.num_beams} beams, {posts:.1f} posts/scan)", fast)


def test_laser_scan_overhead(pal1, path):
    """Our Python around one ``rayTestBatch``: a scan with the engine's answer replayed."""
    with SimClient() as sim:
        laser = RaycastLaser(sim, LMS100, SimWorld(sim, pal1), np.random.default_rng(3))
        poses = [(*path.pose(s)[:2], 0.3, path.pose(s)[2]) for s in np.linspace(0, 10, 50)]
        totals, casts = [], []
        for k in range(500):
            start = time.perf_counter()
            laser.scan(poses[k % len(poses)])
            totals.append(time.perf_counter() - start)
            casts.append(laser.last_raycast_s)
        results = sim.bullet.rayTestBatch(laser._from, laser._to)
        laser._ray_test_batch = lambda *args, **kwargs: results
        python = median_us(lambda: laser.scan(poses[0]), 1000)
    count = len(results)
    fast = median_us(
        lambda: np.fromiter(map(itemgetter(2), results), dtype=float, count=count), 1000
    )
    reference = median_us(
        lambda: np.fromiter((hit[2] for hit in results), dtype=float, count=count), 1000
    )
    report(
        "hit fractions out of rayTestBatch's tuples (map/itemgetter vs generator)", fast, reference
    )
    print(
        f"RaycastLaser.scan: {1e6 * float(np.median(totals)):.1f} us median wall, of which "
        f"rayTestBatch {1e6 * float(np.median(casts)):.1f} us; our Python {python:.1f} us CPU"
    )


def test_odometry_read():
    """One 50 Hz odometry read: the increment and its covariance."""
    encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0))
    encoders.reset([0.0, 0.0])
    angles = np.zeros(2)

    def read():
        angles[:] += (0.16, 0.17)  # 2 cm per wheel per tick, turning gently
        encoders.read(angles)

    report("WheelEncoders.read (increment + covariance)", median_us(read))


def test_safety_fields_against_the_plain_code(pal1, pal1_scans):
    """One safety scan: robot-frame points and field occupancy vs ``Scan.points`` + shapely."""
    segment = pal1.path.segments[0]
    fields = FieldSet(segment.warning, segment.protective)
    mount = PIONEER3DX.safety_laser.pose2d()
    queries = [(scan,) for scan in pal1_scans]

    def plain(scan):
        points = scan_points_with_scan_points(scan, mount)
        x, y = points[:, 0], points[:, 1]
        for polygon in (fields.warning_polygon, fields.protective_polygon):
            np.count_nonzero(shapely.intersects_xy(polygon, x, y))

    def fast(scan):
        field_occupancy(scan_points_in_robot_frame(scan, mount), fields, 3)

    report(
        "scan_points_in_robot_frame + field_occupancy (LMS100)",
        median_over_queries(fast, queries),
        median_over_queries(plain, queries),
    )


def scan_points_with_scan_points(scan, mount):
    """Return the robot-frame end points as first computed: ``Scan.points()`` then a mask."""
    return transform_points(mount, scan.points()[scan.valid_mask()])


def test_ugv_queries_per_tick(pal1, path):
    """The SimUGV calls of one control tick: wheel angles, true pose, sensor pose, command."""
    with SimClient() as sim:
        SimWorld(sim, pal1)
        robot = SimUGV(sim, PIONEER3DX, path.pose(0.0))
        sim.step(24)
        mount = PIONEER3DX.localization_laser
        figures = {
            "wheel_angles": median_us(robot.wheel_angles),
            "true_pose": median_us(robot.true_pose),
            "sensor_pose": median_us(lambda: robot.sensor_pose(mount)),
            "command": median_us(lambda: robot.command(0.4, 0.1)),
        }
    print("\nSimUGV per call: " + ", ".join(f"{k} {v:.1f} us" for k, v in figures.items()))


def test_people_update():
    world_spec = load_world("pal3").enable_people("walker")
    with SimClient() as sim:
        world = SimWorld(sim, world_spec)
        people = People(world)
        bullet = sim.bullet
        upright = bullet.getQuaternionFromEuler([0.0, 0.0, 0.0])
        ids = {person.name: world.person_id(person.name) for person in world.people}

        def every_step(t):
            for person in world.people:
                xy = person_position(person, t)
                xyz = [*person.waypoints[0], PARKED_Z] if xy is None else [*xy.tolist(), 0.0]
                bullet.resetBasePositionAndOrientation(ids[person.name], xyz, upright)

        # A lap's worth of physics steps: walking for ~6 s, then standing.
        times = [(t,) for t in np.arange(0.0, 40.0, 1.0 / 240.0).tolist()]
        walking = [t for t in times if t[0] < 6.0]
        fast_all = median_over_queries(people.update, times)
        fast_walking = median_over_queries(people.update, walking)
        reference = median_over_queries(every_step, times)
    report("People.update (pal3b walker, whole lap)", fast_all, reference)
    print(f"People.update while the walker walks: {fast_walking:.1f} us median")


def test_contacts_and_step(pal1, path):
    with SimClient() as sim:
        world = SimWorld(sim, pal1)
        robot = SimUGV(sim, PIONEER3DX, path.pose(0.0))
        monitor = ContactMonitor(sim, robot.body_id, world)
        sim.step(24)
        bullet, body = sim.bullet, robot.body_id
        check = median_us(monitor.check)
        raw = median_us(lambda: bullet.getContactPoints(bodyA=body))
        step = median_us(sim.step, 1000, clock=time.perf_counter)
        raw_step = median_us(bullet.stepSimulation, 1000, clock=time.perf_counter)
    print(
        f"\nContactMonitor.check: {check:.1f} us median, of which getContactPoints {raw:.1f} us"
        f"\nSimClient.step: {step:.1f} us median, of which stepSimulation {raw_step:.1f} us"
    )


def test_one_lap_of_pal1():
    log = run_scenario(ScenarioSpec(name="bench", world="pal1", laps=1))
    performance = summarize(log)["performance"]
    print(
        f"\npal1, 1 lap: wall {performance['wall_time_s']:.2f} s, engine "
        f"{performance['engine_time_s']:.2f} s, wall/engine {performance['wall_over_engine']:.2f},"
        f" real-time factor {performance['real_time_factor']:.2f}"
    )
    assert log.laps[0].completed
