"""Fitted polyline vertices: edges fitted along the beams between Douglas-Peucker corners.

Douglas-Peucker decides *where* a polyline bends; its vertices are raw readings, i.e. the
noise extremes of their neighbourhoods (docs/design.md#detail-3). :func:`fit_polylines` keeps the
corners but moves the vertices onto the surface the readings describe:

1. each edge (the readings between two consecutive corners, both included) is fitted
   along the beams: a reading's range error lies along its beam, so its distance from the
   line is that error times the sine of the beam's incidence on the line; total least
   squares with each squared distance weighted by 1 / sine^2 (sines from the plain total
   least squares line, at least sin 10 deg; one reweighting step) minimises the squared
   errors along the rays, the maximum-likelihood line under range noise. Grazing
   readings, whose noise runs mostly along the surface, place the line best (on the ACES
   log: PLE's ray-wise RMSE 2.99 -> 2.96 cm; real revisits intel 4.27 -> 4.19 cm);
2. adjacent edges are merged while one such line fits all their readings within the tolerance
   (the merge step of split-and-merge): noise makes Douglas-Peucker cut straight walls;
   an end edge made of the end reading alone (one step past the last corner) is dropped
   when that reading is a *mixed pixel* (:func:`is_mixed_pixel`): reached by a step
   nearly along its own beam and lying beyond the line of the edge before it, i.e. a
   return from between a surface's edge and what lies behind it. Such a hook changes
   from view to view (on the Intel log a third of the revisit pairs' largest distance
   was at a scan polyline's end), and the reading stays out of every polyline, so no
   polyline crosses its ray in front of it;
3. an inner vertex is the intersection of the two adjacent fitted lines, unless they are
   nearly parallel or cross far from the corner reading (then the mean of the corner
   reading's projections onto both lines);
4. an end vertex is where the end reading's beam (from the sensor origin) crosses the
   fitted line, so the polyline never reaches across the neighbouring beams; the end
   reading itself when that crossing lies more than the tolerance farther out along the
   line than the reading (a reading off the line, e.g. on the next face round a box
   corner seen obliquely, moves the crossing outward by its offset over the tangent of
   the beam's incidence, past the corner); the end reading's projection when the beam
   grazes the line.

Each vertex keeps the index of the reading it belongs to (the corner or end reading). One
compiled kernel (numba) does the work for all polylines of a scan.

Examples
--------
>>> x = np.array([1.0, 1.01, 0.99, 1.01, 0.99])  # a noisy wall x = 1 seen at 5 readings
>>> y = np.array([-0.2, -0.1, 0.0, 0.1, 0.2])
>>> vertices, corners, _ = fit_polylines(np.column_stack((x, y)), [0] * 5, [0, 2, 4], 0.03)
>>> vertices.round(3), corners  # one line fits: the middle corner goes
(array([[ 1.004, -0.201],
       [ 0.996,  0.201]]), array([0, 4]))
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba.extending import overload
from numpy.typing import ArrayLike

__all__ = ["MIXED_PIXEL_SINE", "fit_polylines", "is_mixed_pixel", "total_least_squares"]

# Two fitted lines meeting at less than this angle (sin of 10 deg) are treated as parallel:
# their intersection is ill-conditioned, so the corner reading's projections are used.
MIN_CORNER_SINE = math.sin(math.radians(10.0))

# A beam meeting the fitted line at less than this incidence (sin of 10 deg) grazes it: the
# crossing moves by 1/sin of the line's error, so the end reading's projection is used.
MIN_BEAM_SINE = math.sin(math.radians(10.0))

# A one-reading end edge within this angle (sin of 30 deg) of the end reading's own beam
# is a step along the beam: a mixed pixel at a depth jump, or a surface at grazing
# incidence, whose range is the least certain of the scan.
MIXED_PIXEL_SINE = math.sin(math.radians(30.0))

# An intersection farther from its corner reading than this share of the shorter adjacent
# edge (chord) is not where the readings bend: fall back to the projections.
MAX_CORNER_SHIFT = 0.5


def total_least_squares(points: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Return the centroid and unit direction of the line fitted to ``points``.

    Total least squares: the line through the centroid along the principal axis of the
    points, minimising the sum of squared perpendicular distances.

    Parameters
    ----------
    points
        ``(N, 2)`` points, ``N >= 2`` and not all equal.

    Returns
    -------
    tuple of numpy.ndarray
        ``(centroid, direction)``, both ``(2,)``; ``direction`` has unit length.

    Examples
    --------
    >>> centroid, direction = total_least_squares([[0.0, 1.0], [1.0, 2.0], [2.0, 3.0]])
    >>> centroid, np.abs(direction).round(4)
    (array([1., 2.]), array([0.7071, 0.7071]))
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if points.shape[0] < 2:
        raise ValueError(f"total_least_squares: needs at least 2 points, got {points.shape[0]}")
    x, y = points[:, 0], points[:, 1]
    # plain: no ranges read
    mx, my, dx, dy = _fit(x, y, x, 0, points.shape[0] - 1, 0.0, 0.0, np.empty(x.size))
    if dx == 0.0 and dy == 0.0:
        raise ValueError("total_least_squares: all points are equal, no line is defined")
    return np.array([mx, my]), np.array([dx, dy])


def is_mixed_pixel(points: ArrayLike, end: int, corner: int, far: int) -> bool:
    """Return whether reading ``end``, one step past ``corner``, is a mixed pixel.

    ``points`` are readings in the sensor frame (beams from the origin); ``corner`` is the
    reading next to ``end`` and ``far`` the other end of the edge before (the line fitted
    by total least squares to the readings ``corner..far``). ``end`` is a mixed pixel when
    the step from ``corner`` to it is within 30 deg (:data:`MIXED_PIXEL_SINE`) of its own
    beam and it lies farther along that beam than the line: a return from between the
    edge of a surface and what lies behind it.

    Examples
    --------
    >>> wall = [[2.0, y] for y in (-0.2, -0.1, 0.0, 0.1)]  # x = 2, beams from the origin
    >>> behind = [[2.3, 0.2 * 2.3 / 2.0]]  # on the next beam, 30 cm beyond the wall
    >>> is_mixed_pixel(wall + behind, end=4, corner=3, far=0)
    True
    >>> turning = [[2.06, 0.2]]  # the next face turns away at 31 deg to this beam
    >>> is_mixed_pixel(wall + turning, end=4, corner=3, far=0)
    False
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    count = points.shape[0]
    if not (0 <= end < count and 0 <= corner < count and 0 <= far < count):
        raise ValueError(f"is_mixed_pixel: positions must lie in 0..{count - 1}")
    if abs(end - corner) != 1 or corner == far or (end - corner) * (far - corner) > 0:
        raise ValueError("is_mixed_pixel: end must be next to corner, on the side away from far")
    low, high = min(corner, far), max(corner, far)
    return bool(_mixed_pixel(np.ascontiguousarray(points[:, 0]),
                             np.ascontiguousarray(points[:, 1]), end, corner, low, high,
                             np.empty(count)))


