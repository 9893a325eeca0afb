import math

import numpy as np
import pytest
import shapely
from shapely.ops import substring

from semistatic.extraction import douglas_peucker
from semistatic.hausdorff import (
    HAUSDORFF_TOLERANCE,
    hausdorff,
    restrict,
    restricted_hausdorff,
)
from semistatic.polyline import PackedPolylines, Polyline

REFERENCE_SPACING = 0.01  # densify the shapely reference to 1 cm


def _geometry(points):
    points = np.asarray(points, dtype=float)
    return shapely.Point(points[0]) if len(points) == 1 else shapely.LineString(points)


def _reference_hausdorff(points0, points1, spacing=REFERENCE_SPACING):
    """Shapely's discrete Hausdorff with every segment densified to ``spacing`` or finer."""
    longest = max(
        [
            np.hypot(*np.diff(np.asarray(p, float), axis=0).T).max(initial=0.0)
            for p in (points0, points1)
        ]
    )
    densify = min(1.0, spacing / longest) if longest > 0 else None
    return shapely.hausdorff_distance(_geometry(points0), _geometry(points1), densify=densify)


def _restrict_reference(points0, points1):
    """Eq. (3) by the definition, with plain loops and shapely distances."""
    if len(points0) < 2:
        return points0
    nearest = []
    for vertex in points1:
        best, best_segment = math.inf, -1
        for j in range(len(points0) - 1):
            d = shapely.distance(shapely.Point(vertex), shapely.LineString(points0[j : j + 2]))
            if d < best:
                best, best_segment = d, j
        nearest.append(best_segment)
    return points0[min(nearest) : max(nearest) + 2]


def _projection_reference(points0, points1):
    """The "projection" restriction with shapely's linear referencing."""
    line = shapely.LineString(points0)
    positions = [line.project(shapely.Point(vertex)) for vertex in points1]
    cut = substring(line, min(positions), max(positions))
    return shapely.get_coordinates(cut)


def _partial_view(rng):
    """A random polyline P0 and a noisy, simplified scan of part of it, P1."""
    count = int(rng.integers(3, 12))
    headings = np.cumsum(rng.uniform(-1.3, 1.3, count - 1)) + rng.uniform(-np.pi, np.pi)
    lengths = rng.uniform(0.3, 2.5, count - 1)
    steps = lengths[:, None] * np.column_stack((np.cos(headings), np.sin(headings)))
    points0 = np.vstack(([0.0, 0.0], np.cumsum(steps, axis=0)))
    line = shapely.LineString(points0)
    start = rng.uniform(0.0, 0.5) * line.length
    stop = start + rng.uniform(0.2, 1.0) * (line.length - start)
    samples = np.linspace(start, stop, max(int((stop - start) / 0.05), 3))
    seen = shapely.get_coordinates(line.interpolate(samples))
    seen = seen + rng.normal(0.0, 0.01, seen.shape)
    points1 = seen[douglas_peucker(seen, 0.03)]
    return points0, points1


@pytest.mark.parametrize("seed", range(100))
def test_restricted_hausdorff_matches_the_slow_reference_on_partial_views(seed):
    points0, points1 = _partial_view(np.random.default_rng(seed))
    expected = _reference_hausdorff(
        _restrict_reference(points0, points1), _restrict_reference(points1, points0)
    )
    assert restricted_hausdorff(points0, points1) == pytest.approx(expected, abs=0.01)
    # the restriction itself is exactly the definition's
    np.testing.assert_array_equal(
        restrict(points0, points1).points, _restrict_reference(points0, points1)
    )


@pytest.mark.parametrize("seed", range(30))
def test_projection_mode_matches_shapely_linear_referencing(seed):
    points0, points1 = _partial_view(np.random.default_rng(1000 + seed))
    cut = restrict(points0, points1, mode="projection")
    np.testing.assert_allclose(cut.points, _projection_reference(points0, points1), atol=1e-9)
    expected = _reference_hausdorff(
        _projection_reference(points0, points1), _projection_reference(points1, points0)
    )
    assert restricted_hausdorff(points0, points1, mode="projection") == pytest.approx(
        expected, abs=0.01
    )
    # a partial view of the same object is close once restricted (noise is 1 cm)
    assert restricted_hausdorff(points0, points1, mode="projection") < 0.06


