"""The robot's fixed path: connected cubic splines through knots, by arc length.

The paper (Sec. 5.2) drives the UGV along "a fixed path consisting of connected third
order splines so that the complete path is continuous and smooth". ``SplinePath`` builds
one C2 cubic spline ``r(t) = (x(t), y(t))`` through the knots with ``scipy``'s
``CubicSpline``, parameterised by cumulative chord length ``t``, and re-parameterises it by
arc length ``s`` so that ``|dr/ds| = 1``: the follower's reference speed, the curvature and
the segment boundaries (``knot_s``) are then all in metres along the path.

Arc length ``S(t)`` is integrated with Gauss-Legendre quadrature on a fine table of ``t``
nodes (the knots are nodes). Its inverse ``t(s)`` is a cubic Hermite interpolant through
the table using the exact slope ``dt/ds = 1 / |r'(t)|``: C1, and within 1e-6 m of the
true arc length (measured against adaptive quadrature: 2e-7 m on curvy 15 m paths).

Examples
--------
>>> path = SplinePath([(0.0, 0.0), (1.0, 0.0), (2.0, 1.0)])
>>> round(path.length, 3)
2.448
>>> path.knot_s.round(3)
array([0.   , 1.009, 2.448])
>>> path.pose(0.0).round(3)
array([ 0.   ,  0.   , -0.137])
>>> round(path.project([1.0, 0.1]), 3)
1.044
"""

from __future__ import annotations

import itertools
import math

import numba
import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import CubicHermiteSpline, CubicSpline

__all__ = ["SplinePath"]

# Spacing (in the chord-length parameter, ~metres) of the arc-length table. The Hermite
# inverse has error O(h^4); at 5 cm it stays below 1e-6 m for curvatures up to ~2 1/m.
TABLE_SPACING = 0.05
# Every knot interval gets at least this many table sub-intervals, so short, tightly
# curved intervals are still resolved.
MIN_TABLE_SUBINTERVALS = 8
# Gauss-Legendre points per table sub-interval for the arc-length integral (exact for
# polynomials of degree 9; |r'| of a cubic is smooth, so the error is ~1e-12 m).
QUADRATURE_ORDER = 5
# Knots closer than this (m) are considered duplicates: the chord parameterisation
# would be degenerate there.
MIN_KNOT_SEPARATION = 1e-6
# Where the spline's parametric speed |r'(t)| (dimensionless, ~1 on a chord-length
# spline) drops below this the curve has a (near) cusp and arc length cannot be inverted.
MIN_PARAMETRIC_SPEED = 1e-3
# Spacing (m) of the coarse samples used to seed the closest-point search.
PROJECTION_SPACING = 0.05
# Newton iterations (bisection-safeguarded) refining a projection; converges to
# ~1e-12 m in 3-4 iterations from the coarse seed.
PROJECTION_ITERATIONS = 8
# A projection step (m) below this ends the refinement.
PROJECTION_TOLERANCE = 1e-11
# Coarse local minima of the distance refined per query; the best refined one wins.
PROJECTION_BASINS = 3
BOUNDARY_TYPES = ("natural", "not-a-knot", "periodic")


