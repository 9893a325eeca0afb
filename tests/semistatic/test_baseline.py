import itertools
import math

import numpy as np
import pytest

from semistatic.baseline import COLLINEAR_TOLERANCE, extract_split_and_merge, split_and_merge
from semistatic.extraction import douglas_peucker, extract_polylines
from semistatic.params import MapperParams
from semistatic.types import Scan


def line_deviation(points, first, last):
    """Largest distance of points[first..last] to the line through both ends (reference)."""
    a, b = points[first], points[last]
    d = b - a
    worst = 0.0
    for p in points[first : last + 1]:
        worst = max(worst, abs((p[0] - a[0]) * d[1] - (p[1] - a[1]) * d[0]) / math.hypot(*d))
    return worst


def noisy_polygon(rng, corners, per_edge=30, noise=0.005):
    points = []
    for a, b in itertools.pairwise(corners):
        t = np.linspace(0, 1, per_edge, endpoint=False)[:, None]
        points.append(np.asarray(a) + t * (np.asarray(b) - np.asarray(a)))
    points.append(np.asarray([corners[-1]], dtype=float))
    points = np.concatenate(points)
    return points + rng.normal(0, noise, points.shape)


def room_scan(beams=361, noise=0.0, rng=None):
    """A scan from inside a 6 m x 4 m room with a box, 0.5 deg beams over 180 deg."""
    angles = np.radians(-90 + 0.5 * np.arange(beams))
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    with np.errstate(divide="ignore"):
        to_front = np.where(d[:, 0] > 0, 3.0 / d[:, 0], np.inf)
        to_left = np.where(d[:, 1] > 0, 2.0 / d[:, 1], np.inf)
        to_right = np.where(d[:, 1] < 0, -2.0 / d[:, 1], np.inf)
    ranges = np.minimum(np.minimum(to_front, to_left), to_right)
    box = (angles > np.radians(10)) & (angles < np.radians(25))
    ranges[box] = 1.5 / np.cos(angles[box] - np.radians(17.5))
    if noise:
        ranges = ranges + rng.normal(0, noise, beams)
    return Scan(ranges=ranges, angle_min=angles[0], angle_increment=np.radians(0.5))


def test_noiseless_polygon_gives_its_corners():
    corners = [(0, 0), (2, 0), (2, 1), (4, 1.5), (4, 3)]
    points = noisy_polygon(np.random.default_rng(0), corners, noise=0.0)
    assert split_and_merge(points, threshold=0.01).tolist() == [0, 30, 60, 90, 120]
    assert split_and_merge(points, max_vertices=5).tolist() == [0, 30, 60, 90, 120]


@pytest.mark.parametrize("seed", range(5))
def test_threshold_mode_keeps_every_section_within_the_threshold(seed):
    rng = np.random.default_rng(seed)
    corners = rng.uniform(-5, 5, (6, 2))
    points = noisy_polygon(rng, corners, noise=0.01)
    kept = split_and_merge(points, threshold=0.05)
    assert kept[0] == 0
    assert kept[-1] == len(points) - 1
    assert np.all(np.diff(kept) > 0)
    for first, last in itertools.pairwise(kept):
        assert line_deviation(points, first, last) <= 0.05 + 1e-12


@pytest.mark.parametrize("budget", [2, 3, 5, 8, 13])
def test_budget_mode_spends_exactly_the_budget(budget):
    points = noisy_polygon(np.random.default_rng(1), [(0, 0), (3, 0), (3, 2), (0, 2)], noise=0.02)
    kept = split_and_merge(points, max_vertices=budget)
    assert len(kept) == budget
    assert (kept[0], kept[-1]) == (0, len(points) - 1)


def test_budget_mode_splits_the_worst_section_first():
    # An L with a long noisy leg: the corner (the largest deviation) must come first.
    points = np.array([[0, 0], [1, 0.02], [2, 0], [3, 0.0], [3, 1], [3, 2]], dtype=float)
    assert split_and_merge(points, max_vertices=3).tolist() == [0, 3, 5]
    assert split_and_merge(points, max_vertices=4).tolist() == [0, 1, 3, 5]


