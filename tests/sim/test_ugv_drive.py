"""The UGV body in PyBullet: loading, driving on wheel motors, limits, reset, determinism."""

import math

import numpy as np
import pytest

from robots.presets import LGV, PIONEER3DX, PRESETS
from robots.urdf import LASER_LINK_MASS, laser_link_names
from semistatic.frames import compose, wrap_angle
from sim.client import SimClient
from sim.encoders import WheelEncoders
from sim.ugv import SimUGV, add_floor

ALL_PRESETS = sorted(PRESETS.values(), key=lambda spec: spec.name)
SETTLE_STEPS = 24  # 0.1 s to land the 1 mm spawn drop
# Long enough for either preset to reach its wheel targets at its torque limit.
START_UP_S = 1.5
SAMPLE_STEPS = 6  # sample the trajectory at 40 Hz


def _spawn(sim, spec, pose=(0.0, 0.0, 0.0)):
    add_floor(sim)
    robot = SimUGV(sim, spec, pose=pose)
    sim.step(SETTLE_STEPS)
    return robot


def _drive(sim, robot, seconds):
    """Step ``seconds`` of simulated time; return the (N, 3) sampled true poses."""
    poses = [robot.true_pose()]
    for _ in range(round(seconds / (SAMPLE_STEPS * sim.time_step))):
        sim.step(SAMPLE_STEPS)
        poses.append(robot.true_pose())
    return np.array(poses)


def _path_length(poses):
    return float(np.hypot(*np.diff(poses[:, :2], axis=0).T).sum())


def _heading_change(poses):
    return float(np.unwrap(poses[:, 2])[-1] - poses[0, 2])


def _fit_circle(points):
    """Least-squares (Kasa) circle through ``points``: centre and radius."""
    x, y = points[:, 0], points[:, 1]
    design = np.column_stack([x, y, np.ones_like(x)])
    (a, b, c), *_ = np.linalg.lstsq(design, x**2 + y**2, rcond=None)
    centre = np.array([a / 2, b / 2])
    return centre, math.sqrt(c + centre @ centre)


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_urdf_loads_with_its_masses_and_joints(spec):
    with SimClient() as sim:
        robot = SimUGV(sim, spec)
        bullet = sim.bullet
        links = range(-1, bullet.getNumJoints(robot.body_id))
        masses = [bullet.getDynamicsInfo(robot.body_id, link)[0] for link in links]
        lasers = len(laser_link_names(spec)) * LASER_LINK_MASS
        assert sum(masses) == pytest.approx(spec.total_mass + lasers)
        for joint in robot.wheel_joints:
            assert bullet.getJointInfo(robot.body_id, joint)[2] == bullet.JOINT_REVOLUTE
        assert {"left_wheel", "right_wheel", "caster_0"} <= set(robot.link_indices)


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (3.0, -2.0, math.pi), (-1.0, 4.0, -2.0)])
def test_spawns_at_rest_at_the_requested_pose(spec, pose):
    with SimClient() as sim:
        robot = _spawn(sim, spec, pose)
        sim.step(2 * 240)  # 2 s with the motors holding zero speed: no creep
        actual = robot.true_pose()
        np.testing.assert_allclose(actual[:2], pose[:2], atol=1e-3)
        assert abs(wrap_angle(actual[2] - pose[2])) < 1e-3
        np.testing.assert_allclose(robot.true_twist(), 0.0, atol=1e-3)
        # Every laser mount is where the spec says, in the world.
        mount = spec.safety_laser
        expected = compose(pose, mount.pose2d())
        sensor = robot.sensor_pose(mount)
        np.testing.assert_allclose(sensor[:2], expected[:2], atol=2e-3)
        assert sensor[2] == pytest.approx(mount.z, abs=2e-3)
        assert abs(wrap_angle(sensor[3] - expected[2])) < 1e-3


