import math

import numpy as np
import pytest
import shapely

from semistatic.evaluation import paper_params, ray_errors
from semistatic.extraction import (
    MAX_BRIDGED_GAP,
    douglas_peucker,
    extract_polylines,
    remove_invalid,
    remove_outliers,
    split_breakpoints,
)
from semistatic.params import MapperParams
from semistatic.types import Scan
from tests.semistatic.conftest import room_scan

LAMBDA = math.radians(10.0)


def _segment_distance(point, start, end):
    """Plain point-to-segment distance for the references below."""
    return shapely.distance(shapely.Point(point), shapely.LineString([start, end]))


# --- remove_invalid --------------------------------------------------------------------------


def test_remove_invalid_drops_nan_inf_negative_and_out_of_range(nasty_scan):
    valid = remove_invalid(nasty_scan)
    ranges = nasty_scan.ranges
    assert valid.shape == ranges.shape
    assert np.isfinite(ranges[valid]).all()
    assert (ranges[valid] >= nasty_scan.range_min).all()
    assert (ranges[valid] <= nasty_scan.range_max).all()


def test_remove_invalid_applies_the_mapper_max_range():
    scan = Scan(ranges=[1.0, 5.0, 9.0], angle_min=0.0, angle_increment=0.1, range_max=8.0)
    np.testing.assert_array_equal(remove_invalid(scan), [True, True, False])
    np.testing.assert_array_equal(remove_invalid(scan, max_range=4.0), [True, False, False])


# --- remove_outliers -------------------------------------------------------------------------


def _outliers_reference(ranges, valid, k, alpha):
    """docs/design.md#detail-1 with plain loops: windows over valid ranges only."""
    index = [i for i in range(len(ranges)) if valid[i]]
    kept = list(valid)
    for position, i in enumerate(index):
        window = [ranges[j] for j in index[max(0, position - k) : position + k + 1]]
        mean = sum(window) / len(window)
        sigma = math.sqrt(sum((r - mean) ** 2 for r in window) / len(window))
        if sigma > 1e-6 and abs(ranges[i] - mean) > alpha * sigma:
            kept[i] = False
    return np.array(kept, dtype=bool)


@pytest.mark.parametrize("seed", range(40))
def test_remove_outliers_matches_the_loop_reference(seed):
    rng = np.random.default_rng(seed)
    size = int(rng.integers(1, 80))
    base, noise = (3.0, 0.02) if seed % 2 else (78.0, 0.002)  # far ranges, little noise
    ranges = base + rng.normal(0.0, noise, size)
    spikes = rng.random(size) < 0.1
    ranges[spikes] += rng.uniform(-2.0, 2.0, spikes.sum())
    ranges[rng.random(size) < 0.1] = np.nan
    valid = np.isfinite(ranges) & (rng.random(size) < 0.9)
    k, alpha = int(rng.integers(1, 6)), float(rng.uniform(0.8, 2.8))
    np.testing.assert_array_equal(
        remove_outliers(ranges, valid, k, alpha), _outliers_reference(ranges, valid, k, alpha)
    )


def test_isolated_spike_is_removed_and_its_neighbours_kept():
    ranges = 2.0 + 0.01 * np.sin(1.3 * np.arange(40))  # 1 cm ripple
    ranges[20] = 3.5
    kept = remove_outliers(ranges, np.ones(40, bool), k=4, alpha=2.5)
    np.testing.assert_array_equal(np.flatnonzero(~kept), [20])


def test_default_parameters_remove_few_noise_readings_and_catch_big_spikes():
    params = MapperParams()
    rng = np.random.default_rng(5)
    noise = 2.0 + rng.normal(0.0, 0.01, 20000)
    kept = remove_outliers(noise, np.ones(noise.size, bool), params.outlier_k, params.outlier_alpha)
    assert kept.mean() > 0.995
    window = 2 * params.outlier_k + 1
    caught = 0
    for _ in range(200):
        ranges = 2.0 + rng.normal(0.0, 0.01, window)
        ranges[params.outlier_k] += 0.15  # a 15 sigma spike
        caught += not remove_outliers(
            ranges, np.ones(window, bool), params.outlier_k, params.outlier_alpha
        )[params.outlier_k]
    assert caught >= 195