def fit_polylines(
    points: ArrayLike, line_ids: ArrayLike, corners: ArrayLike, epsilon: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the fitted vertices of every polyline of a scan at once.

    See the module docstring for the steps. ``points`` are in the sensor frame (the beams
    start at the origin), in scan order. Compiled kernels call this function too (the
    extraction does): it compiles to the same kernel, without the checks.

    Parameters
    ----------
    points
        ``(P, 2)`` readings of all intervals one after the other.
    line_ids
        ``(P,)`` non-decreasing interval number of each reading (each interval has at
        least two readings).
    corners
        Increasing positions into ``points`` of the Douglas-Peucker vertices, every
        interval's first and last reading included.
    epsilon
        Tolerance (m) within which one line must fit the readings of merged edges, ``> 0``.

    Returns
    -------
    tuple of numpy.ndarray
        ``(vertices, kept, vertex_lines)``: ``(K, 2)`` fitted vertices, the ``(K,)``
        positions into ``points`` of the readings they belong to (a subset of
        ``corners``) and the ``(K,)`` interval of each.

    Examples
    --------
    >>> corner = [[1.0, -0.4], [1.0, -0.2], [1.0, 0.0], [0.8, 0.0], [0.6, 0.0]]
    >>> vertices, kept, _ = fit_polylines(corner, [0] * 5, [0, 2, 4], epsilon=0.01)
    >>> vertices.round(6) + 0.0, kept
    (array([[ 1. , -0.4],
           [ 1. ,  0. ],
           [ 0.6,  0. ]]), array([0, 2, 4]))
    >>> points = np.array([[1.0, 0.0], [1.0, 0.1], [2.0, 0.0], [2.0, 0.2], [2.0, 0.4]])
    >>> vertices, kept, lines = fit_polylines(points, [0, 0, 1, 1, 1], [0, 1, 2, 4], 0.01)
    >>> kept, lines
    (array([0, 1, 2, 4]), array([0, 0, 1, 1]))
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    line_ids = np.asarray(line_ids, dtype=np.int64).reshape(-1)
    corners = np.asarray(corners, dtype=np.int64).reshape(-1)
    count = points.shape[0]
    if count < 2 or corners.size < 2:
        raise ValueError("fit_polylines: needs at least 2 points and 2 corners")
    if not np.isfinite(points).all():
        raise ValueError("fit_polylines: points must be finite; drop invalid readings first")
    starts = np.flatnonzero(np.diff(line_ids)) + 1
    firsts, lasts = np.concatenate(([0], starts)), np.concatenate((starts, [count])) - 1
    if line_ids.shape != (count,) or (np.diff(line_ids) < 0).any() or (lasts <= firsts).any():
        raise ValueError(
            "fit_polylines: line_ids must give each reading its interval, non-decreasing, "
            "each interval at least 2 readings"
        )
    if (
        corners[0] != 0 or corners[-1] != count - 1 or (np.diff(corners) <= 0).any()
        or not (np.isin(firsts, corners).all() and np.isin(lasts, corners).all())
    ):
        raise ValueError(
            "fit_polylines: corners must increase from 0 to the last point's position and "
            "hold every interval's first and last reading"
        )
    if not epsilon > 0.0:
        raise ValueError(f"fit_polylines: epsilon must be > 0 m, got {epsilon!r}")
    return _fitted(
        np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1]), line_ids,
        corners, float(epsilon),
    )


