"""Ordered association of scan polylines with map polylines (paper Sec. 3.3, eq. 4-5).

Scan polylines come in scan order (counter-clockwise around the sensor, from the beam at
``angle_min`` on the right to ``angle_max`` on the left). Map polylines are sorted the same
way around the current viewpoint (:func:`sort_ccw`). The association is then a
dynamic-time-warping recursion over the two ordered lists with the shape similarity
``s(S_i, M_j)`` of eq. (1) as cost (DESIGN.md detail 6): the optimal monotone path from
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
computed at all (:func:`_forced_path` proves it with a bound on the similarities), and
the validation stops each restricted Hausdorff distance as soon as it exceeds the gate.

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

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import wrap_angle
from semistatic.hausdorff import _restricted_distance
from semistatic.polyline import Polyline, as_polyline
from semistatic.similarity import similarity

__all__ = [
    "FAR_COST",
    "associate",
    "associate_with_distances",
    "bounding_boxes",
    "box_gaps",
    "orient_ccw",
    "similarity_matrix",
    "sort_ccw",
]

# Recursion cost of a pair that cannot pass the gate (boxes farther apart than the gate)
# or has no shape (zero length, similarity inf). Similarities of plausible pairs are O(1)
# (a 90 deg corner against a straight line gives 0.6) times a length ratio of at most a
# few tens, so any such pair is cheaper than one unvalidatable pair.
FAR_COST = 1.0e6

# Up to this many vertices in all, the polylines' bearings are summarised with Python floats
# (a few microseconds) rather than in about twenty numpy calls.
PYTHON_CCW_VERTICES = 24

# Up to this many scan x map pairs, box gaps are found with Python floats, not numpy.
PYTHON_BOX_PAIRS = 64


def bounding_boxes(polylines: Sequence[Polyline | ArrayLike]) -> np.ndarray:
    """Return the ``(K, 4)`` axis-aligned boxes ``(xmin, ymin, xmax, ymax)`` of polylines.

    An empty polyline gets the empty box ``(inf, inf, -inf, -inf)``, which is infinitely far
    from everything in :func:`box_gaps`.

    Examples
    --------
    >>> bounding_boxes([[[0.0, 1.0], [2.0, -1.0]], np.empty((0, 2))])
    array([[ 0., -1.,  2.,  1.],
           [ inf,  inf, -inf, -inf]])
    """
    boxes = [as_polyline(polyline).box for polyline in polylines]
    return np.array(boxes, dtype=np.float64).reshape(len(boxes), 4)


def box_gaps(boxes_a: ArrayLike, boxes_b: ArrayLike) -> np.ndarray:
    """Return the ``(K, L)`` Euclidean gaps between two sets of boxes (0 where they touch).

    The gap is a lower bound of the distance between any point in box ``a`` and any point
    in box ``b``. Empty boxes are ``inf`` away.

    Examples
    --------
    >>> box_gaps([[0.0, 0.0, 1.0, 1.0]], [[4.0, 5.0, 6.0, 6.0], [0.5, 0.5, 2.0, 2.0]])
    array([[5., 0.]])
    """
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 1, 4)
    b = np.asarray(boxes_b, dtype=float).reshape(1, -1, 4)
    with np.errstate(invalid="ignore"):
        gap_x = np.maximum(np.maximum(a[..., 0] - b[..., 2], b[..., 0] - a[..., 2]), 0.0)
        gap_y = np.maximum(np.maximum(a[..., 1] - b[..., 3], b[..., 1] - a[..., 3]), 0.0)
        gaps = np.hypot(gap_x, gap_y)
    # inf - inf (two empty boxes) gives nan: empty is never near anything.
    return np.where(np.isnan(gaps), math.inf, gaps)


def _viewpoint_pose(viewpoint: ArrayLike) -> np.ndarray:
    pose = np.asarray(viewpoint, dtype=float).reshape(-1)
    if pose.shape == (2,):
        pose = np.append(pose, 0.0)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ValueError(
            f"viewpoint must be a finite (x, y) or (x, y, theta) pose, got {viewpoint!r}"
        )
    return pose


def _bearings(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Return the bearings of ``points`` seen from ``pose``, in (-pi, pi] about its heading."""
    delta = points - pose[:2]
    return np.asarray(wrap_angle(np.arctan2(delta[:, 1], delta[:, 0]) - pose[2]))


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
    _, clockwise = _ccw_summary([polyline], _viewpoint_pose(viewpoint))
    return _reversed(polyline) if clockwise[0] else polyline