def test_invalid_readings_never_reach_the_statistics():
    rng = np.random.default_rng(2)
    ranges = 2.0 + rng.normal(0.0, 0.05, 30)
    poisoned = ranges.copy()
    poisoned[[5, 14, 15]] = [np.nan, np.inf, -40.0]
    valid = np.isfinite(poisoned) & (poisoned > 0)
    kept = remove_outliers(poisoned, valid, k=3, alpha=1.2)
    clean = remove_outliers(ranges, valid, k=3, alpha=1.2)
    np.testing.assert_array_equal(kept, clean)  # what sits in invalid slots is irrelevant
    assert not kept[[5, 14, 15]].any()
    assert kept.sum() < valid.sum()  # alpha = 1.2 does remove something here


def test_flat_window_removes_nothing():
    ranges = np.full(25, 1.7)
    np.testing.assert_array_equal(remove_outliers(ranges, np.ones(25, bool), 1, 0.1), True)


def test_alpha_at_or_above_sqrt_2k_never_removes():
    # r_i is in its own window, so |r_i - mu| <= sqrt(n - 1) sigma for n readings.
    rng = np.random.default_rng(0)
    ranges = rng.uniform(0.5, 10.0, 200)
    for k in (1, 2, 3, 4):
        kept = remove_outliers(ranges, np.ones(200, bool), k, math.sqrt(2 * k))
        assert kept.all()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (([1.0, 2.0], [True], 2, 2.0), "valid has 1"),
        (([1.0, 2.0], [True, True], 0, 2.0), "k must be"),
        (([1.0, 2.0], [True, True], 2, 0.0), "alpha must be"),
    ],
)
def test_remove_outliers_rejects_bad_arguments(args, message):
    with pytest.raises(ValueError, match=message):
        remove_outliers(*args)


# --- split_breakpoints -----------------------------------------------------------------------


def _wall_scan(ranges, increment_deg=1.0):
    return Scan(ranges=ranges, angle_min=0.0, angle_increment=math.radians(increment_deg))


def test_depth_jump_splits_and_continuous_wall_does_not():
    scan = _wall_scan([2.0] * 10 + [2.5] * 10)
    intervals = split_breakpoints(scan, np.ones(20, bool), LAMBDA, 0.01, min_points=3)
    assert [interval.tolist() for interval in intervals] == [list(range(10)), list(range(10, 20))]


def test_oblique_wall_stays_whole_up_to_the_lambda_incidence():
    # A wall x = 1 seen at bearings 0..60 deg: the beam meets it at up to 60 deg incidence,
    # well inside the 80 deg the adaptive threshold allows for lambda = 10 deg.
    angles = np.radians(np.arange(0.0, 61.0))
    scan = _wall_scan(1.0 / np.cos(angles))
    intervals = split_breakpoints(scan, np.ones(61, bool), LAMBDA, 0.0, min_points=2)
    assert len(intervals) == 1
    # A wall almost along the beams (incidence beyond 90 - lambda) is broken apart.
    grazing = _wall_scan(1.0 / np.cos(np.radians(np.arange(82.0, 88.0))))
    assert len(split_breakpoints(grazing, np.ones(6, bool), LAMBDA, 0.0, min_points=1)) == 6


@pytest.mark.parametrize(("missing", "pieces"), [(1, 1), (2, 2), (5, 2)])
def test_gaps_of_more_than_one_missing_beam_always_break(missing, pieces):
    assert MAX_BRIDGED_GAP == 1
    ranges = np.full(30, 2.0)
    ranges[10 : 10 + missing] = np.nan
    scan = _wall_scan(ranges)
    valid = remove_invalid(scan)
    intervals = split_breakpoints(scan, valid, LAMBDA, 0.01, min_points=3)
    assert len(intervals) == pieces
    assert sum(interval.size for interval in intervals) == 30 - missing


