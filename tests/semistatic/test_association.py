"""Ordered association (paper eq. 4-5): hand-made cases, ordering, gate, degenerate input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semistatic.association import FAR_COST, associate, box_gap, orient_ccw, sort_ccw
from semistatic.extraction import extract_polylines
from semistatic.hausdorff import restricted_hausdorff
from semistatic.polyline import PackedPolylines, Polyline
from semistatic.similarity import similarity
from tests.semistatic.conftest import NASTY_POLYLINES
from tests.semistatic.synthetic import box, cast_scan, scene, wall

GATE = 0.12
ORIGIN = (0.0, 0.0, 0.0)

# Three objects around the origin, in counter-clockwise (scan) order: right, ahead, left.
RIGHT_BOX = np.array([[1.0, -2.0], [1.5, -2.0], [1.5, -1.5]])
AHEAD_WALL = np.array([[3.0, -1.0], [3.0, 1.0]])
LEFT_CORNER = np.array([[1.5, 1.5], [1.5, 2.0], [1.0, 2.0]])
OBJECTS = [RIGHT_BOX, AHEAD_WALL, LEFT_CORNER]


def shifted(points, dx=0.02, dy=-0.01):
    return np.asarray(points, dtype=float) + np.array([dx, dy])


def test_one_to_one_in_order():
    scans = [shifted(points) for points in OBJECTS]
    assert associate(scans, OBJECTS, GATE) == [(0, 0), (1, 1), (2, 2)]


def test_distances_are_the_restricted_hausdorff_distances_under_the_gate():
    scans = [shifted(points) for points in OBJECTS]
    pairs = associate(scans, OBJECTS, GATE)
    assert pairs == [(0, 0), (1, 1), (2, 2)]
    assert len(pairs.distances) == len(pairs)
    for (i, j), distance in zip(pairs, pairs.distances, strict=True):
        assert distance == pytest.approx(restricted_hausdorff(scans[i], OBJECTS[j]))
        assert distance <= GATE


def test_split_scan_polyline_is_many_to_one_in_vertex_mode():
    # A box seen as one L-shaped map polyline; the scan broke it at the corner, so the
    # side starts one beam after it.
    corner = np.array([[2.0, -0.5], [2.0, 0.5], [1.4, 0.5]])
    front, side = shifted(corner[:2]), shifted([[1.95, 0.5], [1.4, 0.5]])
    assert associate([front, side], [corner], GATE) == [(0, 0), (1, 0)]


def test_split_wall_is_many_to_one_in_projection_mode():
    wall_line = np.array([[3.0, -2.0], [3.0, 2.0]])
    lower, upper = [[3.02, -1.9], [3.02, -0.3]], [[3.02, 0.3], [3.02, 1.9]]
    assert associate([lower, upper], [wall_line], GATE, mode="projection") == [(0, 0), (1, 0)]
    # The paper's vertex restriction cannot shorten a two-vertex wall (docs/design.md#detail-5).
    assert associate([lower, upper], [wall_line], GATE, mode="vertex") == []


def test_one_scan_polyline_covering_two_map_polylines_is_one_to_many():
    # The map holds the two faces of a box from two partial views; now the scan sees both.
    corner = np.array([[2.0, -0.5], [2.0, 0.5], [1.4, 0.5]])
    faces = [[[2.0, -0.5], [2.0, 0.45]], [[1.95, 0.5], [1.4, 0.5]]]
    assert associate([shifted(corner)], faces, GATE) == [(0, 0), (0, 1)]


def test_far_polyline_is_rejected_by_the_gate():
    scans = [shifted(RIGHT_BOX), shifted(AHEAD_WALL, dx=0.5), shifted(LEFT_CORNER)]
    assert associate(scans, OBJECTS, GATE) == [(0, 0), (2, 2)]


def test_new_object_between_known_ones_is_left_unassociated():
    newcomer = np.array([[2.0, 0.9], [2.0, 1.2]])
    scans = [shifted(RIGHT_BOX), shifted(AHEAD_WALL), newcomer, shifted(LEFT_CORNER)]
    assert associate(scans, OBJECTS, GATE) == [(0, 0), (1, 1), (3, 2)]


@pytest.mark.parametrize(("scans", "maps"), [([], OBJECTS), (OBJECTS, []), ([], [])])
def test_empty_lists_give_no_pairs(scans, maps):
    assert associate(scans, maps, GATE) == []
    assert associate(scans, maps, GATE, viewpoint=ORIGIN) == []


def test_viewpoint_sorts_the_map_and_indices_refer_to_the_input_list():
    shuffled = [OBJECTS[2], OBJECTS[0], OBJECTS[1]]
    scans = [shifted(points) for points in OBJECTS]
    assert associate(scans, shuffled, GATE, viewpoint=ORIGIN) == [(0, 1), (1, 2), (2, 0)]
    # Without the viewpoint the given order is taken as the counter-clockwise order.
    assert len(associate(scans, shuffled, GATE)) < 3


def test_map_polyline_seen_from_its_other_side_is_still_associated():
    reversed_map = [points[::-1] for points in OBJECTS]
    scans = [shifted(points) for points in OBJECTS]
    assert associate(scans, reversed_map, GATE, viewpoint=ORIGIN) == [(0, 0), (1, 1), (2, 2)]


def test_sort_ccw_matches_the_scan_order_of_a_scan_from_that_viewpoint():
    rng = np.random.default_rng(3)
    world = scene(
        box((3.0, -2.0), 0.6, 0.4, 0.3),
        wall((4.0, -0.5), (4.0, 0.8)),
        box((1.0, 2.5), 0.5, 0.5),
        wall((-2.0, 2.0), (-2.5, 0.0)),
        box((-1.5, -2.0), 0.4, 0.8, 1.0),
    )
    for _ in range(5):
        pose = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-3, 3)])
        lines = [line.transformed(pose) for line in extract_polylines(cast_scan(world, pose))]
        assert len(lines) >= 3
        order = rng.permutation(len(lines))
        shuffled = [lines[k] for k in order]
        recovered = [order[k] for k in sort_ccw(shuffled, pose)]
        assert recovered == list(range(len(lines)))


def test_sort_ccw_puts_the_cut_behind_the_sensor():
    behind = [[-2.0, -0.5], [-2.0, 0.5]]  # straddles +-pi as seen from the origin
    right, left = [[1.0, -2.0], [2.0, -2.0]], [[2.0, 2.0], [1.0, 2.0]]
    assert sort_ccw([left, right, behind], ORIGIN).tolist() == [2, 1, 0]
    assert sort_ccw([left, right, behind], (0.0, 0.0, np.pi)).tolist() == [0, 2, 1]
    assert sort_ccw([], ORIGIN).tolist() == []


def test_orient_ccw_reverses_clockwise_polylines_only():
    line = Polyline([[2.0, 1.0], [2.0, -1.0]], scan_indices=[5, 9])
    flipped = orient_ccw(line, ORIGIN)
    assert flipped.points.tolist() == [[2.0, -1.0], [2.0, 1.0]]
    assert flipped.scan_indices.tolist() == [9, 5]
    assert orient_ccw(flipped, ORIGIN) is flipped


def test_pairs_that_cannot_pass_the_gate_are_pruned_whatever_their_shape():
    far = AHEAD_WALL + np.array([5.0, 0.0])
    assert similarity(AHEAD_WALL, far) == 0.0  # the same shape: only the gate tells them apart
    assert associate([AHEAD_WALL], [AHEAD_WALL, far], GATE) == [(0, 0)]
    assert associate([AHEAD_WALL], [far, AHEAD_WALL], GATE) == [(0, 1)]
    assert associate([AHEAD_WALL], [far], GATE) == []


def test_pruning_is_sound_box_gap_is_a_lower_bound_of_the_restricted_hausdorff():
    rng = np.random.default_rng(11)
    for _ in range(200):
        p0 = rng.uniform(-2, 2, (rng.integers(1, 5), 2))
        p1 = rng.uniform(-2, 2, (rng.integers(1, 5), 2)) + rng.uniform(-3, 3, 2)
        boxes = PackedPolylines([p0, p1]).boxes
        gap = box_gap(boxes, 0, boxes, 1)
        for mode in ("vertex", "projection"):
            assert gap <= restricted_hausdorff(p0, p1, mode=mode) + 1e-9


def test_far_cost_dominates_plausible_similarities():
    corner = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
    long_wall = [[0.0, 0.0], [40.0, 0.0]]
    assert similarity(corner, long_wall) < FAR_COST / 1e3


@pytest.mark.parametrize("name", sorted(NASTY_POLYLINES))
def test_nasty_polylines_go_through_associate(name):
    nasty = NASTY_POLYLINES[name]
    for scans, maps in (([nasty], OBJECTS), (OBJECTS, [nasty]), ([nasty], [nasty])):
        for mode in ("vertex", "projection"):
            pairs = associate(scans, maps, GATE, viewpoint=ORIGIN, mode=mode)
            for (i, j), distance in zip(pairs, pairs.distances, strict=True):
                assert 0 <= i < len(scans)
                assert 0 <= j < len(maps)
                assert distance <= GATE


def test_one_vertex_polylines_at_the_same_place_associate():
    point = [[1.0, 1.0]]
    assert associate([point], [point], GATE) == [(0, 0)]
    assert associate([point], [[[3.0, 1.0]]], GATE) == []


def test_two_vertex_polylines_associate():
    assert associate([[[2.0, 0.0], [2.0, 0.5]]], [[[2.01, 0.0], [2.01, 0.5]]], GATE) == [(0, 0)]


def test_invalid_gate_and_viewpoint_are_rejected():
    with pytest.raises(ValueError, match="gate"):
        associate(OBJECTS, OBJECTS, 0.0)
    with pytest.raises(ValueError, match="viewpoint"):
        associate(OBJECTS, OBJECTS, GATE, viewpoint=(0.0,))


coordinates = st.integers(min_value=-300, max_value=300).map(lambda value: value / 100.0)
polylines = st.lists(st.tuples(coordinates, coordinates), min_size=0, max_size=5).map(
    lambda rows: np.array(rows, dtype=float).reshape(-1, 2)
)


@settings(max_examples=60, deadline=None)
@given(scans=st.lists(polylines, max_size=5), maps=st.lists(polylines, max_size=5))
def test_pairs_are_monotone_valid_and_under_the_gate(scans, maps):
    pairs = associate(scans, maps, 0.5)
    assert pairs == sorted(pairs)
    assert [j for _, j in pairs] == sorted(j for _, j in pairs)  # the path is monotone
    assert len(set(pairs)) == len(pairs)
    for (i, j), distance in zip(pairs, pairs.distances, strict=True):
        assert 0 <= i < len(scans)
        assert 0 <= j < len(maps)
        assert distance == pytest.approx(restricted_hausdorff(scans[i], maps[j]))
        assert distance <= 0.5