@overload(fit_polylines, jit_options={"cache": True})
def _fit_polylines_compiled(points, line_ids, corners, epsilon):  # pragma: no cover
    """Return :func:`fit_polylines` for compiled callers: their arrays are valid already."""

    def fit(points, line_ids, corners, epsilon):
        # The fit reads the readings' coordinates as two contiguous arrays.
        x, y = np.empty(points.shape[0]), np.empty(points.shape[0])
        for k in range(points.shape[0]):
            x[k], y[k] = points[k, 0], points[k, 1]
        return _fitted(x, y, line_ids, corners, epsilon)

    return fit


@numba.njit(cache=True)
def _weight(px, py, norm, bx, by):  # pragma: no cover - compiled
    """Return a reading's weight in a fit along the beams to a line along ``(bx, by)``.

    ``(px, py)`` is the reading, ``norm`` its range; the weight is ``1 / sine^2`` of the
    beam's incidence on the line (the sine at least ``MIN_BEAM_SINE``), or 1 when no
    direction is given (``bx = by = 0``): a plain fit.
    """
    if bx == 0.0 and by == 0.0:
        return 1.0
    sine = abs(px * by - py * bx) / norm if norm > 0.0 else 1.0
    return 1.0 / max(sine, MIN_BEAM_SINE) ** 2


@numba.njit(cache=True)
def _fit(x, y, norms, first, last, bx, by, weights):  # pragma: no cover - compiled
    """Return ``(mx, my, dx, dy)``: centroid and principal direction of readings first..last.

    Each reading is weighted by :func:`_weight` (its range in ``norms``) against
    ``(bx, by)``; ``(0, 0)`` gives the plain total least squares fit (every weight exactly
    1, so bit for bit the unweighted sums; ``norms`` is then not read). ``weights`` is
    scratch as long as ``x``: the weights of the first pass, read again by the second.
    """
    total = 0.0
    mx = 0.0
    my = 0.0
    for k in range(first, last + 1):
        weight = _weight(x[k], y[k], norms[k], bx, by)
        weights[k] = weight
        total += weight
        mx += weight * x[k]
        my += weight * y[k]
    mx /= total
    my /= total
    sxx = 0.0
    sxy = 0.0
    syy = 0.0
    for k in range(first, last + 1):
        weight = weights[k]
        u = x[k] - mx
        v = y[k] - my
        sxx += weight * u * u
        sxy += weight * u * v
        syy += weight * v * v
    if sxx + syy == 0.0:
        return mx, my, 0.0, 0.0
    angle = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    return mx, my, math.cos(angle), math.sin(angle)


@numba.njit(cache=True)
def _fit_rays(x, y, norms, first, last, weights):  # pragma: no cover - compiled
    """Return ``(mx, my, dx, dy)``: the line through readings first..last along their beams.

    A reading's range error lies along its beam (``norms`` holds the ranges), so its
    distance from the line is that error times the sine of the beam's incidence on the
    line. Total least squares with each squared distance weighted by 1 / sine^2 (the sines
    taken on the unweighted fit's line, at least ``MIN_BEAM_SINE``) minimises the squared
    errors along the beams: the maximum-likelihood line under range noise, and PLE's
    ray-wise metric.
    """
    mx, my, dx, dy = _fit(x, y, norms, first, last, 0.0, 0.0, weights)
    if dx == 0.0 and dy == 0.0:
        return mx, my, dx, dy
    cx, cy, ex, ey = _fit(x, y, norms, first, last, dx, dy, weights)
    if ex == 0.0 and ey == 0.0:
        return mx, my, dx, dy
    return cx, cy, ex, ey


