"""ToTal three-object triangulation, least-squares refinement and covariance."""

import numpy as np
import pytest

from robots.triangulation import TriangulationError, total, triangulate
from semistatic.frames import wrap_angle


def bearings_from(pose, landmarks):
    landmarks = np.asarray(landmarks, dtype=float)
    return wrap_angle(np.arctan2(landmarks[:, 1] - pose[1], landmarks[:, 0] - pose[0]) - pose[2])


def random_configuration(rng, count):
    """A robot and ``count`` landmarks, not too close to each other or degenerate."""
    while True:
        landmarks = rng.uniform(-10.0, 10.0, (count, 2))
        pose = np.array([*rng.uniform(-8.0, 8.0, 2), rng.uniform(-np.pi, np.pi)])
        gaps = np.linalg.norm(landmarks - pose[:2], axis=1)
        spread = np.linalg.norm(landmarks[:, None] - landmarks[None], axis=-1)
        if gaps.min() > 0.5 and spread[np.triu_indices(count, 1)].min() > 0.5:
            _, reliability = total(bearings_from(pose, landmarks[:3]), landmarks[:3])
            if reliability > 1e-2:
                return pose, landmarks


def pose_error(estimate, truth):
    return np.hypot(*(estimate[:2] - truth[:2])), abs(wrap_angle(estimate[2] - truth[2]))


# ---------------------------------------------------------------- acceptance: exactness


@pytest.mark.parametrize("count", [3, 4, 7])
def test_noise_free_triangulation_is_exact(count):
    rng = np.random.default_rng(count)
    worst_position, worst_heading = 0.0, 0.0
    for _ in range(200):
        truth, landmarks = random_configuration(rng, count)
        pose, cov = triangulate(bearings_from(truth, landmarks), landmarks, 1e-3)
        position, heading = pose_error(pose, truth)
        worst_position, worst_heading = max(worst_position, position), max(worst_heading, heading)
        assert np.all(np.linalg.eigvalsh(cov) > 0.0)
        assert -np.pi < pose[2] <= np.pi
    assert worst_position <= 1e-9
    assert worst_heading <= 1e-9


def test_total_alone_is_exact_on_three_landmarks():
    rng = np.random.default_rng(0)
    for _ in range(200):
        truth, landmarks = random_configuration(rng, 3)
        pose, reliability = total(bearings_from(truth, landmarks), landmarks)
        position, heading = pose_error(pose, truth)
        assert position <= 1e-9
        assert heading <= 1e-9
        assert reliability > 0.0


def test_robot_on_the_line_through_two_landmarks_is_handled():
    # Bearings to landmarks 1 and 2 differ by exactly pi: ToTal's cot pole.
    landmarks = np.array([[-3.0, 0.0], [4.0, 0.0], [1.0, 5.0]])
    truth = np.array([0.5, 0.0, 0.4])
    pose, _ = triangulate(bearings_from(truth, landmarks), landmarks, 1e-3)
    assert pose_error(pose, truth)[0] <= 1e-9


def test_collinear_landmarks_seen_from_off_their_line_are_not_degenerate():
    # The circle through collinear landmarks is their line: off it, ToTal works.
    landmarks = np.array([[0.0, 0.0], [2.0, 0.0], [5.0, 0.0]])
    truth = np.array([1.3, 2.0, -0.2])
    pose, _ = triangulate(bearings_from(truth, landmarks), landmarks, 1e-3)
    assert pose_error(pose, truth)[0] <= 1e-9


def test_bearings_are_taken_modulo_two_pi():
    truth = np.array([1.0, -1.0, 0.5])
    landmarks = np.array([[5.0, 5.0], [-4.0, 3.0], [0.0, -6.0]])
    bearings = bearings_from(truth, landmarks) + np.array([2 * np.pi, -2 * np.pi, 4 * np.pi])
    pose, _ = triangulate(bearings, landmarks, 1e-3)
    assert max(pose_error(pose, truth)) <= 1e-9


# ---------------------------------------------------------------- acceptance: degenerate


def test_robot_on_the_circle_through_the_landmarks_raises():
    angles = np.array([0.3, 1.9, 4.0])
    landmarks = np.column_stack([2.0 + 5.0 * np.cos(angles), -1.0 + 5.0 * np.sin(angles)])
    robot_angle = 5.5
    truth = np.array([2.0 + 5.0 * np.cos(robot_angle), -1.0 + 5.0 * np.sin(robot_angle), 0.1])
    with pytest.raises(TriangulationError, match="circle through the landmarks"):
        triangulate(bearings_from(truth, landmarks), landmarks, 1e-3)
    _, reliability = total(bearings_from(truth, landmarks), landmarks)
    assert reliability < 1e-12