@pytest.mark.parametrize("seed", range(40))
def test_hausdorff_is_exact_between_continuous_curves(seed):
    rng = np.random.default_rng(seed)
    points0 = np.cumsum(rng.normal(0.0, 0.5, (int(rng.integers(1, 8)), 2)), axis=0)
    points1 = np.cumsum(rng.normal(0.0, 0.5, (int(rng.integers(1, 8)), 2)), axis=0)
    result = hausdorff(points0, points1)
    fine = _reference_hausdorff(points0, points1, spacing=0.0005)
    # the densified reference is below the truth by at most half its spacing
    assert fine - HAUSDORFF_TOLERANCE - 1e-12 <= result <= fine + 0.00025 + 1e-12
    assert result == hausdorff(points1, points0)
    vertices_only = shapely.hausdorff_distance(_geometry(points0), _geometry(points1))
    assert result >= vertices_only - 1e-12


def test_hausdorff_sees_the_middle_of_edges():
    # Each curve's vertices lie on the other one; the edges bulge 1 m apart in between.
    zigzag = [[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]]
    flat = [[0.0, 0.0], [2.0, 0.0]]
    assert hausdorff(zigzag, flat) == pytest.approx(1.0)
    assert hausdorff([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]], [[0.0, 0.0], [2.0, 2.0]]) == (
        pytest.approx(math.sqrt(2.0), abs=HAUSDORFF_TOLERANCE)
    )


def test_points_are_points():
    assert hausdorff([[0.0, 0.0]], [[3.0, 4.0]]) == pytest.approx(5.0)
    assert hausdorff([[0.0, 1.0]], [[-1.0, 0.0], [1.0, 0.0]]) == pytest.approx(math.sqrt(2.0))
    assert hausdorff([[0.0, 0.0], [0.0, 0.0]], [[0.0, 2.0]]) == pytest.approx(2.0)


def test_identical_and_translated_curves():
    rng = np.random.default_rng(4)
    points = np.cumsum(rng.normal(size=(9, 2)), axis=0)
    assert hausdorff(points, points) == pytest.approx(0.0, abs=1e-12)
    assert restricted_hausdorff(points, points) == pytest.approx(0.0, abs=1e-12)
    assert hausdorff(points, points + np.array([0.0, 0.07])) == pytest.approx(0.07, abs=1e-3)


def test_nasty_polylines_give_finite_or_documented_results(nasty_polyline):
    wall = np.array([[0.0, 0.0], [3.0, 0.0]])
    for mode in ("vertex", "projection"):
        result = restricted_hausdorff(nasty_polyline, wall, mode=mode)
        reverse = restricted_hausdorff(wall, nasty_polyline, mode=mode)
        if len(nasty_polyline) == 0:
            assert result == math.inf
            assert reverse == math.inf
        else:
            assert 0.0 <= result < math.inf
            assert 0.0 <= reverse < math.inf
    if len(nasty_polyline):
        expected = _reference_hausdorff(nasty_polyline, wall, spacing=0.001)
        assert hausdorff(nasty_polyline, wall) == pytest.approx(expected, abs=1e-3)


def test_repeated_vertices_do_not_change_the_distance():
    line = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]])
    doubled = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.5], [1.0, 0.5], [2.0, 0.0]])
    other = np.array([[0.2, -0.1], [1.8, 0.1]])
    assert hausdorff(doubled, other) == pytest.approx(hausdorff(line, other), abs=1e-9)
    assert restricted_hausdorff(doubled, other) == pytest.approx(
        restricted_hausdorff(line, other), abs=1e-9
    )


def test_vertex_restriction_keeps_whole_segments_and_scan_indices():
    corridor = Polyline([[0, 0], [1, 0], [2, 0], [3, 0], [4, 0]], scan_indices=[10, 20, 30, 40, 50])
    partial = [[1.5, 0.05], [2.6, 0.05]]
    restricted = restrict(corridor, partial)
    np.testing.assert_array_equal(restricted.scan_indices, [20, 30, 40])
    np.testing.assert_array_equal(restricted.points, corridor.points[1:4])
    # a vertex exactly abreast of a shared vertex picks the lower segment (eq. 3 argmin)
    np.testing.assert_array_equal(restrict(corridor, [[2.0, 1.0]]).scan_indices, [20, 30])


