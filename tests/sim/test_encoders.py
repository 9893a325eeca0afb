"""Wheel encoders: arc model, quantisation, noise model vs covariance, odometry drift."""

import math

import numpy as np
import pytest

from robots.presets import LGV, PIONEER3DX, PRESETS
from semistatic.frames import compose
from sim.client import SimClient
from sim.encoders import WheelEncoders, arc_increment, arc_increment_jacobian
from sim.ugv import SimUGV, add_floor

ALL_PRESETS = sorted(PRESETS.values(), key=lambda spec: spec.name)


def _angles_for(spec, left_m, right_m):
    """Wheel angles (rad) that roll the given distances."""
    return np.array([left_m, right_m]) / spec.wheel_radius


# --- the arc model ----------------------------------------------------------------------


def test_arc_increment_special_motions():
    np.testing.assert_allclose(arc_increment(0.3, 0.3, 0.5), [0.3, 0.0, 0.0])
    np.testing.assert_allclose(arc_increment(-0.2, -0.2, 0.5), [-0.2, 0.0, 0.0])
    np.testing.assert_allclose(arc_increment(-0.25, 0.25, 0.5), [0.0, 0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(arc_increment(0.0, 0.0, 0.5), [0.0, 0.0, 0.0])


def test_arc_increment_matches_the_circle_it_follows():
    # Outer wheel on radius R + b/2, inner on R - b/2, turning by phi.
    radius, track, phi = 2.0, 0.4, 0.7
    left, right = (radius - track / 2) * phi, (radius + track / 2) * phi
    expected = [radius * math.sin(phi), radius * (1 - math.cos(phi)), phi]
    np.testing.assert_allclose(arc_increment(left, right, track), expected, atol=1e-12)


def test_many_small_increments_compose_to_the_big_one():
    radius, track, phi = 1.5, 0.33, 2.5
    left, right = (radius - track / 2) * phi, (radius + track / 2) * phi
    pose = np.zeros(3)
    for _ in range(1000):
        pose = compose(pose, arc_increment(left / 1000, right / 1000, track))
    np.testing.assert_allclose(pose, arc_increment(left, right, track), atol=1e-12)


def test_arc_increment_is_continuous_through_straight_motion():
    for tiny in (1e-12, 1e-8, 1e-5, 1e-3):
        nearly = arc_increment(1.0 - tiny, 1.0 + tiny, 0.5)
        # dtheta = 4 tiny: to first order the chord leans by dtheta / 2.
        assert nearly[0] == pytest.approx(1.0, abs=10 * tiny**2)
        assert nearly[1] == pytest.approx(2 * tiny, rel=1e-5)


@pytest.mark.parametrize(
    ("left", "right"),
    [(0.3, 0.3), (0.1, 0.5), (-0.2, 0.2), (0.4, 0.4 + 1e-6), (0.0, 0.0), (-0.7, -0.1), (2.0, -1.0)],
)
def test_jacobian_matches_finite_differences(left, right):
    track, h = 0.33, 1e-6
    numeric = np.column_stack(
        [
            (arc_increment(left + h, right, track) - arc_increment(left - h, right, track))
            / (2 * h),
            (arc_increment(left, right + h, track) - arc_increment(left, right - h, track))
            / (2 * h),
        ]
    )
    np.testing.assert_allclose(arc_increment_jacobian(left, right, track), numeric, atol=1e-7)


# --- quantisation and bookkeeping --------------------------------------------------------


def test_ticks_are_the_floor_of_the_angle():
    encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0))
    per_rad = 19150 / (2 * math.pi)
    np.testing.assert_array_equal(encoders.ticks([0.0, 1.0]), [0, math.floor(per_rad)])
    np.testing.assert_array_equal(encoders.ticks([-1e-12, -1.0]), [-1, math.floor(-per_rad)])
    with pytest.raises(ValueError, match="finite"):
        encoders.ticks([0.0, np.nan])
    with pytest.raises(ValueError, match="left, right"):
        encoders.ticks([0.0, 1.0, 2.0])


def test_noise_free_increment_is_the_arc_of_the_quantised_travel():
    spec = PIONEER3DX
    encoders = WheelEncoders(spec, np.random.default_rng(0), noise_free=True)
    encoders.reset([0.5, -0.25])
    angles = np.array([0.5, -0.25]) + _angles_for(spec, 0.4, 0.45)
    increment = encoders.odometry_increment(angles)
    ticks = encoders.last_tick_deltas
    expected_ticks = np.floor(angles * 19150 / (2 * math.pi)) - np.floor(
        np.array([0.5, -0.25]) * 19150 / (2 * math.pi)
    )
    np.testing.assert_array_equal(ticks, expected_ticks)
    travel = ticks * spec.metres_per_tick
    np.testing.assert_allclose(travel, [0.4, 0.45], atol=spec.metres_per_tick)
    np.testing.assert_allclose(
        increment, arc_increment(travel[0], travel[1], spec.wheel_separation), atol=1e-15
    )