def test_bridged_gap_still_needs_the_adaptive_test():
    ranges = np.array([2.0] * 10 + [np.nan] + [3.0] * 10)
    scan = _wall_scan(ranges)
    assert len(split_breakpoints(scan, remove_invalid(scan), LAMBDA, 0.01, 3)) == 2


def test_short_intervals_are_dropped():
    ranges = np.array([2.0] * 6 + [1.0] * 3 + [2.0] * 6)
    scan = _wall_scan(ranges)
    intervals = split_breakpoints(scan, np.ones(15, bool), LAMBDA, 0.01, min_points=4)
    assert [interval.tolist() for interval in intervals] == [list(range(6)), list(range(9, 15))]


def test_no_valid_beam_gives_no_interval(nasty_scan):
    valid = np.zeros(len(nasty_scan), bool)
    assert split_breakpoints(nasty_scan, valid, LAMBDA, 0.01, 2) == []


def test_split_rejects_bad_arguments():
    scan = _wall_scan([1.0, 1.0])
    with pytest.raises(ValueError, match="valid has 3"):
        split_breakpoints(scan, np.ones(3, bool), LAMBDA, 0.01, 2)
    with pytest.raises(ValueError, match="lam must be"):
        split_breakpoints(scan, np.ones(2, bool), 2.0, 0.01, 2)
    with pytest.raises(ValueError, match="sigma_r must be"):
        split_breakpoints(scan, np.ones(2, bool), LAMBDA, -0.01, 2)
    with pytest.raises(ValueError, match="min_points must be"):
        split_breakpoints(scan, np.ones(2, bool), LAMBDA, 0.01, 0)


# --- douglas_peucker -------------------------------------------------------------------------


def _geos_segment_distance(p, a, b):
    """GEOS ``Distance::pointToSegment``, operation for operation."""
    if a[0] == b[0] and a[1] == b[1]:
        return math.sqrt((p[0] - a[0]) ** 2 + (p[1] - a[1]) ** 2)
    len2 = (b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1])
    r = ((p[0] - a[0]) * (b[0] - a[0]) + (p[1] - a[1]) * (b[1] - a[1])) / len2
    if r <= 0.0:
        return math.sqrt((p[0] - a[0]) ** 2 + (p[1] - a[1]) ** 2)
    if r >= 1.0:
        return math.sqrt((p[0] - b[0]) ** 2 + (p[1] - b[1]) ** 2)
    s = ((a[1] - p[1]) * (b[0] - a[0]) - (a[0] - p[0]) * (b[1] - a[1])) / len2
    return abs(s) * math.sqrt(len2)


def _douglas_peucker_reference(points, epsilon):
    """The textbook recursion with GEOS's rules, in plain Python."""
    keep = [True] * len(points)

    def section(i, j):
        if i + 1 >= j:
            return
        farthest, index = -1.0, i
        for k in range(i + 1, j):
            d = _geos_segment_distance(points[k], points[i], points[j])
            if d > farthest:
                farthest, index = d, k
        if farthest <= epsilon:
            keep[i + 1 : j] = [False] * (j - i - 1)
        else:
            section(i, index)
            section(index, j)

    section(0, len(points) - 1)
    return [k for k, kept in enumerate(keep) if kept]


