"""EKF localizer: compounding prediction, range-bearing updates, consistency, re-localisation.

The synthetic world is pure numpy: a robot drives a loop among landmark posts, its
odometry increments and landmark observations are drawn from exactly the noise models
the filter assumes, so a correct filter is consistent (NEES) by construction.
"""

import math

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter
from scipy.stats import chi2

from robots.ekf import EKFLocalizer, EKFParams
from robots.landmarks import LandmarkObservation
from semistatic.frames import between, compose, wrap_angle
from tests.spec_errors import raises_spec_error

MOUNT = (0.25, 0.05, 0.1)
RANGE_SIGMA = 0.012
BEARING_SIGMA = 0.003
SENSOR_RANGE = 10.0
SENSOR_HALF_FOV = math.radians(135.0)
DT = 0.1
# Posts along the walls of a 24 m x 14 m hall, irregular so no two views look alike.
POSTS = np.array(
    [
        [-11.0, -6.5],
        [-5.5, -6.8],
        [0.5, -6.6],
        [6.0, -6.9],
        [11.2, -6.4],
        [11.6, 0.4],
        [11.1, 6.6],
        [4.8, 6.8],
        [-1.2, 6.5],
        [-6.9, 6.7],
        [-11.5, 6.2],
        [-11.3, 0.8],
        [-3.0, 0.9],
        [3.5, -1.1],
    ]
)


def true_increments(steps, speed=0.6):
    """A loop around the hall: straight, turn, straight, turn (robot-frame increments)."""
    increments = np.zeros((steps, 3))
    increments[:, 0] = speed * DT
    phase = (np.arange(steps) * DT) % 40.0
    turning = ((phase > 15.0) & (phase < 20.0)) | ((phase > 35.0) & (phase < 40.0))
    increments[turning, 2] = math.pi / 5.0 * DT
    increments[:, 1] = 0.002 * np.sin(np.arange(steps) * 0.3)  # slight side slip
    return increments


def sensor_pose(pose, mount=MOUNT):
    """Return the laser's world pose: the mount ``(x, y, yaw)`` carried by the robot."""
    x, y, theta = pose
    mount_x, mount_y, mount_yaw = mount
    c, s = math.cos(theta), math.sin(theta)
    return np.array(
        [x + c * mount_x - s * mount_y, y + s * mount_x + c * mount_y, theta + mount_yaw]
    )


def true_ranges_and_bearings(pose, posts, mount=MOUNT):
    """Return the exact ``(range, bearing)`` of every post seen from the robot at ``pose``."""
    sx, sy, sensor_heading = sensor_pose(pose, mount)
    rel = np.asarray(posts, dtype=float) - [sx, sy]
    bearings = wrap_angle(np.arctan2(rel[:, 1], rel[:, 0]) - sensor_heading)
    return np.column_stack([np.hypot(rel[:, 0], rel[:, 1]), bearings])


def observe(pose, rng, *, mount=MOUNT):
    """Range-bearing observations of every post in range and field of view."""
    predicted = true_ranges_and_bearings(pose, POSTS, mount)
    visible = (predicted[:, 0] < SENSOR_RANGE) & (np.abs(predicted[:, 1]) < SENSOR_HALF_FOV)
    covariance = np.diag([RANGE_SIGMA**2, BEARING_SIGMA**2])
    observations, indices = [], np.flatnonzero(visible)
    for index in rng.permutation(indices):
        r = predicted[index, 0] + rng.normal(0.0, RANGE_SIGMA)
        b = predicted[index, 1] + rng.normal(0.0, BEARING_SIGMA)
        observations.append(LandmarkObservation(r, b, covariance, [int(index)]))
    return observations


