"""Join (paper Sec. 3.4, docs/design.md#detail-8)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components

from semistatic.hausdorff import restricted_hausdorff
from semistatic.join import MIN_OVERLAP, merge_group, overlapping_groups
from semistatic.polyline import PackedPolylines, Polyline
from tests.semistatic.conftest import NASTY_POLYLINES

EPSILON = 0.03
GATE = 0.12
WALL = np.array([[0.0, 0.0], [3.0, 0.0]])
BOX = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.6]])  # two faces of a box
# Centimetre grid: repeated, collinear and folded vertices come up often.
coordinates = st.integers(min_value=-500, max_value=500).map(lambda value: value / 100.0)
polylines = st.lists(st.tuples(coordinates, coordinates), min_size=0, max_size=6).map(
    lambda rows: np.array(rows, dtype=float).reshape(-1, 2)
)


def join(lines, gate, epsilon, mode="vertex", *, weights=None, candidates=None):
    """Join as the mapper does: the groups, each merged; the others as they are."""
    lines = PackedPolylines(lines)
    changed = np.ones(len(lines), dtype=bool)
    if candidates is not None:
        changed = np.isin(np.arange(len(lines)), candidates)
    weights = [1.0] * len(lines) if weights is None else weights
    groups = overlapping_groups(lines, changed, gate, mode)
    joined = {members[0]: (merge_group(lines, weights, members, epsilon), tuple(members))
              for members in groups}
    grouped = {k for members in groups for k in members}
    return [joined.get(k, (line, (k,))) for k, line in enumerate(lines)
            if k in joined or k not in grouped]


def overlaps(p0, p1, gate, mode="vertex"):
    """Whether two polylines overlap: the groups of the pair alone."""
    return overlapping_groups([p0, p1], [True, True], gate, mode) == [[0, 1]]


def reference_overlaps(p0, p1, gate, mode):
    """docs/design.md#detail-8 for one pair, extents by GEOS linear referencing."""
    def distinct(points):
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        keep = np.concatenate(([True], np.hypot(*np.diff(points, axis=0).T) > 1e-9))
        return points[keep[: len(points)]]

    a, b = distinct(p0), distinct(p1)
    if not (len(a) and len(b)) or restricted_hausdorff(a, b, mode) > gate:
        return False
    if len(a) == 1 and len(b) == 1:
        return bool(np.hypot(*(a[0] - b[0])) <= gate)
    if len(a) == 1 or len(b) == 1:
        point, line = (a, b) if len(a) == 1 else (b, a)
        along = shapely.LineString(line).project(shapely.Point(point[0]))
        return MIN_OVERLAP < along < shapely.LineString(line).length - MIN_OVERLAP

    def span(points, onto):
        along = shapely.line_locate_point(shapely.LineString(onto), shapely.points(points))
        return along.max() - along.min()

    return max(span(b, a), span(a, b)) > MIN_OVERLAP


@pytest.mark.parametrize("name", sorted(NASTY_POLYLINES))
def test_nasty_polylines_go_through_join(name):
    nasty = NASTY_POLYLINES[name]
    groups = join([nasty, BOX, nasty + 10.0], GATE, EPSILON)
    assert sorted(k for _, members in groups for k in members) == [0, 1, 2]


def test_overlaps():
    assert overlaps(WALL, [[2.0, 0.03], [4.0, 0.03]], GATE, mode="projection")
    assert not overlaps(WALL, [[3.05, 0.0], [4.0, 0.0]], GATE, mode="projection")  # a gap
    assert not overlaps(BOX[:2], BOX[1:], GATE)  # two faces meeting at a corner
    assert not overlaps(WALL, WALL + np.array([0.0, 0.5]), GATE)  # parallel, too far
    assert overlaps([[1.0, 0.05]], WALL, GATE, mode="projection")  # a point inside
    # The vertex restriction cannot shorten a two-vertex wall to a point's neighbourhood.
    assert not overlaps([[1.0, 0.05]], WALL, GATE, mode="vertex")
    assert not overlaps([[4.0, 0.0]], WALL, GATE, mode="projection")
    assert overlaps([[1.0, 0.0]], [[1.0, 0.05]], GATE)
    assert not overlaps(np.empty((0, 2)), WALL, GATE)