def test_merge_removes_a_vertex_the_split_left_behind():
    points = np.array([[0.0, 1.5], [0.2, 3.3], [0.3, 2.6], [1.1, 2.8], [1.6, 3.6], [1.7, 3.3]])
    # The split alone keeps 0, 1, 2, 5 (by the reference): point 1 is the farthest from the
    # chord 0-5, point 2 from the chord 1-5, and the chord 2-5 fits within 0.5.
    def farthest(first, last):
        return max(range(first + 1, last),
                   key=lambda k: line_deviation(points[[first, k, last]], 0, 2))

    assert farthest(0, 5) == 1
    assert line_deviation(points, 0, 5) > 0.5
    assert farthest(1, 5) == 2
    assert line_deviation(points, 1, 5) > 0.5
    assert line_deviation(points, 2, 5) <= 0.5
    # Point 1 lies within 0.5 of the line through points 0 and 2: collinear neighbours.
    assert line_deviation(points, 0, 2) <= 0.5
    assert split_and_merge(points, threshold=0.5).tolist() == [0, 2, 5]


def test_threshold_and_budget_together_stop_at_the_first_reached():
    points = noisy_polygon(np.random.default_rng(2), [(0, 0), (3, 0), (3, 2), (0, 2)], noise=0.01)
    assert len(split_and_merge(points, threshold=0.05, max_vertices=2)) == 2
    loose = split_and_merge(points, threshold=0.05, max_vertices=100)
    np.testing.assert_array_equal(loose, split_and_merge(points, threshold=0.05))


NASTY = {
    "empty": (np.empty((0, 2)), []),
    "one": ([[1.0, 2.0]], [0]),
    "two": ([[0.0, 0.0], [1.0, 0.0]], [0, 1]),
    "collinear": ([[0, 0], [1, 1], [2, 2], [3, 3]], [0, 3]),
    "duplicates": ([[0, 0], [0, 0], [1, 0], [1, 0], [2, 0]], [0, 4]),
    "closed_loop": ([[0, 0], [1, 0], [1, 1], [0, 0]], [0, 1, 2, 3]),
}


@pytest.mark.parametrize("case", sorted(NASTY))
@pytest.mark.parametrize("mode", [{"threshold": 0.01}, {"max_vertices": 10}])
def test_nasty_inputs(case, mode):
    points, expected = NASTY[case]
    kept = split_and_merge(points, **mode)
    assert kept.tolist() == expected
    assert kept.dtype == np.int64


def test_collinear_tolerance_is_tiny():
    assert COLLINEAR_TOLERANCE < 1e-6  # rounding only; never a geometric threshold


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({}, "give threshold"),
        ({"threshold": -0.1}, "threshold must be >= 0"),
        ({"max_vertices": 1}, "max_vertices must be an integer >= 2"),
        ({"max_vertices": 2.5}, "max_vertices must be an integer >= 2"),
    ],
)
def test_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        split_and_merge([[0, 0], [1, 1], [2, 0]], **kwargs)


def test_nan_points_are_rejected():
    with pytest.raises(ValueError, match="finite"):
        split_and_merge([[0, 0], [np.nan, 1], [2, 0]], threshold=0.1)


def test_douglas_peucker_and_split_and_merge_agree_on_clean_corners():
    points = noisy_polygon(np.random.default_rng(3), [(0, 0), (4, 0), (4, 3), (1, 3)], noise=0.0)
    np.testing.assert_array_equal(
        split_and_merge(points, threshold=0.02), douglas_peucker(points, 0.02)
    )


def test_scan_extractor_uses_the_paper_intervals():
    scan = room_scan(noise=0.01, rng=np.random.default_rng(4))
    params = MapperParams()
    paper = extract_polylines(scan, params)
    ours = extract_split_and_merge(scan, params)
    assert len(paper) == len(ours) >= 3  # right wall, front wall(s), box, left wall
    for a, b in zip(paper, ours, strict=True):
        assert (a.scan_indices[0], a.scan_indices[-1]) == (b.scan_indices[0], b.scan_indices[-1])
        np.testing.assert_array_equal(b.points, scan.points()[b.scan_indices])


def test_scan_extractor_matches_vertex_counts():
    scan = room_scan(noise=0.01, rng=np.random.default_rng(5))
    params = MapperParams(epsilon=0.02)
    paper = extract_polylines(scan, params)
    counts = [len(p) for p in paper]
    ours = extract_split_and_merge(scan, params, vertex_counts=counts)
    assert [len(p) for p in ours] == counts
    with pytest.raises(ValueError, match="vertex_counts has 1 entries"):
        extract_split_and_merge(scan, params, vertex_counts=counts[:1])


def test_scan_extractor_on_an_empty_scan():
    scan = Scan(ranges=[np.inf] * 10, angle_min=0.0, angle_increment=0.01)
    assert extract_split_and_merge(scan) == []


def test_scan_extractor_is_deterministic():
    scan = room_scan(noise=0.01, rng=np.random.default_rng(6))
    a = extract_split_and_merge(scan)
    b = extract_split_and_merge(scan)
    assert [p.scan_indices.tolist() for p in a] == [p.scan_indices.tolist() for p in b]
