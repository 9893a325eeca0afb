"""Restricted Hausdorff distance between polylines (paper eq. 3, docs/design.md#detail-5).

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
not only their vertices, to within ``HAUSDORFF_TOLERANCE``. One compiled kernel (numba)
computes the restriction and the distance of a pair, whatever its size, or of every pair of
two polyline sets in one call.

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

import math

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.polyline import PackedPolylines, Polyline, as_polyline

__all__ = [
    "HAUSDORFF_TOLERANCE",
    "hausdorff",
    "restrict",
    "restricted_hausdorff",
]

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

# Restriction codes of the kernel, by mode name (no restriction for the plain distance).
_MODES = {"vertex": 1, "projection": 2}
_UNRESTRICTED = 0


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
    code = _mode_code(mode)
    p0, p1 = as_polyline(p0), as_polyline(p1)
    if len(p0) < 2 or len(p1) == 0:
        return p0
    points0, points1 = _kernel_points(p0), _kernel_points(p1)
    if code == _MODES["vertex"]:
        low, high = _vertex_span(points0, points1)
        if low == 0 and high == len(p0) - 1:
            return p0
        return Polyline(p0.points[low : high + 1], p0.scan_indices[low : high + 1])
    vertices, sources = _projection_cut(points0, points1)
    return Polyline(vertices, p0.scan_indices[sources])


def hausdorff(
    p0: Polyline | ArrayLike | PackedPolylines,
    p1: Polyline | ArrayLike | PackedPolylines,
    *,
    pairs: ArrayLike | None = None,
) -> float | np.ndarray:
    """Return the symmetric Hausdorff distance between two polylines as continuous curves.

    Exact to ``HAUSDORFF_TOLERANCE`` (the value returned is attained by a point of one
    curve, and no point is farther by more than the tolerance). A single vertex is a
    point; an empty polyline gives ``inf``. Two
    :class:`~semistatic.polyline.PackedPolylines` of equal length are compared element by
    element in one compiled call (as shapely's functions take arrays of geometries), or,
    with ``pairs`` (``(K, 2)`` indices ``(i, j)``), ``p0[i]`` with ``p1[j]`` for each pair.

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
    return _measured("hausdorff", p0, p1, _UNRESTRICTED, math.inf, pairs)


def restricted_hausdorff(
    p0: Polyline | ArrayLike | PackedPolylines,
    p1: Polyline | ArrayLike | PackedPolylines,
    mode: str = "vertex",
    *,
    limit: float = math.inf,
    pairs: ArrayLike | None = None,
) -> float | np.ndarray:
    """Return the restricted Hausdorff distance ``hausdorff(P0|P1, P1|P0)``.

    Parameters
    ----------
    p0, p1
        Polylines or ``(N, 2)`` arrays; or two
        :class:`~semistatic.polyline.PackedPolylines` of equal length, compared element by
        element in one compiled call (the association validates all its pairs so).
    mode
        Restriction mode, ``"vertex"`` (paper) or ``"projection"``; see :func:`restrict`.
    limit
        A gate (m): once the distance is known to exceed it, the search stops and returns
        the value found so far, a lower bound above ``limit``. So ``result <= limit``
        decides a gate exactly as the full distance does, at a fraction of the cost.
    pairs
        For two sets: ``(K, 2)`` indices ``(i, j)``, the distance of ``p0[i]`` and
        ``p1[j]`` for each (the sets may then differ in length). Default: element by
        element.

    Returns
    -------
    float or numpy.ndarray
        The distance in metres; for two sets, the ``(K,)`` distances of their pairs.

    Examples
    --------
    >>> wall = [[0.0, 0.0], [10.0, 0.0]]
    >>> part = [[4.0, 0.08], [6.0, 0.08]]
    >>> round(restricted_hausdorff(wall, part), 3)  # two-vertex wall: no restriction
    4.001
    >>> round(restricted_hausdorff(wall, part, mode="projection"), 3)
    0.08
    >>> restricted_hausdorff(wall, part, limit=0.1) > 0.1  # stops early, same decision
    True
    >>> walls = PackedPolylines([wall, [[0.0, 1.0], [10.0, 1.0]]])
    >>> restricted_hausdorff(walls, PackedPolylines([part, part]), "projection").round(3)
    array([0.08, 0.92])
    >>> restricted_hausdorff(walls, PackedPolylines([part]), "projection",
    ...                      pairs=[[1, 0], [0, 0]]).round(3)
    array([0.92, 0.08])
    """
    return _measured("restricted_hausdorff", p0, p1, _mode_code(mode), float(limit), pairs)


def _measured(
    caller: str, p0: Polyline | ArrayLike | PackedPolylines,
    p1: Polyline | ArrayLike | PackedPolylines, code: int, limit: float,
    pairs: ArrayLike | None,
) -> float | np.ndarray:
    """Return the distance (code 0: plain, else a restriction) of two polylines or sets."""
    if isinstance(p0, PackedPolylines) and isinstance(p1, PackedPolylines):
        count0, count1 = len(p0), len(p1)
        if pairs is None:
            if count0 != count1:
                raise ValueError(
                    f"{caller}: two polyline sets must be as long, got {count0} and {count1}"
                )
            pairs = _aligned_pairs(count0)
        else:
            pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
            # (Over Python ints: a few pairs cost less so than numpy's reductions.)
            flat = pairs.reshape(-1).tolist()
            if flat and not (
                min(flat[0::2]) >= 0 and max(flat[0::2]) < count0
                and min(flat[1::2]) >= 0 and max(flat[1::2]) < count1
            ):
                raise ValueError(
                    f"{caller}: pairs must index the two sets ({count0} and {count1} "
                    f"polylines), got {pairs.tolist()}"
                )
        return _distances(p0.points, p0.offsets, p1.points, p1.offsets, pairs, code, limit)
    if pairs is not None:
        raise ValueError(f"{caller}: pairs index two PackedPolylines; got single polylines")
    points0 = _kernel_points(as_polyline(p0))
    points1 = _kernel_points(as_polyline(p1))
    bounds0 = np.array([0, points0.shape[0]], dtype=np.int64)
    bounds1 = np.array([0, points1.shape[0]], dtype=np.int64)
    return float(_distances(points0, bounds0, points1, bounds1, _aligned_pairs(1), code,
                            limit)[0])


# The pairs (k, k) of two sets compared element by element, one array per size (nothing
# writes to it; writeable, as the kernel is compiled for).
_ALIGNED: dict[int, np.ndarray] = {}


def _aligned_pairs(count: int) -> np.ndarray:
    pairs = _ALIGNED.get(count)
    if pairs is None:
        pairs = _ALIGNED[count] = np.repeat(np.arange(count, dtype=np.int64), 2).reshape(-1, 2)
    return pairs


def _mode_code(mode: str) -> int:
    code = _MODES.get(mode)
    if code is None:
        raise ValueError(f"restrict: mode must be one of {tuple(_MODES)}, got {mode!r}")
    return code


def _kernel_points(polyline: Polyline) -> np.ndarray:
    """Return a polyline's vertices as the one array type the kernels are compiled for.

    A C-contiguous writeable float64 array: numba compiles one specialisation per array
    layout and write flag, so views (reversed polylines) and read-only arrays are copied
    (a few vertices) rather than compiled for again.
    """
    return np.array(polyline.points, dtype=np.float64, order="C")


@numba.njit(cache=True)
def _distances(points0, bounds0, points1, bounds1, pairs, mode, limit):  # pragma: no cover
    """Return the (restricted) Hausdorff distance of each pair of packed polylines.

    Pair ``p`` is run ``pairs[p, 0]`` of ``points0`` (``points0[bounds0[a]:bounds0[a + 1]]``)
    and run ``pairs[p, 1]`` of ``points1``.
    ``mode`` 0: no restriction; 1: ``"vertex"``; 2: ``"projection"``. A pair's search
    stops as soon as its best distance exceeds ``limit`` (a lower bound above ``limit``).
    The one entry point of the module's distances, and the search is written inline: a
    compiled caller re-optimises and re-emits the machine code of every kernel it calls,
    so each extra layer over the search costs about as much as compiling it again. Hence
    its ~140 lines. Measured (CPU seconds to compile this kernel from an empty cache, 2
    shared cores under load, paired runs): split into a start, a branch-and-bound and a
    halving kernel, mean 6.6 -> 10.4 s over 3 runs (+56%); the same helpers inlined into
    it (``inline="always"``), median 6.6 -> 7.3 s over 6 runs (+16%).

    In ``"vertex"`` mode both polylines are first restricted to each other (eq. 3); the
    vertex-to-segment distances that choose the restriction are the same that start the
    distance computation.

    Both directed distances are found together by branch and bound along the edges of
    the source curve, in rounds. On a piece ``[a, b]`` of an edge the distance ``d_j`` to
    each target segment is convex, hence below its chord; for the segments ``i`` and ``j``
    nearest to ``a`` and ``b``, the maximum of ``f = min_j d_j`` on the piece is at most
    the crossing value of their chords (``max(f(a), f(b))`` when ``i`` serves both ends).
    Pieces whose bound beats the best value found by more than ``HAUSDORFF_TOLERANCE``
    are split at the chord crossing, which is exact when both distances are linear (to
    segment interiors). Every ``d_j`` is 1-Lipschitz, so the bound exceeds ``f(a)`` by at
    most the piece length: halving after ``_CHORD_SPLITS`` rounds ends the search.
    """
    distances = np.empty(pairs.shape[0])
    for p in range(distances.size):
        a, b = pairs[p, 0], pairs[p, 1]
        # Leading-axis slices of C arrays stay C arrays: one specialisation.
        cut0 = points0[bounds0[a] : bounds0[a + 1]]
        cut1 = points1[bounds1[b] : bounds1[b + 1]]
        if cut0.shape[0] == 0 or cut1.shape[0] == 0:
            distances[p] = math.inf
            continue
        if mode == 2:
            whole0 = cut0
            if cut0.shape[0] >= 2:
                cut0, _ = _projection_cut(cut0, cut1)
            if cut1.shape[0] >= 2:
                cut1, _ = _projection_cut(cut1, whole0)
        count0, count1 = cut0.shape[0], cut1.shape[0]
        table0, table1 = _segment_table(cut0), _segment_table(cut1)
        to1 = _distance_rows(cut0, table1)
        to0 = _distance_rows(cut1, table0)
        # Vertex range [low, high] of each polyline taking part; the vertices of each measure
        # against the other polyline's segments [first, stop).
        low0, high0, low1, high1 = 0, count0 - 1, 0, count1 - 1
        first1, stop1, first0, stop0 = 0, table1.shape[0], 0, table0.shape[0]
        if mode == 1 and count0 >= 2 and count1 >= 2:
            low0, high0 = _span_of_rows(to0)
            low1, high1 = _span_of_rows(to1)
            first1, stop1, first0, stop0 = low1, high1, low0, high0
        nearest0, argmin0 = _row_minima(to1, first1, stop1)
        nearest1, argmin1 = _row_minima(to0, first0, stop0)
        best = -math.inf
        for v in range(low0, high0 + 1):
            best = max(best, nearest0[v])
        for v in range(low1, high1 + 1):
            best = max(best, nearest1[v])
        if best <= limit:
            # A piece of an edge: its ends, the middle_rows there to the target segments, their
            # minima, and which polyline it belongs to. An edge whose ends have the same nearest
            # segment is settled from the start (its bound is the larger end value, already in
            # ``best``), so it is not even a piece.
            width0, width1 = stop1 - first1, stop0 - first0
            width = max(width0, width1)
            count = 0
            for v in range(low0, high0):
                count += argmin0[v] != argmin0[v + 1]
            for v in range(low1, high1):
                count += argmin1[v] != argmin1[v + 1]
            ends = np.empty((count, 4))
            lows = np.empty((count, width))
            highs = np.empty((count, width))
            values = np.empty((count, 2))
            sides = np.empty(count, np.int64)
            piece = 0
            for side in range(2):
                points = cut0 if side == 0 else cut1
                rows = to1 if side == 0 else to0
                argmins = argmin0 if side == 0 else argmin1
                nearest = nearest0 if side == 0 else nearest1
                first = first1 if side == 0 else first0
                size = width0 if side == 0 else width1
                low = low0 if side == 0 else low1
                high = high0 if side == 0 else high1
                for v in range(low, high):
                    if argmins[v] != argmins[v + 1]:
                        ends[piece, 0], ends[piece, 1] = points[v, 0], points[v, 1]
                        ends[piece, 2], ends[piece, 3] = points[v + 1, 0], points[v + 1, 1]
                        for k in range(size):
                            lows[piece, k] = rows[v, first + k]
                            highs[piece, k] = rows[v + 1, first + k]
                        values[piece, 0], values[piece, 1] = nearest[v], nearest[v + 1]
                        sides[piece] = side
                        piece += 1
            rounds = 0
            while count > 0:
                middles = np.empty((count, 2))
                middle_rows = np.empty((count, width))
                minima = np.empty(count)
                open_ = np.empty(count, np.bool_)
                found = False
                round_best = best
                kept = 0
                for e in range(count):
                    open_[e] = False
                    side = sides[e]
                    size = width0 if side == 0 else width1
                    fa, fb = values[e, 0], values[e, 1]
                    i, j = 0, 0  # the segments nearest to the ends (the lowest on ties)
                    for k in range(1, size):
                        if lows[e, k] < lows[e, i]:
                            i = k
                        if highs[e, k] < highs[e, j]:
                            j = k
                    # Chord of d_i runs from fa to end_i; chord of d_j from start_j to fb.
                    end_i, start_j = highs[e, i], lows[e, j]
                    lead = start_j - fa
                    crossing = lead / ((end_i - fb) + lead + _TINY)  # in [0, 1]; 0 when i == j
                    bound = max(fa + crossing * (end_i - fa), fb)
                    if bound <= best + HAUSDORFF_TOLERANCE:
                        continue
                    found = True
                    split = crossing if rounds < _CHORD_SPLITS else 0.5
                    split = min(max(split, _MIN_SPLIT), 1.0 - _MIN_SPLIT)
                    mx = ends[e, 0] + split * (ends[e, 2] - ends[e, 0])
                    my = ends[e, 1] + split * (ends[e, 3] - ends[e, 1])
                    middles[e, 0], middles[e, 1] = mx, my
                    table = table1 if side == 0 else table0
                    first = first1 if side == 0 else first0
                    for k in range(size):
                        middle_rows[e, k], _ = _to_segment(mx, my, table, first + k)
                    minimum = middle_rows[e, 0]
                    for k in range(1, size):
                        minimum = min(minimum, middle_rows[e, k])
                    minima[e] = minimum
                    round_best = max(round_best, minima[e])
                    # A piece whose new point comes within the tolerance of its bound is settled:
                    # with linear middle_rows (segment interiors) the chord crossing is the maximum.
                    if minima[e] < bound - HAUSDORFF_TOLERANCE:
                        open_[e] = True
                        kept += 1
                if not found:
                    break
                # The whole round is bounded against the best value from before it.
                best = round_best
                if best > limit:
                    break
                next_ends = np.empty((2 * kept, 4))
                next_lows = np.empty((2 * kept, width))
                next_highs = np.empty((2 * kept, width))
                next_values = np.empty((2 * kept, 2))
                next_sides = np.empty(2 * kept, np.int64)
                q = 0
                for e in range(count):
                    if not open_[e]:
                        continue
                    # The halves [start, middle] and [middle, end].
                    next_sides[q] = next_sides[q + 1] = sides[e]
                    next_ends[q, 0], next_ends[q, 1] = ends[e, 0], ends[e, 1]
                    next_ends[q, 2], next_ends[q, 3] = middles[e, 0], middles[e, 1]
                    next_ends[q + 1, 0], next_ends[q + 1, 1] = middles[e, 0], middles[e, 1]
                    next_ends[q + 1, 2], next_ends[q + 1, 3] = ends[e, 2], ends[e, 3]
                    for k in range(width):
                        next_lows[q, k] = lows[e, k]
                        next_highs[q, k] = next_lows[q + 1, k] = middle_rows[e, k]
                        next_highs[q + 1, k] = highs[e, k]
                    next_values[q, 0], next_values[q, 1] = values[e, 0], minima[e]
                    next_values[q + 1, 0], next_values[q + 1, 1] = minima[e], values[e, 1]
                    q += 2
                ends, lows, highs, values, sides, count = (
                    next_ends, next_lows, next_highs, next_values, next_sides, 2 * kept
                )
                rounds += 1
        distances[p] = best
    return distances


@numba.njit(cache=True)
def _segment_table(points):  # pragma: no cover - compiled
    """Return ``(S, 7)`` rows ``(ax, ay, dx, dy, 1 / length^2, bx, by)`` of the segments.

    A single vertex is one null segment (``1 / length^2`` is 0 for null segments, so the
    projection parameter is 0 and the distance the one to the start point).
    """
    count = max(points.shape[0] - 1, 1)
    table = np.empty((count, 7))
    for k in range(count):
        end = min(k + 1, points.shape[0] - 1)
        ax, ay = points[k, 0], points[k, 1]
        bx, by = points[end, 0], points[end, 1]
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        table[k, 0] = ax
        table[k, 1] = ay
        table[k, 2] = dx
        table[k, 3] = dy
        table[k, 4] = 1.0 / length2 if length2 > 0.0 else 0.0
        table[k, 5] = bx
        table[k, 6] = by
    return table


@numba.njit(cache=True)
def _to_segment(px, py, table, k):  # pragma: no cover - compiled
    """Return ``(distance, t)`` from a point to segment ``k`` of ``table``.

    ``t`` in ``[0, 1]`` is where along the segment the nearest point lies. A point whose
    nearest point is a segment end gets exactly the distance to that end, so two segments
    sharing a vertex tie exactly there (and the lower one wins every argmin).
    """
    ox, oy = px - table[k, 0], py - table[k, 1]
    dx, dy = table[k, 2], table[k, 3]
    t = (ox * dx + oy * dy) * table[k, 4]
    if t >= 1.0:
        return math.hypot(px - table[k, 5], py - table[k, 6]), 1.0
    if t > 0.0:
        return math.hypot(ox - t * dx, oy - t * dy), t
    return math.hypot(ox, oy), 0.0


@numba.njit(cache=True)
def _distance_rows(points, table):  # pragma: no cover - compiled
    """Return the ``(N, S)`` distances from every point to every segment of ``table``."""
    rows = np.empty((points.shape[0], table.shape[0]))
    for v in range(points.shape[0]):
        for k in range(table.shape[0]):
            rows[v, k], _ = _to_segment(points[v, 0], points[v, 1], table, k)
    return rows


@numba.njit(cache=True)
def _row_minima(rows, first, stop):  # pragma: no cover - compiled
    """Return each row's minimum over columns ``[first, stop)`` and its first position.

    Positions count from ``first``.
    """
    minima = np.empty(rows.shape[0])
    where = np.empty(rows.shape[0], np.int64)
    for v in range(rows.shape[0]):
        best, nearest = rows[v, first], 0
        for k in range(first + 1, stop):
            if rows[v, k] < best:
                best, nearest = rows[v, k], k - first
        minima[v], where[v] = best, nearest
    return minima, where


@numba.njit(cache=True)
def _span_of_rows(rows):  # pragma: no cover - compiled
    """Return the first and last vertex spanned by each row's nearest (lowest) segment."""
    low = rows.shape[1]
    high = -1
    for v in range(rows.shape[0]):
        nearest = 0  # the lowest on ties
        for k in range(1, rows.shape[1]):
            if rows[v, k] < rows[v, nearest]:
                nearest = k
        low = min(low, nearest)
        high = max(high, nearest)
    return low, high + 1


@numba.njit(cache=True)
def _vertex_span(points0, points1):  # pragma: no cover - compiled
    """Return the first and last vertex of ``P0|P1`` in ``"vertex"`` mode (eq. 3)."""
    return _span_of_rows(_distance_rows(points1, _segment_table(points0)))


@numba.njit(cache=True)
def _projection_cut(points0, points1):  # pragma: no cover - compiled
    """Return the vertices of the ``"projection"`` restriction ``P0|P1`` and their sources.

    ``sources`` are positions into ``points0``: a kept vertex's own, and for each cut point
    the nearer vertex of the segment it lies on. Needs ``len(points0) >= 2`` and a
    non-empty ``points1``.
    """
    table = _segment_table(points0)
    arc = np.empty(points0.shape[0])
    arc[0] = 0.0
    for k in range(table.shape[0]):
        arc[k + 1] = arc[k] + math.hypot(table[k, 2], table[k, 3])
    count = points1.shape[0]
    positions = np.empty(count)
    segments = np.empty(count, np.int64)
    fractions = np.empty(count)
    for v in range(count):
        # The nearest segment, the lowest on ties.
        best = math.inf
        for k in range(table.shape[0]):
            distance, t = _to_segment(points1[v, 0], points1[v, 1], table, k)
            if distance < best:
                best = distance
                segments[v] = k
                fractions[v] = t
        segment = segments[v]
        positions[v] = arc[segment] + fractions[v] * (arc[segment + 1] - arc[segment])
    # The first smallest and first largest position (as argmin and argmax).
    first, last = 0, 0
    for v in range(1, count):
        if positions[v] < positions[first]:
            first = v
        if positions[v] > positions[last]:
            last = v
    start, stop = positions[first], positions[last]
    inside = 0
    if stop > start:
        for k in range(points0.shape[0]):
            if start < arc[k] < stop:
                inside += 1
    size = 1 if stop == start else inside + 2
    vertices = np.empty((size, 2))
    sources = np.empty(size, np.int64)
    written = 0
    for end in range(2 if size > 1 else 1):
        vertex = first if end == 0 else last
        segment, fraction = segments[vertex], fractions[vertex]
        slot = 0 if end == 0 else size - 1
        for axis in range(2):
            a = points0[segment, axis]
            vertices[slot, axis] = a + fraction * (points0[segment + 1, axis] - a)
        sources[slot] = segment + 1 if fraction >= 0.5 else segment
        if end == 0 and size > 1:
            for k in range(points0.shape[0]):
                if start < arc[k] < stop:
                    written += 1
                    vertices[written, 0] = points0[k, 0]
                    vertices[written, 1] = points0[k, 1]
                    sources[written] = k
    return vertices, sources
