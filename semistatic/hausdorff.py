"""Restricted Hausdorff distance between polylines (paper eq. 3, DESIGN.md detail 5).

The Hausdorff distance of two polylines is the largest distance from a point of one curve
to the other curve. When one polyline is a partial view of the other it measures the
unseen part, not the displacement; so both are first *restricted* to their overlap:

- ``"vertex"`` (the paper's, default): for each vertex of P1 take the nearest segment of
  P0; ``P0|P1`` keeps P0's vertices from the start of the lowest such segment to the end
  of the highest. A long wall with only two vertices is never shortened this way.
- ``"projection"``: cut P0 at the orthogonal projections of P1 onto it, i.e. keep the
  part of P0 between the first and the last arc-length position onto which a vertex of
  P1 projects (for a scan-ordered partial view: the projections of its end points).

The distance between the restricted polylines is taken between the *continuous* curves,
not only their vertices, to within ``HAUSDORFF_TOLERANCE``. Polylines of a few vertices
(the usual case: up to ``PYTHON_PAIRS`` vertex pairs) go through Python-float twins of
the projection restriction and of the vectorised branch and bound, which run the same
steps (in the same rounds).

Conventions for degenerate input: a single vertex is a point (distances to it are point
distances); a polyline with no vertices is at ``inf`` from everything, and restricting
to (or restricting) an empty or single-vertex polyline leaves the polyline unchanged.

Examples
--------
>>> wall = Polyline([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
>>> seen = [[1.5, 0.05], [2.5, 0.05]]  # a partial view, 5 cm off
>>> round(hausdorff(wall, seen), 3)  # dominated by the unseen part of the wall
1.501
>>> restrict(wall, seen).points[:, 0]
array([1., 2., 3.])
>>> round(restricted_hausdorff(wall, seen), 3)  # whole segments are kept
0.502
>>> round(restricted_hausdorff(wall, seen, mode="projection"), 3)
0.05
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from numpy.typing import ArrayLike

from semistatic.polyline import Polyline, as_polyline

__all__ = ["HAUSDORFF_TOLERANCE", "hausdorff", "restrict", "restricted_hausdorff"]

# The continuous Hausdorff distance is returned within this (m) below the true value
# (branch and bound on the distance along each edge stops when no piece can beat the
# best distance found by more than this).
HAUSDORFF_TOLERANCE = 1e-4

# Pieces are split at the chord crossing for this many rounds, then halved; a split never
# lands closer than this fraction to a piece's ends (both guarantee progress).
_CHORD_SPLITS = 8
_MIN_SPLIT = 0.01
# Keeps the chord-crossing division finite when one segment is nearest at both ends.
_TINY = 1e-300

_MODES = ("vertex", "projection")

# Up to this many vertex pairs (N0 * N1) the distance is computed with Python floats:
# numpy costs about 1 us per call whatever the size, and the vectorised branch and bound
# makes 50-170 calls, while the Python twin costs about 0.3 us per point-segment distance.
PYTHON_PAIRS = 100


class _Segments:
    """Segments as complex numbers, prepared once for many point-to-segment queries."""

    __slots__ = ("direction", "ends", "inverse", "reverse", "starts")

    def __init__(self, starts: np.ndarray, ends: np.ndarray) -> None:
        self.starts = starts
        self.ends = ends
        self.direction = ends - starts
        self.reverse = np.conj(self.direction)
        length2 = (self.direction * self.reverse).real
        self.inverse = 1.0 / np.where(length2 > 0.0, length2, np.inf)  # null segment: t = 0

    def distances(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(distance, t)`` from complex ``points`` (M,) to every segment (M, S).

        A point whose nearest point is a segment end gets exactly ``|p - end|``, so two
        segments sharing a vertex tie exactly there (and argmin picks the lower one).
        """
        offset = points[:, None] - self.starts
        t = (offset * self.reverse).real * self.inverse
        np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
        gap = np.where(t < 1.0, offset - t * self.direction, points[:, None] - self.ends)
        return np.abs(gap), t


def _complex(points: np.ndarray) -> np.ndarray:
    """Return ``(N, 2)`` float points as ``(N,)`` complex numbers ``x + iy``."""
    return np.ascontiguousarray(points, dtype=np.float64).view(np.complex128)[:, 0]