def test_quantisation_never_accumulates():
    """Tick rounding telescopes: reading often gives the same total as reading once."""
    spec = PIONEER3DX
    often = WheelEncoders(spec, np.random.default_rng(0), noise_free=True)
    often.reset([0.0, 0.0])
    total = np.zeros(2, dtype=np.int64)
    for angle in np.linspace(0.0, 40.0, 997)[1:]:
        often.odometry_increment([angle, 0.5 * angle])
        total += often.last_tick_deltas
    np.testing.assert_array_equal(total, often.ticks([40.0, 20.0]))


def test_reset_is_required_and_restarts_counting():
    encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0))
    with pytest.raises(RuntimeError, match="reset"):
        encoders.odometry_increment([0.0, 0.0])
    encoders.reset([3.0, 3.0])
    np.testing.assert_allclose(encoders.odometry_increment([3.0, 3.0]), 0.0)


def test_standing_still_gives_exactly_zero_even_with_noise():
    encoders = WheelEncoders(PIONEER3DX.replace(encoder_slip_sigma=0.1), np.random.default_rng(0))
    encoders.reset([1.0, 2.0])
    for _ in range(10):
        assert np.array_equal(encoders.odometry_increment([1.0, 2.0]), np.zeros(3))


def test_rejects_legacy_random_state():
    with pytest.raises(TypeError, match=r"numpy\.random\.Generator"):
        WheelEncoders(PIONEER3DX, np.random.RandomState(0))


# --- noise model and covariance ---------------------------------------------------------


def _sample_increments(spec, seed, left_m, right_m, count):
    encoders = WheelEncoders(spec, np.random.default_rng(seed))
    step = _angles_for(spec, left_m, right_m)
    encoders.reset([0.0, 0.0])
    samples = []
    for k in range(1, count + 1):
        samples.append(encoders.odometry_increment(k * step))
    return np.array(samples), encoders


@pytest.mark.parametrize(("left_m", "right_m"), [(0.5, 0.5), (0.2, 0.6), (-0.3, 0.3)])
def test_covariance_matches_the_sampled_noise(left_m, right_m):
    spec = PIONEER3DX.replace(encoder_slip_sigma=0.02)
    samples, encoders = _sample_increments(spec, 11, left_m, right_m, 4000)
    covariance = encoders.increment_covariance(encoders.last_tick_deltas)
    empirical = np.cov(samples.T)
    scale = np.sqrt(np.outer(np.diag(covariance), np.diag(covariance)))
    # 4000 samples: variances within ~5 %, correlations within a few hundredths.
    np.testing.assert_allclose(np.diag(empirical), np.diag(covariance), rtol=0.08)
    np.testing.assert_allclose(empirical / scale, covariance / scale, atol=0.06)


def test_covariance_is_symmetric_semi_definite_of_rank_two():
    encoders = WheelEncoders(LGV, np.random.default_rng(0))
    covariance = encoders.increment_covariance([5000, 7000])
    np.testing.assert_allclose(covariance, covariance.T)
    eigenvalues = np.linalg.eigvalsh(covariance)
    assert eigenvalues.min() > -1e-12 * eigenvalues.max()
    assert np.linalg.matrix_rank(covariance) == 2


def test_noise_does_not_depend_on_the_odometry_rate():
    """The variance of a wheel's travel grows with distance, not with the number of reads."""
    spec = PIONEER3DX.replace(encoder_slip_sigma=0.01)
    totals = {}
    for reads in (1, 20):
        rng = np.random.default_rng(reads)
        distances = []
        for _ in range(1000):
            encoders = WheelEncoders(spec, rng)
            encoders.reset([0.0, 0.0])
            pose = np.zeros(3)
            for k in range(1, reads + 1):
                pose = compose(
                    pose, encoders.odometry_increment(_angles_for(spec, k / reads, k / reads))
                )
            distances.append(pose[0])
        totals[reads] = np.var(distances)
    # sigma^2 * 1 m travelled per wheel, halved by averaging the two wheels.
    for variance in totals.values():
        assert variance == pytest.approx(0.01**2 / 2, rel=0.15)