@pytest.mark.parametrize("seed", range(100))
def test_douglas_peucker_keeps_exactly_what_shapely_keeps(seed):
    rng = np.random.default_rng(seed)
    size = int(rng.integers(3, 300))
    points = np.cumsum(rng.normal(0.0, rng.uniform(0.01, 1.0), (size, 2)), axis=0)
    if seed % 4 == 0:
        points = points.round(1)  # exact ties, repeated and collinear points
    epsilon = float(rng.uniform(0.0, 0.5))
    kept = douglas_peucker(points, epsilon)
    assert kept.tolist() == _douglas_peucker_reference(points.tolist(), epsilon)
    expected = shapely.get_coordinates(
        shapely.simplify(shapely.LineString(points), epsilon, preserve_topology=False)
    )
    np.testing.assert_array_equal(points[kept], expected)
    assert np.all(np.diff(kept) > 0)


def test_douglas_peucker_keeps_a_point_exactly_at_epsilon_out():
    # GEOS keeps a point only when its distance is strictly greater than the tolerance.
    points = [[0.0, 0.0], [1.0, 0.25], [2.0, 0.0]]
    np.testing.assert_array_equal(douglas_peucker(points, 0.25), [0, 2])
    np.testing.assert_array_equal(douglas_peucker(points, 0.2499), [0, 1, 2])


def test_douglas_peucker_uses_distance_to_the_segment_not_the_line():
    # Point 1 is on the line through 0 and 2 but 1 m beyond the segment's end.
    points = [[0.0, 0.0], [3.0, 0.0], [2.0, 0.0]]
    np.testing.assert_array_equal(douglas_peucker(points, 0.5), [0, 1, 2])


def test_douglas_peucker_tie_keeps_the_first_farthest_point():
    points = [[0.0, 0.0], [1.0, 1.0], [2.0, 1.0], [3.0, 0.0]]
    # Points 1 and 2 are both 1 m from the chord; GEOS splits at the first one.
    np.testing.assert_array_equal(douglas_peucker(points, 1.5), [0, 3])
    np.testing.assert_array_equal(douglas_peucker(points, 0.9), [0, 1, 3])


@pytest.mark.parametrize(
    ("points", "expected"),
    [
        (np.empty((0, 2)), []),
        ([[1.0, 1.0]], [0]),
        ([[1.0, 1.0], [1.0, 1.0]], [0, 1]),
        ([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]], [0, 3]),
    ],
)
def test_douglas_peucker_degenerate_lines(points, expected):
    np.testing.assert_array_equal(douglas_peucker(points, 0.1), expected)


def test_douglas_peucker_rejects_bad_input():
    with pytest.raises(ValueError, match="epsilon"):
        douglas_peucker([[0, 0], [1, 0], [2, 0]], -1.0)
    with pytest.raises(ValueError, match="finite"):
        douglas_peucker([[0, 0], [np.nan, 0], [2, 0]], 0.1)


# --- extract_polylines -----------------------------------------------------------------------


def test_all_no_return_and_nasty_scans(nasty_scan):
    polylines = extract_polylines(nasty_scan, MapperParams(min_points=3))
    for line in polylines:
        assert np.isfinite(line.points).all()
        assert nasty_scan.valid_mask()[line.scan_indices].all()
    if not nasty_scan.valid_mask().any():
        assert polylines == []


def test_extraction_in_sensor_frame_scan_order_and_within_epsilon(noisy_room_scan):
    params = paper_params(MapperParams())  # raw vertices, outliers removed
    scan = noisy_room_scan
    polylines = extract_polylines(scan, params)
    assert len(polylines) == 5  # wall+hidden corner, box front, far walls, pillar, left wall
    points = scan.points()
    previous_end = -1
    for line in polylines:
        # vertices are the scan's own end points (sensor frame) at their beam indices
        np.testing.assert_array_equal(line.points, points[line.scan_indices])
        assert not line.points.flags.writeable
        assert not line.scan_indices.flags.writeable
        assert line.scan_indices.dtype == np.int64
        assert line.scan_indices[0] > previous_end  # counter-clockwise scan order
        assert np.all(np.diff(line.scan_indices) > 0)
        previous_end = line.scan_indices[-1]
    valid = remove_outliers(
        scan.ranges, remove_invalid(scan), params.outlier_k, params.outlier_alpha
    )
    intervals = split_breakpoints(
        scan, valid, params.breakpoint_lambda, params.breakpoint_sigma_r, params.min_points
    )
    assert len(intervals) == len(polylines)
    for interval, line in zip(intervals, polylines, strict=True):
        assert (line.scan_indices[0], line.scan_indices[-1]) == (interval[0], interval[-1])
        curve = shapely.LineString(line.points)
        distances = shapely.distance(shapely.points(points[interval]), curve)
        assert distances.max() <= params.epsilon + 1e-12