def simulate(seed, steps, *, params=None, outage=None, kidnap=None, odometry_scale=1.0):
    """Run the filter along the loop; return truths, estimates, covariances, and the filter."""
    rng = np.random.default_rng(seed)
    params = EKFParams(mount=MOUNT) if params is None else params
    ekf = EKFLocalizer(POSTS, params)
    truth = np.array([-8.0, -3.5, 0.0])
    initial_cov = np.diag([0.05**2, 0.05**2, 0.02**2])
    ekf.initialize(truth + rng.multivariate_normal(np.zeros(3), initial_cov), initial_cov, 0.0)
    truths, estimates, covariances, used = [], [], [], []
    for step, u_true in enumerate(true_increments(steps)):
        stamp = (step + 1) * DT
        increment_cov = params.increment_covariance(u_true)
        truth = compose(truth, u_true)
        if kidnap is not None and abs(stamp - kidnap[0]) < DT / 2:
            truth = compose(truth, kidnap[1])
        u_measured = u_true * odometry_scale + rng.multivariate_normal(np.zeros(3), increment_cov)
        in_outage = outage is not None and outage[0] <= stamp < outage[1]
        observations = [] if in_outage else observe(truth, rng)
        pairs = ekf.step(u_measured, increment_cov, observations, stamp)
        truths.append(truth)
        estimates.append(ekf.pose)
        covariances.append(ekf.covariance)
        used.append(len(pairs))
    return np.array(truths), np.array(estimates), np.array(covariances), np.array(used), ekf


def nees(truths, estimates, covariances):
    errors = truths - estimates
    errors[:, 2] = wrap_angle(errors[:, 2])
    return np.einsum("ki,kij,kj->k", errors, np.linalg.inv(covariances), errors)


# ---------------------------------------------------------------- acceptance: consistency


@pytest.mark.slow  # 50 runs of 200 steps
def test_mean_nees_over_monte_carlo_runs_lies_in_the_chi_square_band():
    runs, steps = 50, 200
    all_nees, position_sq, heading_sq = [], [], []
    for seed in range(runs):
        truths, estimates, covariances, used, _ = simulate(seed, steps)
        assert np.median(used) >= 3  # posts are visible all along the loop
        all_nees.append(nees(truths, estimates, covariances))
        position_sq.append(np.sum((truths[:, :2] - estimates[:, :2]) ** 2, axis=1))
        heading_sq.append(wrap_angle(truths[:, 2] - estimates[:, 2]) ** 2)
    mean_nees = np.mean(all_nees, axis=0)  # average over runs at each step
    low, high = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    inside = np.mean((mean_nees >= low) & (mean_nees <= high))
    rmse_position = math.sqrt(np.mean(position_sq))
    rmse_heading = math.sqrt(np.mean(heading_sq))
    print(
        f"mean NEES {mean_nees.mean():.3f} band [{low:.3f}, {high:.3f}], "
        f"steps in band {inside:.1%}, RMSE xy {rmse_position * 1000:.1f} mm, "
        f"theta {math.degrees(rmse_heading):.3f} deg"
    )
    assert low <= mean_nees.mean() <= high
    assert inside >= 0.9
    assert rmse_position < 0.02
    assert rmse_heading < math.radians(0.5)


# ---------------------------------------------------------------- acceptance: re-localisation


@pytest.mark.parametrize(
    ("kidnap", "odometry_scale"),
    [(None, 1.03), ((15.0, np.array([0.8, -0.6, 0.4])), 1.0)],
    ids=["biased-odometry", "kidnapped-during-outage"],
)
def test_relocalises_within_one_second_after_a_ten_second_outage(kidnap, odometry_scale):
    outage = (10.0, 20.0)
    truths, estimates, covariances, _, ekf = simulate(
        3, 260, outage=outage, kidnap=kidnap, odometry_scale=odometry_scale
    )
    stamps = (np.arange(len(truths)) + 1) * DT
    errors = np.hypot(*(truths[:, :2] - estimates[:, :2]).T)
    # The outage hurt: by its end the estimate is off (odometry alone).
    assert errors[np.argmin(np.abs(stamps - 19.95))] > 0.1
    reinit = [r.stamp for r in ekf.history if r.reinitialized]
    assert any(outage[1] <= stamp <= outage[1] + 1.0 for stamp in reinit)
    back = (stamps >= outage[1] + 1.0) & (stamps < outage[1] + 6.0)
    assert errors[back].max() < 0.05
    headings = np.abs(wrap_angle(truths[back, 2] - estimates[back, 2]))
    assert headings.max() < math.radians(1.0)
    assert np.all(nees(truths[back], estimates[back], covariances[back]) < chi2.ppf(0.999, 3))


