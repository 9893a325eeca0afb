"""Join overlapping map polylines into one (paper Sec. 3.4, DESIGN.md detail 8).

After merging, a map may hold two polylines of one object: pieces seen apart that grew
into each other, or a new polyline that repeats part of an older one. Two polylines
*overlap* when their restricted Hausdorff distance is within the gate and their extents
overlap (:func:`overlaps`); each connected group of overlapping polylines becomes one
polyline, merged into its heaviest member with :func:`semistatic.merge.merge`
(:func:`join`).

Examples
--------
>>> wall, piece = [[0.0, 0.0], [2.0, 0.0]], [[1.5, 0.02], [3.0, 0.02]]
>>> overlaps(wall, piece, gate=0.12, mode="projection")
True
>>> [members for _, members in join([wall, piece], 0.12, 0.03, mode="projection")]
[(0, 1)]
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from semistatic.association import box_gaps
from semistatic.hausdorff import restricted_hausdorff
from semistatic.merge import distinct_vertices, merge, project_onto
from semistatic.polyline import Polyline, as_polyline

__all__ = ["MIN_OVERLAP", "join", "overlaps"]

# Two polylines' extents overlap when the projections of one onto the other span more
# than this (m): end-to-end pieces that merely touch (a box's two faces at their corner)
# do not.
MIN_OVERLAP = 1e-6


def _edge_lengths(points: np.ndarray) -> np.ndarray:
    edges = points[1:] - points[:-1]
    return np.sqrt(np.einsum("ij,ij->i", edges, edges))


def _arc_length(points: np.ndarray) -> float:
    return float(_edge_lengths(points).sum())


def _projection_span(points: np.ndarray, onto: np.ndarray) -> tuple[float, bool]:
    """Return the arc-length span of ``points`` projected on ``onto`` and if one is inside."""
    arc = project_onto(points, onto).arc
    span = float(arc.max() - arc.min())
    length = _arc_length(onto)
    inside = bool(np.any((arc > MIN_OVERLAP) & (arc < length - MIN_OVERLAP)))
    return span, inside


def overlaps(
    p0: Polyline | ArrayLike, p1: Polyline | ArrayLike, gate: float, mode: str = "vertex"
) -> bool:
    """Return whether two polylines overlap and should be joined (DESIGN.md detail 8).

    They overlap when their restricted Hausdorff distance is at most ``gate`` and their
    extents overlap: the orthogonal projections of one onto the other span more than
    ``MIN_OVERLAP`` (pieces that only touch end to end, like a box's two faces meeting at
    a corner, do not), or - for a single vertex - it projects inside the other's extent.

    Examples
    --------
    >>> wall = [[0.0, 0.0], [2.0, 0.0]]
    >>> overlaps(wall, [[1.5, 0.03], [3.0, 0.03]], gate=0.12, mode="projection")
    True
    >>> overlaps(wall, [[2.0, 0.0], [2.0, 1.0]], gate=0.12)  # meets it at a corner
    False
    """
    points0 = distinct_vertices(as_polyline(p0).points)
    points1 = distinct_vertices(as_polyline(p1).points)
    if points0.shape[0] == 0 or points1.shape[0] == 0:
        return False
    if points0.shape[0] == 1 and points1.shape[0] == 1:
        extents = bool(np.hypot(*(points0[0] - points1[0])) <= gate)
    elif points0.shape[0] == 1 or points1.shape[0] == 1:
        point, line = (points0, points1) if points0.shape[0] == 1 else (points1, points0)
        extents = _projection_span(point, line)[1]
    else:
        span01, _ = _projection_span(points1, points0)
        span10, _ = _projection_span(points0, points1)
        extents = max(span01, span10) > MIN_OVERLAP
    if not extents:
        return False
    line0 = Polyline._trusted(points0, np.arange(points0.shape[0], dtype=np.int64))
    line1 = Polyline._trusted(points1, np.arange(points1.shape[0], dtype=np.int64))
    return restricted_hausdorff(line0, line1, mode) <= gate


def join(
    polylines: Sequence[Polyline | ArrayLike],
    gate: float,
    epsilon: float,
    mode: str = "vertex",
    *,
    weights: ArrayLike | None = None,
    candidates: ArrayLike | None = None,
) -> list[tuple[Polyline, tuple[int, ...]]]:
    """Join overlapping polylines into one (paper Sec. 3.4, DESIGN.md detail 8).

    Every pair that :func:`overlaps` is linked; each connected group is merged into its
    heaviest member (:func:`merge`, weights adding up as members are merged in, heaviest
    first). The paper finds overlapping pairs by a linear scan of the viewpoint-sorted
    list, i.e. among neighbours; here all pairs whose bounding boxes are within ``gate``
    are tested, which finds those and overlaps between non-neighbours too.

    Parameters
    ----------
    polylines
        Polylines (or ``(N, 2)`` arrays) in one frame.
    gate
        Restricted Hausdorff gate (m).
    epsilon
        Douglas-Peucker tolerance (m) for the merged result.
    mode
        Restriction mode of the restricted Hausdorff distance.
    weights
        Observation count of each polyline (default 1 each).
    candidates
        Indices of the polylines that may have changed; only pairs with at least one of
        them are tested (the others were tested when they last changed). Default: all.

    Returns
    -------
    list of (Polyline, tuple of int)
        One entry per resulting polyline, with the sorted input indices it was made from,
        ordered by smallest input index. A polyline joined with nothing is returned as
        the very object given.

    Examples
    --------
    >>> wall, door = [[0.0, 0.0], [2.0, 0.0]], [[5.0, 0.0], [6.0, 0.0]]
    >>> piece = [[1.5, 0.02], [3.0, 0.02]]
    >>> [(line.points.round(2).tolist(), members)
    ...  for line, members in join([wall, door, piece], 0.12, 0.03, mode="projection")]
    [([[0.0, 0.0], [3.0, 0.02]], (0, 2)), ([[5.0, 0.0], [6.0, 0.0]], (1,))]
    """
    lines = [as_polyline(polyline) for polyline in polylines]
    count = len(lines)
    weight = [1.0] * count if weights is None else np.asarray(weights, dtype=float).tolist()
    if np.shape(weight) != (count,):
        raise ValueError(
            f"join: weights needs one value per polyline ({count}), got shape {np.shape(weight)}"
        )
    changed = [True] * count
    if candidates is not None:
        changed = [False] * count
        for k in np.asarray(candidates, dtype=np.int64).reshape(-1).tolist():
            changed[k] = True
    parent = list(range(count))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    if count > 1:
        boxes = np.array([line.box for line in lines], dtype=np.float64)
        near = (box_gaps(boxes, boxes) <= gate).tolist()
        # Pairs with a changed member only; the components do not depend on the order.
        pairs = sorted(
            (min(a, b), max(a, b))
            for a in range(count)
            if changed[a]
            for b in range(count)
            if b != a and near[a][b] and (b > a or not changed[b])
        )
        for a, b in pairs:
            if root(a) != root(b) and overlaps(lines[a], lines[b], gate, mode):
                parent[root(b)] = root(a)
    groups: dict[int, list[int]] = {}
    for k in range(count):
        groups.setdefault(root(k), []).append(k)
    joined = []
    for members in sorted(groups.values()):
        if len(members) == 1:
            joined.append((lines[members[0]], (members[0],)))
            continue
        by_weight = sorted(members, key=lambda k: (-weight[k], k))
        result, total = lines[by_weight[0]], float(weight[by_weight[0]])
        for k in by_weight[1:]:
            result = merge(result, lines[k], epsilon, map_weight=total / max(weight[k], 1e-12))
            total += float(weight[k])
        joined.append((result, tuple(members)))
    return joined