def test_same_seed_same_odometry_other_seed_other_odometry():
    first, _ = _sample_increments(PIONEER3DX, 5, 0.1, 0.12, 50)
    again, _ = _sample_increments(PIONEER3DX, 5, 0.1, 0.12, 50)
    other, _ = _sample_increments(PIONEER3DX, 6, 0.1, 0.12, 50)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)


# --- odometry on the simulated robot ----------------------------------------------------

DRIVE_PLAN = [(0.6, 0.0, 8.0), (0.6, 0.4, 6.0), (0.6, 0.0, 6.0), (0.6, -0.3, 5.0)]
ODOMETRY_STEPS = 6  # 40 Hz odometry at 240 Hz physics


def _odometry_drift(spec, seed, *, noise_free=False):
    """Drive about 15 m; return (distance travelled, final position error of odometry)."""
    with SimClient() as sim:
        add_floor(sim)
        robot = SimUGV(sim, spec, pose=(1.0, -2.0, 0.3))
        sim.step(24)
        encoders = WheelEncoders(spec, np.random.default_rng(seed), noise_free=noise_free)
        encoders.reset(robot.wheel_angles())
        odometry = robot.true_pose()
        previous = odometry.copy()
        distance = 0.0
        for v, omega, seconds in DRIVE_PLAN:
            robot.command(v, omega)
            for _ in range(round(seconds / (ODOMETRY_STEPS * sim.time_step))):
                sim.step(ODOMETRY_STEPS)
                odometry = compose(odometry, encoders.odometry_increment(robot.wheel_angles()))
                pose = robot.true_pose()
                distance += float(np.hypot(*(pose[:2] - previous[:2])))
                previous = pose
        return distance, float(np.hypot(*(previous[:2] - odometry[:2])))


@pytest.mark.parametrize(
    ("spec", "seed"),
    [(PIONEER3DX, 0), (PIONEER3DX, 1), (PIONEER3DX, 2), (LGV, 0)],
    ids=["pioneer-0", "pioneer-1", "pioneer-2", "lgv-0"],
)
def test_default_noise_odometry_drifts_at_most_one_percent(spec, seed):
    distance, error = _odometry_drift(spec, seed)
    assert distance > 14.0
    assert error / distance <= 0.01


def test_noise_free_odometry_tracks_the_physics_closely():
    """Without slip noise the only error is the physics' own (no tyre slip here)."""
    distance, error = _odometry_drift(PIONEER3DX, 0, noise_free=True)
    assert error / distance < 0.001


# --- against closed-form differential-drive odometry ------------------------------------
#
# The reference below shares nothing with sim.encoders but the documented model: ticks are
# floor(angle N / 2 pi), a wheel rolls ticks * 2 pi r / N plus slip noise
# sigma sqrt(|d|) n (two standard normals per reading, left then right), and the body
# moves on the circle those two distances describe. The circle is written as a radius
# and an angle (R sin(phi), R (1 - cos(phi)) = 2 R sin^2(phi / 2)), not as the chord and
# sinc the code uses; its covariance uses a numerical Jacobian.


def closed_form_arc(left, right, track):
    """Return the pose after rolling ``left`` and ``right`` metres on a circle (or a line)."""
    phi = (right - left) / track
    if phi == 0.0:
        return np.array([0.5 * (left + right), 0.0, 0.0])
    radius = 0.5 * (left + right) / phi  # of the wheel base's centre; 0 turning on the spot
    return np.array([radius * math.sin(phi), 2.0 * radius * math.sin(0.5 * phi) ** 2, phi])


def closed_form_covariance(left, right, track, variances, step=1e-7):
    """Return J diag(variances) J^T with J the central-difference Jacobian of the arc."""
    jacobian = np.column_stack(
        [
            (
                closed_form_arc(left + step, right, track)
                - closed_form_arc(left - step, right, track)
            )
            / (2 * step),
            (
                closed_form_arc(left, right + step, track)
                - closed_form_arc(left, right - step, track)
            )
            / (2 * step),
        ]
    )
    return jacobian @ np.diag(variances) @ jacobian.T