def _reversed(polyline: Polyline) -> Polyline:
    # Views of valid read-only arrays: nothing to check or copy.
    return Polyline._trusted(polyline.points[::-1], polyline.scan_indices[::-1])


def _ccw_summary(
    polylines: Sequence[Polyline], pose: np.ndarray
) -> tuple[list[tuple[float, float, float]], list[bool]]:
    """Return the sort key and whether it runs clockwise, for every polyline at once.

    The key is (first bearing, last bearing, distance). A straight edge sweeps its bearing
    monotonically, so the vertices bound the bearings of the whole polyline - unless an
    edge crosses the cut behind the sensor (+-pi), in which case the polyline reaches the
    very start (and end) of the scan order. An empty polyline sorts last.
    """
    sizes = [len(polyline) for polyline in polylines]
    keys = [(math.inf, math.inf, math.inf)] * len(polylines)
    clockwise = [False] * len(polylines)
    filled = [k for k, size in enumerate(sizes) if size]
    if not filled:
        return keys, clockwise
    if sum(sizes) <= PYTHON_CCW_VERTICES:
        x, y, theta = pose.tolist()
        for k in filled:
            keys[k], clockwise[k] = _ccw_summary_one(polylines[k].points.tolist(), x, y, theta)
        return keys, clockwise
    points = np.concatenate([polylines[k].points for k in filled])
    starts = np.cumsum([0] + [sizes[k] for k in filled[:-1]])
    bearings = _bearings(points, pose)
    distances = np.hypot(points[:, 0] - pose[0], points[:, 1] - pose[1])
    # Edge k joins vertex k and k + 1; the last "edge" pads reduceat at the final vertex.
    jumps = np.append(bearings[1:] - bearings[:-1], 0.0)
    inside = np.ones(points.shape[0], dtype=bool)
    inside[starts[1:] - 1] = False
    inside[-1] = False
    sweeps = np.where(inside, wrap_angle(jumps), 0.0)
    crossings = inside & (np.abs(jumps) > math.pi)
    first = np.minimum.reduceat(bearings, starts)
    last = np.maximum.reduceat(bearings, starts)
    crosses = np.logical_or.reduceat(crossings, starts)
    first = np.where(crosses, -math.pi, first).tolist()
    last = np.where(crosses, math.pi, last).tolist()
    nearest = np.minimum.reduceat(distances, starts).tolist()
    swept = np.add.reduceat(sweeps, starts).tolist()
    for row, k in enumerate(filled):
        keys[k] = (first[row], last[row], nearest[row])
        clockwise[k] = swept[row] < 0.0
    return keys, clockwise


def _ccw_summary_one(
    rows: list[list[float]], x: float, y: float, theta: float
) -> tuple[tuple[float, float, float], bool]:
    """Return :func:`_ccw_summary` of one non-empty polyline with Python floats."""
    bearings = [wrap_angle(math.atan2(py - y, px - x) - theta) for px, py in rows]
    nearest = min(math.hypot(px - x, py - y) for px, py in rows)
    swept, crosses = 0.0, False
    for before, after in itertools.pairwise(bearings):
        jump = after - before
        swept += wrap_angle(jump)
        crosses = crosses or abs(jump) > math.pi
    if crosses:
        return (-math.pi, math.pi, nearest), swept < 0.0
    return (min(bearings), max(bearings), nearest), swept < 0.0