def _segments(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the start and end points of a polyline's segments (a point: one null one)."""
    if points.shape[0] == 1:
        return points, points
    return points[:-1], points[1:]


def _span(nearest: np.ndarray) -> tuple[int, int]:
    """Return the first and last vertex (inclusive) spanned by the nearest segments."""
    segments = nearest.tolist()  # a handful of ints: plain Python beats two reductions
    return min(segments), max(segments) + 1


def _restricted(p0: Polyline, p1: Polyline, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """Return the vertices and scan indices of ``P0|P1``."""
    if mode not in _MODES:
        raise ValueError(f"restrict: mode must be one of {_MODES}, got {mode!r}")
    points, indices = p0.points, p0.scan_indices
    if points.shape[0] < 2 or p1.points.shape[0] == 0:
        return points, indices
    vertices = _complex(points)
    distance, t = _Segments(vertices[:-1], vertices[1:]).distances(_complex(p1.points))
    # argmin picks the lowest segment on ties, as eq. (3) with its argmin over j.
    nearest = np.argmin(distance, axis=1)
    if mode == "vertex":
        low, high = _span(nearest)
        if low == 0 and high == points.shape[0] - 1:
            return points, indices
        return points[low : high + 1], indices[low : high + 1]
    lengths = p0.edge_lengths
    arc = np.concatenate(([0.0], np.cumsum(lengths)))
    position = arc[nearest] + t[np.arange(nearest.size), nearest] * lengths[nearest]
    first, last = int(np.argmin(position)), int(np.argmax(position))
    start, stop = position[first], position[last]

    def cut(vertex: int) -> tuple[np.ndarray, int]:
        segment, fraction = nearest[vertex], t[vertex, nearest[vertex]]
        point = points[segment] + fraction * (points[segment + 1] - points[segment])
        return point, int(indices[segment + (1 if fraction >= 0.5 else 0)])

    start_point, start_index = cut(first)
    if stop == start:
        return start_point[None, :], np.array([start_index])
    stop_point, stop_index = cut(last)
    inside = (arc > start) & (arc < stop)
    return (
        np.vstack((start_point, points[inside], stop_point)),
        np.concatenate(([start_index], indices[inside], [stop_index])),
    )


def restrict(p0: Polyline | ArrayLike, p1: Polyline | ArrayLike, mode: str = "vertex") -> Polyline:
    """Return ``P0|P1``, polyline ``p0`` restricted to the part facing ``p1``.

    Parameters
    ----------
    p0, p1
        Polylines or ``(N, 2)`` arrays.
    mode
        ``"vertex"`` (paper eq. 3): P0's vertices from the start vertex of the lowest to
        the end vertex of the highest segment of P0 nearest to a vertex of P1.
        ``"projection"``: P0 cut at the first and last arc-length positions of the
        orthogonal projections of P1's vertices; the cut points take the scan index of
        the nearer vertex of their segment. If they coincide the result is one point.

    Returns
    -------
    Polyline
        The restriction, with the scan indices of the kept vertices. ``p0`` itself when it
        has fewer than two vertices or ``p1`` is empty.

    Examples
    --------
    >>> corridor = [[0, 0], [2, 0], [4, 0], [6, 0]]
    >>> restrict(corridor, [[2.5, 0.1], [3.5, 0.1]]).scan_indices
    array([1, 2])
    >>> restrict(corridor, [[2.5, 0.1], [3.5, 0.1]], mode="projection").points
    array([[2.5, 0. ],
           [3.5, 0. ]])
    """
    p0 = as_polyline(p0)
    points, indices = _restricted(p0, as_polyline(p1), mode)
    if points is p0.points:
        return p0
    return Polyline(points, indices)


def _hausdorff_core(points0: np.ndarray, points1: np.ndarray, vertex_restricted: bool) -> float:
    """Return the symmetric Hausdorff distance of two polylines as continuous curves.

    With ``vertex_restricted`` both are first restricted to each other (eq. 3); the
    vertex-to-segment distances that choose the restriction are the same that start the
    distance computation, so all of them come from one matrix.

    Both directed distances are found together by branch and bound along the edges of
    the source curve. On a piece ``[a, b]`` of an edge the distance ``d_j`` to each target
    segment is convex, hence below its chord; for the segments ``i`` and ``j`` nearest to
    ``a`` and ``b``, the maximum of ``f = min_j d_j`` on the piece is at most the crossing
    value of their chords (``max(f(a), f(b))`` when ``i`` serves both ends). Pieces whose
    bound beats the best value found by more than ``HAUSDORFF_TOLERANCE`` are split at the
    chord crossing, which is exact when both distances are linear (to segment
    interiors). Every ``d_j`` is 1-Lipschitz, so the bound exceeds ``f(a)`` by at most
    the piece length: halving after ``_CHORD_SPLITS`` rounds ends the search.
    """
    count0, count1 = points0.shape[0], points1.shape[0]
    if count0 == 0 or count1 == 0:
        return math.inf
    vertices = _complex(np.concatenate((points0, points1)))
    starts0, ends0 = _segments(vertices[:count0])
    starts1, ends1 = _segments(vertices[count0:])
    segments0 = starts0.shape[0]
    segments = _Segments(np.concatenate((starts0, starts1)), np.concatenate((ends0, ends1)))
    distance, _ = segments.distances(vertices)
    # Vertex range [low, high] of each polyline taking part; its segments [low, high).
    low0, high0, low1, high1 = 0, count0 - 1, 0, count1 - 1
    if vertex_restricted and count0 >= 2 and count1 >= 2:
        low0, high0 = _span(np.argmin(distance[count0:, :segments0], axis=1))
        low1, high1 = _span(np.argmin(distance[:count0, segments0:], axis=1))
    # Each vertex may only measure against the other polyline's kept segments.
    blocked = np.full(distance.shape, np.inf)
    blocked[:count0, segments0 + low1 : segments0 + max(high1, low1 + 1)] = 0.0
    blocked[count0:, low0 : max(high0, low0 + 1)] = 0.0
    distance += blocked
    nearest = distance.min(axis=1)
    best = max(
        float(nearest[low0 : high0 + 1].max()),
        float(nearest[count0 + low1 : count0 + high1 + 1].max()),
    )
    # Pieces: the kept edges of both polylines (the pair of vertices across the two
    # polylines is not an edge).
    edge = np.zeros(count0 + count1 - 1, dtype=bool)
    edge[low0:high0] = True
    edge[count0 + low1 : count0 + high1] = True
    if not edge.any():
        return best
    a, b = vertices[:-1][edge], vertices[1:][edge]
    da, db, mask = distance[:-1][edge], distance[1:][edge], blocked[:-1][edge]
    fa, fb = nearest[:-1][edge], nearest[1:][edge]
    rounds = 0
    while True:
        rows = np.arange(a.shape[0])
        i, j = np.argmin(da, axis=1), np.argmin(db, axis=1)
        # Chord of d_i runs from fa to end_i; chord of d_j from start_j to fb.
        end_i, start_j = db[rows, i], da[rows, j]
        lead = start_j - fa
        crossing = lead / ((end_i - fb) + lead + _TINY)  # in [0, 1]; 0 when i == j
        bound = np.maximum(fa + crossing * (end_i - fa), fb)
        open_ = bound > best + HAUSDORFF_TOLERANCE
        if not open_.any():
            return best
        a, b, da, db, mask, fa, fb = (x[open_] for x in (a, b, da, db, mask, fa, fb))
        bound = bound[open_]
        split = crossing[open_] if rounds < _CHORD_SPLITS else np.full(a.shape[0], 0.5)
        np.minimum(np.maximum(split, _MIN_SPLIT, out=split), 1.0 - _MIN_SPLIT, out=split)
        middle = a + split * (b - a)
        dm, _ = segments.distances(middle)
        dm += mask
        fm = dm.min(axis=1)
        best = max(best, float(fm.max()))
        # A piece whose new point comes within the tolerance of its bound is settled: with
        # linear distances (segment interiors) the chord crossing is the maximum itself.
        unsettled = fm < bound - HAUSDORFF_TOLERANCE
        if not unsettled.any():
            return best
        if not unsettled.all():
            a, b, da, db, mask, fa, fb, middle, dm, fm = (
                x[unsettled] for x in (a, b, da, db, mask, fa, fb, middle, dm, fm)
            )
        a, b = np.concatenate((a, middle)), np.concatenate((middle, b))
        da, db = np.concatenate((da, dm)), np.concatenate((dm, db))
        fa, fb = np.concatenate((fa, fm)), np.concatenate((fm, fb))
        mask = np.concatenate((mask, mask))
        rounds += 1


def _python_segments(rows: list[list[float]]) -> list[tuple[float, ...]]:
    """Return ``(ax, ay, dx, dy, inverse squared length, bx, by)`` per segment (a point: one)."""
    if len(rows) == 1:
        (x, y) = rows[0]
        return [(x, y, 0.0, 0.0, 0.0, x, y)]
    segments = []
    for (ax, ay), (bx, by) in itertools.pairwise(rows):
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        segments.append((ax, ay, dx, dy, 1.0 / length2 if length2 > 0.0 else 0.0, bx, by))
    return segments


def _python_distances(px: float, py: float, segments: list[tuple[float, ...]]) -> list[float]:
    """Return the distances from one point to ``segments``, as :meth:`_Segments.distances`."""
    distances = []
    hypot = math.hypot
    for ax, ay, dx, dy, inverse, bx, by in segments:
        ox, oy = px - ax, py - ay
        t = (ox * dx + oy * dy) * inverse
        if t >= 1.0:
            distances.append(hypot(px - bx, py - by))
        elif t > 0.0:
            distances.append(hypot(ox - t * dx, oy - t * dy))
        else:
            distances.append(hypot(ox, oy))
    return distances


def _python_rows(
    points: list[list[float]], segments: list[tuple[float, ...]]
) -> tuple[list[list[float]], list[float], list[int]]:
    """Return each point's distances to ``segments``, their minimum and its first index."""
    rows, nearest, argmins = [], [], []
    hypot = math.hypot
    for px, py in points:
        # _python_distances, inlined: this is the bulk of the work for small polylines.
        row = []
        for ax, ay, dx, dy, inverse, bx, by in segments:
            ox, oy = px - ax, py - ay
            t = (ox * dx + oy * dy) * inverse
            if t >= 1.0:
                row.append(hypot(px - bx, py - by))
            elif t > 0.0:
                row.append(hypot(ox - t * dx, oy - t * dy))
            else:
                row.append(hypot(ox, oy))
        smallest = min(row)
        rows.append(row)
        nearest.append(smallest)
        argmins.append(row.index(smallest))
    return rows, nearest, argmins


def _sliced_rows(
    rows: list[list[float]], start: int, stop: int
) -> tuple[list[list[float]], list[float], list[int]]:
    """Return :func:`_python_rows` for the segments ``start:stop`` only."""
    rows = [row[start:stop] for row in rows]
    nearest = [min(row) for row in rows]
    return rows, nearest, [row.index(smallest) for row, smallest in zip(rows, nearest, strict=True)]


def _hausdorff_python(
    points0: list[list[float]], points1: list[list[float]], vertex_restricted: bool, limit: float
) -> float:
    """Return :func:`_hausdorff_core` computed with Python floats (fast for a few vertices).

    The same branch and bound in the same rounds, so the result only differs from the
    vectorised one by rounding. Returns as soon as the best distance found exceeds
    ``limit``: it is then a lower bound of the result, and above ``limit`` too.
    """
    count0, count1 = len(points0), len(points1)
    if count0 == 0 or count1 == 0:
        return math.inf
    segments0, segments1 = _python_segments(points0), _python_segments(points1)
    # Vertex-to-segment distances across the two polylines: each vertex's row, its
    # minimum and the first segment attaining it (numpy.argmin's rule).
    to1, nearest_to1, argmin_to1 = _python_rows(points0, segments1)
    to0, nearest_to0, argmin_to0 = _python_rows(points1, segments0)
    low0, high0, low1, high1 = 0, count0 - 1, 0, count1 - 1
    stop0, stop1 = len(segments0), len(segments1)
    if vertex_restricted and count0 >= 2 and count1 >= 2:
        low0, high0 = min(argmin_to0), max(argmin_to0) + 1
        low1, high1 = min(argmin_to1), max(argmin_to1) + 1
        # Each vertex only measures against the other polyline's kept segments.
        stop0, stop1 = high0, high1
        if low1 > 0 or stop1 < len(segments1):
            to1, nearest_to1, argmin_to1 = _sliced_rows(to1, low1, stop1)
        if low0 > 0 or stop0 < len(segments0):
            to0, nearest_to0, argmin_to0 = _sliced_rows(to0, low0, stop0)
    best = max(max(nearest_to1[low0 : high0 + 1]), max(nearest_to0[low1 : high1 + 1]))
    if best > limit:
        return best
    # A piece of an edge: (a, b, distances at a and b, nearest at a and b, target segments).
    # An edge whose ends have the same nearest segment is settled from the start (its
    # bound is the larger end value, already in ``best``), so it is not even a piece.
    pieces = []
    for points, rows, nearest, argmins, low, high, targets in (
        (points0, to1, nearest_to1, argmin_to1, low0, high0, segments1[low1:stop1]),
        (points1, to0, nearest_to0, argmin_to0, low1, high1, segments0[low0:stop0]),
    ):
        for k in range(low, high):
            if argmins[k] != argmins[k + 1]:
                (ax, ay), (bx, by) = points[k], points[k + 1]
                pieces.append(
                    (ax, ay, bx, by, rows[k], rows[k + 1], nearest[k], nearest[k + 1], targets)
                )
    rounds = 0
    while pieces:
        split_pieces = []
        found = False
        for piece in pieces:
            ax, ay, bx, by, da, db, fa, fb, targets = piece
            end_i, start_j = db[da.index(min(da))], da[db.index(min(db))]
            lead = start_j - fa
            crossing = lead / ((end_i - fb) + lead + _TINY)
            bound = max(fa + crossing * (end_i - fa), fb)
            if bound <= best + HAUSDORFF_TOLERANCE:
                continue
            found = True
            split = crossing if rounds < _CHORD_SPLITS else 0.5
            split = min(max(split, _MIN_SPLIT), 1.0 - _MIN_SPLIT)
            mx, my = ax + split * (bx - ax), ay + split * (by - ay)
            dm = _python_distances(mx, my, targets)
            fm = min(dm)
            split_pieces.append((piece, mx, my, dm, fm, fm < bound - HAUSDORFF_TOLERANCE))
        if not found:
            return best
        # The whole round is bounded against the best value from before it, as in numpy.
        best = max(best, *(item[4] for item in split_pieces))
        if best > limit:
            return best
        kept = [item for item in split_pieces if item[5]]
        pieces = [
            (p[0], p[1], mx, my, p[4], dm, p[6], fm, p[8]) for p, mx, my, dm, fm, _ in kept
        ] + [(mx, my, p[2], p[3], dm, p[5], fm, p[7], p[8]) for p, mx, my, dm, fm, _ in kept]
        rounds += 1
    return best


def _distance(
    points0: np.ndarray, points1: np.ndarray, vertex_restricted: bool, limit: float = math.inf
) -> float:
    """Return :func:`_hausdorff_core` the cheaper way for the size.

    The result may stop at any value above ``limit`` (a lower bound of the distance, so
    ``result <= limit`` decides the same either way).
    """
    if points0.shape[0] * points1.shape[0] <= PYTHON_PAIRS:
        return _hausdorff_python(points0.tolist(), points1.tolist(), vertex_restricted, limit)
    return _hausdorff_core(points0, points1, vertex_restricted)


def hausdorff(p0: Polyline | ArrayLike, p1: Polyline | ArrayLike) -> float:
    """Return the symmetric Hausdorff distance between two polylines as continuous curves.

    Exact to ``HAUSDORFF_TOLERANCE`` (the value returned is attained by a point of one
    curve, and no point is farther by more than the tolerance). A single vertex is a
    point; an empty polyline gives ``inf``.

    Examples
    --------
    >>> round(hausdorff([[0, 0], [2, 0]], [[0, 1], [1, 0.5], [2, 1]]), 3)
    1.0
    >>> round(hausdorff([[0, 0], [2, 0]], [[1, 1]]), 3)  # the wall's ends are sqrt(2) away
    1.414
    >>> round(hausdorff([[0, 0], [4, 0]], [[0, 0], [2, 2], [4, 0]]), 3)
    2.0
    >>> hausdorff([[0, 0]], np.empty((0, 2)))
    inf
    """
    return _distance(as_polyline(p0).points, as_polyline(p1).points, False)


def restricted_hausdorff(
    p0: Polyline | ArrayLike, p1: Polyline | ArrayLike, mode: str = "vertex"
) -> float:
    """Return the restricted Hausdorff distance ``hausdorff(P0|P1, P1|P0)``.

    Parameters
    ----------
    p0, p1
        Polylines or ``(N, 2)`` arrays.
    mode
        Restriction mode, ``"vertex"`` (paper) or ``"projection"``; see :func:`restrict`.

    Examples
    --------
    >>> wall = [[0.0, 0.0], [10.0, 0.0]]
    >>> part = [[4.0, 0.08], [6.0, 0.08]]
    >>> round(restricted_hausdorff(wall, part), 3)  # two-vertex wall: no restriction
    4.001
    >>> round(restricted_hausdorff(wall, part, mode="projection"), 3)
    0.08
    """
    return _restricted_distance(as_polyline(p0), as_polyline(p1), mode)


def _projection_rows(rows0: list[list[float]], rows1: list[list[float]]) -> list[list[float]]:
    """Return the vertices of the ``"projection"`` restriction ``P0|P1`` with Python floats.

    The steps of :func:`_restricted`, for polylines of a few vertices.
    """
    if len(rows0) < 2 or not rows1:
        return rows0
    segments = _python_segments(rows0)
    lengths = [math.hypot(dx, dy) for _, _, dx, dy, _, _, _ in segments]
    arc = [0.0, *itertools.accumulate(lengths)]
    positions, cuts = [], []
    for px, py in rows1:
        # The nearest segment (the lowest on ties) and where along it, as _Segments does.
        best, segment, fraction = math.inf, 0, 0.0
        for k, (ax, ay, dx, dy, inverse, bx, by) in enumerate(segments):
            ox, oy = px - ax, py - ay
            t = (ox * dx + oy * dy) * inverse
            if t >= 1.0:
                t, distance = 1.0, math.hypot(px - bx, py - by)
            elif t > 0.0:
                distance = math.hypot(ox - t * dx, oy - t * dy)
            else:
                t, distance = 0.0, math.hypot(ox, oy)
            if distance < best:
                best, segment, fraction = distance, k, t
        positions.append(arc[segment] + fraction * lengths[segment])
        cuts.append((segment, fraction))

    def cut(vertex: int) -> list[float]:
        segment, fraction = cuts[vertex]
        (ax, ay), (bx, by) = rows0[segment], rows0[segment + 1]
        return [ax + fraction * (bx - ax), ay + fraction * (by - ay)]

    start, stop = min(positions), max(positions)
    first, last = positions.index(start), positions.index(stop)
    if stop == start:
        return [cut(first)]
    inside = [row for row, at in zip(rows0, arc, strict=True) if start < at < stop]
    return [cut(first), *inside, cut(last)]


def _restricted_distance(p0: Polyline, p1: Polyline, mode: str, limit: float = math.inf) -> float:
    """Return :func:`restricted_hausdorff`, or any value above ``limit`` once it is known."""
    if mode == "vertex":
        return _distance(p0.points, p1.points, True, limit)
    if mode == "projection" and len(p0) * len(p1) <= PYTHON_PAIRS:
        rows0, rows1 = p0.points.tolist(), p1.points.tolist()
        cut0, cut1 = _projection_rows(rows0, rows1), _projection_rows(rows1, rows0)
        return _hausdorff_python(cut0, cut1, False, limit)
    points0, _ = _restricted(p0, p1, mode)
    points1, _ = _restricted(p1, p0, mode)
    return _distance(points0, points1, False, limit)