def test_relocalises_when_the_position_sigma_grows_too_large():
    rng = np.random.default_rng(5)
    ekf = EKFLocalizer(POSTS, EKFParams(mount=MOUNT, max_position_sigma=0.3))
    truth = np.array([2.0, -2.0, 1.0])
    ekf.initialize(truth + np.array([1.0, 1.0, 0.5]), np.diag([1.0, 1.0, 0.5]), stamp=0.0)
    ekf.update(observe(truth, rng), stamp=0.1)
    assert ekf.history[-1].reinitialized
    assert np.hypot(*(ekf.pose[:2] - truth[:2])) < 0.05


def test_a_short_gap_does_not_trigger_relocalisation():
    *_, ekf = simulate(4, 120, outage=(5.0, 8.0))
    assert not any(record.reinitialized for record in ekf.history)


# ---------------------------------------------------------------- prediction


def test_prediction_compounds_the_increment_in_the_robot_frame():
    ekf = EKFLocalizer(POSTS)
    start = np.array([1.0, 2.0, 3.0])
    ekf.initialize(start, np.zeros((3, 3)))
    increment = np.array([0.5, -0.1, 0.4])
    ekf.predict(increment, np.zeros((3, 3)))
    np.testing.assert_allclose(ekf.pose, compose(start, increment), atol=1e-12)
    assert -np.pi < ekf.pose[2] <= np.pi
    np.testing.assert_allclose(between(start, ekf.pose), increment, atol=1e-12)


def numeric_jacobian(function, point, step=1e-6):
    columns = []
    for axis in range(3):
        delta = np.zeros(3)
        delta[axis] = step
        difference = function(point + delta) - function(point - delta)
        difference[2] = wrap_angle(difference[2])
        columns.append(difference / (2 * step))
    return np.column_stack(columns)


def test_prediction_covariance_uses_both_jacobians():
    start = np.array([0.3, -0.7, 2.5])
    increment = np.array([0.4, 0.1, -0.3])
    state_cov = np.array([[0.04, 0.01, 0.002], [0.01, 0.03, -0.001], [0.002, -0.001, 0.01]])
    increment_cov = np.diag([0.01, 0.004, 0.002])
    ekf = EKFLocalizer(POSTS)
    ekf.initialize(start, state_cov)
    ekf.predict(increment, increment_cov)
    state_jacobian = numeric_jacobian(lambda x: compose(x, increment), start)
    increment_jacobian = numeric_jacobian(lambda u: compose(start, u), increment)
    expected = (
        state_jacobian @ state_cov @ state_jacobian.T
        + increment_jacobian @ increment_cov @ increment_jacobian.T
    )
    np.testing.assert_allclose(ekf.covariance, expected, atol=1e-9)


def test_default_noise_model_is_used_without_an_increment_covariance():
    params = EKFParams()
    ekf = EKFLocalizer(POSTS, params)
    ekf.initialize(np.zeros(3), np.zeros((3, 3)))
    ekf.predict([1.0, 0.0, 0.0])
    np.testing.assert_allclose(
        ekf.covariance[:2, :2].diagonal(),
        params.increment_covariance([1.0, 0.0, 0.0])[:2].diagonal()[:2],
    )
    assert params.increment_covariance([0.0, 0.0, 0.0]).diagonal().min() > 0.0


def test_prediction_before_initialisation_is_a_no_op():
    ekf = EKFLocalizer(POSTS)
    ekf.predict([1.0, 0.0, 0.0])
    assert not ekf.initialized
    assert ekf.update(observe(np.zeros(3), np.random.default_rng(0))[:2], 0.0) == []


# ---------------------------------------------------------------- correction


def test_update_with_the_mount_offset_converges_and_without_it_is_refused():
    rng = np.random.default_rng(1)
    truth = np.array([-2.0, 1.0, -0.6])
    cov = np.diag([0.1**2, 0.1**2, 0.03**2])
    start = truth + np.array([0.08, -0.06, 0.02])
    good = EKFLocalizer(POSTS, EKFParams(mount=MOUNT))
    good.initialize(start, cov, stamp=0.0)
    naive = EKFLocalizer(POSTS, EKFParams(mount=(0.0, 0.0, 0.0)))
    naive.initialize(start, cov, stamp=0.0)
    for step in range(20):
        observations = observe(truth, rng)
        good.update(observations, stamp=step * DT)
        naive.update(observations, stamp=step * DT)
    assert np.hypot(*(good.pose[:2] - truth[:2])) < 0.01
    # A filter that ignores the mount puts the robot where the laser is (or gives up).
    assert np.hypot(*(naive.pose[:2] - truth[:2])) > 0.1


