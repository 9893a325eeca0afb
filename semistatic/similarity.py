"""Shape similarity of two polylines from their tangent functions (paper eq. 1-2).

The tangent function ``T(s)`` of a polyline gives, at normalised arc length ``s`` in
``[0, 1]``, the direction of the edge there: a step function (the "tangent histogram" of
the paper's Fig. 2). Edge angles are unwrapped along the polyline, so a polyline that
keeps turning left has an increasing ``T`` without 2 pi jumps. The similarity is

    s(P0, P1) = (integral (T1 - T0 - theta_0)^2 ds) * max(l1 / l0, l0 / l1),
    theta_0 = integral (T1 - T0) ds,

where ``theta_0`` is the rotation that minimises the integral (DESIGN.md detail 4; the
paper's ``+ theta_0`` is read as this minimiser). The integral is exact: both step
functions are constant between consecutive breakpoints of their union. ``s`` is 0 for
rigidly moved copies, grows with shape difference and with length ratio, and is
symmetric. Both polylines must be traversed in the same direction (scan order).

Degenerate polylines (fewer than two distinct vertices, i.e. zero length) have no shape:
their tangent function is empty and their similarity to anything is ``inf``, so an
association never picks them on shape.

Examples
--------
>>> corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
>>> float(similarity(corner, corner + 5.0))
0.0
>>> round(float(similarity(corner, [[0.0, 0.0], [2.0, 0.0]])), 4)  # a 90 deg turn vs none
0.6169
"""

from __future__ import annotations

import itertools
import math
from bisect import bisect_right

import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import wrap_angle
from semistatic.polyline import Polyline, as_polyline

__all__ = ["similarity", "tangent_function"]

# Polylines are immutable, so a polyline's tangent function is computed once and kept in
# the polyline's own instance dictionary under this key (as ``functools.cached_property``
# does), for as long as the polyline lives.
_CACHE_KEY = "_tangent_function"

# Up to this many vertices the tangent function is built with Python floats, and up to
# this many breakpoints in the union of two the integral is taken with them too: numpy
# costs about 1 us per call whatever the size, Python about 0.3 us per edge.
PYTHON_VERTICES = 48

# A tangent function as plain lists: (breaks, angles, length).
_Tangent = tuple[list[float], list[float], float]


def _tangent(polyline: Polyline | ArrayLike) -> _Tangent:
    """Return ``(breaks, angles, length)`` of a polyline, cached for ``Polyline`` objects."""
    if isinstance(polyline, Polyline):
        cached = polyline.__dict__.get(_CACHE_KEY)
        if cached is None:
            cached = _compute_tangent(polyline.points)
            polyline.__dict__[_CACHE_KEY] = cached
        return cached
    return _compute_tangent(as_polyline(polyline).points)


def _compute_tangent(points: np.ndarray) -> _Tangent:
    """Return the tangent function of ``(N, 2)`` vertices the cheaper way for the size."""
    if points.shape[0] <= PYTHON_VERTICES:
        return _tangent_lists(points.tolist())
    breaks, angles, total = _tangent_arrays(points)
    return breaks.tolist(), angles.tolist(), total


def _tangent_lists(rows: list[list[float]]) -> _Tangent:
    """Return the tangent function of vertices ``rows`` with Python floats."""
    lengths, directions = [], []
    for (x0, y0), (x1, y1) in itertools.pairwise(rows):
        dx, dy = x1 - x0, y1 - y0
        length = math.hypot(dx, dy)
        # Zero-length edges (repeated vertices) have no direction and no extent: skip them.
        if length > 0.0:
            lengths.append(length)
            directions.append(math.atan2(dy, dx))
    if not lengths:
        return [0.0], [], 0.0
    # Unwrap: each turn in (-pi, pi], added up along the polyline.
    first = directions[0]
    angles, swept = [first], 0.0
    for previous, direction in itertools.pairwise(directions):
        swept += wrap_angle(direction - previous)
        angles.append(first + swept)
    arcs, total = [0.0], 0.0
    for length in lengths:
        total += length
        arcs.append(total)
    breaks = [arc / total for arc in arcs]
    breaks[-1] = 1.0
    return breaks, angles, total