def sort_ccw(polylines: Sequence[Polyline | ArrayLike], viewpoint: ArrayLike) -> np.ndarray:
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
    keys, _ = _ccw_summary([as_polyline(line) for line in polylines], _viewpoint_pose(viewpoint))
    return np.array(sorted(range(len(keys)), key=keys.__getitem__), dtype=np.int64)


def similarity_matrix(
    scan_polylines: Sequence[Polyline | ArrayLike],
    map_polylines: Sequence[Polyline | ArrayLike],
    gate: float | None = None,
) -> np.ndarray:
    """Return the ``(n, m)`` similarities ``s(S_i, M_j)`` of eq. (1).

    With a ``gate``, pairs whose bounding boxes are more than ``gate`` apart (which can never
    pass the restricted Hausdorff gate) are not computed and get ``inf``. Pairs with a
    zero-length polyline are ``inf`` too (no shape).

    Examples
    --------
    >>> wall = [[2.0, -1.0], [2.0, 1.0]]
    >>> similarity_matrix([wall], [[[2.0, -2.0], [2.0, 2.0]], [[9.0, 0.0], [9.0, 1.0]]], gate=0.1)
    array([[ 0., inf]])
    """
    scans = [as_polyline(polyline) for polyline in scan_polylines]
    maps = [as_polyline(polyline) for polyline in map_polylines]
    costs = np.full((len(scans), len(maps)), math.inf)
    if not scans or not maps:
        return costs
    if gate is None:
        near = np.ones(costs.shape, dtype=bool)
    else:
        near = box_gaps(bounding_boxes(scans), bounding_boxes(maps)) <= gate
    for i, j in zip(*np.nonzero(near), strict=True):
        costs[i, j] = similarity(scans[i], maps[j])
    return costs


def _optimal_path(costs: np.ndarray) -> list[tuple[int, int]]:
    """Return the DTW path of eq. (5) from ``(0, 0)`` to ``(n - 1, m - 1)``.

    On equal totals the diagonal step wins (a one-to-one pair), then the step that keeps
    the map polyline, then the one that keeps the scan polyline.
    """
    path, _ = _dtw(costs.tolist())
    return path


def _dtw(cost: list[list[float]]) -> tuple[list[tuple[int, int]], list[list[float]]]:
    """Return the path of :func:`_optimal_path` and the table of optimal totals."""
    n, m = len(cost), len(cost[0])
    # 0 diagonal, 1 from (i - 1, j), 2 from (i, j - 1); the first row only comes from the left.
    previous = list(itertools.accumulate(cost[0]))
    totals = [previous]
    step = [[0] + [2] * (m - 1)]
    for i in range(1, n):
        cost_row = cost[i]
        left = previous[0] + cost_row[0]
        row, moves = [left], [1]
        for j in range(1, m):
            best, move = previous[j - 1], 0
            if previous[j] < best:
                best, move = previous[j], 1
            if left < best:
                best, move = left, 2
            left = best + cost_row[j]
            row.append(left)
            moves.append(move)
        previous = row
        totals.append(row)
        step.append(moves)
    path = []
    i, j = n - 1, m - 1
    while True:
        path.append((i, j))
        if i == 0 and j == 0:
            break
        move = step[i][j]
        if move == 0:
            i, j = i - 1, j - 1
        elif move == 1:
            i -= 1
        else:
            j -= 1
    path.reverse()
    return path, totals


def _is_unique(path: list[tuple[int, int]], totals: list[list[float]]) -> bool:
    """Return whether no other path reaches the end of ``path`` with the same total.

    Another optimal path would leave this one, walking back from the end, at a cell where
    two predecessors tie for the best total.
    """
    for i, j in path[1:]:
        before = [
            totals[a][b] for a, b in ((i - 1, j - 1), (i - 1, j), (i, j - 1)) if a >= 0 and b >= 0
        ]
        if before.count(min(before)) > 1:
            return False
    return True


