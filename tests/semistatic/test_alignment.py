"""Scan-to-polyline alignment: recovers known offsets, refuses what it cannot know."""

import math

import numpy as np
import pytest
import shapely

from semistatic.alignment import (
    AlignmentParams,
    align_points,
    nearest_on_segments,
    polyline_segments,
)
from semistatic.frames import compose
from semistatic.polyline import Polyline
from tests.semistatic.synthetic import box, cast_scan, scene, wall

ROOM = scene(
    wall((-4.0, -3.0), (5.0, -3.0)),
    wall((5.0, -3.0), (5.0, 3.0)),
    wall((5.0, 3.0), (-4.0, 3.0)),
    wall((-4.0, 3.0), (-4.0, -3.0)),
    box((2.0, 1.5), 0.8, 0.6, yaw=0.3),
)
CORRIDOR = scene(wall((-30.0, -1.0), (30.0, -1.0)), wall((30.0, 1.0), (-30.0, 1.0)))
TRUE_POSE = np.array([0.5, -0.4, 0.2])


def reference(segments):
    return segments[:, 0], segments[:, 1]


def scan_points(segments, pose, rng, noise=0.005):
    scan = cast_scan(segments, pose, noise=noise, rng=rng, range_max=8.0)
    points = scan.points()
    return points[np.isfinite(points).all(axis=1)]


@pytest.mark.parametrize(
    "offset",
    [(0.05, -0.03, 0.0), (-0.08, 0.06, math.radians(2.0)), (0.0, 0.0, math.radians(-3.0))],
)
def test_recovers_a_known_pose_offset(offset):
    rng = np.random.default_rng(3)
    points = scan_points(ROOM, TRUE_POSE, rng)
    guess = TRUE_POSE + np.asarray(offset)
    result = align_points(points, *reference(ROOM), guess)
    assert result.accepted, result.reason
    assert np.hypot(*(result.pose[:2] - TRUE_POSE[:2])) < 0.003
    assert abs(result.pose[2] - TRUE_POSE[2]) < math.radians(0.1)
    assert result.rms_after < result.rms_before
    assert result.translation == pytest.approx(np.hypot(offset[0], offset[1]), abs=0.004)
    assert result.rotation == pytest.approx(abs(offset[2]), abs=math.radians(0.1))


def test_correct_pose_stays_put():
    rng = np.random.default_rng(4)
    points = scan_points(ROOM, TRUE_POSE, rng)
    result = align_points(points, *reference(ROOM), TRUE_POSE)
    assert result.accepted
    assert result.translation < 0.002
    assert result.rotation < math.radians(0.05)


def test_straight_corridor_is_corrected_only_across_its_axis():
    # Seen from the origin; the guess is 10 cm off along the axis (which the walls cannot
    # tell), 3 cm across it and 1 deg in heading (which they can).
    rng = np.random.default_rng(5)
    points = scan_points(CORRIDOR, (0.0, 0.0, 0.0), rng)
    guess = np.array([0.1, 0.03, math.radians(1.0)])
    result = align_points(points, *reference(CORRIDOR), guess)
    assert result.accepted
    assert result.partial
    assert result.constraint < AlignmentParams().min_constraint
    assert abs(result.pose[0] - guess[0]) < 0.002  # along the axis: as given
    assert abs(result.pose[1]) < 0.002  # across: the truth, within the noise's effect
    assert abs(result.pose[2]) < math.radians(0.05)


def test_straight_corridor_rejected_without_partial_corrections():
    rng = np.random.default_rng(5)
    points = scan_points(CORRIDOR, (0.0, 0.0, 0.0), rng)
    guess = np.array([0.1, 0.03, 0.0])
    result = align_points(points, *reference(CORRIDOR), guess, AlignmentParams(partial=False))
    assert not result.accepted
    assert result.reason == "unconstrained direction"
    assert result.constraint < AlignmentParams().min_constraint
    np.testing.assert_array_equal(result.pose, guess)


def test_constrained_room_is_not_a_partial_alignment():
    rng = np.random.default_rng(4)
    points = scan_points(ROOM, TRUE_POSE, rng)
    result = align_points(points, *reference(ROOM), TRUE_POSE + np.array([0.04, -0.02, 0.01]))
    assert result.accepted
    assert not result.partial
    assert result.constraint >= AlignmentParams().min_constraint


def test_corridor_with_a_door_recess_is_constrained():
    recess = scene(
        wall((-30.0, -1.0), (1.0, -1.0)), wall((1.0, -1.0), (1.0, -1.6)),
        wall((1.0, -1.6), (2.5, -1.6)), wall((2.5, -1.6), (2.5, -1.0)),
        wall((2.5, -1.0), (30.0, -1.0)), wall((30.0, 1.0), (-30.0, 1.0)),
    )
    rng = np.random.default_rng(6)
    points = scan_points(recess, (0.0, 0.0, 0.0), rng)
    result = align_points(points, *reference(recess), (0.06, 0.0, 0.0))
    assert result.accepted, (result.reason, result.constraint)
    assert np.hypot(*result.pose[:2]) < 0.005


def test_rejects_a_correction_beyond_the_bound():
    rng = np.random.default_rng(7)
    points = scan_points(ROOM, TRUE_POSE, rng)
    guess = TRUE_POSE + np.array([0.15, 0.0, 0.0])
    result = align_points(points, *reference(ROOM), guess, AlignmentParams(max_translation=0.1))
    assert not result.accepted
    assert result.reason == "translation beyond max_translation"
    assert result.translation == pytest.approx(0.15, abs=0.005)  # how far the match went
    np.testing.assert_array_equal(result.pose, guess)


