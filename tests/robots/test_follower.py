"""Tests for robots.follower: error signs, convergence, curved tracking, limits, stops."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from robots.follower import ChainedFormFollower, FollowerParams
from robots.path import SplinePath
from semistatic.frames import wrap_angle
from tests.robots.scipy_path import ScipyPath
from tests.spec_errors import raises_spec_error

DT = 0.02
NO_LIMITS = {
    "max_speed": math.inf,
    "max_angular_speed": math.inf,
    "max_acceleration": math.inf,
    "max_deceleration": math.inf,
    "max_angular_acceleration": math.inf,
}
# The defaults are the limits: 1 m/s, 1.5 rad/s, 0.5 / 1.0 m/s^2, 3 rad/s^2.
LIMITS = {"with_limits": {}, "no_limits": NO_LIMITS}
# Critically damped at 3 per metre (l^2 + 6 l + 9): what a 2 m convergence needs.
STIFF_GAINS = {"k2": 9.0, "k3": 6.0}
STRAIGHT = SplinePath([(0.0, 0.0), (10.0, 0.0)])
SHORT = SplinePath([(0.0, 0.0), (3.0, 0.0)])
# About 15 m of left and right turns, radius down to 2 m.
CURVE = SplinePath(
    [
        (0.0, 0.0),
        (2.0, 0.0),
        (4.0, 1.0),
        (5.0, 3.0),
        (4.0, 5.0),
        (2.0, 5.5),
        (0.0, 4.5),
        (-1.0, 3.0),
    ]
)


def unicycle_step(pose: np.ndarray, v: float, omega: float, dt: float) -> np.ndarray:
    """Exact motion of a unicycle under constant (v, omega) for dt."""
    x, y, theta = pose
    if abs(omega) < 1e-12:
        return np.array([x + v * dt * math.cos(theta), y + v * dt * math.sin(theta), theta])
    radius = v / omega
    end = theta + omega * dt
    return np.array(
        [
            x + radius * (math.sin(end) - math.sin(theta)),
            y - radius * (math.cos(end) - math.cos(theta)),
            end,
        ]
    )


def simulate(path, params, start, max_time=120.0, speed_scale=lambda t: 1.0):
    """Drive the follower; return the log (distance, lateral error, v, omega) and end pose."""
    follower = ChainedFormFollower(path, params)
    pose = np.array(start, dtype=float)
    rows = []
    travelled = 0.0
    for tick in range(int(max_time / DT)):
        v, omega = follower.command(pose, DT, speed_scale(tick * DT))
        # The progress is the projection of this pose: its distance is the lateral error.
        s = follower.progress
        rows.append((travelled, np.linalg.norm(path.point(s) - pose[:2]), v, omega, s))
        pose = unicycle_step(pose, v, omega, DT)
        travelled += abs(v) * DT
        if follower.done and v == 0.0 and omega == 0.0:
            break
    return np.array(rows), pose, follower


def convergence_distance(log: np.ndarray, tolerance: float = 0.02) -> float:
    """Distance travelled after which the lateral error stays below ``tolerance``."""
    above = np.flatnonzero(log[:, 1] >= tolerance)
    return 0.0 if above.size == 0 else float(log[above[-1] + 1, 0])


def test_error_signs_and_frame():
    follower = ChainedFormFollower(STRAIGHT)
    follower.reset(2.0)  # the projection searches around the progress
    xe, ye, theta_e = follower.errors([2.0, 0.3, 0.0])
    assert (xe, ye, theta_e) == pytest.approx((0.0, 0.3, 0.0))
    # Rotated 90 deg: the world offset (0, 0.3) is "to the right" in the robot frame.
    xe, ye, theta_e = follower.errors([2.0, 0.3, math.pi / 2])
    assert (xe, ye, theta_e) == pytest.approx((0.3, 0.0, math.pi / 2))
    # Errors on a rotated path are the same as on an axis-aligned one.
    diagonal = SplinePath([(0.0, 0.0), (7.0, 7.0)])
    offset = np.array([-0.3, 0.3]) / math.sqrt(2.0)
    pose = [2.0 + offset[0], 2.0 + offset[1], math.pi / 4 + 0.2]
    expected = (0.3 * math.sin(0.2), 0.3 * math.cos(0.2), 0.2)
    follower = ChainedFormFollower(diagonal)
    follower.reset(2.0 * math.sqrt(2.0))
    assert follower.errors(pose) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("pose", "turn"),
    [([1.0, 0.2, 0.0], -1), ([1.0, -0.2, 0.0], 1), ([1.0, 0.0, 0.3], -1), ([1.0, 0.0, -0.3], 1)],
)
def test_command_turns_toward_the_path(pose, turn):
    follower = ChainedFormFollower(STRAIGHT, FollowerParams(**NO_LIMITS))
    _, omega = follower.command(pose, DT)
    assert np.sign(omega) == turn


def test_errors_do_not_advance_the_progress():
    follower = ChainedFormFollower(STRAIGHT)
    follower.errors([0.8, 0.0, 0.0])
    assert follower.progress == 0.0
    follower.command([0.8, 0.0, 0.0], DT)
    assert follower.progress == pytest.approx(0.8)


@pytest.mark.parametrize("limits", sorted(LIMITS))
@pytest.mark.parametrize("heading_sign", [1, -1], ids=["heading_away", "heading_toward"])
def test_converges_from_lateral_and_heading_offset_within_two_metres(limits, heading_sign):
    params = FollowerParams(**STIFF_GAINS, **LIMITS[limits])
    start = [0.0, 0.3, heading_sign * math.radians(20.0)]
    log, _, _ = simulate(STRAIGHT, params, start, max_time=10.0)
    # Measured: 1.60-1.65 m heading away, 1.39 m heading toward the path.
    assert convergence_distance(log) < 2.0


@pytest.mark.parametrize("heading_sign", [1, -1], ids=["heading_away", "heading_toward"])
def test_paper_gains_converge_as_the_linearisation_predicts(heading_sign):
    # Paper gains: per metre d^2 ye/ds^2 + 1.5 dye/ds + 1.5 ye = 0, so
    # ye(d) = e^{-0.75 d} (A cos(w d) + B sin(w d)) with w = sqrt(1.5 - 0.75^2).
    heading = heading_sign * math.radians(20.0)
    log, _, _ = simulate(STRAIGHT, FollowerParams(**NO_LIMITS), [0.0, 0.3, heading], 20.0)
    decay = 0.75
    frequency = math.sqrt(1.5 - decay**2)
    a = 0.3
    b = (math.sin(heading) + decay * a) / frequency
    travelled = log[:, 0]
    predicted = np.exp(-decay * travelled) * (
        a * np.cos(frequency * travelled) + b * np.sin(frequency * travelled)
    )
    # Once the heading error is small, the nonlinear loop follows the linear one
    # (measured: within 3.4 mm heading away, 0.35 mm heading toward the path).
    settled = travelled > 2.0
    assert np.max(np.abs(np.abs(predicted) - log[:, 1])[settled]) < 0.005
    # Measured: 4.56 m heading away, 3.46 m heading toward the path (not 2 m: see the
    # stiffer gains above).
    assert 2.0 < convergence_distance(log) < 5.0


def test_convergence_is_the_same_in_distance_at_any_speed():
    start = [0.0, 0.3, math.radians(20.0)]
    slow, _, _ = simulate(STRAIGHT, FollowerParams(speed=0.2, **NO_LIMITS), start, 30.0)
    fast, _, _ = simulate(STRAIGHT, FollowerParams(speed=0.8, **NO_LIMITS), start, 7.5)
    assert convergence_distance(slow) == pytest.approx(convergence_distance(fast), abs=0.05)


@pytest.mark.parametrize("limits", sorted(LIMITS))
@pytest.mark.parametrize("speed", [0.4, 0.8])
def test_tracks_a_curved_path_under_two_centimetres_rms(limits, speed):
    params = FollowerParams(speed=speed, **LIMITS[limits])
    log, pose, follower = simulate(CURVE, params, CURVE.pose(0.0))
    lateral = log[log[:, 4] < CURVE.length - params.goal_tolerance, 1]
    rms = math.sqrt(np.mean(lateral**2))
    # Measured: 0.13-0.72 mm RMS, 0.35-2.5 mm max.
    assert rms < 0.02
    assert follower.done
    assert np.linalg.norm(pose[:2] - CURVE.knots[-1]) < 2 * params.goal_tolerance


@pytest.mark.parametrize("limits", sorted(LIMITS))
def test_converges_onto_and_then_tracks_the_curved_path(limits):
    params = FollowerParams(**LIMITS[limits])
    start = [0.0, 0.3, math.radians(20.0)]
    log, _, follower = simulate(CURVE, params, start)
    assert convergence_distance(log) < 5.0
    tracked = log[(log[:, 0] > 5.0) & (log[:, 4] < CURVE.length - params.goal_tolerance), 1]
    assert math.sqrt(np.mean(tracked**2)) < 0.02
    assert follower.done


def test_limits_are_respected():
    params = FollowerParams(
        speed=0.8,
        max_speed=0.6,
        max_angular_speed=0.5,
        max_acceleration=0.3,
        max_deceleration=0.6,
        max_angular_acceleration=1.0,
    )
    log, _, _ = simulate(CURVE, params, [0.0, 0.4, math.radians(30.0)])
    v, omega = log[:, 2], log[:, 3]
    assert np.max(np.abs(v)) <= 0.6 + 1e-12
    assert np.max(np.abs(omega)) <= 0.5 + 1e-12
    dv = np.diff(np.concatenate([[0.0], v])) / DT
    assert np.max(dv) <= 0.3 + 1e-9
    assert np.min(dv) >= -0.6 - 1e-9
    domega = np.diff(np.concatenate([[0.0], omega])) / DT
    assert np.max(np.abs(domega)) <= 1.0 + 1e-9
    # The limits bind (otherwise this test would prove nothing).
    assert np.max(np.abs(omega)) == pytest.approx(0.5)
    assert np.max(dv) == pytest.approx(0.3)


def test_speed_limit_keeps_the_commanded_arc():
    params = FollowerParams(**{**NO_LIMITS, "max_speed": 0.2, "max_angular_speed": 0.1})
    follower = ChainedFormFollower(CURVE, FollowerParams(**NO_LIMITS))
    limited = ChainedFormFollower(CURVE, params)
    pose = [0.0, 0.3, 0.4]
    v, omega = follower.command(pose, DT)
    v_limited, omega_limited = limited.command(pose, DT)
    assert abs(omega_limited) == pytest.approx(0.1)
    assert omega_limited / v_limited == pytest.approx(omega / v)


def test_protective_stop_brakes_holds_and_resumes():
    params = FollowerParams()
    # Stop between 4 s and 7 s, as a protective field would.
    log, _, follower = simulate(
        SHORT, params, [0.0, 0.0, 0.0], speed_scale=lambda t: 0.0 if 4.0 <= t < 7.0 else 1.0
    )
    time = np.arange(len(log)) * DT
    v = log[:, 2]
    braking = v[(time >= 4.0) & (time < 7.0)]
    # Brakes at max_deceleration (0.4 m/s in 0.4 s), then stands still.
    assert braking[0] == pytest.approx(0.4 - 1.0 * DT)
    assert np.all(braking[int(0.4 / DT) :] == 0.0)
    progress_while_stopped = log[(time >= 4.5) & (time < 7.0), 4]
    assert np.ptp(progress_while_stopped) < 1e-9
    assert v[(time >= 7.0) & (time < 8.0)].max() == pytest.approx(0.4)
    assert follower.done


def test_warning_scale_slows_down():
    log, _, _ = simulate(SHORT, FollowerParams(), [0.0, 0.0, 0.0], 3.0, lambda t: 0.5)
    assert np.max(log[:, 2]) == pytest.approx(0.2)


def test_done_at_the_goal_stays_stopped_and_reset_restarts():
    params = FollowerParams()
    _, pose, follower = simulate(SHORT, params, [0.0, 0.0, 0.0])
    assert follower.done
    assert pose[0] == pytest.approx(3.0, abs=params.goal_tolerance)
    assert follower.command(pose, DT) == (0.0, 0.0)
    follower.reset()
    assert not follower.done
    assert follower.progress == 0.0
    v, _ = follower.command([0.0, 0.0, 0.0], DT)
    assert v == pytest.approx(params.max_acceleration * DT)


def test_large_heading_error_still_turns_toward_the_path():
    follower = ChainedFormFollower(STRAIGHT, FollowerParams(**NO_LIMITS))
    for theta in (math.radians(100.0), math.radians(179.0)):
        follower.reset()
        _, omega = follower.command([1.0, 0.0, theta], DT)
        assert math.isfinite(omega)
        assert omega < 0.0


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("speed", 0.0, r"must be > 0.0 and <= 20.0, got 0.0 \(m/s"),
        ("speed", 30.0, "<= 20.0, got 30.0"),
        ("k1", -3.0, r"> 0.0 and <= 100.0, got -3.0 \(1/m, along-track gain"),
        ("k3", math.nan, "must be a finite number, got nan"),
        ("max_acceleration", 0.0, r"must be > 0.0 .*math.inf disables it"),
        ("max_speed", -math.inf, "must be a finite number, got -inf"),
        ("max_angular_speed", 25.0, "<= 20.0, got 25.0"),
        ("goal_tolerance", math.inf, "must be a finite number, got inf"),
    ],
)
def test_bad_params_are_rejected(field, value, match):
    with raises_spec_error(field, match):
        FollowerParams(**{field: value})


def test_limits_may_be_switched_off_with_inf():
    params = FollowerParams(**NO_LIMITS)
    assert all(getattr(params, name) == math.inf for name in NO_LIMITS)
    assert type(FollowerParams(speed=1).speed) is float


def test_bad_command_arguments_are_rejected():
    follower = ChainedFormFollower(STRAIGHT)
    with pytest.raises(ValueError, match="dt must be > 0"):
        follower.command([0.0, 0.0, 0.0], 0.0)
    with pytest.raises(ValueError, match=r"speed_scale must be in \[0, 1\]"):
        follower.command([0.0, 0.0, 0.0], DT, speed_scale=1.5)


def chained_form_command(pose, reference_pose, curvature, u1r, params):
    """Return eq. (6) written out: the errors in the robot frame, then the control law."""
    x, y, theta = pose
    x_ref, y_ref, theta_ref = reference_pose
    # [xe, ye] = R(theta)^T [x - xr, y - yr], theta_e = wrap(theta - theta_r), clipped.
    rotation = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    xe, ye = rotation.T @ [x - x_ref, y - y_ref]
    theta_e = math.atan2(math.sin(theta - theta_ref), math.cos(theta - theta_ref))
    theta_e = float(np.clip(theta_e, -math.radians(80.0), math.radians(80.0)))
    u1 = u1r - params.k1 * abs(u1r) * xe
    u2 = curvature * u1r - params.k2 * u1r * ye - params.k3 * abs(u1r) * math.tan(theta_e)
    return u1, u2


def test_commands_are_the_chained_form_law_on_scipys_path():
    # A noisy drive along the curve with a safety stop on the way, no limits: at every
    # tick the progress is scipy's closest point (within the projection window around the
    # last one) and the command is eq. (6) on scipy's pose and curvature there.
    params = FollowerParams(**NO_LIMITS)
    follower = ChainedFormFollower(CURVE, params)
    reference = ScipyPath(CURVE.knots, "natural")
    rng = np.random.default_rng(4)
    pose = np.array([0.0, 0.1, 0.05])
    progress = 0.0
    for tick in range(160):
        scale = 0.0 if 60 <= tick < 70 else 1.0
        v, omega = follower.command(pose, DT, speed_scale=scale)
        window = params.projection_window
        progress = reference.closest(
            pose[:2], max(0.0, progress - window), min(reference.length, progress + window)
        )
        assert follower.progress == pytest.approx(progress, abs=1e-6)
        point, heading, curvature = reference.frame(progress)
        reference_pose = (*point, heading)
        expected = chained_form_command(
            pose, reference_pose, curvature, params.speed * scale, params
        )
        assert (v, omega) == pytest.approx(expected, abs=1e-5)
        assert follower.errors(pose) == pytest.approx(
            tuple(np.linalg.solve(
                [[math.cos(pose[2]), -math.sin(pose[2]), 0.0],
                 [math.sin(pose[2]), math.cos(pose[2]), 0.0], [0.0, 0.0, 1.0]],
                [pose[0] - reference_pose[0], pose[1] - reference_pose[1],
                 wrap_angle(pose[2] - reference_pose[2])],
            )),
            abs=1e-5,
        )
        pose = unicycle_step(pose, v, omega, DT) + rng.normal(0.0, 0.003, 3)
    assert progress > 1.0  # about 1.2 m of the curve, into its first turn


CIRCLE_RADIUS = 3.0
CIRCLE = SplinePath(
    [
        (CIRCLE_RADIUS * math.cos(a), CIRCLE_RADIUS * math.sin(a))
        for a in np.linspace(0.0, 2.0 * math.pi, 33)
    ],
    bc_type="periodic",
)


@pytest.mark.parametrize("limits", sorted(LIMITS))
def test_converges_onto_a_circle_and_turns_at_its_curvature(limits):
    # A circle of radius 3 m (32 knots, periodic), entered 0.3 m outside heading 20 deg
    # off the tangent: the robot joins the TRUE circle (not only the spline) and then
    # drives it at u2 = u1 / R.
    params = FollowerParams(**STIFF_GAINS, **LIMITS[limits])
    start = [CIRCLE_RADIUS + 0.3, 0.0, math.pi / 2 + math.radians(20.0)]
    log, pose, _ = simulate(CIRCLE, params, start, max_time=25.0)
    assert convergence_distance(log) < 2.5
    settled = log[:, 0] > 4.0
    assert np.abs(log[settled, 1]).max() < 0.005
    v, omega = log[settled, 2], log[settled, 3]
    np.testing.assert_allclose(omega / v, 1.0 / CIRCLE_RADIUS, rtol=0.01)
    assert abs(math.hypot(pose[0], pose[1]) - CIRCLE_RADIUS) < 0.005


LOOP = SplinePath([(0.0, 0.0), (3.0, 0.0), (4.0, 1.0), (4.0, 3.0), (3.0, 4.0), (0.0, 4.0),
                   (-1.0, 3.0), (-1.0, 1.0), (0.0, 0.0)], bc_type="periodic")


def test_closed_path_is_driven_lap_after_lap_without_braking_at_the_seam():
    follower = ChainedFormFollower(LOOP, FollowerParams())
    pose = LOOP.pose(0.0)
    # Distances to a 1 mm polyline of the loop, from a k-d tree (the tracking error).
    dense = cKDTree(LOOP.point(np.linspace(0.0, LOOP.length, 20001)))
    laps, speeds, poses = 0, [], []
    for _ in range(int(3.5 * LOOP.length / (FollowerParams().speed * DT))):
        v, omega = follower.command(pose, DT)
        speeds.append(v)
        poses.append(pose[:2])
        pose = unicycle_step(pose, v, omega, DT)
        if follower.done:
            laps += 1
            follower.reset(keep_speed=True)
    assert laps == 3
    cruising = np.array(speeds[int(2.0 / DT):])
    # No stop at a lap end: after the first acceleration the speed never drops below 90 %.
    assert cruising.min() > 0.9 * FollowerParams().speed
    errors, _ = dense.query(np.array(poses))
    assert max(errors[int(2.0 / DT):]) < 0.02


def test_reset_without_keep_speed_starts_from_standstill():
    follower = ChainedFormFollower(LOOP, FollowerParams())
    pose = LOOP.pose(0.0)
    for _ in range(100):
        v, omega = follower.command(pose, DT)
        pose = unicycle_step(pose, v, omega, DT)
    follower.reset()
    v, _ = follower.command(LOOP.pose(0.0), DT)
    assert v <= FollowerParams().max_acceleration * DT + 1e-12