def _length(polyline: Polyline) -> float:
    """Return the arc length (m) of a polyline with Python floats."""
    rows = polyline.points.tolist()
    return sum(map(math.dist, rows, rows[1:]))


def _near_boxes(
    boxes_a: list[tuple[float, ...]], boxes_b: list[tuple[float, ...]], gate: float
) -> list[list[bool]]:
    """Return :func:`box_gaps` ``<= gate`` as lists (Python floats for a few pairs)."""
    if len(boxes_a) * len(boxes_b) > PYTHON_BOX_PAIRS:
        gaps = box_gaps(np.array(boxes_a).reshape(-1, 4), np.array(boxes_b).reshape(-1, 4))
        return (gaps <= gate).tolist()
    near = []
    for xmin, ymin, xmax, ymax in boxes_a:
        row = []
        for other_xmin, other_ymin, other_xmax, other_ymax in boxes_b:
            gap_x = max(xmin - other_xmax, other_xmin - xmax, 0.0)
            gap_y = max(ymin - other_ymax, other_ymin - ymax, 0.0)
            row.append(gap_x <= gate and gap_y <= gate and math.hypot(gap_x, gap_y) <= gate)
        near.append(row)
    return near


def _forced_path(
    feasible: list[list[bool]], scans: list[Polyline], maps: list[Polyline]
) -> list[tuple[int, int]] | None:
    """Return the association path when the similarities cannot change it, else ``None``.

    A pair that cannot pass the gate or has no shape (zero length) costs ``FAR_COST``; any
    other costs its similarity, the integral of eq. (1) times the length ratio. That
    integral is a variance, at most a quarter of the squared range of ``T1 - T0``, which
    is at most ``pi`` per turn of either polyline: less than ``((N0 + N1) pi)^2 / 4`` for
    ``N0`` and ``N1`` vertices (eight times that is used, far clear of any rounding).
    When a single path has the fewest ``FAR_COST`` pairs, every other path costs at least
    one ``FAR_COST`` more; if the bounds along that path add up to less than ``FAR_COST``,
    it is the optimal path of eq. (5) whatever the similarities are, and none needs to be
    computed (for a map in view, usually all of them).
    """
    scan_lengths = [_length(line) for line in scans]
    map_lengths = [_length(line) for line in maps]
    shaped = all(scan_lengths) and all(map_lengths)
    size = len(feasible)
    if (
        shaped
        and size == len(feasible[0])
        and all(feasible[a][b] == (a == b) for a in range(size) for b in range(size))
    ):
        # Each polyline near exactly its counterpart in the same order (the usual case): the
        # diagonal is the only path without a FAR_COST pair.
        path = [(k, k) for k in range(size)]
    else:
        hard = [
            [
                0.0 if near and scan_length > 0.0 and map_length > 0.0 else 1.0
                for near, map_length in zip(row, map_lengths, strict=True)
            ]
            for row, scan_length in zip(feasible, scan_lengths, strict=True)
        ]
        path, totals = _dtw(hard)
        if not _is_unique(path, totals):
            return None
    bound = 0.0
    for a, b in path:
        if feasible[a][b] and scan_lengths[a] > 0.0 and map_lengths[b] > 0.0:
            ratio = max(scan_lengths[a] / map_lengths[b], map_lengths[b] / scan_lengths[a])
            bound += 2.0 * ((len(scans[a]) + len(maps[b])) * math.pi) ** 2 * ratio
    return path if bound < FAR_COST else None


