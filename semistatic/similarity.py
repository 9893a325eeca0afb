"""Shape similarity of two polylines from their tangent functions (paper eq. 1-2).

The tangent function ``T(s)`` of a polyline gives, at normalised arc length ``s`` in
``[0, 1]``, the direction of the edge there: a step function (the "tangent histogram" of
the paper's Fig. 2). Edge angles are unwrapped along the polyline, so a polyline that
keeps turning left has an increasing ``T`` without 2 pi jumps. The similarity is

    s(P0, P1) = (integral (T1 - T0 - theta_0)^2 ds) * max(l1 / l0, l0 / l1),
    theta_0 = integral (T1 - T0) ds,

where ``theta_0`` is the rotation that minimises the integral (docs/design.md#detail-4; the
paper's ``+ theta_0`` is read as this minimiser). The integral is exact: both step
functions are constant between consecutive breakpoints of their union. ``s`` is 0 for
rigidly moved copies, grows with shape difference and with length ratio, and is
symmetric. Both polylines must be traversed in the same direction (scan order).

Degenerate polylines (fewer than two distinct vertices, i.e. zero length) have no shape:
their tangent function is empty and their similarity to anything is ``inf``, so an
association never picks them on shape.

One compiled kernel (numba) builds a tangent function and one takes the similarity of
two, whatever the size; :func:`similarity` of two polyline sets runs both on every pair in
one call.

Examples
--------
>>> corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
>>> float(similarity(corner, corner + 5.0))
0.0
>>> round(float(similarity(corner, [[0.0, 0.0], [2.0, 0.0]])), 4)  # a 90 deg turn vs none
0.6169
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import wrap_angle_compiled
from semistatic.polyline import PackedPolylines, Polyline, as_polyline

__all__ = [
    "similarity",
    "tangent_function",
]

# Polylines are immutable, so a polyline's tangent function is computed once and kept in
# the polyline's own instance dictionary under this key (as ``functools.cached_property``
# does), for as long as the polyline lives.
_CACHE_KEY = "_tangent_function"

# A tangent function: (breaks, angles, length), both arrays read-only.
_Tangent = tuple[np.ndarray, np.ndarray, float]


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
    breaks, angles, total = _tangent_of(np.array(points, dtype=np.float64, order="C"))
    breaks.flags.writeable = False
    angles.flags.writeable = False
    return breaks, angles, total


@numba.njit(cache=True)
def _tangent_of(points):  # pragma: no cover - compiled
    """Return ``(breaks, angles, length)`` of ``(N, 2)`` C-contiguous float64 vertices.

    :func:`tangent_function` and the length.
    """
    count = max(points.shape[0] - 1, 0)
    lengths = np.empty(count)
    angles = np.empty(count)
    edges = 0
    for k in range(count):
        dx = points[k + 1, 0] - points[k, 0]
        dy = points[k + 1, 1] - points[k, 1]
        length = math.hypot(dx, dy)
        # Zero-length edges (repeated vertices) have no direction and no extent: skip them.
        if length > 0.0:
            lengths[edges] = length
            angles[edges] = math.atan2(dy, dx)
            edges += 1
    if edges == 0:
        return np.zeros(1), np.zeros(0), 0.0
    # Unwrap: each turn in (-pi, pi], added up along the polyline.
    directions = angles[:edges].copy()
    swept = 0.0
    for k in range(1, edges):
        swept += wrap_angle_compiled(directions[k] - directions[k - 1])
        angles[k] = directions[0] + swept
    breaks = np.empty(edges + 1)
    breaks[0] = 0.0
    total = 0.0
    for k in range(edges):
        total += lengths[k]
        breaks[k + 1] = total
    for k in range(edges):
        breaks[k] /= total
    breaks[edges] = 1.0
    return breaks, angles[:edges].copy(), total


@numba.njit(cache=True)
def _integral(breaks0, angles0, breaks1, angles1):  # pragma: no cover - compiled
    """Return ``integral (T1 - T0 - theta_0)^2 ds`` of two tangent functions."""
    # Between consecutive breakpoints of the union both step functions are constant; a
    # repeated breakpoint only adds an interval of zero width. On [u_k, u_k+1) edge j of a
    # polyline applies when j of its inner breaks are at or before u_k.
    size0, size1 = breaks0.size, breaks1.size
    union = np.empty(size0 + size1)
    first, second = 0, 0
    for k in range(union.size):  # merge the two sorted break lists
        if second >= size1 or (first < size0 and breaks0[first] <= breaks1[second]):
            union[k] = breaks0[first]
            first += 1
        else:
            union[k] = breaks1[second]
            second += 1
    count = union.size - 1
    widths = np.empty(count)
    differences = np.empty(count)
    edge0, edge1 = 0, 0
    theta_0 = 0.0
    for k in range(count):
        at = union[k]
        while edge0 < size0 - 2 and breaks0[edge0 + 1] <= at:
            edge0 += 1
        while edge1 < size1 - 2 and breaks1[edge1 + 1] <= at:
            edge1 += 1
        widths[k] = union[k + 1] - at
        differences[k] = angles1[edge1] - angles0[edge0]
        theta_0 += widths[k] * differences[k]
    integral = 0.0
    for k in range(count):
        residual = differences[k] - theta_0
        integral += widths[k] * (residual * residual)
    return integral


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
    return breaks, angles


@numba.njit(cache=True)
def _tangent_similarity(
    breaks0, angles0, length0, breaks1, angles1, length1
):  # pragma: no cover - compiled
    """Return :func:`similarity` of two tangent functions and their lengths.

    The integral of :func:`_integral` times the length ratio; ``inf`` when either length
    is 0 (no shape).
    """
    if length0 == 0.0 or length1 == 0.0:
        return math.inf
    integral = _integral(breaks0, angles0, breaks1, angles1)
    return integral * max(length1 / length0, length0 / length1)


def similarity(
    p0: Polyline | ArrayLike | PackedPolylines, p1: Polyline | ArrayLike | PackedPolylines
) -> float | np.ndarray:
    """Return the shape similarity ``s(P0, P1)`` of eq. (1); 0 means the same shape.

    Parameters
    ----------
    p0, p1
        Polylines (or ``(N, 2)`` arrays) traversed in the same direction; or two
        :class:`~semistatic.polyline.PackedPolylines` of equal length, compared element by
        element in one compiled call (as shapely's functions take arrays of geometries).

    Returns
    -------
    float or numpy.ndarray
        ``(integral (T1 - T0 - theta_0)^2 ds) * max(l1 / l0, l0 / l1) >= 0``, with
        ``theta_0`` the mean of ``T1 - T0`` (the minimising rotation). ``inf`` when either
        polyline has zero length (fewer than two distinct vertices). For two sets, the
        ``(K,)`` similarities of their pairs.

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
    >>> similarity(PackedPolylines([left, wall]), PackedPolylines([right, wall])).round(4)
    array([2.4674, 0.    ])
    """
    if isinstance(p0, PackedPolylines) and isinstance(p1, PackedPolylines):
        if len(p0) != len(p1):
            raise ValueError(
                f"similarity: two polyline sets must be as long, got {len(p0)} and {len(p1)}"
            )
        return _similarities(p0.points, p0.offsets, p1.points, p1.offsets)
    return _tangent_similarity(*_tangent(p0), *_tangent(p1))


@numba.njit(cache=True)
def _similarities(points0, offsets0, points1, offsets1):  # pragma: no cover - compiled
    """Return the similarity of each pair of packed polylines ``k`` of both sides."""
    values = np.empty(offsets0.size - 1)
    for k in range(values.size):
        breaks0, angles0, length0 = _tangent_of(points0[offsets0[k] : offsets0[k + 1]])
        breaks1, angles1, length1 = _tangent_of(points1[offsets1[k] : offsets1[k + 1]])
        values[k] = _tangent_similarity(breaks0, angles0, length0, breaks1, angles1, length1)
    return values