class SplinePath:
    """Build a C2 cubic-spline path through knots, parameterised by arc length.

    Parameters
    ----------
    knots
        ``(N, 2)`` world-frame points the path passes through, in driving order, ``N >= 2``.
        Consecutive knots must be distinct.
    bc_type
        End conditions of the spline: ``"natural"`` (default; zero curvature at both ends,
        so the robot starts and stops on a straight stretch) or ``"not-a-knot"`` (the
        first and last two intervals share one cubic, often a closer fit to a sketch) or
        ``"periodic"`` (a closed route: the last knot repeats the first and the spline
        joins itself C2 there, so it can be driven lap after lap; see ``closed``).

    Attributes
    ----------
    knots : numpy.ndarray
        ``(N, 2)`` the knots (read-only).
    length : float
        Total arc length in metres.
    knot_s : numpy.ndarray
        ``(N,)`` arc length at each knot; ``knot_s[0] == 0`` and ``knot_s[-1] == length``.

    Notes
    -----
    All queries take scalars or arrays of ``s`` (returning the same shape) and clamp
    ``s`` to ``[0, length]``: beyond its ends the path does not exist.

    Examples
    --------
    >>> path = SplinePath([(0.0, 0.0), (2.0, 0.0)])
    >>> path.length
    2.0
    >>> path.point([0.5, 1.5])
    array([[0.5, 0. ],
           [1.5, 0. ]])
    >>> float(path.curvature(1.0))
    0.0
    """

    def __init__(self, knots: ArrayLike, bc_type: str = "natural") -> None:
        knots = np.array(knots, dtype=float)
        if knots.ndim != 2 or knots.shape[1] != 2 or knots.shape[0] < 2:
            raise ValueError(
                f"SplinePath: knots must be an (N, 2) array with N >= 2, got shape {knots.shape}"
            )
        if not np.all(np.isfinite(knots)):
            raise ValueError("SplinePath: knots must be finite (no nan or inf coordinates)")
        if bc_type not in BOUNDARY_TYPES:
            raise ValueError(
                f"SplinePath: bc_type must be one of {BOUNDARY_TYPES}, got {bc_type!r}"
            )
        if bc_type == "periodic" and (
            knots.shape[0] < 4 or np.hypot(*(knots[-1] - knots[0])) > MIN_KNOT_SEPARATION
        ):
            raise ValueError(
                "SplinePath: a periodic (closed) path needs at least 4 knots, the last equal "
                f"to the first; got {knots.shape[0]} knots ending at {knots[-1].tolist()} "
                f"for a start at {knots[0].tolist()}"
            )
        if bc_type == "periodic":
            knots[-1] = knots[0]  # scipy demands the exact value
        chords = np.hypot(*np.diff(knots, axis=0).T)
        if np.any(chords < MIN_KNOT_SEPARATION):
            index = int(np.argmin(chords))
            raise ValueError(
                f"SplinePath: knots {index} and {index + 1} coincide "
                f"({chords[index]:.2e} m apart); remove the duplicate knot"
            )
        knots.flags.writeable = False
        self.knots = knots
        self.bc_type = bc_type
        knot_t = np.concatenate([[0.0], np.cumsum(chords)])
        self._spline = CubicSpline(knot_t, knots, axis=0, bc_type=bc_type)
        # Every cubic as plain (breaks, (4, pieces, columns) coefficients) arrays, the
        # layout the compiled kernels read: r(t), then t(s) and s(t).
        self._xy = _cubic_table(self._spline)

        table_t, knot_rows = _table_nodes(knot_t)
        speed = np.hypot(*self._evaluate(table_t)[1].T)
        if np.min(speed) < MIN_PARAMETRIC_SPEED:
            raise ValueError(
                "SplinePath: the spline through these knots has a cusp near "
                f"({', '.join(f'{v:.2f}' for v in self._spline(table_t[np.argmin(speed)]))}); "
                "space the knots more evenly or remove a knot that doubles back"
            )
        table_s = np.concatenate([[0.0], np.cumsum(self._arc_length(table_t[:-1], table_t[1:]))])
        self.length = float(table_s[-1])
        knot_s = table_s[knot_rows]
        knot_s.flags.writeable = False
        self.knot_s = knot_s
        self._s_to_t = _cubic_table(CubicHermiteSpline(table_s, table_t, 1.0 / speed))
        # The forward map, for projections found in t.
        self._t_to_s = _cubic_table(CubicHermiteSpline(table_t, table_s, speed))

        count = max(2, int(np.ceil(self.length / PROJECTION_SPACING)) + 1)
        coarse_s = np.linspace(0.0, self.length, count)
        coarse_t = self._t(coarse_s)
        coarse_points = self._evaluate(coarse_t)[0]
        # What the compiled projection reads.
        self._projection_tables = (
            coarse_s,
            coarse_t,
            np.ascontiguousarray(coarse_points[:, 0]),
            np.ascontiguousarray(coarse_points[:, 1]),
            *self._xy,
            *self._s_to_t,
            *self._t_to_s,
        )

    @property
    def closed(self) -> bool:
        """Return whether the path is a closed loop (``bc_type="periodic"``).

        Its end pose equals its start pose, so a vehicle at the end of one lap is at the
        start of the next.

        Examples
        --------
        >>> square = [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0)]
        >>> loop = SplinePath(square, bc_type="periodic")
        >>> loop.closed, bool(np.allclose(loop.pose(0.0), loop.pose(loop.length)))
        (True, True)
        """
        return self.bc_type == "periodic"

    def __repr__(self) -> str:
        return (
            f"SplinePath({self.knots.shape[0]} knots, length={self.length:.3f} m, "
            f"bc_type={self.bc_type!r})"
        )

    def _arc_length(self, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """Integrate ``|r'(t)|`` from ``t0`` to ``t1`` (arrays) with Gauss-Legendre."""
        nodes, weights = np.polynomial.legendre.leggauss(QUADRATURE_ORDER)
        half = 0.5 * (t1 - t0)
        t = (0.5 * (t0 + t1))[:, None] + half[:, None] * nodes
        speed = np.hypot(*np.moveaxis(self._evaluate(t)[1], -1, 0))
        return half * (speed @ weights)

    def _t(self, s: ArrayLike) -> np.ndarray:
        s = np.minimum(np.maximum(np.asarray(s, dtype=float), 0.0), self.length)
        return _evaluate_cubic(*self._s_to_t, s)[0][..., 0]

    def _evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return position, first and second ``t``-derivative of the spline at ``t``."""
        return _evaluate_cubic(*self._xy, t)

    def point(self, s: ArrayLike) -> np.ndarray:
        """Return the path point(s) at arc length ``s``: shape ``s.shape + (2,)``.

        Examples
        --------
        >>> SplinePath([(0.0, 0.0), (0.0, 3.0)]).point(1.0)
        array([0., 1.])
        """
        return self._evaluate(self._t(s))[0]

    def heading(self, s: ArrayLike) -> np.ndarray | float:
        """Return the tangent direction(s) at ``s`` in radians, wrapped to ``(-pi, pi]``.

        Examples
        --------
        >>> round(SplinePath([(0.0, 0.0), (0.0, 3.0)]).heading(1.0), 4)
        1.5708
        """
        _, velocity, _ = self._evaluate(self._t(s))
        heading = _heading(velocity[..., 0], velocity[..., 1])
        return float(heading) if heading.ndim == 0 else heading

    def curvature(self, s: ArrayLike) -> np.ndarray | float:
        """Return the signed curvature(s) at ``s`` in 1/m (positive turning left, CCW).

        Examples
        --------
        >>> parabola = SplinePath([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)], bc_type="not-a-knot")
        >>> round(parabola.curvature(parabola.length / 2), 2)  # y = 1 - x^2 at its apex
        2.0
        """
        _, d1, d2 = self._evaluate(self._t(s))
        curvature = _curvature(d1[..., 0], d1[..., 1], d2[..., 0], d2[..., 1])
        return float(curvature) if curvature.ndim == 0 else curvature

    def pose(self, s: ArrayLike) -> np.ndarray:
        """Return the path pose(s) ``(x, y, heading)`` at ``s``: shape ``s.shape + (3,)``.

        Examples
        --------
        >>> SplinePath([(0.0, 0.0), (2.0, 0.0)]).pose(0.5)
        array([0.5, 0. , 0. ])
        """
        point, velocity, _ = self._evaluate(self._t(s))
        heading = _heading(velocity[..., 0], velocity[..., 1])
        return np.concatenate([point, heading[..., None]], axis=-1)

    def frame(self, s: float) -> tuple[float, float, float, float]:
        """Return ``(x, y, heading, curvature)`` at one arc length ``s``, as floats.

        The values of :meth:`pose` and :meth:`curvature` at ``s`` to the last bit, from one
        compiled evaluation: the follower asks for them at 50 Hz, where numpy's per-call
        overhead on one-element arrays would cost more than the arithmetic.

        Examples
        --------
        >>> parabola = SplinePath([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)], bc_type="not-a-knot")
        >>> x, y, heading, curvature = parabola.frame(parabola.length / 2)
        >>> round(x, 6) + 0.0, round(y, 6), round(heading, 4), round(curvature, 2)
        (0.0, 1.0, 3.1416, 2.0)
        """
        x, y, dx, dy, ddx, ddy = _frame_at(*self._s_to_t, *self._xy, self.length, float(s))
        return x, y, float(_heading(dx, dy)), float(_curvature(dx, dy, ddx, ddy))

    def reference(
        self, s: ArrayLike, speed: float
    ) -> tuple[np.ndarray | float, np.ndarray | float]:
        """Return the reference velocities ``(u1r, u2r)`` for driving at ``speed`` at ``s``.

        ``u1r = speed`` (m/s) and ``u2r = curvature(s) * speed`` (rad/s): the unicycle
        inputs that keep a robot exactly on the path.

        Examples
        --------
        >>> parabola = SplinePath([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)], bc_type="not-a-knot")
        >>> u1r, u2r = parabola.reference(parabola.length / 2, 0.5)
        >>> round(u1r, 3), round(u2r, 3)
        (0.5, 1.0)
        """
        curvature = self.curvature(s)
        u1r = np.full_like(curvature, float(speed)) if np.ndim(curvature) else float(speed)
        return u1r, curvature * float(speed)

    def knot_interval(self, s: ArrayLike) -> np.ndarray | int:
        """Return the index ``i`` of the knot interval holding ``s``: ``knot_s[i] <= s``.

        ``s`` at or beyond the path end belongs to the last interval, ``N - 2``.

        Examples
        --------
        >>> path = SplinePath([(0.0, 0.0), (1.0, 0.0), (3.0, 0.0)])
        >>> path.knot_interval([0.0, 0.99, 1.0, 3.0])
        array([0, 0, 1, 1])
        """
        index = np.searchsorted(self.knot_s, np.asarray(s, dtype=float), side="right") - 1
        index = np.clip(index, 0, self.knot_s.size - 2)
        return int(index) if index.ndim == 0 else index

    def sample(self, ds: float) -> tuple[np.ndarray, np.ndarray]:
        """Return arc lengths and poses every ``ds`` metres (both ends included).

        The spacing is the largest one not above ``ds`` that divides the path evenly.

        Returns
        -------
        s : numpy.ndarray
            ``(M,)`` arc lengths from 0 to ``length``.
        poses : numpy.ndarray
            ``(M, 3)`` poses ``(x, y, heading)``.

        Examples
        --------
        >>> s, poses = SplinePath([(0.0, 0.0), (1.0, 0.0)]).sample(0.4)
        >>> s.round(3)
        array([0.   , 0.333, 0.667, 1.   ])
        """
        if not ds > 0.0:
            raise ValueError(f"SplinePath.sample: ds must be > 0 m, got {ds}")
        s = np.linspace(0.0, self.length, int(np.ceil(self.length / ds)) + 1)
        return s, self.pose(s)

    def project(
        self, xy: ArrayLike, s_hint: float | None = None, window: float | None = None
    ) -> np.ndarray | float:
        """Return the arc length of the path point closest to ``xy``.

        Parameters
        ----------
        xy
            A point ``(2,)`` or points ``(N, 2)`` in the world frame.
        s_hint
            Where to look (e.g. the follower's current progress). Without it the whole
            path is searched.
        window
            Half-width (m) of the arc-length interval searched around ``s_hint``; only
            with ``s_hint``. Default 1 m. A local search is what a tracker wants: where the
            path passes close to itself, the global closest point may be on the wrong leg.

        Returns
        -------
        float or numpy.ndarray
            ``s`` in ``[0, length]`` (a float for one point, ``(N,)`` for many).

        Examples
        --------
        >>> path = SplinePath([(0.0, 0.0), (2.0, 0.0), (2.0, 0.2), (0.0, 0.2)])
        >>> round(path.project([0.5, 0.25]), 2)  # globally, the return leg is closer
        4.19
        >>> round(path.project([0.5, 0.25], s_hint=0.4, window=0.5), 2)
        0.5
        """
        points = np.asarray(xy, dtype=float)
        single = points.ndim == 1
        if s_hint is None:
            if window is not None:
                raise ValueError("SplinePath.project: window needs s_hint (where to centre it)")
            lo, hi = 0.0, self.length
        else:
            window = 1.0 if window is None else float(window)
            if not window > 0.0:
                raise ValueError(f"SplinePath.project: window must be > 0 m, got {window}")
            # min/max on a float clip like numpy.clip (nan stays nan) at a tenth of the cost.
            centre = min(max(float(s_hint), 0.0), self.length)
            lo, hi = max(0.0, centre - window), min(self.length, centre + window)
        # Coordinate columns as the kernel takes them; for one point (the follower's, at
        # 50 Hz) from two Python floats, numpy's per-call cost being most of the query.
        if single and points.shape == (2,):
            x, y = points.tolist()
            xs, ys, finite = np.array([x]), np.array([y]), math.isfinite(x) and math.isfinite(y)
        else:
            points = points.reshape(-1, 2)
            xs, ys = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
            finite = bool(np.isfinite(points).all())
        if not finite:
            raise ValueError("SplinePath.project: xy must be finite (got nan or inf)")
        s = _project_points(xs, ys, float(lo), float(hi), *self._projection_tables)
        return float(s[0]) if single else s


def _evaluate_cubic(
    breaks: np.ndarray, coefficients: np.ndarray, x: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Evaluate a piecewise cubic (``(4, pieces, columns)``, scipy's ``PPoly`` layout) at ``x``.

    Returns the value and the first and second derivatives, each of shape
    ``x.shape + (columns,)``, from one compiled pass (:func:`_cubic_rows`) whatever the
    size of ``x``: the follower's single ``s`` as well as a whole table. ``x`` outside the
    breaks extrapolates the end pieces (callers clamp first).
    """
    x = np.asarray(x, dtype=float)
    value, first, second = _cubic_rows(breaks, coefficients, np.ascontiguousarray(x.ravel()))
    shape = (*x.shape, coefficients.shape[2])
    return value.reshape(shape), first.reshape(shape), second.reshape(shape)


def _heading(dx: ArrayLike, dy: ArrayLike) -> np.ndarray:
    """Return the direction of the tangent ``(dx, dy)`` in radians (arrays or floats)."""
    return np.arctan2(dy, dx)


def _curvature(dx: ArrayLike, dy: ArrayLike, ddx: ArrayLike, ddy: ArrayLike) -> np.ndarray:
    """Return the signed curvature from the first and second derivatives (arrays or floats).

    numpy's hypot and power for floats too: math's round differently in the last bit. On
    arrays numpy's power (SIMD since numpy 2.4) differs from its power on one float in the
    last bit too, so an array's cubes are taken one float at a time: a batch query and
    :meth:`SplinePath.frame` (the follower's) agree to the bit.
    """
    norm = np.hypot(dx, dy)
    if np.ndim(norm):
        cube = np.fromiter((value ** 3 for value in norm.flat), float, norm.size)
        return (dx * ddy - dy * ddx) / cube.reshape(norm.shape)
    return (dx * ddy - dy * ddx) / norm ** 3


def _cubic_table(cubic) -> tuple[np.ndarray, np.ndarray]:
    """Return a scipy piecewise cubic's breaks and ``(4, pieces, columns)`` coefficients.

    Plain contiguous arrays: scipy's ``PPoly`` attribute access is slow enough to matter
    at 50 Hz, and the compiled kernels read one layout for scalar and vector cubics.
    """
    coefficients = np.asarray(cubic.c, dtype=float)
    if coefficients.ndim == 2:
        coefficients = coefficients[:, :, None]
    return np.ascontiguousarray(cubic.x, dtype=float), np.ascontiguousarray(coefficients)


def _table_nodes(knot_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the arc-length table's ``t`` nodes and the row of each knot in it."""
    pieces = []
    knot_rows = [0]
    for t0, t1 in itertools.pairwise(knot_t):
        count = max(MIN_TABLE_SUBINTERVALS, int(np.ceil((t1 - t0) / TABLE_SPACING)))
        pieces.append(np.linspace(t0, t1, count + 1)[1:])
        knot_rows.append(knot_rows[-1] + count)
    return np.concatenate([[knot_t[0]], *pieces]), np.array(knot_rows)


# Columns of a coefficient table as numpy integers: numba compiles a call with a Python int
# constant as a separate specialisation on that literal value, a numpy integer it does not.
_COLUMN0, _COLUMN1 = np.int64(0), np.int64(1)


@numba.njit(cache=True)
def _cubic_at(breaks, coefficients, x, column):  # pragma: no cover - compiled
    """Return value, first and second derivative of one piecewise cubic at ``x``.

    ``coefficients`` is scipy's ``PPoly`` layout ``(4, pieces, columns)``; the piece is
    the last one starting at or before ``x`` (clamped to the first and last), evaluated
    by Horner's rule. The one evaluation of the path's cubics: the projection calls it,
    and :func:`_cubic_rows` for every other query.

    Examples
    --------
    >>> breaks = np.array([0.0, 1.0, 2.0])
    >>> coefficients = np.zeros((4, 2, 1))
    >>> coefficients[2:, :, 0] = [[1.0, 1.0], [0.0, 1.0]]  # the line y = x
    >>> _cubic_at(breaks, coefficients, 1.5, 0)
    (1.5, 1.0, 0.0)
    """
    # The last break <= x among breaks[1:-1] (numpy.searchsorted, side "right", clamped
    # to the first and last piece); a plain bisection compiles much faster.
    piece, top = 0, breaks.size - 2
    while piece < top:
        middle = (piece + top + 1) // 2
        if breaks[middle] <= x:
            piece = middle
        else:
            top = middle - 1
    h = x - breaks[piece]
    c3, c2 = coefficients[0, piece, column], coefficients[1, piece, column]
    c1, c0 = coefficients[2, piece, column], coefficients[3, piece, column]
    value = ((c3 * h + c2) * h + c1) * h + c0
    first = (3.0 * c3 * h + 2.0 * c2) * h + c1
    second = 6.0 * c3 * h + 2.0 * c2
    return value, first, second


@numba.njit(cache=True)
def _cubic_rows(breaks, coefficients, x):  # pragma: no cover - compiled
    """Return :func:`_cubic_at` at every ``x``, every column: three ``(x.size, columns)`` arrays.

    Examples
    --------
    >>> breaks = np.array([0.0, 1.0, 2.0])
    >>> coefficients = np.zeros((4, 2, 1))
    >>> coefficients[2:, :, 0] = [[1.0, 1.0], [0.0, 1.0]]  # the line y = x
    >>> value, first, second = _cubic_rows(breaks, coefficients, np.array([0.5, 1.5]))
    >>> value.ravel().tolist(), first.ravel().tolist(), second.ravel().tolist()
    ([0.5, 1.5], [1.0, 1.0], [0.0, 0.0])
    """
    count, columns = x.size, coefficients.shape[2]
    value = np.empty((count, columns))
    first, second = np.empty((count, columns)), np.empty((count, columns))
    for i in range(count):
        for column in range(columns):
            value[i, column], first[i, column], second[i, column] = _cubic_at(
                breaks, coefficients, x[i], column)
    return value, first, second


@numba.njit(cache=True)
def _frame_at(
    s_to_t_breaks, s_to_t_coefficients, breaks, coefficients, length, s
):  # pragma: no cover - compiled
    """Return ``(x, y, x', y', x'', y'')`` of the path at one arc length ``s``.

    ``s`` clamped to ``[0, length]`` as :meth:`SplinePath._t` clamps it, then ``t(s)`` and
    ``r(t)`` by :func:`_cubic_at`: the same evaluation as a table query, for one ``s``.

    Examples
    --------
    >>> path = SplinePath([(0.0, 0.0), (2.0, 0.0)])
    >>> [round(v, 6) + 0.0 for v in _frame_at(*path._s_to_t, *path._xy, path.length, 0.5)]
    [0.5, 0.0, 1.0, 0.0, 0.0, 0.0]
    """
    t = _cubic_at(s_to_t_breaks, s_to_t_coefficients, min(max(s, 0.0), length), _COLUMN0)[0]
    x, dx, ddx = _cubic_at(breaks, coefficients, t, _COLUMN0)
    y, dy, ddy = _cubic_at(breaks, coefficients, t, _COLUMN1)
    return x, y, dx, dy, ddx, ddy


@numba.njit(cache=True)
def _slope_at(breaks, coefficients, t, x, y):  # pragma: no cover - compiled
    """Return ``d/dt |r(t) - q|^2 / 2``, its ``t``-derivative and ``r(t)`` for ``q = (x, y)``."""
    px, dx, ddx = _cubic_at(breaks, coefficients, t, _COLUMN0)
    py, dy, ddy = _cubic_at(breaks, coefficients, t, _COLUMN1)
    ox, oy = px - x, py - y
    return ox * dx + oy * dy, (dx * dx + dy * dy) + (ox * ddx + oy * ddy), px, py


@numba.njit(cache=True)
def _project_points(
    xs, ys, lo, hi, coarse_s, coarse_t, coarse_x, coarse_y, breaks, coefficients,
    s_to_t_breaks, s_to_t_coefficients, t_to_s_breaks, t_to_s_coefficients,
):  # pragma: no cover - compiled
    """Return the arc length in ``[lo, hi]`` of the path point closest to each ``(x, y)``.

    Seeds: the coarse samples strictly inside ``(lo, hi)``, framed by the window ends;
    the ``PROJECTION_BASINS`` best local minima of the distance among them (stably
    ranked by distance, then other samples in order) are each refined by Newton steps
    safeguarded by bisection inside the bracket of their neighbouring samples. All rows
    (points x basins) step in lock step, as one array computation would, and the best
    refined basin wins.

    Examples
    --------
    >>> path = SplinePath([(0.0, 0.0), (2.0, 0.0)])
    >>> s = path.project(np.array([[0.5, 0.3], [1.5, -0.2]]))
    >>> s.round(6)
    array([0.5, 1.5])
    """
    lo_t = _cubic_at(s_to_t_breaks, s_to_t_coefficients, lo, _COLUMN0)[0]
    hi_t = _cubic_at(s_to_t_breaks, s_to_t_coefficients, hi, _COLUMN0)[0]
    count = 2
    for k in range(coarse_s.size):
        if lo < coarse_s[k] < hi:
            count += 1
    candidates, sample_x, sample_y = np.empty(count), np.empty(count), np.empty(count)
    candidates[0], candidates[count - 1] = lo_t, hi_t
    row = 1
    for k in range(coarse_s.size):
        if lo < coarse_s[k] < hi:
            candidates[row] = coarse_t[k]
            sample_x[row], sample_y[row] = coarse_x[k], coarse_y[k]
            row += 1
    for k in range(0, count, count - 1):  # the window ends, 0 and count - 1 (count >= 2)
        sample_x[k] = _cubic_at(breaks, coefficients, candidates[k], _COLUMN0)[0]
        sample_y[k] = _cubic_at(breaks, coefficients, candidates[k], _COLUMN1)[0]
    points, basins = xs.size, min(PROJECTION_BASINS, count)
    rows = points * basins
    t, low, high = np.empty(rows), np.empty(rows), np.empty(rows)
    position_x, position_y = np.empty(rows), np.empty(rows)
    active = np.empty(rows, np.bool_)
    distance, key = np.empty(count), np.empty(count)
    picked = np.zeros(count, np.bool_)
    ranked = np.empty(basins, np.int64)
    for p in range(points):
        x, y = xs[p], ys[p]
        for k in range(count):
            dx, dy = x - sample_x[k], y - sample_y[k]
            distance[k] = dx * dx + dy * dy
        for k in range(count):
            minimum = (k == 0 or distance[k] <= distance[k - 1]) and (
                k == count - 1 or distance[k] <= distance[k + 1])
            key[k] = distance[k] if minimum else np.inf
        # The first `basins` of a stable sort by key: each pick is the earliest smallest
        # key not picked yet.
        for b in range(basins):
            best = -1
            for k in range(count):
                if not picked[k] and (best < 0 or key[k] < key[best]):
                    best = k
            picked[best] = True
            ranked[b] = best
        for k in range(basins):
            picked[ranked[k]] = False
        for b in range(basins):
            best = ranked[b]
            r = b * points + p
            low[r] = candidates[max(best - 1, 0)]
            high[r] = candidates[min(best + 1, count - 1)]
            # The bracket ends: where the distance still grows at the low end (or falls
            # at the high end), that end is the constrained minimum.
            slope_low, _, low_x, low_y = _slope_at(breaks, coefficients, low[r], x, y)
            slope_high, _, high_x, high_y = _slope_at(breaks, coefficients, high[r], x, y)
            at_low, at_high = slope_low >= 0.0, slope_high <= 0.0
            active[r] = not at_low and not at_high
            t[r] = low[r] if at_low else (high[r] if at_high else candidates[best])
            position_x[r] = low_x if at_low else high_x
            position_y[r] = low_y if at_low else high_y
    step = np.zeros(rows)
    converged = False
    for _ in range(PROJECTION_ITERATIONS):
        any_active = False
        for r in range(rows):
            any_active = any_active or active[r]
        if not any_active:
            converged = True
            break
        small = True
        for r in range(rows):
            if not active[r]:
                continue
            x, y = xs[r % points], ys[r % points]
            slope, second, here_x, here_y = _slope_at(breaks, coefficients, t[r], x, y)
            position_x[r], position_y[r] = here_x, here_y
            if slope < 0.0:
                low[r] = t[r]
            if slope > 0.0:
                high[r] = t[r]
            # Newton inside the bracket, else bisection. Inclusive bounds: a converged
            # Newton step lands on the bracket end it set.
            step[r] = 0.5 * (low[r] + high[r]) - t[r]
            if second > 0.0:
                newton = t[r] - slope / second
                if low[r] <= newton <= high[r]:
                    step[r] = newton - t[r]
            small = small and abs(step[r]) < PROJECTION_TOLERANCE
        if small:
            converged = True
            break
        for r in range(rows):
            t[r] = t[r] + step[r]
    result = np.empty(points)
    for p in range(points):
        best_gap, best_t = np.inf, 0.0
        for b in range(basins):
            r = b * points + p
            if not converged:
                position_x[r] = _cubic_at(breaks, coefficients, t[r], _COLUMN0)[0]
                position_y[r] = _cubic_at(breaks, coefficients, t[r], _COLUMN1)[0]
            dx, dy = position_x[r] - xs[p], position_y[r] - ys[p]
            gap = dx * dx + dy * dy
            if gap < best_gap or b == 0:
                best_gap, best_t = gap, t[r]
        s = _cubic_at(t_to_s_breaks, t_to_s_coefficients, best_t, _COLUMN0)[0]
        result[p] = min(max(s, lo), hi)
    return result
