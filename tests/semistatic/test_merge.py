"""Merge (paper Sec. 3.4, docs/design.md#detail-7)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from semistatic.hausdorff import hausdorff
from semistatic.merge import END_TOLERANCE_FACTOR, merge, project_onto, transfer_weights
from semistatic.polyline import PackedPolylines, Polyline
from tests.semistatic.conftest import NASTY_POLYLINES

EPSILON = 0.03
GATE = 0.12
WALL = np.array([[0.0, 0.0], [3.0, 0.0]])
BOX = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.6]])  # two faces of a box


def merge_pair(map_polyline, scan_polyline, epsilon, *, map_weight=1.0, end_tolerance=None):
    """Merge one scan polyline into one map polyline with one weight for the whole of it."""
    edges = max(len(map_polyline) - 1, 0)
    ((line, _),) = merge([map_polyline], [[scan_polyline]], epsilon,
                         edge_weights=np.full(edges, float(map_weight)), end_weights=[map_weight],
                         end_tolerance=end_tolerance)
    return line


def test_merging_an_identical_observation_changes_nothing():
    for shape in (WALL, BOX):
        merged = merge_pair(shape, shape, EPSILON, map_weight=4.0)
        np.testing.assert_allclose(merged.points, shape, atol=1e-12)


def test_scan_that_reaches_farther_extends_the_map():
    merged = merge_pair(WALL, [[2.0, 0.0], [4.0, 0.0]], EPSILON)
    np.testing.assert_allclose(merged.points, [[0.0, 0.0], [4.0, 0.0]], atol=1e-12)
    merged = merge_pair(WALL, [[-1.0, 0.0], [1.0, 0.0]], EPSILON)
    np.testing.assert_allclose(merged.points, [[-1.0, 0.0], [3.0, 0.0]], atol=1e-12)


def test_scan_that_sees_around_a_corner_adds_the_new_face():
    merged = merge_pair(BOX[:2], BOX, EPSILON)
    np.testing.assert_allclose(merged.points, BOX, atol=1e-12)


def test_partial_view_leaves_the_ends_alone():
    merged = merge_pair(BOX, [[0.3, 0.02], [0.7, 0.02]], EPSILON, map_weight=1.0)
    np.testing.assert_allclose(merged.points[[0, -1]], BOX[[0, -1]])
    assert len(merged) == 3


def test_scan_direction_does_not_matter():
    scan = np.array([[0.1, 0.02], [1.02, 0.01], [1.01, 0.7]])
    forward = merge_pair(BOX, scan, EPSILON, map_weight=2.0)
    backward = merge_pair(BOX, scan[::-1], EPSILON, map_weight=2.0)
    np.testing.assert_allclose(forward.points, backward.points, atol=1e-12)
    # The map's direction is kept.
    assert forward.points[0, 0] < forward.points[-1, 1]


@pytest.mark.parametrize("weight", [0.0, 1.0, 9.0])
def test_map_moves_toward_the_scan_by_one_over_one_plus_weight(weight):
    merged = merge_pair(WALL, WALL + np.array([0.0, 0.02]), EPSILON, map_weight=weight)
    np.testing.assert_allclose(merged.points[:, 1], 0.02 / (1.0 + weight), atol=1e-12)


def test_ends_within_tolerance_are_averaged_in_both_directions():
    # Alternate observations 4 cm too long and 4 cm too short: no ratchet either way.
    line = Polyline(WALL)
    for k in range(40):
        end = 3.04 if k % 2 == 0 else 2.96
        line = merge_pair(line, [[0.0, 0.0], [end, 0.0]], EPSILON, map_weight=min(k + 1, 30))
    assert line.points[-1, 0] == pytest.approx(3.0, abs=0.01)
    assert END_TOLERANCE_FACTOR * EPSILON > 0.04


def test_repeated_noisy_observations_converge_without_growing():
    rng = np.random.default_rng(5)
    line = Polyline(BOX)
    for k in range(200):
        dense = np.concatenate(
            (np.linspace(BOX[0], BOX[1], 40), np.linspace(BOX[1], BOX[2], 25)[1:])
        )
        noisy = dense + rng.normal(0.0, 0.01, dense.shape)
        keep = shapely.get_coordinates(
            shapely.simplify(shapely.LineString(noisy), EPSILON, preserve_topology=False)
        )
        line = merge_pair(line, keep, EPSILON, map_weight=min(k + 1, 30))
        assert len(line) <= 2 * len(BOX)
    assert hausdorff(line, BOX) < 0.02


def test_merged_scan_indices_are_the_vertex_order():
    merged = merge_pair(Polyline(WALL, scan_indices=[7, 9]), [[2.0, 0.0], [4.0, 0.0]], EPSILON)
    assert merged.scan_indices.tolist() == list(range(len(merged)))


def test_degenerate_inputs():
    empty = np.empty((0, 2))
    assert merge_pair(WALL, empty, EPSILON).points.tolist() == WALL.tolist()
    line = Polyline(WALL)
    assert merge_pair(line, empty, EPSILON) is line
    assert merge_pair(empty, WALL, EPSILON).points.tolist() == WALL.tolist()
    # One vertex: a point far beyond an end extends, a point near the middle does nothing.
    assert merge_pair(WALL, [[4.0, 0.0]], EPSILON).points.tolist() == [[0.0, 0.0], [4.0, 0.0]]
    assert merge_pair(WALL, [[1.5, 0.05]], EPSILON).points.tolist() == WALL.tolist()
    # A one-vertex map polyline: the scan gives the shape, the point may extend it.
    assert merge_pair([[1.5, 0.0]], WALL, EPSILON).points.tolist() == WALL.tolist()
    assert merge_pair([[-1.0, 0.0]], WALL, EPSILON).points.tolist() == [[-1.0, 0.0], [3.0, 0.0]]
    np.testing.assert_allclose(merge_pair([[0.0, 0.0]], [[0.0, 0.2]], EPSILON).points, [[0.0, 0.1]])
    # Two vertices each.
    assert len(merge_pair([[0.0, 0.0], [1.0, 0.0]], [[0.5, 0.01], [1.5, 0.01]], EPSILON)) == 2


@pytest.mark.parametrize("name", sorted(NASTY_POLYLINES))
def test_nasty_polylines_go_through_merge(name):
    nasty = NASTY_POLYLINES[name]
    for old, new in ((nasty, BOX), (BOX, nasty), (nasty, nasty)):
        merged = merge_pair(old, new, EPSILON)
        assert np.all(np.isfinite(merged.points))


def test_invalid_arguments_are_rejected():
    with pytest.raises(ValueError, match="epsilon"):
        merge_pair(WALL, WALL, 0.0)
    with pytest.raises(ValueError, match="edge_weights must be >= 0"):
        merge_pair(WALL, WALL, EPSILON, map_weight=-1.0)
    with pytest.raises(ValueError, match="end_tolerance"):
        merge_pair(WALL, WALL, EPSILON, end_tolerance=-1.0)
    with pytest.raises(ValueError, match="two distinct vertices"):
        project_onto([[0.0, 0.0]], [[1.0, 1.0], [1.0, 1.0]])


def test_projection_matches_shapely():
    rng = np.random.default_rng(2)
    for _ in range(50):
        vertices = np.cumsum(rng.uniform(-1.0, 1.0, (rng.integers(2, 8), 2)), axis=0)
        points = rng.uniform(-3.0, 3.0, (rng.integers(1, 12), 2))
        found = project_onto(points, vertices)
        line = shapely.LineString(vertices)
        for k, point in enumerate(points):
            assert found.distance[k] == pytest.approx(line.distance(shapely.Point(point)))
            assert found.arc[k] == pytest.approx(line.project(shapely.Point(point)), abs=1e-9)
            foot = line.interpolate(line.project(shapely.Point(point)))
            np.testing.assert_allclose(found.foot[k], [foot.x, foot.y], atol=1e-9)


def test_before_and_after_flags():
    found = project_onto([[-1.0, 0.5], [4.0, 0.0], [1.0, 1.0], [3.0, 1.0], [0.0, 0.0]], WALL)
    assert found.before.tolist() == [True, False, False, False, True]
    assert found.after.tolist() == [False, True, False, True, False]


# Centimetre grid: repeated, collinear and folded vertices come up often, and no
# denormal lengths (which say nothing about the merge).
coordinates = st.integers(min_value=-500, max_value=500).map(lambda value: value / 100.0)
polylines = st.lists(st.tuples(coordinates, coordinates), min_size=0, max_size=6).map(
    lambda rows: np.array(rows, dtype=float).reshape(-1, 2)
)


@settings(max_examples=60, deadline=None)
@given(old=polylines, new=polylines, weight=st.floats(0.0, 50.0))
def test_merge_always_gives_a_finite_polyline_no_longer_than_its_inputs(old, new, weight):
    merged = merge_pair(old, new, EPSILON, map_weight=weight)
    assert np.all(np.isfinite(merged.points))
    assert len(merged) <= len(old) + len(new)
    if len(old) or len(new):
        assert len(merged) >= 1
    if len(new) == 0:
        np.testing.assert_array_equal(merged.points, old)


@settings(max_examples=60, deadline=None)
@given(line=polylines)
def test_merging_a_polyline_with_itself_keeps_its_simplified_shape(line):
    merged = merge_pair(line, line, EPSILON, map_weight=3.0)
    if len(line) >= 2 and Polyline(line).length > 0.0:
        assert hausdorff(merged, line) <= EPSILON + 1e-9


def test_a_moved_box_does_not_draw_a_diagonal_across_its_new_footprint():
    # sim1's carton_aisle: the old box's right face (x = 3.3, with a bit of its top face)
    # ends up hidden inside the new footprint after the box moves 0.5 m along +x; the new
    # top face, seen again and again, continues past the old corner.
    old_face = [[3.157, -0.423], [3.293, -0.449], [3.294, -0.92]]
    footprint = shapely.box(3.2, -0.91, 3.8, -0.41)
    rng = np.random.default_rng(0)
    line = Polyline(old_face)
    for hits in range(27, 127):
        end = rng.uniform(3.5, 3.8)
        top = np.array([[3.2, -0.41], [end, -0.41]]) + rng.normal(0.0, 0.005, (2, 2))
        line = merge_pair(line, top, epsilon=0.03, map_weight=hits)
    curve = shapely.LineString(line.points)
    assert curve.intersection(footprint.buffer(-0.02)).length == 0.0  # no edge across it
    visible_top = shapely.LineString([(3.2, -0.41), (3.8, -0.41)])
    assert shapely.hausdorff_distance(curve, visible_top) < 0.05


def test_an_end_the_scan_contradicts_is_cut_and_the_scan_extends_the_map():
    corner = [[0.0, 0.0], [1.0, 0.0], [1.0, -1.0]]  # a wall turning down at x = 1
    straight_on = [[0.5, 0.0], [2.0, 0.0]]  # the scan sees the wall go on instead
    merged = merge_pair(corner, straight_on, epsilon=0.03, map_weight=0.0)
    np.testing.assert_allclose(merged.points, [[0.0, 0.0], [2.0, 0.0]], atol=1e-12)
    # a partial view that agrees everywhere leaves the corner alone
    assert len(merge_pair(corner, [[0.2, 0.01], [0.8, 0.01]], epsilon=0.03)) == 3


def _farthest_from(outline: shapely.Geometry, line: Polyline) -> float:
    """Return the largest distance (m) of a point of ``line`` from ``outline`` (shapely)."""
    probes = shapely.get_coordinates(shapely.segmentize(shapely.LineString(line.points), 0.005))
    return float(shapely.distance(outline, shapely.points(probes)).max())


# sim2's carton_bend, lap 1: its first views, from 3 m away along its front face, saw
# its top face at grazing incidence and cut the corner between them; every later view
# saw the corner, yet the map, standing for hundreds of observations, kept the chord.
BOX_OUTLINE = shapely.box(0.0, -0.5, 0.5, 0.0).exterior  # the corner at the origin
CORNER = shapely.Point(0.0, 0.0)


def test_a_map_edge_cutting_a_corner_gives_way_to_the_corner_the_scans_see():
    chord = Polyline([[0.0, -0.5], [0.0, -0.07], [0.14, 0.0], [0.5, 0.0]])
    assert shapely.distance(CORNER, shapely.LineString(chord.points)) > 2 * EPSILON
    line = chord
    rng = np.random.default_rng(1)
    for hits in range(200, 210):
        seen = np.array([[0.0, -0.45], [0.0, 0.0], [0.45, 0.0]])
        line = merge_pair(line, seen + rng.normal(0.0, 0.003, seen.shape), EPSILON,
                     map_weight=float(hits))
    assert shapely.distance(CORNER, shapely.LineString(line.points)) < 0.01
    assert _farthest_from(BOX_OUTLINE, line) < 0.01


# Per-edge weights (issue 10, Build item 4): two faces of a box, the first seen often.
FACE_SEEN_OFTEN = np.array([[0.0, 0.0], [1.0, 0.0]])
TWO_FACES = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, -0.6]])


def _noisy_view(rng: np.random.Generator, outline: np.ndarray, sigma: float) -> np.ndarray:
    """Return a Douglas-Peucker polyline of dense noisy readings of ``outline`` (shapely)."""
    dense = shapely.get_coordinates(shapely.segmentize(shapely.LineString(outline), 0.025))
    noisy = dense + rng.normal(0.0, sigma, dense.shape)
    return shapely.get_coordinates(
        shapely.simplify(shapely.LineString(noisy), EPSILON, preserve_topology=False)
    )


@pytest.mark.parametrize("seed", range(3))
def test_a_face_seen_late_converges_though_the_other_face_weighs_200_views(seed):
    rng = np.random.default_rng(seed)
    line, weights = Polyline(FACE_SEEN_OFTEN + np.array([0.0, 0.003])), np.array([200.0])
    # The second face's first view is bent 5 cm out (grazing incidence, a few readings).
    first = [[0.0, 0.0], [1.0, 0.0], [1.05, -0.3], [1.0, -0.6]]
    one_weight = merge_pair(line, first, EPSILON, map_weight=200.0)
    (line, weights), = merge([line], [[first]], EPSILON, edge_weights=weights,
                                      end_weights=[200.0])
    truth = shapely.LineString(TWO_FACES)
    assert shapely.hausdorff_distance(shapely.LineString(line.points), truth) > 0.045
    for hits in range(201, 221):
        view = _noisy_view(rng, TWO_FACES, 0.005)
        one_weight = merge_pair(one_weight, view, EPSILON, map_weight=float(hits))
        (line, weights), = merge([line], [[view]], EPSILON, edge_weights=weights,
                                          end_weights=[float(hits)])
    # Each edge weighs the views along it: the new face follows its 20 views...
    assert _farthest_from(truth, line) < 0.008
    np.testing.assert_allclose(weights, [220.0, 21.0], atol=1.0)
    # ... the face seen 220 times stays where they put it (3 mm off, noise 5 mm) ...
    seen_often = shapely.LineString(FACE_SEEN_OFTEN)
    probes = shapely.points(shapely.get_coordinates(
        shapely.segmentize(shapely.LineString(line.points[:2]), 0.01)))
    assert shapely.distance(seen_often, probes).max() < 0.006
    # ... while one weight for the whole polyline keeps the first view's bend.
    assert _farthest_from(truth, one_weight) > 0.04


def test_a_chord_bridging_a_gap_weighs_nothing_and_gives_way_to_the_corner():
    # sim1's carton_aisle in lap 1: an observation holds the box's right face and, past a
    # gap, two readings of its top face; the map extends to them across the gap.
    right_face = Polyline([[1.0, -0.05], [1.0, -0.6]])
    parts = [[[0.70, 0.0], [0.74, 0.0]], [[1.0, -0.06], [1.0, -0.6]]]
    (line, weights), = merge([right_face], [parts], EPSILON, edge_weights=[50.0],
                                      end_weights=[50.0])
    assert len(line) == 3
    assert weights[0] < 0.2 * weights[1]  # the bridge: hardly seen
    outline = shapely.LineString([[0.7, 0.0], [1.0, 0.0], [1.0, -0.6]])
    assert _farthest_from(outline, line) > 0.03  # the chord cuts the corner
    one_weight = line
    rng = np.random.default_rng(2)
    for hits in range(51, 56):
        view = np.array([[0.7, 0.0], [1.0, 0.0], [1.0, -0.6]]) + rng.normal(0.0, 0.003, (3, 2))
        one_weight = merge_pair(one_weight, view, EPSILON, map_weight=float(hits))
        (line, weights), = merge([line], [[view]], EPSILON, edge_weights=weights,
                                          end_weights=[float(hits)])
    assert _farthest_from(outline, line) < 0.015  # the corner, within noise
    assert _farthest_from(outline, one_weight) > 0.03  # the chord's weight: the map's


def test_transfer_weights_matches_hand_computed_pieces():
    box = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
    # Along face 1, across the corner (9.5 cm off), along face 2, beyond the end, away.
    piece = [[0.2, 0.01], [0.8, 0.0], [1.01, 0.3], [1.0, 0.7], [1.0, 1.6], [3.0, 1.6]]
    np.testing.assert_array_equal(
        transfer_weights(piece, box, [3.0, 5.0], tolerance=0.05), [3.0, 0.0, 5.0, 0.0, 0.0]
    )
    with pytest.raises(ValueError, match="one weight per source edge"):
        transfer_weights(piece, box, [3.0], tolerance=0.05)


def test_merge_checks_its_weights():
    with pytest.raises(ValueError, match="one value per edge"):
        merge([BOX], [[BOX]], EPSILON, edge_weights=[1.0])
    with pytest.raises(ValueError, match=">= 0"):
        merge([BOX], [[BOX]], EPSILON, edge_weights=[1.0, -1.0])
    with pytest.raises(ValueError, match=">= 0"):
        merge([BOX], [[BOX]], EPSILON, end_weights=[np.nan])
    with pytest.raises(ValueError, match="one value per map polyline"):
        merge([BOX], [[BOX]], EPSILON, end_weights=[1.0, 2.0])
    with pytest.raises(ValueError, match="one observation per map polyline"):
        merge([BOX, WALL], [[BOX]], EPSILON)
    # By default every edge and end weighs one observation.
    seen = BOX + np.array([0.0, 0.02])
    ((line, weights),) = merge([BOX], [[seen]], EPSILON)
    ((ones, one_weights),) = merge([BOX], [[seen]], EPSILON, edge_weights=[1.0, 1.0],
                                   end_weights=[1.0])
    np.testing.assert_array_equal(line.points, ones.points)
    np.testing.assert_allclose(weights, [2.0, 2.0])
    np.testing.assert_array_equal(weights, one_weights)


def test_many_map_polylines_merge_as_each_alone():
    rng = np.random.default_rng(7)
    maps = [WALL, BOX, [[5.0, 5.0]], BOX + 2.0, WALL - 1.0]
    observations = [[WALL + 0.02], [BOX[:2] + 0.01, BOX[1:] - 0.01], [[[5.0, 5.1]]], [],
                    [WALL + rng.normal(0.0, 0.01, WALL.shape) - 1.0]]
    edge_weights = [[2.0], [1.0, 7.0], [], [1.0, 1.0], [5.0]]
    end_weights = [2.0, 4.0, 3.0, 1.0, 5.0]
    merged = merge(maps, observations, EPSILON, edge_weights=np.concatenate(edge_weights),
                   end_weights=end_weights)
    for k in range(len(maps)):
        ((alone, alone_weights),) = merge([maps[k]], [observations[k]], EPSILON,
                                          edge_weights=edge_weights[k],
                                          end_weights=[end_weights[k]])
        np.testing.assert_array_equal(merged[k][0].points, alone.points)
        np.testing.assert_array_equal(merged[k][1], alone_weights)
    # An observation without vertices leaves its map polyline and weights as they were.
    np.testing.assert_array_equal(merged[3][0].points, BOX + 2.0)
    np.testing.assert_array_equal(merged[3][1], [1.0, 1.0])


def test_flat_observations_with_counts_merge_as_the_nested_ones():
    """``counts`` groups one flat (packed) sequence; each map polyline merges as alone."""
    maps = [WALL, BOX, [[5.0, 5.0]], BOX + 2.0]
    nested = [[WALL + 0.02], [BOX[:2] + 0.01, BOX[1:] - 0.01], [[[5.0, 5.1]]], []]
    flat = PackedPolylines([part for parts in nested for part in parts])
    for k, parts in enumerate(nested):
        ((alone, alone_weights),) = merge([maps[k]], [parts], EPSILON)
        (line, weights) = merge(maps, flat, EPSILON, counts=[1, 2, 1, 0])[k]
        np.testing.assert_array_equal(line.points, alone.points)
        np.testing.assert_array_equal(weights, alone_weights)
    for counts in ([1, 2, 1], [1, 2, 1, 1], [1, 2.5, 0.5, 0], [2, 2, 1, -1]):
        with pytest.raises(ValueError, match=r"counts|one observation per map polyline"):
            merge(maps, flat, EPSILON, counts=counts)
