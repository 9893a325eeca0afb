"""Ordered association of scan polylines with map polylines (paper Sec. 3.3, eq. 4-5).

Scan polylines come in scan order (counter-clockwise around the sensor, from the beam at
``angle_min`` on the right to ``angle_max`` on the left). Map polylines are sorted the same
way around the current viewpoint (:func:`sort_ccw`). The association is then a
dynamic-time-warping recursion over the two ordered lists with the shape similarity
``s(S_i, M_j)`` of eq. (1) as cost (docs/design.md#detail-6): the optimal monotone path from
``(0, 0)`` to ``(n - 1, m - 1)`` may pair one scan polyline with several map polylines and
vice versa. Every pair on the path is then validated by the restricted Hausdorff gate.

Cheap pruning
-------------
The restricted polylines are parts of the polylines, so their Hausdorff distance is at
least the distance between the two polylines, which is at least the gap between their
bounding boxes. A pair whose boxes are more than ``gate`` apart therefore can never pass
the gate: its validation is decided without computing anything, and the recursion gets the
constant cost ``FAR_COST`` for it instead of its similarity. ``FAR_COST`` exceeds any
plausible similarity, so the optimal path first avoids pairs that cannot be validated and
among the remaining paths minimises the similarity of eq. (4). This is the cost the
recursion is defined with (not an approximation of another one): it cannot validate a pair
the gate rejects, and a pair that can pass the gate is costed exactly as in eq. (4). What it
does change, on purpose, is that a far-apart pair of similar shape (two parallel walls)
can no longer pull the path away from a nearby correct pair. For the same reason scan and
map polylines with no partner within the gate (new objects, map polylines out of view)
are left out of the recursion: they could only add pairs the gate rejects, and without
them the recursion runs over the candidates only (a map of a whole building costs no
more than the part in view).

Since one ``FAR_COST`` outweighs the similarities of any path, the gate alone often fixes
the optimal path (each polyline near only its own counterpart): then no similarity is
computed at all (:func:`_forced_kernel` proves it with a bound on the similarities), and
the validation stops each restricted Hausdorff distance as soon as it exceeds the gate.

The broad phase (box gaps), the counter-clockwise order and the path the gate fixes run
in one compiled kernel (numba) per update, the validation of all pairs in another.

Examples
--------
>>> wall = np.array([[2.0, -1.0], [2.0, 1.0]])
>>> box = np.array([[1.0, 1.5], [1.0, 2.0], [0.5, 2.0]])
>>> associate([wall + [0.02, 0.0], box], [wall, box], gate=0.12)
[(0, 0), (1, 1)]
>>> associate([wall + [1.0, 0.0]], [wall], gate=0.12)  # 1 m away: rejected by the gate
[]
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import wrap_angle_compiled
from semistatic.hausdorff import restricted_hausdorff
from semistatic.polyline import PackedPolylines, Polyline, as_polyline, as_polylines
from semistatic.similarity import similarity

__all__ = [
    "FAR_COST",
    "ValidatedPairs",
    "associate",
    "box_gap",
    "optimal_path",
    "orient_ccw",
    "sort_ccw",
]

# Recursion cost of a pair that cannot pass the gate (boxes farther apart than the gate)
# or has no shape (zero length, similarity inf). Similarities of plausible pairs are O(1)
# (a 90 deg corner against a straight line gives 0.6) times a length ratio of at most a
# few tens, so any such pair is cheaper than one unvalidatable pair.
FAR_COST = 1.0e6


@numba.njit(cache=True)
def box_gap(boxes_a, k, boxes_b, m):  # pragma: no cover - compiled
    """Return the Euclidean gap between box ``k`` of ``boxes_a`` and box ``m`` of ``boxes_b``.

    The gap is a lower bound of the distance between any point in one box and any point
    in the other, 0 where they touch. Compiled, for kernels that test pairs of boxes (rows
    ``(xmin, ymin, xmax, ymax)`` as :attr:`~semistatic.polyline.PackedPolylines.boxes`);
    an empty box is ``inf`` away from everything.

    Examples
    --------
    >>> boxes = np.array([[0.0, 0.0, 1.0, 1.0], [4.0, 5.0, 6.0, 6.0]])
    >>> box_gap(boxes, 0, boxes, 1)
    5.0
    """
    gap_x = max(boxes_a[k, 0] - boxes_b[m, 2], boxes_b[m, 0] - boxes_a[k, 2], 0.0)
    gap_y = max(boxes_a[k, 1] - boxes_b[m, 3], boxes_b[m, 1] - boxes_a[k, 3], 0.0)
    gap = math.hypot(gap_x, gap_y)
    # An empty box is never near anything (inf - inf would otherwise give nan).
    empty = boxes_a[k, 0] > boxes_a[k, 2] or boxes_b[m, 0] > boxes_b[m, 2]
    return math.inf if empty or math.isnan(gap) else gap


def _viewpoint_pose(viewpoint: ArrayLike) -> np.ndarray:
    pose = viewpoint
    # (A map update's pose is such an array already: no numpy call for it.)
    if not (type(pose) is np.ndarray and pose.dtype == np.float64 and pose.shape == (3,)):
        pose = np.asarray(viewpoint, dtype=float).reshape(-1)
    if pose.shape == (2,):
        pose = np.append(pose, 0.0)
    # (Three Python floats: numpy's per-call cost would exceed the test itself.)
    if pose.shape != (3,) or not all(map(math.isfinite, pose.tolist())):
        raise ValueError(
            f"viewpoint must be a finite (x, y) or (x, y, theta) pose, got {viewpoint!r}"
        )
    return pose


def orient_ccw(polyline: Polyline | ArrayLike, viewpoint: ArrayLike) -> Polyline:
    """Return ``polyline`` traversed counter-clockwise around ``viewpoint`` (as a scan is).

    The direction is the sign of the bearing swept along the polyline; a polyline that
    sweeps no net bearing (e.g. pointing straight at the viewpoint) is returned unchanged.
    A reversed polyline also gets its scan indices reversed.

    Examples
    --------
    >>> orient_ccw([[1.0, 1.0], [1.0, -1.0]], (0.0, 0.0, 0.0)).points
    array([[ 1., -1.],
           [ 1.,  1.]])
    """
    polyline = as_polyline(polyline)
    packed = PackedPolylines([polyline])
    _, clockwise = _ccw_kernel(packed.points, packed.offsets, _viewpoint_pose(viewpoint))
    return polyline.reversed() if clockwise[0] else polyline


@numba.njit(cache=True)
def _ccw_kernel(points, bounds, pose):  # pragma: no cover - compiled
    """Return the counter-clockwise order of polylines and whether each runs clockwise.

    The sort key is (first bearing, last bearing, distance). A straight edge sweeps its
    bearing monotonically, so the vertices bound the bearings of the whole polyline -
    unless an edge crosses the cut behind the sensor (+-pi), in which case the polyline
    reaches the very start (and end) of the scan order. An empty polyline sorts last; ties
    keep the input order. A polyline runs clockwise when the bearing it sweeps is negative.
    """
    count = bounds.size - 1
    keys = np.empty((count, 3))
    clockwise = np.empty(count, np.bool_)
    order = np.empty(count, np.int64)
    for k in range(count):
        order[k] = k
        keys[k, 0] = keys[k, 1] = keys[k, 2] = math.inf
        clockwise[k] = False
        if bounds[k + 1] == bounds[k]:
            continue
        first, last, nearest = math.inf, -math.inf, math.inf
        swept, crosses, before = 0.0, False, 0.0
        for v in range(bounds[k], bounds[k + 1]):
            dx, dy = points[v, 0] - pose[0], points[v, 1] - pose[1]
            bearing = wrap_angle_compiled(math.atan2(dy, dx) - pose[2])
            nearest = min(nearest, math.hypot(dx, dy))
            first = min(first, bearing)
            last = max(last, bearing)
            if v > bounds[k]:
                jump = bearing - before
                swept += wrap_angle_compiled(jump)
                crosses = crosses or abs(jump) > math.pi
            before = bearing
        if crosses:
            first, last = -math.pi, math.pi
        keys[k, 0], keys[k, 1], keys[k, 2] = first, last, nearest
        clockwise[k] = swept < 0.0
    # Insertion sort: stable, lexicographic, and fast for the few polylines in view.
    for k in range(1, count):
        item = order[k]
        j = k - 1
        while j >= 0:
            # Whether the key of item sorts before the key of order[j].
            less = False
            for column in range(3):
                if keys[item, column] != keys[order[j], column]:
                    less = keys[item, column] < keys[order[j], column]
                    break
            if not less:
                break
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = item
    return order, clockwise


def sort_ccw(
    polylines: PackedPolylines | Iterable[Polyline | ArrayLike], viewpoint: ArrayLike
) -> np.ndarray:
    """Return the order of ``polylines`` counter-clockwise around ``viewpoint``.

    The order matches the order in which a scan taken from ``viewpoint`` would see them:
    bearings are measured from the viewpoint's heading and wrapped to ``(-pi, pi]``, so the
    cut lies straight behind the sensor, where a 270 deg scanner is blind, and the first
    beam (``angle_min``, on the right) comes first. Polylines are ordered by their smallest
    bearing, then by their largest, then by their distance; an empty polyline comes last.

    Parameters
    ----------
    polylines
        Polylines (or ``(N, 2)`` arrays) in the viewpoint's parent frame.
    viewpoint
        Sensor pose ``(x, y, theta)`` (or position ``(x, y)``, heading 0) in that frame.

    Returns
    -------
    numpy.ndarray
        ``(K,)`` int64 permutation: ``[polylines[k] for k in order]`` is sorted.

    Examples
    --------
    >>> left, right, ahead = [[0, 2], [-1, 2]], [[0, -2], [1, -2]], [[2, -0.5], [2, 0.5]]
    >>> sort_ccw([left, right, ahead], (0.0, 0.0, 0.0))
    array([1, 2, 0])
    >>> sort_ccw([left, right, ahead], (0.0, 0.0, np.pi))  # turned: "ahead" spans the cut
    array([2, 0, 1])
    """
    lines = as_polylines(polylines)
    order, _ = _ccw_kernel(lines.points, lines.offsets, _viewpoint_pose(viewpoint))
    return order


def optimal_path(costs: ArrayLike) -> list[tuple[int, int]]:
    """Return the optimal monotone path of eq. (5) through a cost matrix.

    The dynamic-time-warping recursion ``A_ij = {(i, j)} + argmin(A_{i-1,j}, A_{i,j-1},
    A_{i-1,j-1})`` from ``(0, 0)`` to ``(n - 1, m - 1)`` minimising the summed cost. On
    equal totals the diagonal step wins (a one-to-one pair), then the step that keeps the
    map polyline, then the one that keeps the scan polyline.

    Parameters
    ----------
    costs
        ``(n, m)`` cost of each (scan polyline, map polyline) pair, ``n, m >= 1``.

    Returns
    -------
    list of (int, int)
        The cells of the path, from ``(0, 0)`` to ``(n - 1, m - 1)``.

    Examples
    --------
    >>> optimal_path([[0.0, 5.0, 5.0], [5.0, 0.0, 0.0]])  # the second scan polyline twice
    [(0, 0), (1, 1), (1, 2)]
    """
    costs = np.ascontiguousarray(costs, dtype=np.float64)
    if costs.ndim != 2 or 0 in costs.shape:
        raise ValueError(
            f"optimal_path: costs must be an (n, m) array, n, m >= 1, got {costs.shape}"
        )
    path, _ = _dtw_kernel(costs)
    return [(int(i), int(j)) for i, j in path]


@numba.njit(cache=True)
def _dtw_kernel(cost):  # pragma: no cover - compiled
    """Return the ``(P, 2)`` path of :func:`optimal_path` and the table of optimal totals."""
    n, m = cost.shape
    totals = np.empty((n, m))
    # 0 diagonal, 1 from (i - 1, j), 2 from (i, j - 1); the first row only comes from the left.
    step = np.empty((n, m), np.int64)
    totals[0, 0] = cost[0, 0]
    step[0, 0] = 0
    for j in range(1, m):
        totals[0, j] = totals[0, j - 1] + cost[0, j]
        step[0, j] = 2
    for i in range(1, n):
        left = totals[i - 1, 0] + cost[i, 0]
        totals[i, 0] = left
        step[i, 0] = 1
        for j in range(1, m):
            best, move = totals[i - 1, j - 1], 0
            if totals[i - 1, j] < best:
                best, move = totals[i - 1, j], 1
            if left < best:
                best, move = left, 2
            left = best + cost[i, j]
            totals[i, j] = left
            step[i, j] = move
    path = np.empty((n + m - 1, 2), np.int64)
    size = 0
    i, j = n - 1, m - 1
    while True:
        path[size, 0], path[size, 1] = i, j
        size += 1
        if i == 0 and j == 0:
            break
        move = step[i, j]
        if move == 0:
            i, j = i - 1, j - 1
        elif move == 1:
            i -= 1
        else:
            j -= 1
    forward = np.empty((size, 2), np.int64)
    for k in range(size):
        forward[k, 0], forward[k, 1] = path[size - 1 - k, 0], path[size - 1 - k, 1]
    return forward, totals


@numba.njit(cache=True)
def _lengths(points, bounds):  # pragma: no cover - compiled
    """Return the arc length (m) of each polyline of concatenated ``points``."""
    lengths = np.zeros(bounds.size - 1)
    for k in range(bounds.size - 1):
        for v in range(bounds[k], bounds[k + 1] - 1):
            dx, dy = points[v + 1, 0] - points[v, 0], points[v + 1, 1] - points[v, 1]
            lengths[k] += math.hypot(dx, dy)
    return lengths


@numba.njit(cache=True)
def _forced_kernel(feasible, scan_points, scan_bounds, map_points, map_bounds):  # pragma: no cover
    """Return whether the similarities cannot change the path, and then its gateable pairs.

    ``(pairs, forced)``: when ``forced``, ``pairs`` are the pairs of the optimal path
    that can pass the gate (:func:`_gateable`); else ``pairs`` mean nothing.

    ``feasible`` marks the pairs that can pass the gate; the polylines are given as
    packed vertices with bounds (as :func:`_candidates` packs them). A pair that cannot pass
    the gate or has no shape (zero length) costs ``FAR_COST``; any other costs its similarity,
    the integral of eq. (1) times the length ratio. That integral is a variance, at most a
    quarter of the squared range of ``T1 - T0``, which is at most ``pi`` per turn of either
    polyline: less than ``((N0 + N1) pi)^2 / 4`` for ``N0`` and ``N1`` vertices (eight
    times that is used, far clear of any rounding). When a single path has the fewest
    ``FAR_COST`` pairs, every other path costs at least one ``FAR_COST`` more; if the
    bounds along that path add up to less than ``FAR_COST``, it is the optimal path of
    eq. (5) whatever the similarities are, and none needs to be computed (for a map in
    view, usually all of them).
    """
    scan_lengths = _lengths(scan_points, scan_bounds)
    map_lengths = _lengths(map_points, map_bounds)
    n, m = feasible.shape
    shaped = True
    for length in scan_lengths:
        shaped = shaped and length > 0.0
    for length in map_lengths:
        shaped = shaped and length > 0.0
    diagonal = shaped and n == m
    for a in range(n):
        for b in range(m):
            if feasible[a, b] != (a == b):
                diagonal = False
    if diagonal:
        # Each polyline near exactly its counterpart in the same order (the usual case): the
        # diagonal is the only path without a FAR_COST pair.
        path = np.empty((n, 2), np.int64)
        for k in range(n):
            path[k, 0], path[k, 1] = k, k
    else:
        hard = np.empty((n, m))
        for a in range(n):
            for b in range(m):
                shaped_pair = scan_lengths[a] > 0.0 and map_lengths[b] > 0.0
                hard[a, b] = 0.0 if feasible[a, b] and shaped_pair else 1.0
        path, totals = _dtw_kernel(hard)
        # Only a unique path is fixed: another optimal path would leave this one, walking
        # back from the end, at a cell where two predecessors tie for the best total.
        for k in range(1, path.shape[0]):
            i, j = path[k, 0], path[k, 1]
            best, ties = math.inf, 0
            for a, b in ((i - 1, j - 1), (i - 1, j), (i, j - 1)):
                if a >= 0 and b >= 0:
                    if totals[a, b] < best:
                        best, ties = totals[a, b], 1
                    elif totals[a, b] == best:
                        ties += 1
            if ties > 1:
                return path, False
    bound = 0.0
    for k in range(path.shape[0]):
        a, b = path[k, 0], path[k, 1]
        if feasible[a, b] and scan_lengths[a] > 0.0 and map_lengths[b] > 0.0:
            ratio = max(scan_lengths[a] / map_lengths[b], map_lengths[b] / scan_lengths[a])
            vertices = (scan_bounds[a + 1] - scan_bounds[a]) + (map_bounds[b + 1] - map_bounds[b])
            bound += 2.0 * (vertices * math.pi) ** 2 * ratio
    return _gateable(path, feasible, scan_bounds, map_bounds), bound < FAR_COST


# The viewpoint passed to the kernel when there is none (then unused).
_NO_POSE = np.zeros(3)


@numba.njit(cache=True)
def _candidates(
    scan_boxes, map_boxes, gate, scan_points, scan_offsets, map_points, map_offsets, pose,
    oriented,
):  # pragma: no cover - compiled
    """Return the candidates of :func:`associate`, packed and ordered, in one call.

    ``(rows, order, feasible, scan_points, scan_bounds, map_points, map_bounds)``: the
    scan polylines (``rows``) and the map polylines in counter-clockwise order around
    ``pose`` (``order``; each packed reversed where it runs clockwise, unless not
    ``oriented``: then in input order, none reversed) that
    have a partner within ``gate``, which pairs of them can pass it, and their vertices
    packed.

    (The path the gate fixes is another call, :func:`_forced_kernel`: a cached kernel two
    calls above :func:`_dtw_kernel` leaves the one loaded for Python without its
    environment, and the recursion's fallback calls it from Python.)
    """
    near, rows, columns = _broad_phase(scan_boxes, map_boxes, gate)
    scan_points, scan_bounds = _gathered(scan_points, scan_offsets, rows)
    map_points, map_bounds = _gathered(map_points, map_offsets, columns)
    if oriented:
        ranks, clockwise = _ccw_kernel(map_points, map_bounds, pose)
    else:
        ranks, clockwise = np.arange(columns.size), np.zeros(columns.size, np.bool_)
    feasible, map_points, map_bounds = _arranged(
        near, rows, columns, ranks, clockwise, map_points, map_bounds
    )
    return rows, columns[ranks], feasible, scan_points, scan_bounds, map_points, map_bounds


@numba.njit(cache=True)
def _gathered(points, offsets, which):  # pragma: no cover - compiled
    """Return the packed runs ``which`` of packed ``points`` and their bounds."""
    bounds = np.zeros(which.size + 1, np.int64)
    for k in range(which.size):
        bounds[k + 1] = bounds[k] + offsets[which[k] + 1] - offsets[which[k]]
    gathered = np.empty((bounds[which.size], 2))
    for k in range(which.size):
        start = offsets[which[k]]
        for v in range(bounds[k + 1] - bounds[k]):
            gathered[bounds[k] + v, 0] = points[start + v, 0]
            gathered[bounds[k] + v, 1] = points[start + v, 1]
    return gathered, bounds


@numba.njit(cache=True)
def _broad_phase(scan_boxes, map_boxes, gate):  # pragma: no cover - compiled
    """Return which pairs' boxes are within ``gate``, and the scan and map polylines in one."""
    n, m = scan_boxes.shape[0], map_boxes.shape[0]
    near = np.empty((n, m), np.bool_)
    rows = np.empty(n, np.int64)
    columns = np.zeros(m, np.int64)  # first a count of near pairs per map polyline
    row_count, column_count = 0, 0
    for a in range(n):
        any_near = False
        for b in range(m):
            near[a, b] = box_gap(scan_boxes, a, map_boxes, b) <= gate
            any_near = any_near or near[a, b]
            columns[b] += near[a, b]
        if any_near:
            rows[row_count] = a
            row_count += 1
    for b in range(m):
        if columns[b] > 0:
            columns[column_count] = b
            column_count += 1
    return near, rows[:row_count], columns[:column_count]


@numba.njit(cache=True)
def _arranged(near, rows, columns, ranks, clockwise, points, bounds):  # pragma: no cover
    """Return the feasible pairs and the candidate map polylines in counter-clockwise order.

    Candidate ``k`` (``points[bounds[k]:bounds[k + 1]]``) takes place ``ranks``-position
    and is reversed where ``clockwise``.
    """
    feasible = np.empty((rows.size, ranks.size), np.bool_)
    for a in range(rows.size):
        for b in range(ranks.size):
            feasible[a, b] = near[rows[a], columns[ranks[b]]]
    ordered = np.empty_like(points)
    ordered_bounds = np.zeros(ranks.size + 1, np.int64)
    for b in range(ranks.size):
        k = ranks[b]
        start, stop = bounds[k], bounds[k + 1]
        base = ordered_bounds[b]
        for v in range(stop - start):
            source = stop - 1 - v if clockwise[k] else start + v
            ordered[base + v, 0] = points[source, 0]
            ordered[base + v, 1] = points[source, 1]
        ordered_bounds[b + 1] = base + stop - start
    return feasible, ordered, ordered_bounds


@numba.njit(cache=True)
def _gateable(path, feasible, scan_bounds, map_bounds):  # pragma: no cover - compiled
    """Return the pairs of ``path`` that can pass the gate (feasible, both non-empty)."""
    pairs = np.empty_like(path)
    count = 0
    for k in range(path.shape[0]):
        a, b = path[k, 0], path[k, 1]
        filled = scan_bounds[a + 1] > scan_bounds[a] and map_bounds[b + 1] > map_bounds[b]
        if feasible[a, b] and filled:
            pairs[count, 0], pairs[count, 1] = a, b
            count += 1
    return pairs[:count]


class ValidatedPairs(list):
    """The ``(scan index, map index)`` pairs :func:`associate` validated, with their distances.

    A list of pairs, as eq. (5) gives them, that also holds the restricted Hausdorff
    distance of each: ``distances[k]`` (m, at most the gate) is the one of ``self[k]``.

    Examples
    --------
    >>> pairs = ValidatedPairs([(0, 2)], [0.03])
    >>> pairs == [(0, 2)], pairs.distances
    (True, [0.03])
    """

    def __init__(self, pairs: Iterable[tuple[int, int]] = (), distances: Iterable[float] = ()):
        super().__init__(pairs)
        self.distances = list(distances)


def associate(
    scan_polylines: PackedPolylines | Sequence[Polyline | ArrayLike],
    map_polylines: PackedPolylines | Sequence[Polyline | ArrayLike],
    gate: float,
    *,
    viewpoint: ArrayLike | None = None,
    mode: str = "vertex",
) -> ValidatedPairs:
    """Associate scan polylines with map polylines (paper eq. 4-5, docs/design.md#detail-6).

    The recursion ``A_ij = {(i, j)} + argmin(A_{i-1,j}, A_{i,j-1}, A_{i-1,j-1})`` runs over
    the scan polylines in the given (scan) order and the map polylines in counter-clockwise
    order, with the similarity of eq. (1) as cost (see the module notes for far pairs).
    Every pair on the optimal path is kept if its restricted Hausdorff distance is at most
    ``gate``. Pairs can be many-to-many: a scan polyline split in two by an occluder is
    associated twice with the same map polyline.

    Parameters
    ----------
    scan_polylines
        Scan polylines in the map frame, in scan order (as :func:`extract_polylines` gives
        them, with the sensor pose).
    map_polylines
        Map polylines. Without ``viewpoint`` they must already be sorted counter-clockwise
        around the sensor and traversed counter-clockwise; with ``viewpoint`` they may come
        in any order and direction: they are sorted with :func:`sort_ccw` and oriented with
        :func:`orient_ccw` here.
    gate
        Restricted Hausdorff validation gate in metres (paper: slightly above 0.10).
    viewpoint
        Sensor pose ``(x, y, theta)`` in the map frame, or ``None`` (see ``map_polylines``).
    mode
        Restriction of :func:`semistatic.hausdorff.restricted_hausdorff`: ``"vertex"`` (the
        paper's) or ``"projection"``.

    Returns
    -------
    ValidatedPairs
        ``(scan index, map index)`` pairs, indices into the inputs, sorted by scan index
        then by position in the counter-clockwise map order, with their restricted
        Hausdorff distances. Empty when either input is.

    Examples
    --------
    >>> wall = np.array([[2.0, -1.0], [2.0, 1.0]])
    >>> box = np.array([[1.0, 1.5], [1.0, 2.0], [0.5, 2.0]])
    >>> associate([wall + [0.02, 0.0], box], [wall, box], gate=0.12)
    [(0, 0), (1, 1)]
    >>> halves = [wall * [1.0, 0.5] - [0.0, 0.5], wall * [1.0, 0.5] + [0.0, 0.5]]
    >>> associate(halves, [wall], gate=0.12, mode="projection")  # many-to-one
    [(0, 0), (1, 0)]
    >>> [round(distance, 3) for distance in associate([wall + 0.05], [wall], 0.12).distances]
    [0.071]
    >>> associate([wall + [1.0, 0.0]], [wall], gate=0.12)  # 1 m away: rejected by the gate
    []
    """
    if not gate > 0.0:
        raise ValueError(f"associate: gate must be > 0 m, got {gate!r}")
    pose = None if viewpoint is None else _viewpoint_pose(viewpoint)
    scans, maps = as_polylines(scan_polylines), as_polylines(map_polylines)
    if not scans or not maps:
        return ValidatedPairs()
    # Only polylines with at least one partner near enough to pass the gate take part:
    # the others could only fill the path with pairs the gate rejects. One kernel call
    # finds them, packs them and orders them.
    rows, order, feasible, scan_points, scan_bounds, map_points, map_bounds = (
        _candidates(
            scans.boxes, maps.boxes, float(gate), scans.points, scans.offsets, maps.points,
            maps.offsets, _NO_POSE if pose is None else pose, pose is not None,
        )
    )
    if rows.size == 0:
        return ValidatedPairs()
    # The map polylines as the kernels see them: in counter-clockwise order and direction.
    pairs, forced = _forced_kernel(feasible, scan_points, scan_bounds, map_points, map_bounds)
    # The candidates as sets: those the kernel packed (the map's run the scan's way).
    # (Vertices gathered from the two sets, which are finite.)
    candidate_scans = PackedPolylines.from_runs(scan_points, scan_bounds, check_finite=False)
    candidate_maps = PackedPolylines.from_runs(map_points, map_bounds, check_finite=False)
    if not forced:
        costs = _similarity_costs(feasible, candidate_scans, candidate_maps)
        path = np.array(optimal_path(costs), dtype=np.int64).reshape(-1, 2)
        pairs = _gateable(path, feasible, scan_bounds, map_bounds)
    # Stops early above the gate: the value is then only a lower bound, but one that fails
    # the gate exactly when the full distance does.
    distances = restricted_hausdorff(
        candidate_scans, candidate_maps, mode, limit=float(gate), pairs=pairs
    ).tolist()
    rows, order = rows.tolist(), order.tolist()
    kept = [
        (k, (rows[i], order[j]))
        for k, ((i, j), distance) in enumerate(zip(pairs.tolist(), distances, strict=True))
        if distance <= gate
    ]
    return ValidatedPairs([pair for _, pair in kept], [distances[k] for k, _ in kept])


def _similarity_costs(
    feasible: np.ndarray, scans: PackedPolylines, maps: PackedPolylines
) -> np.ndarray:
    """Return the recursion's costs: :func:`similarity` of each feasible pair, else ``FAR_COST``.

    A pair without shape (similarity ``inf``) costs ``FAR_COST`` too; the map polylines
    run in the scan's direction.
    """
    a, b = np.nonzero(feasible)
    costs = np.full(feasible.shape, FAR_COST)
    values = similarity(scans.take(a), maps.take(b))
    costs[a, b] = np.where(values < FAR_COST, values, FAR_COST)
    return costs