def test_rejects_a_rotation_beyond_the_bound():
    rng = np.random.default_rng(8)
    points = scan_points(ROOM, TRUE_POSE, rng)
    guess = TRUE_POSE + np.array([0.0, 0.0, math.radians(3.0)])
    params = AlignmentParams(max_rotation=math.radians(1.0))
    result = align_points(points, *reference(ROOM), guess, params)
    assert not result.accepted
    assert result.reason == "rotation beyond max_rotation"


def test_points_the_reference_never_saw_do_not_bias_it():
    # A box that moved in after the reference was built: its points are far from every
    # reference segment and must be ignored.
    rng = np.random.default_rng(9)
    changed = scene(ROOM, box((-1.5, -1.0), 1.0, 1.0))
    points = scan_points(changed, TRUE_POSE, rng)
    result = align_points(points, *reference(ROOM), TRUE_POSE + np.array([0.04, 0.04, 0.0]))
    assert result.accepted
    assert np.hypot(*(result.pose[:2] - TRUE_POSE[:2])) < 0.004


@pytest.mark.parametrize(
    ("points", "segments"),
    [
        (np.empty((0, 2)), ROOM),
        (np.full((40, 2), np.nan), ROOM),
        (np.column_stack([np.linspace(0, 1, 40), np.zeros(40)]), np.empty((0, 2, 2))),
        (np.column_stack([np.full(40, 50.0), np.linspace(0, 1, 40)]), ROOM),  # nothing near
    ],
)
def test_too_few_points_is_rejected(points, segments):
    result = align_points(points, *reference(segments), TRUE_POSE)
    assert not result.accepted
    assert result.reason == "too few points"
    np.testing.assert_array_equal(result.pose, TRUE_POSE)


def test_nan_points_are_ignored():
    rng = np.random.default_rng(10)
    points = scan_points(ROOM, TRUE_POSE, rng)
    with_nan = np.vstack([points, np.full((20, 2), np.nan)])
    guess = TRUE_POSE + np.array([0.03, -0.02, 0.01])
    a = align_points(points, *reference(ROOM), guess)
    b = align_points(with_nan, *reference(ROOM), guess)
    np.testing.assert_array_equal(a.pose, b.pose)


def test_same_input_same_output():
    rng = np.random.default_rng(11)
    points = scan_points(ROOM, TRUE_POSE, rng)
    guess = compose(TRUE_POSE, (0.02, 0.05, -0.01))
    a = align_points(points, *reference(ROOM), guess)
    b = align_points(points.copy(), *reference(ROOM), guess.copy())
    assert a.accepted == b.accepted
    np.testing.assert_array_equal(a.pose, b.pose)
    np.testing.assert_array_equal(a.correction, b.correction)


def test_non_finite_pose_is_an_error():
    with pytest.raises(ValueError, match="pose must be a finite"):
        align_points(np.zeros((40, 2)), *reference(ROOM), (np.nan, 0.0, 0.0))


def test_nearest_on_segments_matches_shapely():
    rng = np.random.default_rng(12)
    starts = rng.uniform(-3, 3, (15, 2))
    ends = starts + rng.uniform(-1, 1, (15, 2))
    points = rng.uniform(-4, 4, (200, 2))
    distance, foot, normal, _ = nearest_on_segments(points, starts, ends)
    lines = shapely.MultiLineString([[a, b] for a, b in zip(starts, ends, strict=True)])
    expected = shapely.distance(shapely.points(points), lines)
    np.testing.assert_allclose(distance, expected, atol=1e-12)
    np.testing.assert_allclose(np.hypot(*(points - foot).T), distance, atol=1e-12)
    np.testing.assert_allclose(np.hypot(*normal.T), 1.0)


def test_nearest_on_segments_inside_flag_and_degenerate_segments():
    distance, foot, _, inside = nearest_on_segments(
        [[0.5, 1.0], [-1.0, 0.0], [5.0, 5.0]], [[0.0, 0.0], [5.0, 4.0]], [[1.0, 0.0], [5.0, 4.0]]
    )
    assert inside.tolist() == [True, False, False]  # beyond the end; a point-like segment
    np.testing.assert_allclose(distance, [1.0, 1.0, 1.0])
    np.testing.assert_allclose(foot, [[0.5, 0.0], [0.0, 0.0], [5.0, 4.0]])


def test_nearest_on_segments_needs_segments():
    with pytest.raises(ValueError, match="K >= 1 segments"):
        nearest_on_segments([[0.0, 0.0]], np.empty((0, 2)), np.empty((0, 2)))


def test_polyline_segments_takes_polylines_and_arrays():
    line = Polyline([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    starts, ends = polyline_segments([line, [[5.0, 5.0]], np.array([[0, 1], [0, 2]])])
    assert starts.tolist() == [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    assert ends.tolist() == [[1.0, 0.0], [1.0, 2.0], [0.0, 2.0]]
    empty = polyline_segments([])
    assert empty[0].shape == (0, 2)
    assert empty[1].shape == (0, 2)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_distance", 0.0), ("noise", -0.01), ("max_translation", 0.0),
        ("max_rotation", 0.0), ("iterations", 0), ("iterations", 2.5), ("min_points", 2),
        ("min_constraint", -0.1), ("min_constraint", 1.5), ("partial", "yes"),
    ],
)
def test_params_are_validated(field, value):
    with pytest.raises(ValueError, match=f"AlignmentParams.{field}"):
        AlignmentParams(**{field: value})