def _tangent_arrays(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Return the tangent function of ``(N, 2)`` vertices with numpy (for long polylines)."""
    edges = points[1:] - points[:-1]
    lengths = np.hypot(edges[:, 0], edges[:, 1])
    # The same steps as _tangent_lists, on arrays.
    proper = lengths > 0.0
    if not proper.all():
        edges, lengths = edges[proper], lengths[proper]
    total = float(lengths.sum())
    if edges.shape[0] == 0:
        return np.zeros(1), np.zeros(0), 0.0
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    turns = np.pi - np.mod(np.pi - (angles[1:] - angles[:-1]), 2.0 * np.pi)
    angles[1:] = angles[0] + np.cumsum(turns)
    breaks = np.empty(lengths.size + 1)
    breaks[0] = 0.0
    np.cumsum(lengths, out=breaks[1:])
    breaks /= total
    breaks[-1] = 1.0
    return breaks, angles, total


def tangent_function(polyline: Polyline | ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Return the tangent step function of a polyline over normalised arc length.

    Parameters
    ----------
    polyline
        A :class:`Polyline` or an ``(N, 2)`` array of vertices.

    Returns
    -------
    breaks : numpy.ndarray
        ``(K + 1,)`` normalised arc lengths from 0 to 1, one per boundary between the ``K``
        non-zero-length edges. ``[0.]`` for a polyline of zero length.
    angles : numpy.ndarray
        ``(K,)`` edge directions in radians, ``T(s) = angles[j]`` for
        ``breaks[j] <= s < breaks[j + 1]``. The first lies in ``(-pi, pi]``, the others
        are unwrapped along the polyline: each turn is in ``(-pi, pi]``, so an exact
        U-turn counts as a left turn.

    Examples
    --------
    >>> breaks, angles = tangent_function([[0, 0], [1, 0], [1, 0], [1, 3]])
    >>> breaks, angles.round(4)
    (array([0.  , 0.25, 1.  ]), array([0.    , 1.5708]))
    >>> tangent_function([[2.0, 1.0]])
    (array([0.]), array([], dtype=float64))
    """
    breaks, angles, _ = _tangent(polyline)
    breaks, angles = np.array(breaks), np.array(angles, dtype=np.float64)
    breaks.flags.writeable = False
    angles.flags.writeable = False
    return breaks, angles


def similarity(p0: Polyline | ArrayLike, p1: Polyline | ArrayLike) -> float:
    """Return the shape similarity ``s(P0, P1)`` of eq. (1); 0 means the same shape.

    Parameters
    ----------
    p0, p1
        Polylines (or ``(N, 2)`` arrays) traversed in the same direction.

    Returns
    -------
    float
        ``(integral (T1 - T0 - theta_0)^2 ds) * max(l1 / l0, l0 / l1) >= 0``, with
        ``theta_0`` the mean of ``T1 - T0`` (the minimising rotation). ``inf`` when either
        polyline has zero length (fewer than two distinct vertices).

    Examples
    --------
    >>> wall = [[0.0, 0.0], [4.0, 0.0]]
    >>> float(similarity(wall, [[1.0, 1.0], [1.0, 3.0]]))  # same shape: rotation is free
    0.0
    >>> left, right = [[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 0], [1, -1]]
    >>> round(float(similarity(left, right)), 4)  # (pi / 2)^2: turns of opposite sign
    2.4674
    >>> similarity(wall, [[1.0, 1.0]])
    inf
    """
    breaks0, angles0, length0 = _tangent(p0)
    breaks1, angles1, length1 = _tangent(p1)
    if length0 == 0.0 or length1 == 0.0:
        return math.inf
    if len(breaks0) + len(breaks1) <= PYTHON_VERTICES:
        integral = _integral_lists(breaks0, angles0, breaks1, angles1)
    else:
        integral = _integral_arrays(
            np.array(breaks0), np.array(angles0), np.array(breaks1), np.array(angles1)
        )
    return integral * max(length1 / length0, length0 / length1)


def _integral_lists(
    breaks0: list[float], angles0: list[float], breaks1: list[float], angles1: list[float]
) -> float:
    """Return ``integral (T1 - T0 - theta_0)^2 ds`` with Python floats."""
    # Between consecutive breakpoints of the union both step functions are constant; a
    # repeated breakpoint only adds an interval of zero width. On [u_k, u_k+1) edge j of a
    # polyline applies when j of its inner breaks are at or before u_k.
    union = sorted(breaks0 + breaks1)
    inner0, inner1 = breaks0[1:-1], breaks1[1:-1]
    widths = [b - a for a, b in itertools.pairwise(union)]
    differences = [
        angles1[bisect_right(inner1, at)] - angles0[bisect_right(inner0, at)] for at in union[:-1]
    ]
    theta_0 = sum(w * d for w, d in zip(widths, differences, strict=True))
    residuals = [d - theta_0 for d in differences]
    return sum(w * (r * r) for w, r in zip(widths, residuals, strict=True))


def _integral_arrays(
    breaks0: np.ndarray, angles0: np.ndarray, breaks1: np.ndarray, angles1: np.ndarray
) -> float:
    """Return ``integral (T1 - T0 - theta_0)^2 ds`` with numpy (for long polylines)."""
    union = np.sort(np.concatenate((breaks0, breaks1)))
    width = np.diff(union)
    index0 = np.searchsorted(breaks0[1:-1], union[:-1], side="right")
    index1 = np.searchsorted(breaks1[1:-1], union[:-1], side="right")
    difference = angles1[index1] - angles0[index0]
    theta_0 = float(width @ difference)
    residual = difference - theta_0
    return float(width @ (residual * residual))
