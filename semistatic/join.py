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

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.association import box_gap
from semistatic.hausdorff import pairwise_restricted_hausdorff
from semistatic.merge import distinct_vertices, merge, project_onto
from semistatic.polyline import Polyline, as_polyline, pack_vertices

__all__ = ["MIN_OVERLAP", "join", "merge_group", "overlapping_groups", "overlaps"]

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
    if not _extents_overlap(points0, points1, gate):
        return False
    points, offsets = pack_vertices([points0, points1])
    return _restricted_hausdorffs(points, offsets, np.array([[0, 1]]), gate, mode)[0] <= gate


def _extents_overlap(points0: np.ndarray, points1: np.ndarray, gate: float) -> bool:
    """Return the extent test of :func:`overlaps` on distinct, non-empty vertices."""
    if points0.shape[0] == 1 and points1.shape[0] == 1:
        return bool(np.hypot(*(points0[0] - points1[0])) <= gate)
    if points0.shape[0] == 1 or points1.shape[0] == 1:
        point, line = (points0, points1) if points0.shape[0] == 1 else (points1, points0)
        return _projection_span(point, line)[1]
    span01, _ = _projection_span(points1, points0)
    span10, _ = _projection_span(points0, points1)
    return max(span01, span10) > MIN_OVERLAP


def _restricted_hausdorffs(
    points: np.ndarray, offsets: np.ndarray, pairs: np.ndarray, gate: float, mode: str
) -> list[float]:
    """Return the restricted Hausdorff distance of packed polyline ``pairs``, in one call.

    A distance above ``gate`` may be only a lower bound, but it fails the gate exactly
    when the full distance does (:func:`semistatic.hausdorff.pairwise_restricted_hausdorff`).
    """
    return pairwise_restricted_hausdorff(
        points, offsets, points, offsets, pairs, mode, limit=gate
    ).tolist()


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

    Every pair that :func:`overlaps` is linked (:func:`overlapping_groups`); each
    connected group is merged into its heaviest member (:func:`merge_group`). The paper
    finds overlapping pairs by a linear scan of the viewpoint-sorted list, i.e. among
    neighbours; here all pairs whose bounding boxes are within ``gate`` are tested, which
    finds those and overlaps between non-neighbours too.

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
    changed = np.ones(count, dtype=bool)
    if candidates is not None:
        changed[:] = False
        changed[np.asarray(candidates, dtype=np.int64).reshape(-1)] = True
    boxes = np.array([line.box for line in lines], dtype=np.float64).reshape(count, 4)
    groups = overlapping_groups(lines, boxes, changed, gate, mode)
    joined = {members[0]: (merge_group(lines, weight, members, epsilon), tuple(members))
              for members in groups}
    grouped = {k for members in groups for k in members}
    return [
        joined.get(k, (line, (k,)))
        for k, line in enumerate(lines)
        if k in joined or k not in grouped
    ]


def overlapping_groups(
    polylines: Sequence[Polyline],
    boxes: np.ndarray,
    changed: np.ndarray,
    gate: float,
    mode: str = "vertex",
) -> list[list[int]]:
    """Return the groups of two or more polylines linked by :func:`overlaps`.

    Only pairs with at least one ``changed`` member whose ``boxes`` (``(K, 4)``, as
    :func:`semistatic.association.bounding_boxes`) are within ``gate`` of each other are
    tested: a pair farther apart cannot pass the gate.

    Returns
    -------
    list of list of int
        The sorted member indices of each group, groups ordered by their first member.

    Examples
    --------
    >>> lines = [Polyline([[0.0, 0.0], [2.0, 0.0]]), Polyline([[1.5, 0.02], [3.0, 0.02]])]
    >>> boxes = np.array([line.box for line in lines])
    >>> overlapping_groups(lines, boxes, np.array([False, True]), 0.12, "projection")
    [[0, 1]]
    >>> overlapping_groups(lines, boxes, np.array([False, False]), 0.12, "projection")
    []
    """
    first, second = _changed_near_pairs(
        np.ascontiguousarray(boxes, dtype=np.float64),
        np.ascontiguousarray(changed, dtype=np.bool_),
        float(gate),
    )
    if not first.size:
        return []
    # Distinct vertices of every polyline in a near pair, packed: the restricted Hausdorff
    # test of all near pairs in one compiled call, the extents only where it passes.
    members = sorted({*first.tolist(), *second.tolist()})
    distinct = {k: distinct_vertices(as_polyline(polylines[k]).points) for k in members}
    position = {k: n for n, k in enumerate(members)}
    points, offsets = pack_vertices([distinct[k] for k in members])
    pairs = [
        (a, b) for a, b in zip(first.tolist(), second.tolist(), strict=True)
        if distinct[a].shape[0] and distinct[b].shape[0]  # an empty polyline overlaps nothing
    ]
    if not pairs:
        return []
    distances = _restricted_hausdorffs(
        points, offsets,
        np.array([(position[a], position[b]) for a, b in pairs], dtype=np.int64),
        gate, mode,
    )
    parent = list(range(len(polylines)))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    # The components do not depend on the order in which the pairs are linked.
    for (a, b), distance in zip(pairs, distances, strict=True):
        if (
            distance <= gate
            and root(a) != root(b)
            and _extents_overlap(distinct[a], distinct[b], gate)
        ):
            parent[root(b)] = root(a)
    groups: dict[int, list[int]] = {}
    for k in members:
        groups.setdefault(root(k), []).append(k)
    return sorted(members for members in groups.values() if len(members) > 1)


@numba.njit(cache=True)
def _changed_near_pairs(boxes, changed, gate):  # pragma: no cover - compiled
    """Return the pairs ``a < b`` (lexicographic) with a changed member, boxes within gate.

    The gap is :func:`semistatic.association.box_gap`: Euclidean between the boxes, 0
    where they touch, infinite for an empty box (never near).
    """
    count = boxes.shape[0]
    first = np.empty(count * (count - 1) // 2 + 1, np.int64)
    second = np.empty(first.size, np.int64)
    found = 0
    for a in range(count):
        for b in range(a + 1, count):
            if not (changed[a] or changed[b]):
                continue
            if box_gap(boxes, a, boxes, b) <= gate:
                first[found], second[found] = a, b
                found += 1
    return first[:found], second[:found]


def merge_group(
    polylines: Sequence[Polyline], weights: Sequence[float], members: Sequence[int],
    epsilon: float,
) -> Polyline:
    """Return the polylines ``members`` merged into one, heaviest first (:func:`merge`).

    Each is merged into the result so far with the weights added up, so that a heavy
    polyline stays in place and a light one moves toward it; ties go to the lower index.

    Examples
    --------
    >>> lines = [Polyline([[0.0, 0.06], [3.0, 0.06]]), Polyline([[0.0, 0.0], [3.0, 0.0]])]
    >>> merge_group(lines, [1.0, 99.0], [0, 1], 0.03).points.round(4).tolist()
    [[0.0, 0.0006], [3.0, 0.0006]]
    """
    by_weight = sorted(members, key=lambda k: (-weights[k], k))
    result, total = polylines[by_weight[0]], float(weights[by_weight[0]])
    for k in by_weight[1:]:
        result = merge(result, polylines[k], epsilon, map_weight=total / max(weights[k], 1e-12))
        total += float(weights[k])
    return result
