"""Split-and-merge (iterative end-point fit), the classic line extractor, as a baseline.

The paper simplifies each scan interval with Douglas-Peucker. The textbook alternative
for 2D laser scans is split-and-merge (Pavlidis & Horowitz 1974; the "iterative end-point
fit" of Duda & Hart), compared on laser data by Nguyen et al. (IROS 2005):

- *split*: fit the chord between the end points of a section and split it at the point
  farthest from the chord's **line** (not segment), until every section is within the
  threshold - or, to compare extractors at the same vertex count, until a vertex budget
  is spent, always splitting the section with the largest deviation first;
- *merge*: drop a vertex between two neighbouring sections when the points of both are
  within the threshold of the chord joining their outer ends (collinear neighbours),
  cheapest first.

:func:`extract_split_and_merge` runs it over a scan with the paper pipeline's own
interval split (``semistatic.extraction``), so only the vertex selection differs.

Examples
--------
>>> corner = [[0, 0], [1, 0.01], [2, 0], [2, 1], [2, 2]]
>>> split_and_merge(corner, threshold=0.05)
array([0, 2, 4])
>>> split_and_merge(corner, max_vertices=2)
array([0, 4])
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from semistatic.extraction import remove_invalid, remove_outliers, split_breakpoints
from semistatic.params import MapperParams
from semistatic.polyline import Polyline
from semistatic.types import Scan

__all__ = ["extract_split_and_merge", "split_and_merge"]

# A chord shorter than this (m) has no direction: deviations are then measured to its
# start point instead of to its line.
DEGENERATE_CHORD = 1e-12
# In budget-only mode (no threshold) neighbours count as collinear, and a section as
# straight, when every point is within this (m) of the chord line: rounding, not geometry.
COLLINEAR_TOLERANCE = 1e-9


def _line_deviations(points: np.ndarray, first: int, last: int) -> np.ndarray:
    """Return distances of ``points[first + 1:last]`` to the line through first and last."""
    inner = points[first + 1 : last]
    start, end = points[first], points[last]
    direction = end - start
    length = math.hypot(direction[0], direction[1])
    offset = inner - start
    if length < DEGENERATE_CHORD:
        return np.hypot(offset[:, 0], offset[:, 1])
    return np.abs(offset[:, 0] * direction[1] - offset[:, 1] * direction[0]) / length


def _farthest(points: np.ndarray, first: int, last: int) -> tuple[float, int]:
    """Return the largest line deviation inside ``first..last`` and where it is."""
    if last - first < 2:
        return 0.0, -1
    deviations = _line_deviations(points, first, last)
    at = int(np.argmax(deviations))  # the first maximum on ties
    return float(deviations[at]), first + 1 + at


def _split(points: np.ndarray, threshold: float, max_vertices: float) -> list[int]:
    """Split greedily, largest deviation first, until within threshold or on budget."""
    last = len(points) - 1
    kept = [0, last]
    # heapq is a min-heap: store negated deviations. The index breaks ties towards the
    # earliest section, so the result does not depend on heap internals.
    heap: list[tuple[float, int, int, int]] = []
    deviation, at = _farthest(points, 0, last)
    heap.append((-deviation, 0, last, at))
    while heap and len(kept) < max_vertices:
        negative, first, end, at = heapq.heappop(heap)
        if -negative <= threshold:
            break  # the worst section is within the threshold: all are
        kept.append(at)
        for a, b in ((first, at), (at, end)):
            deviation, pivot = _farthest(points, a, b)
            if pivot >= 0:
                heapq.heappush(heap, (-deviation, a, b, pivot))
    return sorted(kept)


def _merge(points: np.ndarray, kept: list[int], tolerance: float) -> list[int]:
    """Drop interior vertices whose neighbours' chord fits within ``tolerance``."""
    kept = list(kept)

    def cost(position: int) -> float:
        deviation, _ = _farthest(points, kept[position - 1], kept[position + 1])
        return deviation

    while len(kept) > 2:
        costs = [cost(position) for position in range(1, len(kept) - 1)]
        best = int(np.argmin(costs))
        if costs[best] > tolerance:
            break
        del kept[best + 1]
    return kept