@pytest.mark.parametrize(
    ("spec", "v", "omega"),
    [
        (PIONEER3DX, 0.5, 0.0),
        (PIONEER3DX, 0.5, 0.2),
        (PIONEER3DX, 1.0, -0.3),
        (LGV, 0.8, 0.1),
        (LGV, 1.2, -0.25),
    ],
    ids=["pioneer-straight", "pioneer-left-arc", "pioneer-fast-right-arc", "lgv-arc", "lgv-fast"],
)
def test_commanded_arc_is_driven_within_two_percent(spec, v, omega):
    """Ten seconds of a constant (v, omega) command give the commanded arc.

    Physics relied on: the wheel motors are velocity servos limited by the motor
    torque, the tyres grip the floor with Coulomb friction 1 (floor 1 x tyre 1) and do
    not slip because the torque limit bounds the tractive force far below friction times
    load, the casters slide without friction, and the speeds here are inside the wheel
    speed limits. After the start-up (torque-limited acceleration, checked separately)
    the robot must follow the circle of radius v/omega at speed v.
    """
    with SimClient() as sim:
        robot = _spawn(sim, spec, pose=(0.5, -0.5, 0.3))
        robot.command(v, omega)
        sim.step(round(START_UP_S / sim.time_step))
        poses = _drive(sim, robot, 10.0)

    distance = _path_length(poses)
    assert distance == pytest.approx(v * 10.0, rel=0.02)
    turned = _heading_change(poses)
    # The end pose: the start pose composed with the commanded arc.
    if omega == 0.0:
        assert abs(turned) < 0.02
        expected_step = np.array([v * 10.0, 0.0, 0.0])
    else:
        assert turned == pytest.approx(omega * 10.0, rel=0.02)
        _, radius = _fit_circle(poses[:, :2])
        assert radius == pytest.approx(abs(v / omega), rel=0.02)
        angle = omega * 10.0
        r = v / omega
        expected_step = np.array([r * math.sin(angle), r * (1 - math.cos(angle)), angle])
    expected_end = compose(poses[0], expected_step)
    end_error = float(np.hypot(*(poses[-1, :2] - expected_end[:2])))
    assert end_error / distance < 0.02


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_start_up_is_limited_by_the_wheel_torque(spec):
    """From rest the robot accelerates at 2 tau / (r m_eff) until it reaches v.

    ``m_eff`` adds the wheels' rotational inertia (I / r^2 each) to the mass. The
    distance lost against v T is v^2 / (2 a); it must match within 10 %.
    """
    v = 0.5
    wheel_inertia = 0.5 * spec.wheel_mass * spec.wheel_radius**2
    effective_mass = spec.total_mass + 2 * wheel_inertia / spec.wheel_radius**2
    acceleration = 2 * spec.max_wheel_torque / (spec.wheel_radius * effective_mass)
    with SimClient() as sim:
        robot = _spawn(sim, spec)
        robot.command(v, 0.0)
        poses = _drive(sim, robot, 3.0)
    lost = v * 3.0 - _path_length(poses)
    assert lost == pytest.approx(v**2 / (2 * acceleration), rel=0.10)


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_tiny_torque_limit_cannot_reach_the_commanded_speed(spec):
    """With 1 % of the torque the robot crawls: the limit is real, not cosmetic."""
    weak = spec.replace(max_wheel_torque=0.01 * spec.max_wheel_torque)
    with SimClient() as sim:
        robot = _spawn(sim, weak)
        robot.command(0.5, 0.0)
        sim.step(2 * 240)
        speed = robot.true_twist()[0]
        wheel_speed = robot.wheel_velocities()
    assert speed < 0.1 * 0.5
    assert np.all(wheel_speed < 0.1 * robot.wheel_targets)
    # ... and it still accelerates as F = m a predicts with that torque (within 20 %).
    wheel_inertia = 0.5 * spec.wheel_mass * spec.wheel_radius**2
    effective_mass = spec.total_mass + 2 * wheel_inertia / spec.wheel_radius**2
    predicted = 2 * weak.max_wheel_torque / (spec.wheel_radius * effective_mass) * 2.0
    assert speed == pytest.approx(predicted, rel=0.2)


def test_command_scales_both_wheels_to_keep_the_curvature():
    with SimClient() as sim:
        robot = SimUGV(sim, PIONEER3DX)
        left, right = robot.command(3.0, 2.0)
        assert max(abs(left), abs(right)) == pytest.approx(PIONEER3DX.max_wheel_speed)
        v, omega = PIONEER3DX.twist_from_wheel_speeds(left, right)
        assert v / omega == pytest.approx(3.0 / 2.0)
        # Inside the limits the command passes through unchanged.
        left, right = robot.command(0.3, 0.1)
        np.testing.assert_allclose([left, right], PIONEER3DX.wheel_speeds(0.3, 0.1))
        with pytest.raises(ValueError, match="finite"):
            robot.command(float("nan"), 0.0)


def test_set_wheel_speeds_clips_each_wheel():
    with SimClient() as sim:
        robot = SimUGV(sim, PIONEER3DX)
        applied = robot.set_wheel_speeds(-50.0, 3.0)
        np.testing.assert_allclose(applied, [-PIONEER3DX.max_wheel_speed, 3.0])
        np.testing.assert_allclose(robot.wheel_targets, applied)


