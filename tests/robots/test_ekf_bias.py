"""EKF range-bias state: the laser's systematic range error, estimated with the pose.

A Sick LMS100 adds a constant error of up to +-30 mm to every range, drawn once per
instrument. The synthetic runs below reuse the hall, loop and noise of ``test_ekf`` and
add such a bias, drawn from U(-3 cm, +3 cm) per Monte Carlo run, to every observed range.
The 3-state filter then becomes overconfident; the 4-state filter is consistent and
finds the bias.
"""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from robots.ekf import EKFLocalizer, EKFParams
from robots.landmarks import LandmarkObservation, range_bearing_model
from semistatic.frames import compose, wrap_angle
from tests.robots.test_ekf import DT, MOUNT, POSTS, observe, true_increments
from tests.spec_errors import raises_spec_error

BIAS_MAX = 0.03
# The prior 1-sigma that matches a bias uniform in [-BIAS_MAX, BIAS_MAX].
BIAS_SIGMA = BIAS_MAX / math.sqrt(3.0)
RUNS = 50
STEPS = 200
THREE_STATE = EKFParams(mount=MOUNT)
FOUR_STATE = EKFParams(mount=MOUNT, range_bias_sigma=BIAS_SIGMA)


def with_bias(observations, bias):
    """Return the observations with ``bias`` added to every range."""
    return [
        LandmarkObservation(obs.range + bias, obs.bearing, obs.covariance, obs.beam_indices)
        for obs in observations
    ]


def run(seed, steps, params, bias, *, bias_walk=0.0, outage=None, kidnap=None):
    """Drive the loop with a biased laser; return per-step arrays and the filter.

    ``bias`` is the true range bias at the start; it follows a random walk of density
    ``bias_walk`` (m per square-root second). The noise draws depend on ``seed`` only,
    so filters with different params see exactly the same data.
    """
    rng = np.random.default_rng(seed)
    walk_rng = np.random.default_rng([seed, 1])
    ekf = EKFLocalizer(POSTS, params)
    truth = np.array([-8.0, -3.5, 0.0])
    initial_cov = np.diag([0.05**2, 0.05**2, 0.02**2])
    ekf.initialize(truth + rng.multivariate_normal(np.zeros(3), initial_cov), initial_cov, 0.0)
    out = {key: [] for key in ("truth", "pose", "cov", "bias", "bias_hat", "bias_sigma", "full")}
    for step, u_true in enumerate(true_increments(steps)):
        stamp = (step + 1) * DT
        increment_cov = params.increment_covariance(u_true)
        truth = compose(truth, u_true)
        if kidnap is not None and abs(stamp - kidnap[0]) < DT / 2:
            truth = compose(truth, kidnap[1])
        bias += bias_walk * math.sqrt(DT) * walk_rng.normal()
        u_measured = u_true + rng.multivariate_normal(np.zeros(3), increment_cov)
        in_outage = outage is not None and outage[0] <= stamp < outage[1]
        observations = [] if in_outage else with_bias(observe(truth, rng), bias)
        ekf.step(u_measured, increment_cov, observations, stamp)
        out["truth"].append(truth)
        out["pose"].append(ekf.pose)
        out["cov"].append(ekf.covariance)
        out["bias"].append(bias)
        out["bias_hat"].append(ekf.range_bias)
        out["bias_sigma"].append(ekf.range_bias_sigma)
        out["full"].append(ekf.state_covariance)
    return {key: np.array(value) for key, value in out.items()}, ekf


def pose_errors(result):
    errors = result["truth"] - result["pose"]
    errors[:, 2] = wrap_angle(errors[:, 2])
    return errors


def nees(result):
    errors = pose_errors(result)
    return np.einsum("ki,kij,kj->k", errors, np.linalg.inv(result["cov"]), errors)


def monte_carlo(params, *, zero_bias=False, runs=RUNS, steps=STEPS):
    """Run ``runs`` seeds; the true bias of run k is drawn from its own generator."""
    results = []
    for seed in range(runs):
        bias_rng = np.random.default_rng([seed, 2])
        bias = 0.0 if zero_bias else float(bias_rng.uniform(-BIAS_MAX, BIAS_MAX))
        results.append(run(seed, steps, params, bias)[0])
    return results