def test_two_vertex_wall_is_restricted_only_by_projection():
    wall = Polyline([[0.0, 0.0], [10.0, 0.0]], scan_indices=[100, 300])
    partial = [[4.0, 0.05], [5.0, 0.04], [6.0, 0.05]]
    assert restrict(wall, partial) is wall
    cut = restrict(wall, partial, mode="projection")
    np.testing.assert_allclose(cut.points, [[4.0, 0.0], [6.0, 0.0]])
    np.testing.assert_array_equal(cut.scan_indices, [100, 300])  # nearer vertex each
    assert restricted_hausdorff(wall, partial) == pytest.approx(4.0, abs=1e-3)
    assert restricted_hausdorff(wall, partial, mode="projection") == pytest.approx(0.05)


def test_projection_beyond_the_ends_and_collapse_to_a_point():
    wall = [[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]]
    longer = [[-1.0, 0.1], [5.0, 0.1]]
    np.testing.assert_allclose(restrict(wall, longer, mode="projection").points, wall)
    point = restrict(wall, [[3.0, 1.0]], mode="projection")
    np.testing.assert_allclose(point.points, [[3.0, 0.0]])
    assert restricted_hausdorff(wall, [[3.0, 1.0]], mode="projection") == pytest.approx(1.0)


def test_restrict_leaves_degenerate_inputs_alone():
    wall = Polyline([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    assert restrict(wall, np.empty((0, 2))) is wall
    single = Polyline([[5.0, 5.0]])
    assert restrict(single, wall) is single
    with pytest.raises(ValueError, match="mode must be one of"):
        restrict(wall, wall, mode="nearest")
    with pytest.raises(ValueError, match="mode must be one of"):
        restricted_hausdorff(wall, wall, mode="nearest")


def test_restriction_makes_partial_views_comparable():
    # Fig. 3 of the paper: the unseen part of P0 dominates the plain Hausdorff distance.
    points0, points1 = _partial_view(np.random.default_rng(123))
    plain = hausdorff(points0, points1)
    assert restricted_hausdorff(points0, points1, mode="projection") < 0.06
    assert plain > restricted_hausdorff(points0, points1)


def test_arrays_and_polylines_agree():
    points0, points1 = _partial_view(np.random.default_rng(9))
    assert restricted_hausdorff(Polyline(points0), Polyline(points1)) == pytest.approx(
        restricted_hausdorff(points0, points1), abs=0.0
    )


def _random_pair(seed):
    """Random polylines of 1-8 vertices: unrelated, a noisy copy, a partial copy, a point."""
    rng = np.random.default_rng(seed)
    first = np.cumsum(rng.normal(0.0, 1.0, (int(rng.integers(1, 9)), 2)), axis=0)
    if seed % 5 == 0:
        first = first.round(1)  # exact ties between segments
    kind = seed % 4
    if kind == 0:
        second = np.cumsum(rng.normal(0.0, 1.0, (int(rng.integers(1, 9)), 2)), axis=0)
    elif kind == 1:
        second = first + rng.normal(0.0, 0.03, first.shape)
    elif kind == 2:
        second = first[: max(1, first.shape[0] // 2)] + rng.normal(0.0, 0.03, (1, 2))
    else:
        second = rng.normal(0.0, 1.0, (1, 2))
    return first, second


@pytest.mark.parametrize("seed", range(60))
def test_small_random_pairs_match_the_slow_reference_in_both_modes(seed):
    points0, points1 = _random_pair(seed)
    for a, b in ((points0, points1), (points1, points0)):
        # Restricting to (or restricting) a single point changes nothing (the convention).
        if len(a) >= 2 and len(b) >= 2:
            a_cut, b_cut = _restrict_reference(a, b), _restrict_reference(b, a)
        else:
            a_cut, b_cut = a, b
        vertex = _reference_hausdorff(a_cut, b_cut, 0.002)
        assert restricted_hausdorff(a, b) == pytest.approx(vertex, abs=0.0011 + HAUSDORFF_TOLERANCE)
        if len(a) >= 2 and len(b) >= 2:
            a_cut, b_cut = _projection_reference(a, b), _projection_reference(b, a)
            cut = _reference_hausdorff(a_cut, b_cut, 0.002)
            assert restricted_hausdorff(a, b, mode="projection") == pytest.approx(
                cut, abs=0.0011 + HAUSDORFF_TOLERANCE
            )


def test_long_polylines_match_the_slow_reference():
    rng = np.random.default_rng(3)
    line = np.cumsum(rng.normal(0.0, 0.3, (40, 2)), axis=0)
    noisy = line + rng.normal(0.0, 0.02, line.shape)
    expected = _reference_hausdorff(
        _restrict_reference(line, noisy), _restrict_reference(noisy, line), 0.002
    )
    assert restricted_hausdorff(line, noisy) == pytest.approx(expected, abs=0.0011)


@pytest.mark.parametrize("seed", range(60))
@pytest.mark.parametrize("mode", ["vertex", "projection"])
def test_gate_limit_stops_early_with_the_same_decision(seed, mode):
    first, second = _random_pair(seed)
    p0, p1 = Polyline(first), Polyline(second)
    exact = restricted_hausdorff(p0, p1, mode=mode)
    for gate in (0.01, 0.05, 0.12, 0.5, 2.0):
        limited = restricted_hausdorff(p0, p1, mode, limit=gate)
        assert (limited <= gate) == (exact <= gate)
        if exact <= gate:
            assert limited == exact
        else:
            assert limited <= exact + HAUSDORFF_TOLERANCE


def test_reversed_and_read_only_inputs_give_the_same_distance():
    points0 = np.array([[0.0, 0.0], [1.0, 0.3], [2.0, 0.0], [3.0, 0.5]])
    points1 = points0[1:3] + 0.04
    line = Polyline(points0)  # read-only storage
    reversed_view = line.reversed()  # views of read-only arrays, negative strides
    expected = restricted_hausdorff(points0[::-1].copy(), points1)
    assert restricted_hausdorff(reversed_view, points1) == expected
    assert restricted_hausdorff(line, points1) == restricted_hausdorff(points0.copy(), points1)


@pytest.mark.parametrize("mode", ["vertex", "projection"])
def test_two_sets_are_measured_pair_by_pair(mode):
    rng = np.random.default_rng(9)
    first = [np.cumsum(rng.normal(0.0, 0.5, (int(rng.integers(0, 6)), 2)), axis=0)
             for _ in range(12)]
    second = [line + rng.normal(0.0, 0.1, 2) if len(line) and k % 3 else
              rng.normal(0.0, 1.0, (int(rng.integers(1, 4)), 2)) for k, line in enumerate(first)]
    sets = PackedPolylines(first), PackedPolylines(second)
    for limit in (math.inf, 0.2):
        together = restricted_hausdorff(*sets, mode, limit=limit)
        assert together.tolist() == [restricted_hausdorff(a, b, mode, limit=limit)
                                     for a, b in zip(first, second, strict=True)]
    assert hausdorff(*sets).tolist() == [hausdorff(a, b) for a, b in zip(first, second,
                                                                         strict=True)]
    with pytest.raises(ValueError, match="as long"):
        restricted_hausdorff(sets[0], PackedPolylines(second[:3]))


def test_pairs_index_two_sets_of_any_length():
    """``pairs=(i, j)``: ``p0[i]`` against ``p1[j]``, each as the single-polyline call gives it."""
    rng = np.random.default_rng(11)
    first = [np.cumsum(rng.normal(0.0, 0.5, (int(rng.integers(1, 6)), 2)), axis=0)
             for _ in range(7)]
    second = [np.cumsum(rng.normal(0.0, 0.5, (int(rng.integers(1, 6)), 2)), axis=0)
              for _ in range(4)]
    pairs = np.array([[6, 0], [0, 3], [0, 3], [2, 1], [5, 2]])
    sets = PackedPolylines(first), PackedPolylines(second)
    for mode in ("vertex", "projection"):
        assert restricted_hausdorff(*sets, mode, pairs=pairs).tolist() == [
            restricted_hausdorff(first[i], second[j], mode) for i, j in pairs.tolist()
        ]
    distances = hausdorff(*sets, pairs=pairs)
    np.testing.assert_allclose(distances, [_reference_hausdorff(first[i], second[j])
                                           for i, j in pairs.tolist()], atol=2e-3)
    assert hausdorff(*sets, pairs=np.empty((0, 2), int)).shape == (0,)
    for bad in ([[7, 0]], [[0, 4]], [[-1, 0]]):
        with pytest.raises(ValueError, match="pairs must index"):
            restricted_hausdorff(*sets, pairs=bad)
    with pytest.raises(ValueError, match="pairs index two PackedPolylines"):
        hausdorff(first[0], second[0], pairs=[[0, 0]])