def test_heading_near_pi_stays_wrapped_and_corrections_are_small():
    rng = np.random.default_rng(2)
    truth = np.array([0.0, -2.0, math.pi - 0.002])
    ekf = EKFLocalizer(POSTS, EKFParams(mount=MOUNT))
    ekf.initialize([0.0, -2.0, -math.pi + 0.003], np.diag([0.01, 0.01, 0.01**2]), stamp=0.0)
    for step in range(30):
        ekf.step([0.0, 0.0, 0.0], np.diag([1e-8, 1e-8, 1e-8]), observe(truth, rng), step * DT)
    assert -np.pi < ekf.pose[2] <= np.pi
    assert abs(wrap_angle(ekf.pose[2] - truth[2])) < 0.002
    corrections = ekf.history_arrays()["correction"]
    assert np.abs(corrections[:, 2]).max() < 0.01  # never a 2*pi jump


def test_outlier_observation_is_gated_out():
    rng = np.random.default_rng(3)
    truth = np.array([0.0, 0.0, 0.2])
    ekf = EKFLocalizer(POSTS, EKFParams(mount=MOUNT))
    ekf.initialize(truth, np.diag([0.01**2, 0.01**2, 0.002**2]), stamp=0.0)
    observations = observe(truth, rng)
    wrong = LandmarkObservation(
        observations[0].range + 0.5, observations[0].bearing, observations[0].covariance, [99]
    )
    pairs = ekf.update([wrong, *observations[1:]], stamp=0.1)
    assert 0 not in [k for k, _ in pairs]
    assert len(pairs) == len(observations) - 1
    assert np.hypot(*(ekf.pose[:2] - truth[:2])) < 0.02


def test_covariance_stays_symmetric_positive_definite_over_a_long_run():
    _, _, covariances, _, _ = simulate(6, 600)
    np.testing.assert_array_equal(covariances, np.swapaxes(covariances, 1, 2))
    assert np.linalg.eigvalsh(covariances).min() > 0.0


def test_broken_covariance_is_repaired_to_positive_definite():
    ekf = EKFLocalizer(POSTS)
    ekf.initialize(np.zeros(3), np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, -1.0]]))
    cov = ekf.covariance
    np.testing.assert_array_equal(cov, cov.T)
    assert np.linalg.eigvalsh(cov).min() > 0.0


def test_history_records_corrections_and_sigma_bounds():
    _, _, covariances, _, ekf = simulate(7, 50)
    history = ekf.history_arrays()
    assert history["correction"].shape == history["sigma"].shape == (50, 3)
    np.testing.assert_allclose(history["sigma"][-1], np.sqrt(np.diag(covariances[-1])))
    for record in ekf.history[-5:]:
        expected = record.posterior - record.prior
        expected[2] = wrap_angle(expected[2])
        np.testing.assert_allclose(record.correction, expected)
        assert len(record.nis) == len(record.landmarks) >= 3
    # As in the paper's Figure 5: corrections mostly lie inside the 3-sigma bounds.
    inside = np.abs(history["correction"]) <= 3 * history["sigma"]
    assert inside.mean() > 0.9
    quiet = simulate(7, 50, params=EKFParams(mount=MOUNT, record_history=False))[-1]
    assert quiet.history == []


def test_same_seed_gives_identical_estimates():
    first = simulate(11, 80)
    second = simulate(11, 80)
    np.testing.assert_array_equal(first[1], second[1])
    np.testing.assert_array_equal(first[2], second[2])


# ---------------------------------------------------------------- (re)initialisation


def test_starts_from_triangulation_when_never_initialised():
    rng = np.random.default_rng(8)
    truth = np.array([5.0, 2.0, -2.5])
    ekf = EKFLocalizer(POSTS, EKFParams(mount=MOUNT))
    pairs = ekf.update(observe(truth, rng), stamp=0.0)
    assert ekf.initialized
    assert len(pairs) >= 3
    assert np.hypot(*(ekf.pose[:2] - truth[:2])) < 0.05
    assert abs(wrap_angle(ekf.pose[2] - truth[2])) < 0.01
    assert np.all(np.linalg.eigvalsh(ekf.covariance) > 0.0)