def test_join_merges_overlapping_pieces_and_keeps_the_rest():
    piece = Polyline([[2.5, 0.02], [4.0, 0.02]])
    far = Polyline([[0.0, 5.0], [1.0, 5.0]])
    groups = join([WALL, far, piece], GATE, EPSILON, mode="projection")
    assert [members for _, members in groups] == [(0, 2), (1,)]
    joined, untouched = groups[0][0], groups[1][0]
    assert untouched is far
    assert joined.points[0, 0] == pytest.approx(0.0)
    assert joined.points[-1, 0] == pytest.approx(4.0)


def test_join_keeps_the_heavier_polyline_in_place():
    shifted = WALL + np.array([0.0, 0.06])
    light_first = join([shifted, WALL], GATE, EPSILON, weights=[1.0, 99.0])
    np.testing.assert_allclose(light_first[0][0].points[:, 1], 0.0006, atol=1e-12)


def test_join_only_tests_pairs_with_a_candidate():
    duplicate = WALL + np.array([0.0, 0.01])
    assert len(join([WALL, duplicate], GATE, EPSILON, candidates=[])) == 2
    assert len(join([WALL, duplicate], GATE, EPSILON, candidates=[1])) == 1


def test_join_chains_groups_and_handles_empty_input():
    pieces = [[[0.0, 0.0], [1.2, 0.0]], [[1.0, 0.01], [2.2, 0.01]], [[2.0, 0.0], [3.0, 0.0]]]
    groups = join(pieces, GATE, EPSILON, mode="projection")
    assert len(groups) == 1
    assert groups[0][1] == (0, 1, 2)
    assert groups[0][0].length == pytest.approx(3.0, abs=0.01)
    assert join([], GATE, EPSILON) == []


@settings(max_examples=40, deadline=None)
@given(lines=st.lists(polylines, max_size=5))
def test_join_partitions_its_input(lines):
    groups = join(lines, GATE, EPSILON, mode="projection")
    members = sorted(k for _, group in groups for k in group)
    assert members == list(range(len(lines)))
    for line, _ in groups:
        assert np.all(np.isfinite(line.points))


def test_overlapping_groups_are_the_components_of_all_overlapping_pairs():
    # Reference: every pair tested by the definition, components by scipy's graph search.
    rng = np.random.default_rng(5)
    for _ in range(20):
        lines = []
        for _ in range(rng.integers(1, 9)):
            start = rng.uniform(0.0, 2.0, 2)
            lines.append(Polyline(start + np.cumsum(rng.uniform(-0.4, 0.4, (3, 2)), axis=0)))
        lines.append(Polyline(lines[0].points + 0.01))  # one sure overlap
        count = len(lines)
        linked = np.array([
            [a != b and reference_overlaps(lines[a].points, lines[b].points, GATE, "projection")
             for b in range(count)] for a in range(count)
        ])
        _, labels = connected_components(linked, directed=False)
        expected = sorted(
            members for label in set(labels.tolist())
            if len(members := np.flatnonzero(labels == label).tolist()) > 1
        )
        assert overlapping_groups(lines, np.ones(count, dtype=bool), GATE, "projection") == (
            expected
        )
        # Unchanged polylines are not tested against each other.
        assert overlapping_groups(lines, np.zeros(count, dtype=bool), GATE, "projection") == []


def test_join_does_not_link_polylines_with_empty_or_far_boxes():
    empty = Polyline(np.empty((0, 2)))
    near = Polyline(WALL + np.array([0.0, 0.05]))
    far = Polyline(WALL + np.array([0.0, 0.5]))
    groups = join([empty, WALL, far, near, empty], GATE, EPSILON, mode="projection")
    assert [members for _, members in groups] == [(0,), (1, 3), (2,), (4,)]
