"""Join overlapping map polylines into one (paper Sec. 3.4, docs/design.md#detail-8).

After merging, a map may hold two polylines of one object: pieces seen apart that grew
into each other, or a new polyline that repeats part of an older one. Two polylines
*overlap* when their restricted Hausdorff distance is within the gate and their extents
overlap; :func:`overlapping_groups` finds the connected groups of overlapping polylines,
and :func:`merge_group` merges each group into its heaviest member with
:func:`semistatic.merge.merge`.

Examples
--------
>>> wall, door = [[0.0, 0.0], [2.0, 0.0]], [[5.0, 0.0], [6.0, 0.0]]
>>> lines = PackedPolylines([wall, door, [[1.5, 0.02], [3.0, 0.02]]])
>>> groups = overlapping_groups(lines, [True, True, True], 0.12, mode="projection")
>>> groups
[[0, 2]]
>>> merge_group(lines, [1.0, 1.0, 1.0], groups[0], 0.03).points.round(2).tolist()
[[0.0, 0.0], [3.0, 0.02]]
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.association import box_gap
from semistatic.hausdorff import restricted_hausdorff
from semistatic.merge import distinct_vertices, merge, project_onto
from semistatic.polyline import PackedPolylines, Polyline, as_polylines

__all__ = ["MIN_OVERLAP", "merge_group", "overlapping_groups"]

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


def _extents_overlap(points0: np.ndarray, points1: np.ndarray, gate: float) -> bool:
    """Return whether the extents of two polylines (distinct, non-empty vertices) overlap.

    The orthogonal projections of one onto the other span more than ``MIN_OVERLAP``
    (pieces that only touch end to end, like a box's two faces meeting at a corner, do
    not), or - for a single vertex - it projects inside the other's extent; two single
    vertices overlap within ``gate``.
    """
    if points0.shape[0] == 1 and points1.shape[0] == 1:
        return bool(np.hypot(*(points0[0] - points1[0])) <= gate)
    if points0.shape[0] == 1 or points1.shape[0] == 1:
        point, line = (points0, points1) if points0.shape[0] == 1 else (points1, points0)
        return _projection_span(point, line)[1]
    span01, _ = _projection_span(points1, points0)
    span10, _ = _projection_span(points0, points1)
    return max(span01, span10) > MIN_OVERLAP


def overlapping_groups(
    polylines: PackedPolylines | Sequence[Polyline | ArrayLike],
    changed: ArrayLike,
    gate: float,
    mode: str = "vertex",
) -> list[list[int]]:
    """Return the groups of two or more overlapping polylines (docs/design.md#detail-8).

    Two polylines overlap when their restricted Hausdorff distance (``mode``) is at most
    ``gate`` and their extents overlap: the orthogonal projections of one onto the other
    span more than ``MIN_OVERLAP`` (pieces that only touch end to end, like a box's two
    faces meeting at a corner, do not), or - for a single vertex - it projects inside the
    other's extent. The groups are the connected components of that relation. The paper
    finds overlapping pairs by a linear scan of the viewpoint-sorted list, i.e. among
    neighbours; here all pairs whose bounding boxes are within ``gate`` are tested, which
    finds those and overlaps between non-neighbours too. Only pairs with at least one
    ``changed`` member are tested (the others were tested when they last changed).

    Parameters
    ----------
    polylines
        Polylines in one frame.
    changed
        ``(K,)`` booleans: which polylines may have changed since they were last tested.
    gate
        Restricted Hausdorff gate (m).
    mode
        Restriction mode of the restricted Hausdorff distance.

    Returns
    -------
    list of list of int
        The sorted member indices of each group, groups ordered by their first member.

    Examples
    --------
    >>> lines = [[[0.0, 0.0], [2.0, 0.0]], [[1.5, 0.02], [3.0, 0.02]], [[2.0, 0.0], [2.0, 1.0]]]
    >>> overlapping_groups(lines, [False, True, False], 0.12, "projection")
    [[0, 1]]
    >>> overlapping_groups(lines, [False, False, True], 0.12)  # meets the wall at a corner
    []
    """
    lines = as_polylines(polylines)
    first, second = _changed_near_pairs(
        lines.boxes, np.ascontiguousarray(changed, dtype=np.bool_), float(gate)
    )
    if not first.size:
        return []
    members = sorted({*first.tolist(), *second.tolist()})
    # Distinct vertices of every polyline in a near pair: the restricted Hausdorff test of
    # all near pairs in one compiled call, the extents only where it passes.
    distinct = {k: distinct_vertices(lines[k].points) for k in members}
    pairs = [
        (a, b) for a, b in zip(first.tolist(), second.tolist(), strict=True)
        if distinct[a].shape[0] and distinct[b].shape[0]  # an empty polyline overlaps nothing
    ]
    if not pairs:
        return []
    # A polyline without repeated vertices serves as it is.
    measured = PackedPolylines([
        lines[k] if distinct[k].shape[0] == len(lines[k]) else Polyline(distinct[k])
        for k in members
    ])
    position = {k: n for n, k in enumerate(members)}
    distances = restricted_hausdorff(
        measured, measured, mode, limit=gate,
        pairs=[(position[a], position[b]) for a, b in pairs],
    ).tolist()
    parent = list(range(len(lines)))

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
    polylines: PackedPolylines | Sequence[Polyline], weights: Sequence[float],
    members: Sequence[int], epsilon: float,
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
        weight = total / max(weights[k], 1e-12)
        (result, _), = merge([result], [[polylines[k]]], epsilon,
                             edge_weights=np.full(max(len(result) - 1, 0), weight),
                             end_weights=[weight])
        total += float(weights[k])
    return result