def summary(results):
    """Mean NEES per step (over runs), the 95% band, and per-axis normalised RMS errors."""
    runs = len(results)
    mean_nees = np.mean([nees(r) for r in results], axis=0)
    low, high = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    normalised = np.concatenate(
        [pose_errors(r) / np.sqrt(np.diagonal(r["cov"], axis1=1, axis2=2)) for r in results]
    )
    errors = np.concatenate([pose_errors(r) for r in results])
    return {
        "mean_nees": mean_nees,
        "low": low,
        "high": high,
        "in_band": float(np.mean((mean_nees >= low) & (mean_nees <= high))),
        "normalised_rms": np.sqrt(np.mean(normalised**2, axis=0)),
        "rmse_xy": math.sqrt(np.mean(np.sum(errors[:, :2] ** 2, axis=1))),
    }


def report(name, stats):
    print(
        f"{name}: mean NEES {stats['mean_nees'].mean():.2f} "
        f"band [{stats['low']:.2f}, {stats['high']:.2f}], steps in band {stats['in_band']:.0%}, "
        f"normalised RMS x/y/theta {np.round(stats['normalised_rms'], 2)}, "
        f"RMSE xy {stats['rmse_xy'] * 1000:.2f} mm"
    )


@pytest.fixture(scope="module")
def biased_runs():
    return {"three": monte_carlo(THREE_STATE), "four": monte_carlo(FOUR_STATE)}


# ---------------------------------------------------------------- acceptance: consistency


@pytest.mark.slow
def test_without_a_bias_state_the_range_bias_makes_the_filter_overconfident(biased_runs):
    stats = summary(biased_runs["three"])
    report("3-state, biased laser", stats)
    # Far outside the band: the estimate is shifted by the bias, the covariance ignores it.
    assert stats["mean_nees"].mean() > 1.5 * stats["high"]
    assert stats["in_band"] < 0.1
    assert stats["normalised_rms"][:2].max() > 1.5


@pytest.mark.slow
def test_with_a_bias_state_the_filter_is_consistent_and_finds_the_bias(biased_runs):
    results = biased_runs["four"]
    stats = summary(results)
    report("4-state, biased laser", stats)
    assert stats["low"] <= stats["mean_nees"].mean() <= stats["high"]
    assert stats["in_band"] >= 0.9
    np.testing.assert_array_less(stats["normalised_rms"], 1.2)
    # The bias estimate converges to the true bias, within 3 sigma, in every run.
    final_error = np.array([r["bias_hat"][-1] - r["bias"][-1] for r in results])
    final_sigma = np.array([r["bias_sigma"][-1] for r in results])
    z = final_error / final_sigma
    print(
        f"bias: |error| max {np.abs(final_error).max() * 1000:.2f} mm, sigma "
        f"{final_sigma.mean() * 1000:.2f} mm, z RMS {np.sqrt(np.mean(z**2)):.2f}, "
        f"|z| max {np.abs(z).max():.2f}"
    )
    assert np.all(np.abs(z) <= 3.0)
    assert final_sigma.max() < 0.1 * BIAS_SIGMA
    # The whole 4-dimensional state (pose and bias) is consistent too.
    full_nees = []
    for r in results:
        errors = np.column_stack([pose_errors(r), r["bias"] - r["bias_hat"]])
        full_nees.append(np.einsum("ki,kij,kj->k", errors, np.linalg.inv(r["full"]), errors))
    low, high = chi2.ppf([0.025, 0.975], 4 * len(results)) / len(results)
    assert low <= np.mean(full_nees) <= high


@pytest.mark.slow
def test_with_a_bias_state_the_pose_is_more_accurate_under_a_bias(biased_runs):
    three = summary(biased_runs["three"])["rmse_xy"]
    four = summary(biased_runs["four"])["rmse_xy"]
    print(f"RMSE xy under a bias: 3-state {three * 1000:.2f} mm, 4-state {four * 1000:.2f} mm")
    assert four < 0.75 * three


