import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from semistatic.frames import transform_points
from semistatic.polyline import Polyline
from semistatic.similarity import similarity, tangent_function

# Polylines with integer edge lengths (0 allowed: repeated vertices) and free directions.
# Their normalised breakpoints are multiples of 1 / total length, so a grid of
# total0 * total1 * GRID_REFINE cells never straddles a breakpoint of either polyline and
# the midpoint rule integrates both step functions exactly (up to rounding).
GRID_REFINE = 4

edge_lengths = st.lists(st.integers(0, 6), min_size=1, max_size=7).filter(lambda x: sum(x) > 0)
directions = st.floats(-math.pi, math.pi, allow_nan=False)
# An exact U-turn is +pi or -pi depending on rounding (the tangent function is
# discontinuous there); real polylines never fold back exactly, so keep away from it.
U_TURN_MARGIN = 1e-6


def _no_u_turn(lengths, angles):
    proper = [a for n, a in zip(lengths, angles, strict=True) if n > 0]
    turns = np.abs(np.angle(np.exp(1j * np.diff(proper))))
    return bool(np.all(turns < math.pi - U_TURN_MARGIN))


@st.composite
def integer_polylines(draw):
    lengths = draw(edge_lengths)
    angles = draw(st.lists(directions, min_size=len(lengths), max_size=len(lengths)))
    assume(_no_u_turn(lengths, angles))
    steps = np.array(
        [[n * math.cos(a), n * math.sin(a)] for n, a in zip(lengths, angles, strict=True)]
    )
    start = draw(st.tuples(st.floats(-5, 5), st.floats(-5, 5)))
    points = np.vstack(([start], start + np.cumsum(steps, axis=0)))
    return points, lengths, angles


def _tangent_on_grid(points, lengths, grid):
    """T(s) at the grid points by walking the edges (independent of the module)."""
    directions = [
        math.atan2(end[1] - start[1], end[0] - start[0])
        for start, end, n in zip(points[:-1], points[1:], lengths, strict=True)
        if n > 0
    ]
    unwrapped = [directions[0]]
    for direction in directions[1:]:
        turn = math.pi - (math.pi - (direction - unwrapped[-1])) % (2 * math.pi)  # (-pi, pi]
        unwrapped.append(unwrapped[-1] + turn)
    kept = [n for n in lengths if n > 0]
    total = sum(kept)
    ends = np.cumsum(kept) / total
    return np.array(unwrapped)[np.searchsorted(ends, grid, side="right")], total


def _grid_similarity(poly0, poly1):
    (points0, lengths0, _), (points1, lengths1, _) = poly0, poly1
    cells = sum(lengths0) * sum(lengths1) * GRID_REFINE
    grid = (np.arange(cells) + 0.5) / cells
    t0, total0 = _tangent_on_grid(points0, lengths0, grid)
    t1, total1 = _tangent_on_grid(points1, lengths1, grid)
    difference = t1 - t0
    theta_0 = difference.mean()
    return np.mean((difference - theta_0) ** 2) * max(total1 / total0, total0 / total1)


@settings(max_examples=150, deadline=None)
@given(integer_polylines(), integer_polylines())
def test_similarity_equals_the_exact_grid_integral(poly0, poly1):
    expected = _grid_similarity(poly0, poly1)
    assert similarity(poly0[0], poly1[0]) == pytest.approx(expected, rel=1e-6, abs=1e-9)


@settings(max_examples=150, deadline=None)
@given(integer_polylines(), integer_polylines())
def test_similarity_is_non_negative_and_symmetric(poly0, poly1):
    forward = similarity(poly0[0], poly1[0])
    assert forward >= 0.0
    assert similarity(poly1[0], poly0[0]) == pytest.approx(forward, rel=1e-9, abs=1e-12)


@settings(max_examples=150, deadline=None)
@given(
    integer_polylines(),
    st.floats(-10, 10),
    st.floats(-10, 10),
    st.floats(-2 * math.pi, 2 * math.pi),
)
def test_rigidly_moved_copy_has_zero_similarity(poly, dx, dy, rotation):
    points = poly[0]
    moved = transform_points([dx, dy, rotation], points)
    assert similarity(points, moved) == pytest.approx(0.0, abs=1e-9)