def associate_with_distances(
    scan_polylines: Sequence[Polyline | ArrayLike],
    map_polylines: Sequence[Polyline | ArrayLike],
    gate: float,
    *,
    viewpoint: ArrayLike | None = None,
    mode: str = "vertex",
) -> list[tuple[int, int, float]]:
    """Return the validated pairs of :func:`associate` with their restricted Hausdorff distance.

    Parameters and ordering as in :func:`associate`.

    Returns
    -------
    list of (int, int, float)
        ``(scan index, map index, restricted Hausdorff distance in m)``, distance ``<= gate``.

    Examples
    --------
    >>> wall = np.array([[2.0, -1.0], [2.0, 1.0]])
    >>> [(i, j, round(d, 3)) for i, j, d in associate_with_distances([wall + 0.05], [wall], 0.12)]
    [(0, 0, 0.071)]
    """
    if not gate > 0.0:
        raise ValueError(f"associate: gate must be > 0 m, got {gate!r}")
    scans = [as_polyline(polyline) for polyline in scan_polylines]
    maps = [as_polyline(polyline) for polyline in map_polylines]
    if not scans or not maps:
        return []
    # Only polylines with at least one partner near enough to pass the gate take part:
    # the others could only fill the path with pairs the gate rejects.
    near = _near_boxes([line.box for line in scans], [line.box for line in maps], gate)
    rows = [i for i, row in enumerate(near) if any(row)]
    if not rows:
        return []
    columns = [j for j in range(len(maps)) if any(row[j] for row in near)]
    if viewpoint is None:
        order = columns
        ordered = [maps[k] for k in order]
    else:
        candidates = [maps[k] for k in columns]
        keys, clockwise = _ccw_summary(candidates, _viewpoint_pose(viewpoint))
        ranks = sorted(range(len(candidates)), key=keys.__getitem__)
        order = [columns[k] for k in ranks]
        # Similarity compares tangent functions, which needs both polylines traversed the
        # same way round: a map polyline first seen from its other side is reversed.
        ordered = [_reversed(candidates[k]) if clockwise[k] else candidates[k] for k in ranks]
    feasible = [[near[row][column] for column in order] for row in rows]
    path = _forced_path(feasible, [scans[row] for row in rows], ordered)
    if path is None:
        costs = np.full((len(rows), len(order)), FAR_COST)
        for a, b in zip(*np.nonzero(feasible), strict=True):
            value = similarity(scans[rows[a]], ordered[b])
            if value < FAR_COST:
                costs[a, b] = value
        path = _optimal_path(costs)
    pairs = []
    for a, b in path:
        scan, candidate = scans[rows[a]], ordered[b]
        if not feasible[a][b] or len(scan) == 0 or len(candidate) == 0:
            continue
        # Stops early above the gate: the value is then only a lower bound, but one that
        # fails the gate exactly when the full distance does.
        distance = _restricted_distance(scan, candidate, mode, limit=gate)
        if distance <= gate:
            pairs.append((rows[a], order[b], float(distance)))
    return pairs


def associate(
    scan_polylines: Sequence[Polyline | ArrayLike],
    map_polylines: Sequence[Polyline | ArrayLike],
    gate: float,
    *,
    viewpoint: ArrayLike | None = None,
    mode: str = "vertex",
) -> list[tuple[int, int]]:
    """Associate scan polylines with map polylines (paper eq. 4-5, DESIGN.md detail 6).

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
        them, transformed by the sensor pose).
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
    list of (int, int)
        ``(scan index, map index)`` pairs, indices into the input lists, sorted by scan
        index then by position in the counter-clockwise map order. Empty when either list
        is empty.

    Examples
    --------
    >>> wall = np.array([[2.0, -1.0], [2.0, 1.0]])
    >>> halves = [wall * [1.0, 0.5] - [0.0, 0.5], wall * [1.0, 0.5] + [0.0, 0.5]]
    >>> associate(halves, [wall], gate=0.12, mode="projection")  # many-to-one
    [(0, 0), (1, 0)]
    >>> associate([], [wall], gate=0.12)
    []
    """
    return [
        (i, j)
        for i, j, _ in associate_with_distances(
            scan_polylines, map_polylines, gate, viewpoint=viewpoint, mode=mode
        )
    ]