@pytest.mark.slow
def test_with_zero_true_bias_four_states_are_as_accurate_as_three():
    three = summary(monte_carlo(THREE_STATE, zero_bias=True, runs=30))
    four = summary(monte_carlo(FOUR_STATE, zero_bias=True, runs=30))
    report("3-state, unbiased laser", three)
    report("4-state, unbiased laser", four)
    assert four["rmse_xy"] <= 1.05 * three["rmse_xy"]
    for stats in (three, four):
        assert stats["low"] <= stats["mean_nees"].mean() <= stats["high"]


@pytest.mark.slow
def test_a_drifting_bias_is_tracked_with_its_random_walk_and_lost_without():
    walk, runs, steps = 0.002, 20, 300
    z = {}
    for name, density in (("walk", walk), ("constant", 0.0)):
        params = EKFParams(mount=MOUNT, range_bias_sigma=BIAS_SIGMA, range_bias_walk=density)
        results = [run(seed, steps, params, 0.01, bias_walk=walk)[0] for seed in range(runs)]
        errors = np.concatenate([r["bias_hat"][100:] - r["bias"][100:] for r in results])
        sigmas = np.concatenate([r["bias_sigma"][100:] for r in results])
        z[name] = math.sqrt(np.mean((errors / sigmas) ** 2))
        if name == "walk":
            stats = summary(results)
            report("4-state with walk, drifting bias", stats)
            assert stats["low"] <= stats["mean_nees"].mean() <= stats["high"]
    print(f"bias error / sigma RMS: with the walk {z['walk']:.2f}, without {z['constant']:.2f}")
    assert 0.7 < z["walk"] < 1.3
    assert z["constant"] > 3.0


# ---------------------------------------------------------------- the 4-state filter itself


def numeric_jacobian(function, point, step=1e-7):
    columns = []
    for axis in range(point.size):
        delta = np.zeros(point.size)
        delta[axis] = step
        difference = function(point + delta) - function(point - delta)
        difference[1::2] = wrap_angle(difference[1::2])
        columns.append(difference / (2 * step))
    return np.column_stack(columns)


def test_update_matches_a_textbook_ekf_with_range_equal_distance_plus_bias():
    rng = np.random.default_rng(20)
    truth = np.array([1.0, -2.0, 0.7])
    ekf = EKFLocalizer(POSTS, FOUR_STATE)
    ekf.initialize(
        truth + np.array([0.02, -0.01, 0.005]), np.diag([0.03**2, 0.03**2, 0.01**2]), 0.0
    )
    for step in range(3):  # build up a bias estimate and pose-bias correlations
        ekf.update(with_bias(observe(truth, rng), 0.02), stamp=0.1 * (step + 1))
    state = np.append(ekf.pose, ekf.range_bias)
    cov = ekf.state_covariance
    assert np.abs(cov[:3, 3]).max() > 0.0
    observations = with_bias(observe(truth, rng), 0.02)
    pairs = ekf.update(observations, stamp=0.4)
    assert len(pairs) == len(observations)
    landmarks = [m for _, m in pairs]

    def measure(x):
        predicted, _ = range_bearing_model(x[:3], POSTS[landmarks], MOUNT)
        predicted[:, 0] += x[3]
        return predicted.reshape(-1)

    jacobian = numeric_jacobian(measure, state)
    noise = np.kron(np.eye(len(pairs)), observations[0].covariance)
    measured = np.array([(observations[k].range, observations[k].bearing) for k, _ in pairs])
    innovation = measured.reshape(-1) - measure(state)
    innovation[1::2] = wrap_angle(innovation[1::2])
    gain = cov @ jacobian.T @ np.linalg.inv(jacobian @ cov @ jacobian.T + noise)
    keep = np.eye(4) - gain @ jacobian
    expected_cov = keep @ cov @ keep.T + gain @ noise @ gain.T
    expected_state = state + gain @ innovation
    np.testing.assert_allclose(ekf.pose, expected_state[:3], atol=1e-9)
    assert ekf.range_bias == pytest.approx(expected_state[3], abs=1e-9)
    np.testing.assert_allclose(ekf.state_covariance, expected_cov, rtol=1e-5, atol=1e-12)