def test_symmetric_layout_is_ambiguous_until_a_prior_breaks_the_tie():
    square = np.array([[3.0, 3.0], [-3.0, 3.0], [-3.0, -3.0], [3.0, -3.0]])
    truth = np.array([0.5, 0.2, 0.3])
    predicted = true_ranges_and_bearings(truth, square, (0.0, 0.0, 0.0))
    covariance = np.diag([1e-4, 1e-6])
    observations = [LandmarkObservation(r, b, covariance, [0]) for r, b in predicted]
    lost = EKFLocalizer(square)
    assert lost.update(observations, stamp=0.0) == []  # four rotations fit equally well
    assert not lost.initialized
    hinted = EKFLocalizer(square)
    hinted.initialize(truth + np.array([0.3, -0.3, 0.2]), np.diag([4.0, 4.0, 1.0]), stamp=-10.0)
    assert len(hinted.update(observations, stamp=0.0)) == 4
    assert np.hypot(*(hinted.pose[:2] - truth[:2])) < 0.01


def test_initialize_and_params_validate_their_input():
    ekf = EKFLocalizer(POSTS)
    with pytest.raises(ValueError, match="finite"):
        ekf.initialize([0.0, np.nan, 0.0], np.eye(3))
    with raises_spec_error("mount", "expected a list of 3 numbers, got 2 value"):
        EKFParams(mount=(0.0, 0.0))
    with raises_spec_error("mount", r"every value must be >= -20.0 and <= 20.0, got \[30.0"):
        EKFParams(mount=(30.0, 0.0, 0.0))
    with raises_spec_error("nis_gate", r"must be > 0.0 and <= 100.0, got -1.0 \(a chi-square"):
        EKFParams(nis_gate=-1.0)
    with raises_spec_error("translation_sigma", "must be a finite number, got nan"):
        EKFParams(translation_sigma=float("nan"))
    with raises_spec_error("translation_sigma", "<= 1.0, got 2.0"):
        EKFParams(translation_sigma=2.0)
    with raises_spec_error("outage_timeout", "<= 3600.0, got 7200.0"):
        EKFParams(outage_timeout=7200.0)
    with raises_spec_error("min_reliability", ">= 0.0 and <= 1.0, got -1e-06"):
        EKFParams(min_reliability=-1e-6)
    with raises_spec_error("record_history", "expected true or false, got an integer 1"):
        EKFParams(record_history=1)
    assert EKFParams(mount=np.array([0.1, 0.0, 0.0])).mount == (0.1, 0.0, 0.0)


def test_initialising_without_a_stamp_starts_the_outage_timer_at_the_first_update():
    rng = np.random.default_rng(9)
    truth = np.array([1.0, 1.0, 0.5])
    ekf = EKFLocalizer(POSTS, EKFParams(mount=MOUNT))
    ekf.initialize(truth, np.diag([0.02**2, 0.02**2, 0.005**2]))
    assert len(ekf.update(observe(truth, rng), stamp=100.0)) >= 3
    assert not ekf.history[-1].reinitialized
    ekf.update(observe(truth, rng), stamp=106.0)  # a real 6 s gap: re-localise
    assert ekf.history[-1].reinitialized


# ---------------------------------------------------------------- against filterpy directly
#
# The reference: filterpy's ExtendedKalmanFilter driven by hand. The state is compounded
# with the odometry increment and the covariance propagated with the Jacobians of the
# module docstring written out here; observations are gated with their own NIS (solve,
# not the closed-form inverse), stacked and handed to filterpy's update with the bearing
# rows wrapped. Nothing of robots.ekf or robots.landmarks is used.


def compound_jacobians(pose, increment):
    """Return ``F = d(x + u)/dx`` and ``J_u = d(x + u)/du`` for ``x + u`` (compounding)."""
    theta = pose[2]
    dx, dy, _ = increment
    c, s = math.cos(theta), math.sin(theta)
    state = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0, 0, 1.0]])
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return state, rotation