@pytest.mark.parametrize(
    ("left_ticks", "right_ticks", "expected"),
    [
        # 1000 ticks a wheel is 1000 * 2 pi r / N metres: straight, forward and back.
        (1000, 1000, lambda d, b: (d, 0.0, 0.0)),
        (-700, -700, lambda d, b: (-0.7 * d, 0.0, 0.0)),
        # Opposite wheels: on the spot by 2 d / b.
        (-1000, 1000, lambda d, b: (0.0, 0.0, 2.0 * d / b)),
        (1000, -1000, lambda d, b: (0.0, 0.0, -2.0 * d / b)),
        # One wheel still: a circle of radius b / 2 about the still wheel.
        (0, 1000, lambda d, b: (0.5 * b * math.sin(d / b), 0.5 * b * (1 - math.cos(d / b)), d / b)),
        (
            1000,
            0,
            lambda d, b: (0.5 * b * math.sin(d / b), -0.5 * b * (1 - math.cos(d / b)), -d / b),
        ),
    ],
    ids=["straight", "backwards", "spot-left", "spot-right", "pivot-left", "pivot-right"],
)
@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda spec: spec.name)
def test_tick_counts_give_the_closed_form_motion(spec, left_ticks, right_ticks, expected):
    encoders = WheelEncoders(spec, np.random.default_rng(0), noise_free=True)
    per_tick = 2.0 * math.pi / spec.encoder_ticks_per_rev  # wheel angle of one tick
    # Half a tick past each count: floor() lands on the count whatever the rounding.
    encoders.reset([0.5 * per_tick, 0.5 * per_tick])
    increment = encoders.odometry_increment(
        [(left_ticks + 0.5) * per_tick, (right_ticks + 0.5) * per_tick]
    )
    assert encoders.last_tick_deltas.tolist() == [left_ticks, right_ticks]
    metres = 1000 * per_tick * spec.wheel_radius
    np.testing.assert_allclose(
        increment, expected(metres, spec.wheel_separation), rtol=1e-12, atol=1e-15
    )


def test_covariance_at_rest_by_hand():
    # At rest the arc's Jacobian is [[1/2, 1/2], [0, 0], [-1/b, 1/b]]: each wheel's
    # quantisation variance q = (2 pi r / N)^2 / 6 reaches x by a quarter and theta by 1/b^2.
    spec = PIONEER3DX
    quantisation = (2 * math.pi * spec.wheel_radius / spec.encoder_ticks_per_rev) ** 2 / 6
    b = spec.wheel_separation
    expected = quantisation * np.diag([0.5, 0.0, 2.0 / b**2])
    covariance = WheelEncoders(spec, np.random.default_rng(0)).increment_covariance([0, 0])
    np.testing.assert_allclose(covariance, expected, rtol=1e-12, atol=1e-12 * expected.max())


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda spec: spec.name)
def test_noisy_odometry_is_the_closed_form_arc_of_the_noisy_travel(spec):
    # Straight, turning, on the spot, standing still and backwards, slip noise on: every
    # increment and covariance against the closed form fed the same documented draws.
    sigma = 0.02
    spec = spec.replace(encoder_slip_sigma=sigma)
    encoders = WheelEncoders(spec, np.random.default_rng(5))
    draws = np.random.default_rng(5)  # the same stream, drawn as documented
    rng = np.random.default_rng(6)
    ticks_per_radian = spec.encoder_ticks_per_rev / (2 * math.pi)
    metres_per_tick = 2 * math.pi * spec.wheel_radius / spec.encoder_ticks_per_rev
    quantisation = metres_per_tick**2 / 6
    angles = np.array([3.0, -1.5])
    encoders.reset(angles)
    counts = [math.floor(a * ticks_per_radian) for a in angles]
    for tick in range(400):
        left, right = [(0.2, 0.2), (0.1, 0.3), (-0.2, 0.2), (0.0, 0.0), (-0.1, -0.12)][tick % 5]
        angles = angles + np.array([left, right]) + rng.normal(0.0, 0.01, 2)
        increment, covariance = encoders.read(angles)

        now = [math.floor(a * ticks_per_radian) for a in angles]
        deltas = [now[0] - counts[0], now[1] - counts[1]]
        counts = now
        assert encoders.last_tick_deltas.tolist() == deltas
        nominal = [delta * metres_per_tick for delta in deltas]
        noise = draws.standard_normal(2)
        travel = [d + sigma * math.sqrt(abs(d)) * n for d, n in zip(nominal, noise, strict=True)]
        expected = closed_form_arc(*travel, spec.wheel_separation)
        np.testing.assert_allclose(increment, expected, rtol=1e-11, atol=1e-14)

        variances = [sigma**2 * abs(d) + quantisation for d in nominal]
        reference = closed_form_covariance(*nominal, spec.wheel_separation, variances)
        # Central differences carry ~1e-9 relative error into the Jacobian.
        np.testing.assert_allclose(
            covariance, reference, rtol=1e-6, atol=1e-8 * np.abs(reference).max()
        )
        np.testing.assert_array_equal(
            covariance, encoders.increment_covariance(encoders.last_tick_deltas)
        )