def test_robot_on_the_line_of_collinear_landmarks_raises():
    landmarks = np.array([[0.0, 0.0], [2.0, 0.0], [5.0, 0.0]])
    for robot_x in (-3.0, 1.0, 7.0):
        truth = np.array([robot_x, 0.0, 0.7])
        with pytest.raises(TriangulationError, match="degenerate"):
            triangulate(bearings_from(truth, landmarks), landmarks, 1e-3)


def test_reliability_falls_towards_the_circle_and_the_covariance_grows():
    angles = np.array([0.3, 1.9, 4.0])
    landmarks = np.column_stack([5.0 * np.cos(angles), 5.0 * np.sin(angles)])
    reliabilities, sigmas = [], []
    for radius in (0.0, 2.0, 4.0, 4.9, 4.99):
        truth = np.array([radius * np.cos(5.5), radius * np.sin(5.5), 0.0])
        bearings = bearings_from(truth, landmarks)
        reliabilities.append(total(bearings, landmarks)[1])
        sigmas.append(np.sqrt(np.trace(triangulate(bearings, landmarks, 1e-3)[1][:2, :2])))
    assert np.all(np.diff(reliabilities) < 0.0)
    assert np.all(np.diff(sigmas) > 0.0)
    near_circle = bearings_from([4.99 * np.cos(5.5), 4.99 * np.sin(5.5), 0.0], landmarks)
    with pytest.raises(TriangulationError):
        triangulate(near_circle, landmarks, 1e-3, min_reliability=0.01)


@pytest.mark.parametrize(
    ("bearings", "landmarks", "message"),
    [
        ([0.1, 0.2], [[1.0, 0.0], [0.0, 1.0]], "at least 3"),
        ([0.1, 0.2, 0.3], [[1.0, 0.0], [0.0, 1.0]], "at least 3"),
        ([0.1, np.nan, 0.3], [[1.0, 0.0], [0.0, 1.0], [2.0, 2.0]], "finite"),
        ([0.1, 0.2, 0.3], [[1.0, 0.0], [1.0, 0.0], [2.0, 2.0]], "coincide"),
    ],
    ids=["two-bearings", "count-mismatch", "nan-bearing", "coincident-landmarks"],
)
def test_invalid_input_raises_a_clear_error(bearings, landmarks, message):
    with pytest.raises(TriangulationError, match=message):
        triangulate(bearings, landmarks, 1e-3)


def test_non_positive_sigma_is_refused():
    landmarks = [[5.0, 0.0], [0.0, 5.0], [-5.0, 0.0]]
    with pytest.raises(ValueError, match="bearing_sigma"):
        triangulate(bearings_from(np.zeros(3), landmarks), landmarks, 0.0)


# ---------------------------------------------------------------- acceptance: covariance


@pytest.mark.parametrize(
    ("landmarks", "sigma"),
    [
        ([[6.0, 1.0], [-2.0, 7.0], [-5.0, -4.0]], 0.004),
        ([[6.0, 1.0], [-2.0, 7.0], [-5.0, -4.0], [3.0, -6.0], [8.0, 6.0]], 0.004),
        ([[6.0, 1.0], [-2.0, 7.0], [-5.0, -4.0]], [0.002, 0.006, 0.004]),
    ],
    ids=["three", "five", "three-unequal-sigma"],
)
def test_covariance_matches_monte_carlo_within_20_percent(landmarks, sigma):
    rng = np.random.default_rng(2024)
    landmarks = np.array(landmarks)
    truth = np.array([0.7, 0.4, 0.9])
    clean = bearings_from(truth, landmarks)
    sigma_per_bearing = np.broadcast_to(np.asarray(sigma, dtype=float), clean.shape)
    _, predicted = triangulate(clean, landmarks, sigma)
    samples = np.array(
        [
            triangulate(clean + rng.normal(0.0, sigma_per_bearing), landmarks, sigma)[0]
            for _ in range(3000)
        ]
    )
    errors = samples - truth
    errors[:, 2] = wrap_angle(errors[:, 2])
    empirical = np.cov(errors.T)
    ratio = np.diag(empirical) / np.diag(predicted)
    assert np.all((ratio > 0.8) & (ratio < 1.2)), ratio
    relative = np.linalg.norm(empirical - predicted) / np.linalg.norm(predicted)
    assert relative < 0.2
    # The estimator is unbiased to well within its spread.
    assert np.all(np.abs(errors.mean(axis=0)) < 0.1 * np.sqrt(np.diag(predicted)))