def measurement_jacobian(pose, post, mount):
    """Return ``d(range, bearing)/d(x, y, theta)`` of one post seen through the mount."""
    theta = pose[2]
    mount_x, mount_y, _ = mount
    sensor = sensor_pose(pose, mount)
    rel = np.asarray(post, dtype=float) - sensor[:2]
    distance_sq = rel @ rel
    distance = math.sqrt(distance_sq)
    # The sensor's position turns with the robot: d(sensor)/d(theta) = R'(theta) mount.
    lever = np.array(
        [
            -math.sin(theta) * mount_x - math.cos(theta) * mount_y,
            math.cos(theta) * mount_x - math.sin(theta) * mount_y,
        ]
    )
    perpendicular = np.array([-rel[1], rel[0]])  # d(atan2(rel))/d(rel) * distance_sq
    d_range = np.concatenate([-rel / distance, [-(rel @ lever) / distance]])
    d_bearing = np.concatenate(
        [-perpendicular / distance_sq, [-(perpendicular @ lever) / distance_sq - 1.0]]
    )
    return np.vstack([d_range, d_bearing])


class FilterpyReference:
    """A textbook EKF on filterpy's ``ExtendedKalmanFilter`` (optionally with a range bias)."""

    def __init__(self, landmarks, params, pose, covariance, stamp):
        self.landmarks = np.asarray(landmarks, dtype=float)
        self.params = params
        self.dim = 4 if params.range_bias_sigma > 0.0 else 3
        self.filter = ExtendedKalmanFilter(dim_x=self.dim, dim_z=2)
        self.filter.x = np.zeros((self.dim, 1))
        self.filter.x[:3, 0] = [pose[0], pose[1], wrap_angle(pose[2])]
        self.filter.P = np.zeros((self.dim, self.dim))
        self.filter.P[:3, :3] = covariance
        if self.dim == 4:
            self.filter.P[3, 3] = params.range_bias_sigma**2
        self.bias_stamp = stamp
        self.history = []

    def predict(self, increment, increment_cov):
        pose = self.filter.x[:3, 0]
        state_jacobian, increment_jacobian = compound_jacobians(pose, increment)
        transition = np.eye(self.dim)
        transition[:3, :3] = state_jacobian
        noise = np.zeros((self.dim, self.dim))
        noise[:3, :3] = increment_jacobian @ increment_cov @ increment_jacobian.T
        self.filter.x[:3, 0] = compose(pose, increment)
        self.filter.P = transition @ self.filter.P @ transition.T + noise

    def predicted(self, post):
        """Return the expected ``(range, bearing)`` of a post and its Jacobian."""
        state = self.filter.x[:, 0]
        expected = true_ranges_and_bearings(state[:3], [post], self.params.mount)[0]
        jacobian = np.zeros((2, self.dim))
        jacobian[:, :3] = measurement_jacobian(state[:3], post, self.params.mount)
        if self.dim == 4:
            expected[0] += state[3]  # range = |post - sensor| + b
            jacobian[0, 3] = 1.0
        return expected, jacobian

    def update(self, observations, stamp):
        if self.dim == 4 and stamp > self.bias_stamp:
            self.filter.P[3, 3] += self.params.range_bias_walk**2 * (stamp - self.bias_stamp)
            self.bias_stamp = stamp
        models = [self.predicted(post) for post in self.landmarks]
        nis = np.empty((len(observations), len(self.landmarks)))
        for k, obs in enumerate(observations):
            for m, (expected, jacobian) in enumerate(models):
                innovation = np.array(
                    [obs.range - expected[0], wrap_angle(obs.bearing - expected[1])]
                )
                covariance = jacobian @ self.filter.P @ jacobian.T + obs.covariance
                nis[k, m] = innovation @ np.linalg.solve(covariance, innovation)
        inside = nis < self.params.nis_gate
        pairs = [
            (k, int(np.flatnonzero(inside[k])[0]))
            for k in range(len(observations))
            if inside[k].sum() == 1 and inside[:, np.flatnonzero(inside[k])[0]].sum() == 1
        ]
        if not pairs:
            return []
        prior = self.filter.x[:3, 0].copy()
        measured = np.concatenate(
            [[observations[k].range, observations[k].bearing] for k, _ in pairs]
        )
        expected = np.concatenate([models[m][0] for _, m in pairs])
        jacobian = np.vstack([models[m][1] for _, m in pairs])
        noise = np.zeros((2 * len(pairs), 2 * len(pairs)))
        for row, (k, _) in enumerate(pairs):
            noise[2 * row : 2 * row + 2, 2 * row : 2 * row + 2] = observations[k].covariance

        def residual(a, b):
            difference = a - b
            difference[1::2] = wrap_angle(difference[1::2])
            return difference

        self.filter.update(
            measured[:, None],
            lambda _x: jacobian,
            lambda _x: expected[:, None],
            R=noise,
            residual=residual,
        )
        self.filter.x[2, 0] = wrap_angle(self.filter.x[2, 0])
        self.filter.P = 0.5 * (self.filter.P + self.filter.P.T)
        self.history.append(
            (
                stamp,
                prior,
                self.filter.x[:3, 0].copy(),
                [m for _, m in pairs],
                [nis[k, m] for k, m in pairs],
            )
        )
        return pairs


