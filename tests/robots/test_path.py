"""Tests for robots.path: C2 continuity, arc-length accuracy, projection, validation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import make_interp_spline

from robots.path import SplinePath
from tests.robots.scipy_path import ScipyPath

# One-sided finite-difference step (m) for the continuity checks.
STEP = 1e-3


def wavy_knots(rng: np.random.Generator, count: int = 9) -> np.ndarray:
    """Knots marching in +x with random lateral wiggle, like a warehouse path."""
    steps = np.column_stack([rng.uniform(0.8, 2.0, count), rng.normal(0.0, 0.7, count)])
    return np.cumsum(steps, axis=0)


KNOT_SETS = {
    "straight": np.array([[0.0, 0.0], [3.0, 0.0]]),
    "l_turn": np.array([[0.0, 0.0], [2.0, 0.0], [3.0, 1.0], [3.0, 3.0]]),
    "s_curve": np.array([[0.0, 0.0], [1.5, 0.3], [3.0, -0.4], [4.5, 0.5], [6.0, 0.0]]),
    "loop_like": np.array([[0.0, 0.0], [4.0, 0.0], [5.0, 2.0], [2.0, 3.0], [-0.5, 1.5]]),
    "random": wavy_knots(np.random.default_rng(7)),
}


def one_sided_derivatives(f, s: float, h: float) -> tuple[np.ndarray, ...]:
    """Left and right first and second derivatives of ``f`` at ``s`` (second-order stencils)."""
    left = [f(s - k * h) for k in range(3)]
    right = [f(s + k * h) for k in range(3)]
    d1_left = (3 * left[0] - 4 * left[1] + left[2]) / (2 * h)
    d1_right = (-3 * right[0] + 4 * right[1] - right[2]) / (2 * h)
    d2_left = (left[0] - 2 * left[1] + left[2]) / h**2
    d2_right = (right[0] - 2 * right[1] + right[2]) / h**2
    return d1_left, d1_right, d2_left, d2_right


def c2_jumps(f, s: float, h: float = STEP) -> tuple[float, float]:
    """Largest jumps of the first and second derivative of ``f`` across ``s``."""
    d1_left, d1_right, d2_left, d2_right = one_sided_derivatives(f, s, h)
    return float(np.max(np.abs(d1_left - d1_right))), float(np.max(np.abs(d2_left - d2_right)))


@pytest.mark.parametrize("name", sorted(KNOT_SETS))
@pytest.mark.parametrize("bc_type", ["natural", "not-a-knot"])
def test_path_is_c2_at_every_knot(name, bc_type):
    path = SplinePath(KNOT_SETS[name], bc_type=bc_type)
    for s_knot in path.knot_s[1:-1]:
        d1_jump, d2_jump = c2_jumps(path.point, s_knot)
        # A stencil of width 2 mm has O(h) error ~1e-3 * |r'''|; a real C1/C2 break is O(1).
        assert d1_jump < 1e-4
        assert d2_jump < 2e-2
        # The closed-form heading and curvature are continuous too (no stencil error).
        eps = 1e-9
        assert abs(path.heading(s_knot + eps) - path.heading(s_knot - eps)) < 1e-6
        assert abs(path.curvature(s_knot + eps) - path.curvature(s_knot - eps)) < 1e-5


def test_c2_check_detects_a_curvature_jump():
    # Negative control for the stencil: a C1 quadratic spline has curvature jumps at knots.
    knots = KNOT_SETS["s_curve"]
    chord = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(knots, axis=0).T))])
    quadratic = make_interp_spline(chord, knots, k=2)
    # Even-degree interpolating B-splines put their knots between the data sites.
    inner_knots = np.unique(quadratic.t[3:-3])
    jumps = [c2_jumps(quadratic, t)[1] for t in inner_knots]
    assert max(jumps) > 0.1


@pytest.mark.parametrize("name", sorted(KNOT_SETS))
def test_arc_length_parameterisation_has_unit_speed(name):
    path = SplinePath(KNOT_SETS[name])
    h = 1e-4
    s = np.linspace(h, path.length - h, 4001)
    speed = np.linalg.norm(path.point(s + h) - path.point(s - h), axis=1) / (2 * h)
    assert np.max(np.abs(speed - 1.0)) < 1e-3


@pytest.mark.parametrize("name", sorted(KNOT_SETS))
def test_length_and_knot_positions_match_a_dense_polyline(name):
    path = SplinePath(KNOT_SETS[name])
    # The t-parameterised spline sampled densely: its polyline length is independent of
    # our arc-length table and inversion.
    t = np.linspace(0.0, path._spline.x[-1], 200_001)
    dense = path._spline(t)
    polyline_length = np.sum(np.linalg.norm(np.diff(dense, axis=0), axis=1))
    assert path.length == pytest.approx(polyline_length, abs=1e-6)
    np.testing.assert_allclose(path.point(path.knot_s), KNOT_SETS[name], atol=1e-9)
    assert path.knot_s[0] == 0.0
    assert path.knot_s[-1] == pytest.approx(path.length)
    assert np.all(np.diff(path.knot_s) > 0.0)


def test_straight_path_is_exact():
    path = SplinePath([(1.0, 1.0), (4.0, 5.0)])
    assert path.length == pytest.approx(5.0, abs=1e-12)
    np.testing.assert_allclose(path.point(2.5), [2.5, 3.0], atol=1e-12)
    assert path.heading(1.0) == pytest.approx(np.arctan2(4.0, 3.0))
    assert path.curvature(1.0) == pytest.approx(0.0, abs=1e-12)


def test_circle_through_many_knots_has_radius_curvature():
    radius = 2.0
    angle = np.linspace(0.0, np.pi, 25)
    path = SplinePath(radius * np.column_stack([np.cos(angle), np.sin(angle)]), "not-a-knot")
    assert path.length == pytest.approx(np.pi * radius, rel=1e-4)
    s = np.linspace(0.2, path.length - 0.2, 50)
    # A cubic through points of a circle wiggles around 1/R by a few 1e-3 relative.
    np.testing.assert_allclose(path.curvature(s), 1.0 / radius, rtol=5e-3)
    clockwise = SplinePath(path.knots[::-1], "not-a-knot")
    np.testing.assert_allclose(clockwise.curvature(s), -1.0 / radius, rtol=5e-3)


def test_heading_is_the_direction_of_travel():
    path = SplinePath(KNOT_SETS["l_turn"])
    s = np.linspace(0.01, path.length - 0.01, 200)
    h = 1e-5
    delta = path.point(s + h) - path.point(s - h)
    np.testing.assert_allclose(path.heading(s), np.arctan2(delta[:, 1], delta[:, 0]), atol=1e-6)
    poses = path.pose(s)
    assert poses.shape == (200, 3)
    np.testing.assert_allclose(poses[:, :2], path.point(s))
    np.testing.assert_allclose(poses[:, 2], path.heading(s))


def test_curvature_matches_the_heading_rate():
    path = SplinePath(KNOT_SETS["random"])
    s = np.linspace(0.01, path.length - 0.01, 300)
    h = 1e-5
    rate = np.unwrap(np.stack([path.heading(s - h), path.heading(s + h)]), axis=0)
    np.testing.assert_allclose(path.curvature(s), (rate[1] - rate[0]) / (2 * h), atol=1e-4)


def test_natural_ends_have_zero_curvature():
    path = SplinePath(KNOT_SETS["s_curve"], bc_type="natural")
    assert path.curvature(0.0) == pytest.approx(0.0, abs=1e-9)
    assert path.curvature(path.length) == pytest.approx(0.0, abs=1e-9)


def test_queries_clamp_to_the_path_ends():
    path = SplinePath(KNOT_SETS["l_turn"])
    np.testing.assert_allclose(path.point(-3.0), path.knots[0])
    np.testing.assert_allclose(path.point(path.length + 3.0), path.knots[-1])


def test_queries_keep_the_shape_of_s():
    path = SplinePath(KNOT_SETS["s_curve"])
    s = np.linspace(0.0, path.length, 12).reshape(3, 4)
    assert path.point(s).shape == (3, 4, 2)
    assert path.pose(s).shape == (3, 4, 3)
    assert path.heading(s).shape == (3, 4)
    assert path.curvature(s).shape == (3, 4)
    assert isinstance(path.heading(1.0), float)
    assert isinstance(path.curvature(1.0), float)


def test_reference_is_curvature_times_speed():
    path = SplinePath(KNOT_SETS["random"])
    s = np.linspace(0.0, path.length, 40)
    u1r, u2r = path.reference(s, 0.4)
    np.testing.assert_allclose(u1r, 0.4)
    np.testing.assert_allclose(u2r, 0.4 * path.curvature(s))
    scalar = path.reference(1.0, 0.4)
    assert scalar == (0.4, pytest.approx(0.4 * path.curvature(1.0)))


def test_sample_spacing_and_ends():
    path = SplinePath(KNOT_SETS["l_turn"])
    s, poses = path.sample(0.1)
    assert s[0] == 0.0
    assert s[-1] == pytest.approx(path.length)
    assert np.all(np.diff(s) <= 0.1 + 1e-12)
    assert poses.shape == (s.size, 3)
    with pytest.raises(ValueError, match="ds must be > 0"):
        path.sample(0.0)


def brute_force_distance(path: SplinePath, points: np.ndarray) -> np.ndarray:
    s = np.linspace(0.0, path.length, 100_001)
    curve = path.point(s)
    return np.array([np.min(np.linalg.norm(curve - p, axis=1)) for p in points])


@pytest.mark.parametrize("name", sorted(KNOT_SETS))
def test_projection_finds_the_closest_point(name):
    rng = np.random.default_rng(3)
    path = SplinePath(KNOT_SETS[name])
    points = path.point(rng.uniform(0.0, path.length, 60)) + rng.normal(0.0, 0.3, (60, 2))
    s = path.project(points)
    assert s.shape == (60,)
    found = np.linalg.norm(path.point(s) - points, axis=1)
    # The brute-force grid is ~1e-4 m fine, so it may be worse than us by ~1e-9 m, never better.
    assert np.all(found <= brute_force_distance(path, points) + 1e-9)


def test_projection_of_a_point_on_the_path_returns_its_arc_length():
    path = SplinePath(KNOT_SETS["random"])
    s = np.linspace(0.0, path.length, 37)
    np.testing.assert_allclose(path.project(path.point(s)), s, atol=1e-8)


def test_projection_beyond_the_ends_clamps():
    path = SplinePath([(0.0, 0.0), (2.0, 0.0)])
    assert path.project([-1.0, 0.5]) == 0.0
    assert path.project([5.0, -0.5]) == pytest.approx(2.0)


def test_projection_window_keeps_the_tracked_leg():
    # A hairpin: the return leg 0.2 m away is globally closer to this point.
    path = SplinePath([(0.0, 0.0), (2.0, 0.0), (2.0, 0.2), (0.0, 0.2)])
    point = np.array([0.5, 0.15])
    assert path.project(point) > path.knot_s[2]
    local = path.project(point, s_hint=0.45, window=0.5)
    assert local < 0.95
    s_window = np.linspace(0.0, 0.95, 100_001)
    best_in_window = np.min(np.linalg.norm(path.point(s_window) - point, axis=1))
    assert np.linalg.norm(path.point(local) - point) <= best_in_window + 1e-9
    # The search never leaves the window, even when the closest point is outside it.
    assert path.project([1.5, 0.0], s_hint=0.2, window=0.3) == pytest.approx(0.5)


def test_projection_window_validation():
    path = SplinePath([(0.0, 0.0), (2.0, 0.0)])
    with pytest.raises(ValueError, match="window needs s_hint"):
        path.project([0.0, 0.0], window=1.0)
    with pytest.raises(ValueError, match="window must be > 0"):
        path.project([0.0, 0.0], s_hint=1.0, window=0.0)
    with pytest.raises(ValueError, match="xy must be finite"):
        path.project([np.nan, 0.0])


@pytest.mark.parametrize(
    ("knots", "match"),
    [
        ([(0.0, 0.0)], r"N >= 2"),
        ([0.0, 1.0, 2.0], r"\(N, 2\)"),
        ([(0.0, 0.0), (np.nan, 1.0)], "finite"),
        ([(0.0, 0.0), (1.0, 0.0), (1.0, 0.0), (2.0, 1.0)], "knots 1 and 2 coincide"),
        ([(0.0, 0.0), (1.0, 0.0), (0.0, 0.0)], "cusp"),
    ],
)
def test_bad_knots_are_rejected_with_a_clear_message(knots, match):
    with pytest.raises(ValueError, match=match):
        SplinePath(knots)


def test_bad_boundary_type_is_rejected():
    with pytest.raises(ValueError, match="bc_type must be one of"):
        SplinePath([(0.0, 0.0), (1.0, 0.0)], bc_type="clamped")


def test_knots_are_read_only():
    path = SplinePath([(0.0, 0.0), (1.0, 0.0)])
    with pytest.raises(ValueError, match="read-only"):
        path.knots[0, 0] = 5.0
    with pytest.raises(ValueError, match="read-only"):
        path.knot_s[0] = 5.0


def test_knot_interval_maps_arc_length_to_segments():
    path = SplinePath(KNOT_SETS["s_curve"])
    mid = 0.5 * (path.knot_s[:-1] + path.knot_s[1:])
    np.testing.assert_array_equal(path.knot_interval(mid), np.arange(4))
    np.testing.assert_array_equal(path.knot_interval(path.knot_s), [0, 1, 2, 3, 3])
    assert path.knot_interval(-1.0) == 0
    assert path.knot_interval(path.length + 1.0) == 3
    assert isinstance(path.knot_interval(1.0), int)


# ------------------------------------------------- against scipy, one s or many
#
# The reference, tests/robots/scipy_path.py: scipy's CubicSpline through the knots by
# chord length (the documented curve), its arc length by adaptive quadrature and the
# inverse s -> t by root finding. Queries are made one float at a time (what the
# follower does at 50 Hz) and as a batch.

HAIRPIN = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 0.2], [0.0, 0.2]])
ROUNDED_SQUARE = [(0.0, 0.0), (3.0, 0.0), (4.0, 1.0), (4.0, 3.0), (3.0, 4.0), (0.0, 4.0),
                  (-1.0, 3.0), (-1.0, 1.0), (0.0, 0.0)]
REFERENCE_SETS = {
    **{name: (knots, "natural") for name, knots in KNOT_SETS.items()},
    "hairpin": (HAIRPIN, "natural"),
    "not_a_knot": (KNOT_SETS["loop_like"], "not-a-knot"),
    "periodic": (np.array(ROUNDED_SQUARE), "periodic"),
}


@pytest.mark.parametrize("name", sorted(REFERENCE_SETS))
def test_queries_match_scipy_by_arc_length(name):
    knots, bc_type = REFERENCE_SETS[name]
    path, reference = SplinePath(knots, bc_type=bc_type), ScipyPath(knots, bc_type)
    assert path.length == pytest.approx(reference.length, abs=1e-9)
    np.testing.assert_allclose(path.knot_s, reference.knot_s, rtol=0.0, atol=1e-9)
    s_values = np.random.default_rng(2).uniform(-0.5, path.length + 0.5, 60)
    s_values[:4] = [0.0, path.length, path.knot_s[1], -0.0]
    frames = [reference.frame(s) for s in s_values]
    expected = {
        "point": np.array([point for point, _, _ in frames]),
        "heading": np.array([heading for _, heading, _ in frames]),
        "curvature": np.array([curvature for _, _, curvature in frames]),
    }
    # The Hermite inverse t(s) is within 1e-6 m (module docstring); heading and curvature
    # move with it by at most |kappa| and |kappa'| times that.
    tolerance = {"point": 1e-6, "heading": 1e-5, "curvature": 1e-4}
    for query, values in expected.items():
        batch = getattr(path, query)(s_values)
        one_by_one = np.array([getattr(path, query)(s) for s in s_values.tolist()])
        np.testing.assert_allclose(batch, values, rtol=0.0, atol=tolerance[query])
        np.testing.assert_allclose(one_by_one, values, rtol=0.0, atol=tolerance[query])
    poses = np.array([path.pose(s) for s in s_values.tolist()])
    np.testing.assert_allclose(poses[:, :2], expected["point"], rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(poses[:, 2], expected["heading"], rtol=0.0, atol=1e-5)
    assert isinstance(path.heading(1.0), float)
    assert isinstance(path.curvature(1.0), float)
    assert path.pose(3).shape == path.pose(np.array(3.0)).shape == (3,)  # ints too
    # frame(s), the follower's query: scipy's values, and pose's and curvature's to the bit.
    framed = np.array([path.frame(s) for s in s_values.tolist()])
    np.testing.assert_allclose(framed[:, :2], expected["point"], rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(framed[:, 2], expected["heading"], rtol=0.0, atol=1e-5)
    np.testing.assert_allclose(framed[:, 3], expected["curvature"], rtol=0.0, atol=1e-4)
    np.testing.assert_array_equal(framed[:, :3], path.pose(s_values))
    np.testing.assert_array_equal(framed[:, 3], path.curvature(s_values))


def poses_near(path: SplinePath, rng: np.random.Generator, count: int, spread: float):
    """Seeded points around the path with a progress hint near their arc length."""
    s = rng.uniform(0.0, path.length, count)
    points = path.point(s) + rng.normal(0.0, spread, (count, 2))
    hints = s + rng.normal(0.0, 0.1, count)
    return points, hints


@pytest.mark.parametrize("name", sorted(REFERENCE_SETS))
def test_projection_with_a_window_finds_scipys_closest_point(name):
    # One point at a time with the follower's hint and windows from 5 cm to 1 m (on the
    # hairpin three basins compete): the distance found is scipy's closest point's within
    # the window.
    knots, bc_type = REFERENCE_SETS[name]
    path, reference = SplinePath(knots, bc_type=bc_type), ScipyPath(knots, bc_type)
    points, hints = poses_near(path, np.random.default_rng(11), 15, 0.3)
    for point, hint in zip(points, hints, strict=True):
        for window in (0.05, 0.3, 1.0):
            found = path.project(point, s_hint=float(hint), window=window)
            assert isinstance(found, float)
            centre = min(max(float(hint), 0.0), path.length)
            low, high = max(0.0, centre - window), min(path.length, centre + window)
            assert low <= found <= high
            best = np.linalg.norm(reference.point(reference.closest(point, low, high)) - point)
            # Our closest point is at least as close (to the Hermite inverse's 1e-6 m).
            assert np.linalg.norm(reference.point(found) - point) <= best + 2e-6
            assert found == path.project(point[None, :], s_hint=float(hint), window=window)[0]


@pytest.mark.parametrize("name", sorted(KNOT_SETS))
def test_tracking_projection_equals_the_full_projection_near_the_path(name):
    # A robot near the path, tracked with the follower's hint and window: the local
    # search finds the same closest point as the search over the whole path.
    path = SplinePath(KNOT_SETS[name])
    points, hints = poses_near(path, np.random.default_rng(5), 300, 0.05)
    tracked = np.array(
        [path.project(p, s_hint=float(h), window=1.0) for p, h in zip(points, hints, strict=True)]
    )
    np.testing.assert_allclose(tracked, path.project(points), rtol=0.0, atol=1e-9)


def test_non_finite_s_clamps_to_the_ends():
    path = SplinePath(KNOT_SETS["l_turn"])
    np.testing.assert_allclose(path.pose(np.inf), path.pose(path.length))
    assert path.curvature(-np.inf) == path.curvature(0.0)
    assert path.pose(np.nan).shape == (3,)  # nan does not crash the search
    with pytest.raises(ValueError, match="finite"):
        path.project([np.nan, 0.0], s_hint=1.0)


def test_closed_path_joins_itself_c2_and_is_driven_by_arc_length():
    path = SplinePath(ROUNDED_SQUARE, bc_type="periodic")
    assert path.closed
    np.testing.assert_allclose(path.pose(0.0), path.pose(path.length), atol=1e-12)
    # Across the seam: the one-sided derivatives from each end agree (C1 and C2).
    h = 1e-3
    ahead = (path.point(h) - path.point(0.0)) / h
    behind = (path.point(path.length) - path.point(path.length - h)) / h
    np.testing.assert_allclose(ahead, behind, atol=2e-3)
    assert abs(path.curvature(0.0) - path.curvature(path.length)) < 1e-9
    s = np.linspace(0.0, path.length, 2001)
    speed = np.linalg.norm(np.gradient(path.point(s), s, axis=0), axis=1)
    assert np.max(np.abs(speed[1:-1] - 1.0)) < 1e-3
    # Its length is a dense polyline's (an independent estimate).
    dense = path.point(np.linspace(0.0, path.length, 20001))
    assert abs(np.sum(np.linalg.norm(np.diff(dense, axis=0), axis=1)) - path.length) < 1e-6


def test_open_paths_are_not_closed_and_a_closed_one_must_return_to_its_start():
    assert not SplinePath(ROUNDED_SQUARE).closed
    with pytest.raises(ValueError, match="last equal to the first"):
        SplinePath(ROUNDED_SQUARE[:-1], bc_type="periodic")
    with pytest.raises(ValueError, match="at least 4 knots"):
        SplinePath([(0.0, 0.0), (1.0, 0.0), (0.0, 0.0)], bc_type="periodic")