def split_and_merge(
    points: ArrayLike,
    *,
    threshold: float | None = None,
    max_vertices: int | None = None,
) -> np.ndarray:
    """Return the indices of the vertices split-and-merge keeps.

    Parameters
    ----------
    points
        ``(N, 2)`` points in traversal order (e.g. one scan interval).
    threshold
        Split while some point is farther than this (m) from its section's chord line;
        merge neighbours whose joint chord keeps every point within it.
    max_vertices
        Stop splitting at this many vertices (>= 2). Alone (no ``threshold``) the split
        spends the whole budget unless the points are collinear, and the merge only
        removes vertices that are collinear to rounding (``COLLINEAR_TOLERANCE``): the
        result has exactly ``min(max_vertices, needed)`` vertices.

    Returns
    -------
    numpy.ndarray
        Increasing int64 indices into ``points``, always with the first and last point
        (empty for no points, ``[0]`` for one).

    Examples
    --------
    >>> arc = [[np.cos(a), np.sin(a)] for a in np.linspace(0, np.pi / 2, 9)]
    >>> split_and_merge(arc, threshold=0.05)  # sagitta of 22.5 deg: 0.076 m; of 11.25: 0.019
    array([0, 2, 4, 6, 8])
    >>> split_and_merge(arc, max_vertices=3)
    array([0, 4, 8])
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if threshold is None and max_vertices is None:
        raise ValueError(
            "split_and_merge: give threshold (m) or max_vertices (a vertex budget), or both"
        )
    if threshold is not None and not threshold >= 0:
        raise ValueError(f"split_and_merge: threshold must be >= 0 m, got {threshold!r}")
    if max_vertices is not None and not (int(max_vertices) == max_vertices and max_vertices >= 2):
        raise ValueError(
            f"split_and_merge: max_vertices must be an integer >= 2, got {max_vertices!r}"
        )
    if not np.isfinite(points).all():
        raise ValueError("split_and_merge: points must be finite; drop invalid readings first")
    if len(points) <= 2:
        return np.arange(len(points), dtype=np.int64)
    budget = math.inf if max_vertices is None else int(max_vertices)
    split_threshold = COLLINEAR_TOLERANCE if threshold is None else threshold
    kept = _split(points, split_threshold, budget)
    kept = _merge(points, kept, split_threshold)
    return np.array(kept, dtype=np.int64)


def extract_split_and_merge(
    scan: Scan,
    params: MapperParams | None = None,
    *,
    vertex_counts: Sequence[int] | None = None,
) -> list[Polyline]:
    """Extract polylines like the paper pipeline, choosing vertices by split-and-merge.

    Invalid readings, outliers (when ``params.outlier_removal``) and the breakpoint split
    are exactly those of
    :func:`semistatic.extraction.extract_polylines` (same ``params``), so the intervals
    are the same; each is then simplified with :func:`split_and_merge`.

    Parameters
    ----------
    scan
        The laser scan; polylines come out in its sensor frame, in scan order.
    params
        Extraction thresholds; ``MapperParams()`` when omitted. ``params.epsilon`` is the
        split-and-merge threshold unless ``vertex_counts`` is given.
    vertex_counts
        One vertex budget per interval (e.g. ``[len(p) for p in extract_polylines(scan,
        params)]``) to compare both extractors at the same vertex count.

    Returns
    -------
    list of Polyline
        One per interval, vertices with their beam indices.

    Examples
    --------
    >>> angles = np.radians(np.arange(-45.0, 45.5, 1.0))
    >>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0],
    ...             angle_increment=np.radians(1.0))
    >>> [p.scan_indices.tolist() for p in extract_split_and_merge(scan)]
    [[0, 90]]
    """
    params = MapperParams() if params is None else params
    valid = remove_invalid(scan, params.max_range)
    if params.outlier_removal:
        valid = remove_outliers(scan.ranges, valid, params.outlier_k, params.outlier_alpha)
    intervals = split_breakpoints(
        scan, valid, params.breakpoint_lambda, params.breakpoint_sigma_r, params.min_points
    )
    if vertex_counts is not None and len(vertex_counts) != len(intervals):
        raise ValueError(
            f"extract_split_and_merge: vertex_counts has {len(vertex_counts)} entries but "
            f"the scan splits into {len(intervals)} intervals; use the same params as the "
            "extraction the counts came from"
        )
    points = scan.points()
    polylines = []
    for number, beams in enumerate(intervals):
        section = points[beams]
        if vertex_counts is None:
            kept = split_and_merge(section, threshold=params.epsilon)
        else:
            kept = split_and_merge(section, max_vertices=vertex_counts[number])
        polylines.append(Polyline(section[kept], beams[kept]))
    return polylines