@pytest.mark.parametrize(
    "params",
    [
        EKFParams(mount=MOUNT),
        EKFParams(mount=MOUNT, range_bias_sigma=0.0173),
        EKFParams(mount=MOUNT, range_bias_sigma=0.0173, range_bias_walk=1e-3),
    ],
    ids=["pose", "bias", "bias-walk"],
)
def test_filter_is_filterpy_with_the_documented_jacobians(params):
    rng = np.random.default_rng(11)
    truth = np.array([-8.0, -3.5, 0.0])
    start, start_cov = truth + np.array([0.03, -0.02, 0.01]), np.diag([0.05**2, 0.05**2, 0.02**2])
    ekf = EKFLocalizer(POSTS, params)
    ekf.initialize(start, start_cov, 0.0)
    reference = FilterpyReference(POSTS, params, start, start_cov, 0.0)
    refused = 0
    for step, u_true in enumerate(true_increments(200)):
        stamp = (step + 1) * DT
        increment_cov = params.increment_covariance(u_true)
        truth = compose(truth, u_true)
        u = u_true + rng.multivariate_normal(np.zeros(3), increment_cov)
        observations = observe(truth, rng)
        # A far outlier now and then: the gate must refuse it.
        if step % 17 == 0:
            observations.append(LandmarkObservation(3.0, 0.5, np.diag([1e-4, 1e-6]), [0]))
            refused += 1
        pairs = ekf.step(u, increment_cov, observations, stamp)
        reference.predict(u, increment_cov)
        assert pairs == reference.update(observations, stamp)
        # Each observation paired with the post it came from, the outlier with none.
        assert [observations[k].beam_indices[0] for k, _ in pairs] == [m for _, m in pairs]
        np.testing.assert_allclose(
            ekf._filter.x[:, 0], reference.filter.x[:, 0], rtol=0, atol=1e-10
        )
        np.testing.assert_allclose(ekf.state_covariance, reference.filter.P, rtol=1e-8, atol=1e-16)
    assert refused > 10
    assert len(ekf.history) == len(reference.history) > 150
    for ours, (stamp, prior, posterior, landmarks, nis) in zip(
        ekf.history, reference.history, strict=True
    ):
        assert (ours.stamp, ours.landmarks, ours.reinitialized) == (stamp, tuple(landmarks), False)
        np.testing.assert_allclose(ours.prior, prior, rtol=0, atol=1e-10)
        np.testing.assert_allclose(ours.posterior, posterior, rtol=0, atol=1e-10)
        np.testing.assert_allclose(ours.correction, posterior - prior, rtol=0, atol=1e-10)
        np.testing.assert_allclose(ours.nis, nis, rtol=1e-6)
    np.testing.assert_allclose(
        ekf.history[-1].sigma, np.sqrt(np.diag(reference.filter.P)[:3]), rtol=1e-8
    )
    if reference.dim == 4:
        assert ekf.range_bias == pytest.approx(reference.filter.x[3, 0], abs=1e-10)
        assert ekf.range_bias_sigma == pytest.approx(math.sqrt(reference.filter.P[3, 3]), rel=1e-8)
        assert (ekf.history[-1].range_bias, ekf.history[-1].range_bias_sigma) == (
            ekf.range_bias,
            ekf.range_bias_sigma,
        )