@numba.njit(cache=True)
def _project(px, py, mx, my, dx, dy):  # pragma: no cover - compiled
    """Return the projection of ``(px, py)`` onto a line."""
    along = (px - mx) * dx + (py - my) * dy
    return mx + along * dx, my + along * dy


@numba.njit(cache=True)
def _mixed_pixel(x, y, end, corner, low, high, weights):  # pragma: no cover - compiled
    """Return whether reading ``end`` next to ``corner`` is a mixed pixel (see above).

    ``weights`` is scratch as long as ``x`` (for :func:`_fit`).
    """
    px = x[end]
    py = y[end]
    norm = math.hypot(px, py)
    ex = x[corner] - px
    ey = y[corner] - py
    step = math.hypot(ex, ey)
    if norm == 0.0 or step == 0.0 or abs(px * ey - py * ex) / (norm * step) >= MIXED_PIXEL_SINE:
        return False
    mx, my, dx, dy = _fit(x, y, x, low, high, 0.0, 0.0, weights)  # plain: no ranges read
    sine = (px * dy - py * dx) / norm
    if sine == 0.0:
        return False
    # Beyond the line: the reading is farther along its beam than where the beam
    # crosses it (at t = cross(m, d) / cross(beam, d)).
    return norm > (mx * dy - my * dx) / sine


@numba.njit(cache=True)
def _fitted(x, y, line_ids, corners, epsilon):  # pragma: no cover - compiled
    """Return :func:`fit_polylines` of readings given as two contiguous coordinate arrays."""
    count = corners.size
    # The readings' ranges, once: every fit along the beams weighs each reading by them.
    norms = np.empty(x.size)
    for k in range(x.size):
        norms[k] = math.hypot(x[k], y[k])
    out = np.empty((count, 2))
    kept = np.empty(count, np.int64)
    lines = np.empty(count, np.int64)
    merged = np.empty(count, np.int64)
    fits = np.empty((count, 4))
    # Per edge, the last reading of the span whose line ``fits`` holds (-1: none yet).
    fitted = np.empty(count, np.int64)
    weights = np.empty(x.size)
    written = 0
    start = 0
    while start < count:
        stop = start
        while stop + 1 < count and line_ids[corners[stop + 1]] == line_ids[corners[start]]:
            stop += 1
        size = _merged_edges(x, y, norms, corners, start, stop, epsilon, merged, fits, fitted,
                             weights)
        for vertex in range(size):
            reading = merged[vertex]
            if vertex == 0 or vertex == size - 1:
                edge = 0 if vertex == 0 else size - 2
                other = merged[1] if vertex == 0 else merged[size - 2]
                vx, vy = _end_vertex(x[reading], y[reading], x[other], y[other], fits[edge, 0],
                                     fits[edge, 1], fits[edge, 2], fits[edge, 3], epsilon)
            else:
                vx, vy = _inner_vertex(x, y, merged[vertex - 1], reading, merged[vertex + 1],
                                       fits, vertex)
            out[written, 0] = vx
            out[written, 1] = vy
            kept[written] = reading
            lines[written] = line_ids[reading]
            written += 1
        start = stop + 1
    return out[:written].copy(), kept[:written].copy(), lines[:written].copy()