def test_prediction_moves_the_pose_and_leaves_the_bias_alone():
    start, increment = np.array([0.3, -0.7, 2.5]), np.array([0.4, 0.1, -0.3])
    pose_cov = np.array([[0.04, 0.01, 0.002], [0.01, 0.03, -0.001], [0.002, -0.001, 0.01]])
    increment_cov = np.diag([0.01, 0.004, 0.002])
    three, four = EKFLocalizer(POSTS, THREE_STATE), EKFLocalizer(POSTS, FOUR_STATE)
    for ekf in (three, four):
        ekf.initialize(start, pose_cov)
        ekf.predict(increment, increment_cov)
    np.testing.assert_array_equal(four.pose, three.pose)
    np.testing.assert_allclose(four.covariance, three.covariance, atol=1e-15)
    assert four.range_bias == 0.0
    assert four.range_bias_sigma == pytest.approx(BIAS_SIGMA)
    np.testing.assert_array_equal(four.state_covariance[:3, 3], 0.0)


def test_bias_variance_grows_by_its_random_walk_between_updates():
    params = EKFParams(mount=MOUNT, range_bias_sigma=0.01, range_bias_walk=0.002)
    ekf = EKFLocalizer(POSTS, params)
    ekf.initialize(np.zeros(3), np.eye(3) * 1e-4, stamp=10.0)
    assert ekf.update([], stamp=14.0) == []
    assert ekf.range_bias_sigma**2 == pytest.approx(0.01**2 + 0.002**2 * 4.0)
    ekf.update([], stamp=13.0)  # an older stamp: time does not run backwards
    assert ekf.range_bias_sigma**2 == pytest.approx(0.01**2 + 0.002**2 * 4.0)
    ekf.initialize(np.zeros(3), np.eye(3) * 1e-4, stamp=20.0)  # a reset keeps the bias belief
    assert ekf.range_bias_sigma**2 == pytest.approx(0.01**2 + 0.002**2 * 10.0)


def test_relocalisation_keeps_the_bias_estimate_and_drops_its_correlations():
    rng = np.random.default_rng(21)
    truth = np.array([2.0, 1.0, -0.4])
    ekf = EKFLocalizer(POSTS, FOUR_STATE)
    ekf.initialize(truth, np.diag([0.02**2, 0.02**2, 0.005**2]), stamp=0.0)
    for step in range(20):
        ekf.update(with_bias(observe(truth, rng), -0.025), stamp=0.1 * (step + 1))
    bias, sigma = ekf.range_bias, ekf.range_bias_sigma
    assert abs(bias + 0.025) < 3 * sigma
    moved = compose(truth, [1.5, -0.5, 0.8])
    pairs = ekf.relocalize(with_bias(observe(moved, rng), -0.025), stamp=2.2)
    assert len(pairs) >= 3
    assert ekf.history[-1].reinitialized
    assert np.hypot(*(ekf.pose[:2] - moved[:2])) < 0.05
    assert (ekf.range_bias, ekf.range_bias_sigma) == (bias, sigma)
    assert (ekf.history[-1].range_bias, ekf.history[-1].range_bias_sigma) == (bias, sigma)
    np.testing.assert_array_equal(ekf.state_covariance[:3, 3], 0.0)
    np.testing.assert_array_equal(ekf.state_covariance[3, :3], 0.0)


def test_biased_laser_relocalises_after_a_kidnapping_during_an_outage():
    outage = (10.0, 20.0)
    result, ekf = run(
        3, 260, FOUR_STATE, 0.028, outage=outage, kidnap=(15.0, np.array([0.8, -0.6, 0.4]))
    )
    stamps = (np.arange(260) + 1) * DT
    reinit = [r.stamp for r in ekf.history if r.reinitialized]
    assert any(outage[1] <= stamp <= outage[1] + 1.0 for stamp in reinit)
    back = (stamps >= outage[1] + 1.0) & (stamps < outage[1] + 6.0)
    errors = np.hypot(*(result["truth"][back, :2] - result["pose"][back, :2]).T)
    assert errors.max() < 0.05
    assert np.all(nees({k: v[back] for k, v in result.items()}) < chi2.ppf(0.999, 3))
    assert abs(result["bias_hat"][-1] - 0.028) < 3 * result["bias_sigma"][-1]