def test_spin_in_place_turns_about_the_axle_midpoint():
    with SimClient() as sim:
        robot = _spawn(sim, PIONEER3DX, pose=(2.0, 1.0, 0.0))
        robot.command(0.0, 1.0)
        poses = _drive(sim, robot, 3.0)
    # base_link is the centre of rotation: it barely moves while the heading turns.
    assert np.abs(poses[:, :2] - [2.0, 1.0]).max() < 0.01
    assert _heading_change(poses) > 2.5


def test_wheel_angles_accumulate_past_a_turn():
    with SimClient() as sim:
        robot = _spawn(sim, PIONEER3DX)
        start = robot.wheel_angles()
        robot.command(0.6, 0.0)
        sim.step(5 * 240)
        travelled = robot.wheel_angles() - start
    assert np.all(travelled > 4 * math.pi)  # not wrapped to (-pi, pi]


def test_reset_teleports_to_rest_keeping_the_wheel_angles():
    with SimClient() as sim:
        robot = _spawn(sim, PIONEER3DX)
        robot.command(0.8, 0.4)
        sim.step(3 * 240)
        angles = robot.wheel_angles()
        robot.reset((-2.0, 3.0, 1.0))
        np.testing.assert_allclose(robot.wheel_angles(), angles)
        np.testing.assert_allclose(robot.wheel_targets, 0.0)
        sim.step(SETTLE_STEPS)
        pose = robot.true_pose()
        np.testing.assert_allclose(pose, [-2.0, 3.0, 1.0], atol=2e-3)
        np.testing.assert_allclose(robot.true_twist(), 0.0, atol=2e-3)
        # ... and it drives on from there.
        robot.command(0.5, 0.0)
        sim.step(240)
        moved = robot.true_pose()[:2] - pose[:2]
        assert np.hypot(*moved) > 0.3
        assert moved @ [math.cos(1.0), math.sin(1.0)] > 0.3  # forward along its heading


def test_rejects_bad_poses():
    with SimClient() as sim:
        with pytest.raises(ValueError, match="pose must be a finite"):
            SimUGV(sim, PIONEER3DX, pose=(0.0, 0.0))
        robot = SimUGV(sim, PIONEER3DX)
        with pytest.raises(ValueError, match="pose must be a finite"):
            robot.reset((0.0, float("inf"), 0.0))


def _run(seed):
    """Drive a fixed command schedule; return true poses and odometry, every 40 Hz."""
    schedule = [(0.6, 0.0), (0.6, 0.5), (0.3, -0.8), (0.0, 1.0)]
    with SimClient() as sim:
        robot = _spawn(sim, PIONEER3DX, pose=(1.0, 1.0, 0.5))
        encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(seed))
        encoders.reset(robot.wheel_angles())
        poses, increments = [], []
        for v, omega in schedule:
            robot.command(v, omega)
            for _ in range(60):
                sim.step(SAMPLE_STEPS)
                poses.append(robot.true_pose())
                increments.append(encoders.odometry_increment(robot.wheel_angles()))
    return np.array(poses), np.array(increments)


def test_same_seed_and_commands_give_bitwise_identical_runs():
    poses_a, odometry_a = _run(seed=7)
    poses_b, odometry_b = _run(seed=7)
    assert np.array_equal(poses_a, poses_b)
    assert np.array_equal(odometry_a, odometry_b)
    _, odometry_c = _run(seed=8)
    assert not np.array_equal(odometry_a, odometry_c)


def test_two_live_clients_stepped_alternately_stay_identical():
    with SimClient() as sim_a, SimClient() as sim_b:
        robot_a = _spawn(sim_a, LGV)
        robot_b = _spawn(sim_b, LGV)
        for v, omega in [(1.0, 0.3), (0.5, -0.6)]:
            robot_a.command(v, omega)
            robot_b.command(v, omega)
            for _ in range(100):
                sim_a.step(SAMPLE_STEPS)
                sim_b.step(SAMPLE_STEPS)
                assert np.array_equal(robot_a.true_pose(), robot_b.true_pose())
        assert np.array_equal(robot_a.wheel_angles(), robot_b.wheel_angles())


def test_infinite_wheel_speeds_clip_to_the_limit_and_nan_is_refused():
    # The float clip must keep numpy.clip's semantics: +-inf is a request for full speed.
    with SimClient() as sim:
        robot = SimUGV(sim, PIONEER3DX)
        limit = PIONEER3DX.max_wheel_speed
        np.testing.assert_array_equal(robot.set_wheel_speeds(np.inf, -np.inf), [limit, -limit])
        with pytest.raises(ValueError, match="speeds must be finite"):
            robot.set_wheel_speeds(np.nan, 0.0)
        with pytest.raises(ValueError, match="v and omega must be finite"):
            robot.command(np.inf, 0.0)
        np.testing.assert_array_equal(robot.wheel_targets, [limit, -limit])