@numba.njit(cache=True)
def _merged_edges(
    x, y, norms, corners, start, stop, epsilon, merged, fits, fitted, weights
):  # pragma: no cover - compiled
    """Write the corners that stay of one interval, ``corners[start..stop]``; return how many.

    Steps 1 and 2 of the module docstring: ``merged`` gets the corners that stay,
    ``fits[e]`` the line ``(mx, my, dx, dy)`` fitted along the beams to edge ``e``
    (``fitted`` and ``weights`` are scratch).
    """
    # Merge step: drop a corner while one line fits its two edges within epsilon.
    # The line of the last merge that dropped a corner spans merged[size - 1]..span:
    # when the next corner stays, it is the edge's own line (no second fit).
    size = 1
    merged[0] = corners[start]
    span = -1
    for j in range(start + 1, stop):
        mx, my, dx, dy = _fit_rays(x, y, norms, merged[size - 1], corners[j + 1], weights)
        # Whether a reading lies farther than epsilon from that line (inline: a kernel
        # of its own costs a compilation at first use); the first one decides.
        apart = False
        for k in range(merged[size - 1], corners[j + 1] + 1):
            if abs((x[k] - mx) * dy - (y[k] - my) * dx) > epsilon:
                apart = True
                break
        if apart:
            fitted[size - 1] = span if span == corners[j] else -1
            merged[size] = corners[j]
            size += 1
            span = -1
        else:
            span = corners[j + 1]
            fits[size - 1, 0], fits[size - 1, 1] = mx, my
            fits[size - 1, 2], fits[size - 1, 3] = dx, dy
    fitted[size - 1] = span if span == corners[stop] else -1
    merged[size] = corners[stop]
    size += 1
    # A one-reading end edge from a mixed pixel goes, the rest of the edge ends the line.
    if size >= 3 and merged[size - 1] - merged[size - 2] == 1 and _mixed_pixel(
            x, y, merged[size - 1], merged[size - 2], merged[size - 3], merged[size - 2],
            weights):
        size -= 1
    if size >= 3 and merged[1] - merged[0] == 1 and _mixed_pixel(
            x, y, merged[0], merged[1], merged[1], merged[2], weights):
        for k in range(size - 1):
            merged[k] = merged[k + 1]
        for k in range(size - 2):
            fitted[k] = fitted[k + 1]
            for value in range(4):
                fits[k, value] = fits[k + 1, value]
        size -= 1
    for edge in range(size - 1):
        if fitted[edge] == merged[edge + 1]:
            continue
        mx, my, dx, dy = _fit_rays(x, y, norms, merged[edge], merged[edge + 1], weights)
        fits[edge, 0] = mx
        fits[edge, 1] = my
        fits[edge, 2] = dx
        fits[edge, 3] = dy
    return size


@numba.njit(cache=True)
def _end_vertex(px, py, ox, oy, mx, my, dx, dy, epsilon):  # pragma: no cover - compiled
    """Return an end vertex: where the end reading's beam crosses its edge's line (step 4).

    ``(px, py)`` is the end reading, ``(ox, oy)`` the edge's other reading and
    ``(mx, my, dx, dy)`` the edge's fitted line.
    """
    norm = math.hypot(px, py)
    sine = (px * dy - py * dx) / norm if norm > 0.0 else 0.0
    if (dx == 0.0 and dy == 0.0) or abs(sine) < MIN_BEAM_SINE:
        return _project(px, py, mx, my, dx, dy)
    # The beam t * (px, py) / norm crosses the line m + s d where
    # t = cross(m, d) / cross(beam, d).
    t = (mx * dy - my * dx) / sine
    cx = t * px / norm
    cy = t * py / norm
    # A reading on the surface puts the crossing its range error times cos(incidence)
    # along the line from itself: at most about epsilon (3 sigma). One off the line (on
    # the next face round a corner, a mixed pixel) moves it outward by its offset over
    # tan(incidence), past the corner: then the reading itself, on the same beam, marks
    # how far the readings reach. Outward: away from the edge's other reading.
    outward = (px - ox) * dx + (py - oy) * dy
    beyond = (cx - px) * dx + (cy - py) * dy
    if beyond * outward <= epsilon * abs(outward):
        return cx, cy
    return px, py


@numba.njit(cache=True)
def _inner_vertex(x, y, before, reading, after, fits, vertex):  # pragma: no cover - compiled
    """Return inner vertex ``vertex`` at reading ``reading``: where its two lines meet (step 3).

    ``before`` and ``after`` are the readings of the neighbouring vertices.
    """
    px, py = x[reading], y[reading]
    vx, vy = px, py
    ax, ay, adx, ady = fits[vertex - 1, 0], fits[vertex - 1, 1], fits[vertex - 1, 2], fits[
        vertex - 1, 3]
    bx, by, bdx, bdy = fits[vertex, 0], fits[vertex, 1], fits[vertex, 2], fits[vertex, 3]
    sine = adx * bdy - ady * bdx
    use_projection = abs(sine) < MIN_CORNER_SINE
    if not use_projection:
        # a + s ad = b + u bd  ->  s = cross(b - a, bd) / cross(ad, bd)
        s = ((bx - ax) * bdy - (by - ay) * bdx) / sine
        vx = ax + s * adx
        vy = ay + s * ady
        chord = min(
            math.hypot(px - x[before], py - y[before]),
            math.hypot(x[after] - px, y[after] - py),
        )
        use_projection = math.hypot(vx - px, vy - py) > MAX_CORNER_SHIFT * chord
    if use_projection:
        qx, qy = _project(px, py, ax, ay, adx, ady)
        rx, ry = _project(px, py, bx, by, bdx, bdy)
        vx = 0.5 * (qx + rx)
        vy = 0.5 * (qy + ry)
    return vx, vy