def test_straight_line_prediction_has_the_closed_form_pose_and_covariance():
    # From a pose with covariance p I heading theta0, n increments (d, 0, 0) of covariance
    # diag(a, a, c): the pose is start + n d (cos, sin), and in the frame of travel
    # var(along) = p + n a, var(theta) = p + n c,
    # var(across) = p + (n d)^2 p + n a + d^2 c (n - 1) n (2n - 1) / 6 and
    # cov(across, theta) = n d p + d c n (n - 1) / 2: each heading error swings the rest.
    n, d, a, c, p, theta0 = 40, 0.25, 1e-4, 4e-5, 1e-6, 0.7
    ekf = EKFLocalizer(POSTS)
    ekf.initialize([1.0, -2.0, theta0], p * np.eye(3))
    for _ in range(n):
        ekf.predict([d, 0.0, 0.0], np.diag([a, a, c]))
    heading = np.array([math.cos(theta0), math.sin(theta0)])
    expected_pose = [1.0 + n * d * heading[0], -2.0 + n * d * heading[1], theta0]
    np.testing.assert_allclose(ekf.pose, expected_pose, atol=1e-12)
    # Rotate the covariance into the frame of travel (along, across, theta).
    rotation = np.array(
        [[heading[0], heading[1], 0.0], [-heading[1], heading[0], 0.0], [0.0, 0.0, 1.0]]
    )
    local = rotation @ ekf.covariance @ rotation.T
    across = p + (n * d) ** 2 * p + n * a + d**2 * c * (n - 1) * n * (2 * n - 1) / 6
    coupling = n * d * p + d * c * n * (n - 1) / 2
    expected = np.array(
        [[p + n * a, 0.0, 0.0], [0.0, across, coupling], [0.0, coupling, p + n * c]]
    )
    np.testing.assert_allclose(local, expected, rtol=1e-10, atol=1e-15)


def test_arc_prediction_lands_on_the_closed_form_circle():
    # Equal chords of a circle of radius R, turning phi each: after n of them the robot is
    # at angle n phi on the circle, heading tangent to it.
    radius, phi, n = 2.5, 0.05, 90
    chord = (radius * math.sin(phi), radius * (1.0 - math.cos(phi)), phi)
    start = np.array([3.0, 1.0, -0.4])
    ekf = EKFLocalizer(POSTS)
    ekf.initialize(start, np.eye(3) * 1e-6)
    for _ in range(n):
        ekf.predict(chord, np.zeros((3, 3)))
    centre = start[:2] + radius * np.array([-math.sin(start[2]), math.cos(start[2])])
    end_heading = start[2] + n * phi
    expected = [
        centre[0] + radius * math.sin(end_heading),
        centre[1] - radius * math.cos(end_heading),
        wrap_angle(end_heading),
    ]
    np.testing.assert_allclose(ekf.pose, expected, atol=1e-12)
    # Without process noise the covariance is only carried along: the heading's variance
    # stays, and it stays positive definite.
    assert ekf.covariance[2, 2] == pytest.approx(1e-6, rel=1e-12)
    assert np.linalg.eigvalsh(ekf.covariance).min() > 0.0


def test_one_update_by_hand():
    # A robot at the origin, a post straight ahead at 4 m (mount at the origin): the range
    # residual moves x alone, by the scalar Kalman gain P / (P + R) and P shrinks to P R / (P + R).
    ekf = EKFLocalizer([[4.0, 0.0]])
    prior_x, measurement = 1e-2, 1e-4
    ekf.initialize([0.0, 0.0, 0.0], np.diag([prior_x, 1e-2, 1e-4]), stamp=0.0)
    pairs = ekf.update([LandmarkObservation(3.9, 0.0, np.diag([measurement, 1e-6]), [0])], 0.1)
    assert pairs == [(0, 0)]
    gain = prior_x / (prior_x + measurement)
    np.testing.assert_allclose(ekf.pose, [0.1 * gain, 0.0, 0.0], atol=1e-15)
    assert ekf.covariance[0, 0] == pytest.approx(
        prior_x * measurement / (prior_x + measurement), rel=1e-12
    )
    # The NIS of that residual: 0.1^2 / (P + R).
    assert ekf.history[-1].nis[0] == pytest.approx(0.1**2 / (prior_x + measurement), rel=1e-12)