def test_batched_simplification_equals_one_douglas_peucker_per_interval():
    params = paper_params(MapperParams(epsilon=0.02))
    for seed in range(5):
        scan = room_scan(np.random.default_rng(seed), noise=0.015)
        valid = remove_outliers(
            scan.ranges, remove_invalid(scan), params.outlier_k, params.outlier_alpha
        )
        intervals = split_breakpoints(
            scan, valid, params.breakpoint_lambda, params.breakpoint_sigma_r, params.min_points
        )
        points = scan.points()
        lines = extract_polylines(scan, params)
        for interval, line in zip(intervals, lines, strict=True):
            expected = interval[douglas_peucker(points[interval], params.epsilon)]
            np.testing.assert_array_equal(line.scan_indices, expected)


def test_extraction_is_deterministic_and_ignores_the_scan_pose():
    scan = room_scan(np.random.default_rng(11))
    moved = Scan(
        ranges=scan.ranges,
        angle_min=scan.angle_min,
        angle_increment=scan.angle_increment,
        range_max=scan.range_max,
        pose=(4.0, -1.0, 2.0),
    )
    first, second = extract_polylines(scan), extract_polylines(moved)
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.scan_indices, b.scan_indices)


def spiked_wall_scan():
    angles = np.radians(np.arange(-30.0, 30.5, 0.5))
    ranges = 3.0 / np.cos(angles)
    ranges[40] = np.nan  # dropout
    ranges[80] = 1.2  # isolated spike: a thin pole, or a stray return
    return Scan(ranges=ranges, angle_min=angles[0], angle_increment=np.radians(0.5))


def test_paper_removal_bridges_a_dropout_and_deletes_a_spike():
    scan = spiked_wall_scan()
    params = MapperParams(outlier_removal=True, outlier_k=4, outlier_alpha=2.5)
    lines = extract_polylines(scan, params)
    assert len(lines) == 1
    np.testing.assert_array_equal(lines[0].scan_indices, [0, scan.ranges.size - 1])
    # the deleted spike's ray (at 10 deg) now crosses the wall 1.85 m behind its reading
    assert ray_errors(scan, lines)[80] == pytest.approx(3.0 / np.cos(np.radians(10.0)) - 1.2)


def test_a_kept_spike_breaks_the_wall_and_no_polyline_crosses_its_ray():
    scan = spiked_wall_scan()
    lines = extract_polylines(scan)
    assert [line.scan_indices.tolist() for line in lines] == [[0, 79], [81, 120]]
    errors = ray_errors(scan, lines)
    assert np.isnan(errors[80])  # no polyline on the spike's ray (one reading, no line)
    returned = ~np.isinf(errors) & ~np.isnan(errors)
    assert np.abs(errors[returned]).max() < 1e-9


def test_max_range_cuts_far_readings():
    angles = np.radians(np.arange(-20.0, 20.5, 0.5))
    ranges = np.where(angles < 0, 2.0, 9.0) / np.cos(angles)
    scan = Scan(ranges=ranges, angle_min=angles[0], angle_increment=np.radians(0.5))
    assert len(extract_polylines(scan)) == 2
    near_only = extract_polylines(scan, MapperParams(max_range=5.0))
    assert len(near_only) == 1
    assert near_only[0].points[:, 0].max() < 5.0