def test_length_ratio_weights_the_shape_term():
    corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    straight = np.array([[0.0, 0.0], [2.0, 0.0]])
    base = similarity(corner, straight)
    assert base == pytest.approx(math.pi**2 / 16)  # (pi/2)^2 / 4, equal lengths
    assert similarity(corner, 3.0 * straight) == pytest.approx(3.0 * base)
    assert similarity(corner, 3.0 * corner) == pytest.approx(0.0, abs=1e-12)  # shape only


def test_tangent_function_unwraps_along_the_polyline():
    # A spiral turning left by 60 deg per edge, twice around: T keeps growing.
    angles = np.radians(170.0 + 60.0 * np.arange(12))
    points = np.vstack(
        ([0.0, 0.0], np.cumsum(np.column_stack((np.cos(angles), np.sin(angles))), axis=0))
    )
    breaks, tangent = tangent_function(points)
    np.testing.assert_allclose(breaks, np.linspace(0.0, 1.0, 13), atol=1e-12)
    np.testing.assert_allclose(np.diff(tangent), np.radians(60.0), atol=1e-9)
    assert -math.pi < tangent[0] <= math.pi
    assert tangent[-1] > 4 * math.pi


def test_tangent_function_skips_zero_length_edges(nasty_polyline):
    breaks, angles = tangent_function(nasty_polyline)
    assert breaks.shape == (angles.size + 1,)
    assert breaks[0] == 0.0
    if angles.size:
        assert breaks[-1] == 1.0
        assert np.all(np.diff(breaks) > 0.0)
    else:
        np.testing.assert_array_equal(breaks, [0.0])


def test_degenerate_polylines_are_infinitely_dissimilar(nasty_polyline):
    wall = [[0.0, 0.0], [1.0, 0.0]]
    result = similarity(nasty_polyline, wall)
    if Polyline(nasty_polyline).length == 0.0:
        assert result == math.inf
        assert similarity(wall, nasty_polyline) == math.inf
    else:
        assert 0.0 <= result < math.inf


def test_repeated_vertices_do_not_change_similarity():
    corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    doubled = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    other = np.array([[0.0, 0.0], [2.0, 0.5], [2.0, 1.0], [3.0, 3.0]])
    assert similarity(doubled, other) == pytest.approx(similarity(corner, other), rel=1e-12)


def test_polylines_and_arrays_agree_and_cached_results_are_stable():
    a = Polyline([[0.0, 0.0], [1.0, 0.2], [2.0, 0.0], [2.5, 1.0]])
    b = Polyline([[0.0, 0.0], [1.0, -0.1], [2.0, 0.3]])
    first = similarity(a, b)
    assert similarity(a, b) == first
    assert similarity(a.points, b.points) == pytest.approx(first, rel=1e-15)
    assert tangent_function(a)[1].flags.writeable is False


def test_traversal_direction_matters():
    # The paper compares polylines traversed in the same (scan) direction; a reversed
    # copy of a bent line is a different tangent function.
    bent = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]])
    assert similarity(bent, bent[::-1]) > 0.1


def test_tangent_function_is_computed_once_per_polyline():
    line = Polyline([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    first = tangent_function(line)
    second = tangent_function(line)
    assert first[0] is second[0]
    assert first[1] is second[1]
    assert tangent_function(line.points)[0] is not first[0]  # arrays are not cached


def _long_integer_polyline(rng, count):
    """``count`` edges of integer length 0-3 turning by less than 170 deg at each vertex."""
    lengths = rng.integers(0, 4, count)
    lengths[0] = 1
    angles = np.cumsum(rng.uniform(-2.9, 2.9, count))
    steps = lengths[:, None] * np.column_stack((np.cos(angles), np.sin(angles)))
    points = np.vstack(([0.0, 0.0], np.cumsum(steps, axis=0)))
    return points, lengths.tolist(), angles.tolist()


@pytest.mark.parametrize("count", [40, 120])
def test_long_polylines_equal_the_exact_grid_integral(count):
    rng = np.random.default_rng(count)
    poly0 = _long_integer_polyline(rng, count)
    poly1 = _long_integer_polyline(rng, count // 2)
    expected = _grid_similarity(poly0, poly1)
    assert similarity(poly0[0], poly1[0]) == pytest.approx(expected, rel=1e-6, abs=1e-9)