def test_covariance_stays_symmetric_positive_definite_and_history_records_the_bias():
    result, ekf = run(6, 400, FOUR_STATE, -0.02)
    full = result["full"]
    np.testing.assert_array_equal(full, np.swapaxes(full, 1, 2))
    assert np.linalg.eigvalsh(full).min() > 0.0
    history = ekf.history_arrays()
    assert history["correction"].shape == history["sigma"].shape == (400, 3)
    np.testing.assert_allclose(history["sigma"][-1], np.sqrt(np.diag(result["cov"][-1])))
    np.testing.assert_array_equal(history["range_bias"], result["bias_hat"])
    np.testing.assert_array_equal(history["range_bias_sigma"], result["bias_sigma"])
    assert np.all(np.diff(history["range_bias_sigma"]) <= 0.0)  # constant bias: only learns


def test_three_state_filter_reports_no_bias():
    result, ekf = run(7, 30, THREE_STATE, 0.01)
    assert ekf.state_covariance.shape == (3, 3)
    assert ekf.range_bias == ekf.range_bias_sigma == 0.0
    np.testing.assert_array_equal(ekf.history_arrays()["range_bias_sigma"], np.zeros(30))
    np.testing.assert_array_equal(result["bias_hat"], 0.0)


def test_same_seed_gives_identical_estimates_with_the_bias_state():
    first, _ = run(11, 80, FOUR_STATE, 0.015)
    second, _ = run(11, 80, FOUR_STATE, 0.015)
    for key in ("pose", "full", "bias_hat"):
        np.testing.assert_array_equal(first[key], second[key])


def test_broken_four_state_covariance_is_repaired():
    ekf = EKFLocalizer(POSTS, FOUR_STATE)
    broken = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
    ekf.initialize(np.zeros(3), broken)
    cov = ekf.state_covariance
    np.testing.assert_array_equal(cov, cov.T)
    assert np.linalg.eigvalsh(cov).min() > 0.0
    assert ekf.range_bias_sigma == pytest.approx(BIAS_SIGMA)


@pytest.mark.parametrize("params", [THREE_STATE, FOUR_STATE], ids=["three", "four"])
def test_a_positive_definite_covariance_is_kept_and_any_other_repaired(params):
    """The positive-definiteness check against the eigenvalues, through ``initialize``."""
    rng = np.random.default_rng(22)
    kept = repaired = 0
    for _ in range(300):
        root = rng.normal(size=(3, 3))
        matrix = root @ root.T + rng.uniform(-1.0, 1.0) * np.eye(3)
        smallest = np.linalg.eigvalsh(matrix).min()
        if abs(smallest) <= 1e-9:
            continue
        ekf = EKFLocalizer(POSTS, params)
        ekf.initialize(np.zeros(3), matrix)
        pose_cov = ekf.state_covariance[:3, :3]
        if smallest > 0.0:
            np.testing.assert_array_equal(pose_cov, matrix)
            kept += 1
        else:
            assert not np.array_equal(pose_cov, matrix)
            np.testing.assert_array_equal(pose_cov, pose_cov.T)
            assert np.linalg.eigvalsh(pose_cov).min() > 0.0
            repaired += 1
    assert kept > 50
    assert repaired > 50


@pytest.mark.parametrize(
    ("kwargs", "key", "match"),
    [
        ({"range_bias_sigma": -0.01}, "range_bias_sigma", ">= 0.0 and <= 1.0, got -0.01"),
        ({"range_bias_sigma": float("inf")}, "range_bias_sigma", "finite number, got inf"),
        ({"range_bias_sigma": 0.01, "range_bias_walk": float("nan")}, "range_bias_walk", "nan"),
        ({"range_bias_walk": 1e-4}, "range_bias_walk", "needs the bias state"),
    ],
)
def test_bias_params_are_validated(kwargs, key, match):
    with raises_spec_error(key, match):
        EKFParams(**kwargs)
