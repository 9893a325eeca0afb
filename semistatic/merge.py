"""Merge a scan polyline into its map polyline, and join overlapping map polylines.

Paper Sec. 3.4 and DESIGN.md details 7-8. The vertices of the scan polyline are projected
onto the map polyline and inserted by their arc-length position; where the scan sees
farther than the map at either end, the map is extended with the scan's vertices; the
result is simplified again with Douglas-Peucker.

Merging is also an averaging step, so that repeated observations of an unchanged object
converge instead of drifting or growing:

- a map polyline that summarises ``w`` observations moves toward the scan by
  ``alpha = 1 / (1 + w)`` (``map_weight=w``): each map vertex that faces the scan moves
  ``alpha`` of the way to its nearest point on the scan polyline, and each inserted scan
  vertex lies ``alpha`` of the way from its projection on the map to where the scan saw it.
  Vertices inserted close to a map edge are collinear with it and removed by
  Douglas-Peucker, so the vertex count stays that of the shape, not of the observations;
- an end of the scan within ``end_tolerance`` of the map's end (noise, beam spacing) moves
  the map's end by ``alpha`` too, in whichever direction: ends neither ratchet outwards
  nor shrink. Only a scan that reaches farther than ``end_tolerance`` extends the map, and
  only a scan that stops short of it leaves the map's end alone (a partial view).
- a map edge that cuts a corner (the lines of its neighbouring edges meet within
  ``epsilon`` of a scan vertex farther than ``epsilon`` from the edge) is no surface: the
  scan's corner is averaged with that intersection, not with its foot on the edge, so a
  corner that the first views cut is learnt however many observations the map holds.

Examples
--------
>>> wall = [[0.0, 0.0], [2.0, 0.0]]
>>> merge(wall, [[1.0, 0.02], [3.0, 0.02]], epsilon=0.03).points.round(3)  # seen farther
array([[0.  , 0.  ],
       [3.  , 0.02]])
>>> merge(wall, [[0.0, 0.02], [2.0, 0.02]], epsilon=0.03, map_weight=3.0).points.round(3)
array([[0.   , 0.005],
       [2.   , 0.005]])
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike

from semistatic.association import box_gaps
from semistatic.extraction import (
    PYTHON_DOUGLAS_PEUCKER,
    douglas_peucker,
    douglas_peucker_rows,
)
from semistatic.fitting import MIN_CORNER_SINE
from semistatic.hausdorff import restricted_hausdorff
from semistatic.polyline import Polyline, as_polyline

__all__ = [
    "END_TOLERANCE_FACTOR",
    "MIN_OVERLAP",
    "join",
    "merge",
    "merge_observation",
    "overlaps",
    "project_onto",
]

# Default end tolerance in units of the Douglas-Peucker epsilon. Scan ends wander by beam
# spacing and noise (2-5 cm at a few metres for 0.5 deg beams); 3 * 3 cm covers that, so
# only a real partial view (or a real extension) counts as one.
END_TOLERANCE_FACTOR = 3.0

# Consecutive vertices closer than this (m) are one vertex (zero-length edges have no
# direction to project onto).
DUPLICATE_DISTANCE = 1e-9

# Up to this many point-segment pairs, projecting with Python floats beats numpy, whose
# per-call overhead dominates on the handful of vertices of a merge.
SMALL_PROJECTION = 64

# Two polylines' extents overlap when the projections of one onto the other span more
# than this (m): end-to-end pieces that merely touch (a box's two faces at their corner)
# do not.
MIN_OVERLAP = 1e-6


@dataclass(frozen=True)
class Projection:
    """Orthogonal projections of points onto a polyline (see :func:`project_onto`).

    Examples
    --------
    >>> project_onto([[3.0, 1.0]], [[0.0, 0.0], [2.0, 0.0]]).after
    array([ True])
    """

    arc: np.ndarray
    """``(K,)`` arc-length position of the nearest point, in ``[0, length]``."""
    foot: np.ndarray
    """``(K, 2)`` nearest point on the polyline."""
    distance: np.ndarray
    """``(K,)`` distance to the polyline."""
    before: np.ndarray
    """``(K,)`` true where the nearest point is the start vertex (the point lies at or
    beyond the polyline's start)."""
    after: np.ndarray
    """``(K,)`` true where the nearest point is the end vertex."""


def _distinct(points: np.ndarray) -> np.ndarray:
    """Return ``points`` without consecutive repeats."""
    if points.shape[0] < 2:
        return points
    if points.shape[0] * (points.shape[0] - 1) <= SMALL_PROJECTION:
        rows = points.tolist()
        kept = [0] + [
            k
            for k in range(1, len(rows))
            if (rows[k][0] - rows[k - 1][0]) ** 2 + (rows[k][1] - rows[k - 1][1]) ** 2
            > DUPLICATE_DISTANCE**2
        ]
        return points if len(kept) == len(rows) else points[kept]
    steps = points[1:] - points[:-1]
    repeated = np.einsum("ij,ij->i", steps, steps) <= DUPLICATE_DISTANCE**2
    if not repeated.any():
        return points
    return points[np.concatenate(([True], ~repeated))]


def _distinct_rows(rows: list[list[float]]) -> list[list[float]]:
    """Return vertex ``rows`` without consecutive repeats (Python floats)."""
    if len(rows) < 2:
        return rows
    # As _distinct: each vertex is compared with the one before it in the input.
    return [rows[0]] + [
        row
        for previous, row in itertools.pairwise(rows)
        if (row[0] - previous[0]) ** 2 + (row[1] - previous[1]) ** 2 > DUPLICATE_DISTANCE**2
    ]


# Projections inside merge travel as plain lists: (arc, foot, distance, before, after).
_Found = tuple[list[float], list[list[float]], list[float], list[bool], list[bool]]


def _project(points: np.ndarray, vertices: np.ndarray) -> Projection:
    """Project ``(K, 2)`` points onto distinct ``(N >= 2, 2)`` vertices (no checks)."""
    if points.shape[0] * (vertices.shape[0] - 1) <= SMALL_PROJECTION:
        arc, foot, distance, before, after = _project_lists(points.tolist(), vertices.tolist())
        return Projection(
            arc=np.array(arc),
            foot=np.array(foot).reshape(-1, 2),
            distance=np.array(distance),
            before=np.array(before, dtype=bool),
            after=np.array(after, dtype=bool),
        )
    return _project_vectorised(points, vertices)


def _found(points: list[list[float]], vertices: list[list[float]]) -> _Found:
    """Return :func:`_project` as lists, computed the cheaper way for the size."""
    if len(points) * (len(vertices) - 1) <= SMALL_PROJECTION:
        return _project_lists(points, vertices)
    found = _project_vectorised(np.array(points), np.array(vertices))
    return (
        found.arc.tolist(),
        found.foot.tolist(),
        found.distance.tolist(),
        found.before.tolist(),
        found.after.tolist(),
    )


def _project_lists(points: list[list[float]], vertices: list[list[float]]) -> _Found:
    """Return :func:`_project` with plain Python floats (fast for a few pairs)."""
    segments = []
    arc = 0.0
    for (ax, ay), (bx, by) in itertools.pairwise(vertices):
        ex, ey = bx - ax, by - ay
        squared = ex * ex + ey * ey
        length = math.sqrt(squared)
        segments.append((ax, ay, ex, ey, squared, length, arc))
        arc += length
    last = len(segments) - 1
    arcs, feet, distances, before, after = [], [], [], [], []
    for px, py in points:
        best = (math.inf, 0, 0.0, 0.0)
        for index, (ax, ay, ex, ey, squared, _, _) in enumerate(segments):
            raw = ((px - ax) * ex + (py - ay) * ey) / squared
            t = 0.0 if raw < 0.0 else 1.0 if raw > 1.0 else raw
            gx, gy = px - ax - t * ex, py - ay - t * ey
            squared_distance = gx * gx + gy * gy
            if squared_distance < best[0]:  # strict: the lowest segment wins ties
                best = (squared_distance, index, t, raw)
        squared_distance, index, t, raw = best
        ax, ay, ex, ey, _, length, start = segments[index]
        arcs.append(start + t * length)
        feet.append([ax + t * ex, ay + t * ey])
        distances.append(math.sqrt(squared_distance))
        before.append(index == 0 and raw <= 0.0)
        after.append(index == last and raw >= 1.0)
    return arcs, feet, distances, before, after


def _project_vectorised(points: np.ndarray, vertices: np.ndarray) -> Projection:
    """Return :func:`_project` with numpy (for many point-segment pairs)."""
    starts = vertices[:-1]
    edges = vertices[1:] - starts
    edge_x, edge_y = edges[:, 0], edges[:, 1]
    squared = edge_x * edge_x + edge_y * edge_y
    lengths = np.sqrt(squared)
    rel_x = points[:, 0, None] - starts[:, 0]
    rel_y = points[:, 1, None] - starts[:, 1]
    raw = (rel_x * edge_x + rel_y * edge_y) / squared
    t = np.minimum(np.maximum(raw, 0.0), 1.0)
    gap_x, gap_y = rel_x - t * edge_x, rel_y - t * edge_y
    squared_distances = gap_x * gap_x + gap_y * gap_y
    nearest = squared_distances.argmin(axis=1)
    rows = np.arange(points.shape[0])
    t_near, raw_near = t[rows, nearest], raw[rows, nearest]
    arcs = np.concatenate(([0.0], np.add.accumulate(lengths)))
    return Projection(
        arc=arcs[nearest] + t_near * lengths[nearest],
        foot=starts[nearest] + t_near[:, None] * edges[nearest],
        distance=np.sqrt(squared_distances[rows, nearest]),
        before=(nearest == 0) & (raw_near <= 0.0),
        after=(nearest == edges.shape[0] - 1) & (raw_near >= 1.0),
    )


def project_onto(points: ArrayLike, polyline: Polyline | ArrayLike) -> Projection:
    """Project points orthogonally onto a polyline of at least two distinct vertices.

    Each point goes to its nearest point on the polyline (the lowest segment on ties),
    flagged ``before``/``after`` when that nearest point is the first/last vertex.

    Examples
    --------
    >>> found = project_onto([[1.0, 0.5], [-1.0, 0.0]], [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    >>> found.arc, found.distance, found.before
    (array([1., 0.]), array([0.5, 1. ]), array([False,  True]))
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    vertices = _distinct(as_polyline(polyline).points)
    if vertices.shape[0] < 2:
        raise ValueError(
            "project_onto: the polyline needs at least two distinct vertices, "
            f"got {vertices.shape[0]}"
        )
    return _project(points, vertices)


# The scan indices 0..N-1 of merged polylines, one read-only array per N.
_VERTEX_ORDER: dict[int, np.ndarray] = {}


def _polyline(rows: list[list[float]]) -> Polyline:
    """Wrap finite vertex rows computed here as a polyline (scan indices: vertex order)."""
    points = np.array(rows, dtype=np.float64).reshape(-1, 2)
    indices = _VERTEX_ORDER.get(points.shape[0])
    if indices is None:  # frozen by _trusted, so shared by every polyline of that size
        indices = _VERTEX_ORDER[points.shape[0]] = np.arange(points.shape[0], dtype=np.int64)
    return Polyline._trusted(points, indices)


def _simplified(rows: list[list[float]], epsilon: float) -> Polyline:
    """Return vertex ``rows`` simplified with Douglas-Peucker as a new polyline.

    Both ways keep exactly the vertices ``douglas_peucker`` keeps (DESIGN.md detail 3):
    a merge has a handful of vertices, for which the Python twin of GEOS's recursion is
    cheapest; GEOS is called directly for more (the vectorised many-section version is
    tuned for whole scans).
    """
    if len(rows) <= 2:
        return _polyline(rows)
    if len(rows) <= PYTHON_DOUGLAS_PEUCKER:
        return _polyline([rows[k] for k in douglas_peucker_rows(rows, epsilon)])
    points = np.array(rows, dtype=np.float64)
    line = shapely.simplify(shapely.linestrings(points), epsilon, preserve_topology=False)
    kept = shapely.get_coordinates(line)
    if kept.shape[0] < 2:  # GEOS gave up on a degenerate line: do it ourselves
        kept = points[douglas_peucker(points, epsilon)]
    return _polyline(kept.tolist())


def _extend_with_point(
    vertices: list[list[float]], point: list[float], tolerance: float
) -> list[list[float]]:
    """Return ``vertices`` extended by ``point`` when it lies beyond an end by > tolerance."""
    _, _, distance, before, after = _found([point], vertices)
    if distance[0] > tolerance:
        if before[0]:
            return [point, *vertices]
        if after[0]:
            return [*vertices, point]
    return vertices


def _run_length(flags: list[bool]) -> int:
    """Return the length of the leading run of true values."""
    count = 0
    for flag in flags:
        if not flag:
            break
        count += 1
    return count


def merge(
    map_polyline: Polyline | ArrayLike,
    scan_polyline: Polyline | ArrayLike,
    epsilon: float,
    *,
    map_weight: float = 1.0,
    end_tolerance: float | None = None,
) -> Polyline:
    """Merge an associated scan polyline into a map polyline (DESIGN.md detail 7).

    Parameters
    ----------
    map_polyline
        The map polyline; its direction is kept.
    scan_polyline
        The associated observation, in the same frame; it is reversed if it runs the other
        way along the map polyline.
    epsilon
        Douglas-Peucker tolerance (m) of the re-simplification, ``> 0``.
    map_weight
        How many observations the map polyline stands for relative to the scan polyline
        (e.g. its hit count): the map moves ``1 / (1 + map_weight)`` of the way toward the
        scan. ``0`` replaces the overlapping part by the scan's.
    end_tolerance
        Ends closer than this (m) are the same end seen again and are averaged; farther
        scan ends extend the map. Default ``END_TOLERANCE_FACTOR * epsilon``.

    Returns
    -------
    Polyline
        The merged polyline; its scan indices are the vertex order (``0..N-1``), since
        its vertices no longer come from one scan. An empty scan polyline returns
        ``map_polyline`` itself; a single-vertex one only extends the map when it lies
        beyond an end.

    Examples
    --------
    >>> box = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
    >>> merge(box, [[1.0, 0.5], [1.0, 1.6]], epsilon=0.03).points  # the scan saw more
    array([[0. , 0. ],
           [1. , 0. ],
           [1. , 1.6]])
    >>> len(merge(box, [[0.4, 0.01], [0.6, -0.01]], epsilon=0.03))  # a partial view
    3
    """
    return _merged_parts("merge", map_polyline, [scan_polyline], epsilon, map_weight,
                         end_tolerance)


def merge_observation(
    map_polyline: Polyline | ArrayLike,
    parts: Sequence[Polyline | ArrayLike],
    epsilon: float,
    *,
    map_weight: float = 1.0,
    end_tolerance: float | None = None,
) -> Polyline:
    """Merge the scan polylines one observation associated with a map polyline.

    A map polyline may be associated with several polylines of one scan (an object cut
    by an occluder): each is merged in turn with :func:`merge`, all with the same
    ``map_weight``, since together they are one observation. Parameters as :func:`merge`.

    Examples
    --------
    >>> wall = [[0.0, 0.0], [4.0, 0.0]]
    >>> parts = [[[0.0, 0.02], [1.5, 0.02]], [[2.5, 0.02], [4.0, 0.02]]]  # a pillar between
    >>> merge_observation(wall, parts, epsilon=0.03).points.round(3)
    array([[0.  , 0.01],
           [4.  , 0.01]])
    """
    return _merged_parts("merge_observation", map_polyline, parts, epsilon, map_weight,
                         end_tolerance)


def _merged_parts(
    caller: str,
    map_polyline: Polyline | ArrayLike,
    parts: Sequence[Polyline | ArrayLike],
    epsilon: float,
    map_weight: float,
    end_tolerance: float | None,
) -> Polyline:
    """Return :func:`merge_observation` with its parameters checked once for ``caller``."""
    if not epsilon > 0.0:
        raise ValueError(f"{caller}: epsilon must be > 0 m, got {epsilon!r}")
    if not map_weight >= 0.0:
        raise ValueError(f"{caller}: map_weight must be >= 0, got {map_weight!r}")
    tolerance = END_TOLERANCE_FACTOR * epsilon if end_tolerance is None else end_tolerance
    if not tolerance >= 0.0:
        raise ValueError(f"{caller}: end_tolerance must be >= 0 m, got {end_tolerance!r}")
    line = as_polyline(map_polyline)
    for part in parts:
        line = _merge_rows(line, as_polyline(part).points.tolist(), epsilon, map_weight,
                           tolerance)
    return line


def _merge_rows(
    original: Polyline,
    scan_rows: list[list[float]],
    epsilon: float,
    map_weight: float,
    tolerance: float,
) -> Polyline:
    """Return :func:`merge` of scan vertices given as rows, with checked parameters."""
    old = _distinct_rows(original.points.tolist())
    new = _distinct_rows(scan_rows)
    alpha = 1.0 / (1.0 + map_weight) if math.isfinite(map_weight) else 0.0
    if not new:
        return original
    if not old:
        return _simplified(new, epsilon)
    if len(old) == 1 and len(new) == 1:
        (x0, y0), (x1, y1) = old[0], new[0]
        return _polyline([[x0 + alpha * (x1 - x0), y0 + alpha * (y1 - y0)]])
    if len(old) == 1:
        # A point has no extent to average: the scan's shape wins, the point may extend it.
        return _simplified(_extend_with_point(new, old[0], tolerance), epsilon)
    if len(new) == 1:
        return _simplified(_extend_with_point(old, new[0], tolerance), epsilon)
    return _simplified(_merged(old, new, alpha, tolerance, epsilon), epsilon)


def _cut_at(vertices: list[list[float]], arc: float, keep_head: bool) -> list[list[float]]:
    """Return the part of a polyline before (``keep_head``) or after arc length ``arc``."""
    position = 0.0
    for k, (start, end) in enumerate(itertools.pairwise(vertices)):
        length = math.dist(start, end)
        if position + length >= arc:
            t = (arc - position) / length if length > 0.0 else 0.0
            cut = [start[0] + t * (end[0] - start[0]), start[1] + t * (end[1] - start[1])]
            return [*vertices[: k + 1], cut] if keep_head else [cut, *vertices[k + 1 :]]
        position += length
    return list(vertices) if keep_head else [vertices[-1]]


def _past_edge(
    vertices: list[list[float]], arc: float, point: list[float], tolerance: float,
    forward: bool,
) -> bool:
    """Return whether ``point`` continues the map edge at arc length ``arc`` past its end.

    True when ``point`` projects on that edge's line more than ``tolerance`` beyond the
    edge's end vertex (before its start vertex when not ``forward``): the scan goes on
    where the map turns. A point beside the edge (a noisy end) does not count.
    """
    position = 0.0
    edges = list(itertools.pairwise(vertices))
    for number, (start, end) in enumerate(edges):
        length = math.dist(start, end)
        if position + length < arc and number < len(edges) - 1:
            position += length
            continue
        if length == 0.0:
            return False
        ux, uy = (end[0] - start[0]) / length, (end[1] - start[1]) / length
        along = (point[0] - start[0]) * ux + (point[1] - start[1]) * uy
        return along > length + tolerance if forward else along < -tolerance
    return False


def _contradicted(
    old: list[list[float]], new: list[list[float]], on_map: _Found, tolerance: float
) -> list[list[float]] | None:
    """Return ``old`` without the ends the scan contradicts, or ``None`` if none is.

    Where the scan, past the last (first) of its vertices that agree with the map (within
    ``tolerance``), runs on straight beyond the end of the map edge they agree on while
    the map turns away, the two disagree on where the surface goes: the map's end beyond
    that point is what the scan no longer sees there (a moved object's old face, hidden
    inside the new footprint). It is cut,
    and the scan's continuation then extends the map like any longer view. Averaging the
    two instead would pull scan vertices onto the old face and draw an edge across the
    object.
    """
    arcs, _, distances, before, after = on_map
    agree = [k for k, distance in enumerate(distances) if distance <= tolerance]
    if not agree:
        return None
    first, last = agree[0], agree[-1]
    tail = any(
        distances[k] > tolerance and not after[k]
        and _past_edge(old, arcs[last], new[k], tolerance, forward=True)
        for k in range(last + 1, len(arcs))
    )
    head = any(
        distances[k] > tolerance and not before[k]
        and _past_edge(old, arcs[first], new[k], tolerance, forward=False)
        for k in range(first)
    )
    if not (tail or head):
        return None
    cut = old
    if tail:
        cut = _cut_at(cut, arcs[last], keep_head=True)
    if head:
        cut = _cut_at(cut, arcs[first], keep_head=False)
    cut = _distinct_rows(cut)
    return cut if len(cut) >= 2 else None


def _cut_corner(
    vertices: list[list[float]], map_arcs: list[float], arc: float, point: list[float],
    epsilon: float,
) -> list[float] | None:
    """Return the corner a map edge cuts off where the scan sees it, or ``None``.

    The map edge at arc length ``arc`` is a chord across a corner when the lines of the
    edges before and after it meet within ``epsilon`` of ``point`` (the scan's vertex
    there): the map's own faces run on to where the scan sees them meet. Their
    intersection is returned. A corner's first views can cut it like that: one face seen
    at grazing incidence from afar, with a reading or two on it.
    """
    edge = bisect.bisect_right(map_arcs, arc) - 1
    if not 1 <= edge <= len(vertices) - 3:
        return None
    (ax, ay), (bx, by) = vertices[edge - 1], vertices[edge]
    (cx, cy), (dx, dy) = vertices[edge + 1], vertices[edge + 2]
    ux, uy, vx, vy = bx - ax, by - ay, dx - cx, dy - cy
    cross = ux * vy - uy * vx
    if abs(cross) <= MIN_CORNER_SINE * math.hypot(ux, uy) * math.hypot(vx, vy):
        return None  # nearly parallel faces meet nowhere useful
    t = ((cx - ax) * vy - (cy - ay) * vx) / cross
    corner = [ax + t * ux, ay + t * uy]
    return corner if math.dist(corner, point) <= epsilon else None


def _merged(
    old: list[list[float]], new: list[list[float]], alpha: float, tolerance: float,
    epsilon: float, cut: bool = True,
) -> list[list[float]]:
    """Return the merge candidates of :func:`merge` before Douglas-Peucker (>= 2 each)."""
    on_map = _found(new, old)
    arcs = on_map[0]
    if arcs[0] > arcs[-1] or (
        arcs[0] == arcs[-1]
        and (new[-1][0] - new[0][0]) * (old[-1][0] - old[0][0])
        + (new[-1][1] - new[0][1]) * (old[-1][1] - old[0][1])
        < 0.0
    ):
        new = new[::-1]
        on_map = tuple(values[::-1] for values in on_map)  # type: ignore[assignment]
    if cut and (kept := _contradicted(old, new, on_map, tolerance)) is not None:
        return _merged(kept, new, alpha, tolerance, epsilon, cut=False)
    arcs, feet, distances, before, after = on_map
    _, scan_feet, scan_distances, scan_before, scan_after = _found(old, new)

    def toward(point: list[float], target: list[float]) -> list[float]:
        return [
            point[0] + alpha * (target[0] - point[0]),
            point[1] + alpha * (target[1] - point[1]),
        ]

    # Map vertices facing the scan move toward it.
    moved = [
        [x + alpha * (foot_x - x), y + alpha * (foot_y - y)]
        if not (ahead or behind) and distance <= tolerance
        else [x, y]
        for (x, y), (foot_x, foot_y), distance, ahead, behind in zip(
            old, scan_feet, scan_distances, scan_before, scan_after, strict=True
        )
    ]
    # Scan vertices facing the map are inserted, pulled toward the map by its weight.
    inserted = [not (ahead or behind) for ahead, behind in zip(before, after, strict=True)]
    count = len(new)
    prepend, append = 0, 0
    map_arcs = [0.0, *itertools.accumulate(map(math.dist, old, old[1:]))]

    # Start: by how much does the scan reach beyond the map's start?
    reach = distances[0] if before[0] else -arcs[0]
    if reach > tolerance:
        prepend = _run_length(before)
    elif reach >= -tolerance:
        moved[0] = toward(old[0], new[0])
        inserted[0] = False
    # End: the same, mirrored.
    reach = distances[-1] if after[-1] else arcs[-1] - map_arcs[-1]
    if reach > tolerance:
        append = _run_length(after[::-1])
    elif reach >= -tolerance:
        moved[-1] = toward(old[-1], new[-1])
        inserted[-1] = False

    # Map vertices first on equal arc length, then scan vertices in scan order: the keys
    # (arc, 0 or 1, index) are unique, so the vertices themselves are never compared.
    middle = [((map_arcs[k], 0, k), vertex) for k, vertex in enumerate(moved)]
    # An inner scan vertex farther than epsilon from a map edge that cuts a corner is
    # averaged with the corner the map's faces imply, not with its foot on the chord:
    # pulled toward the chord, it would lie within epsilon of it once the map stands for
    # a few observations, Douglas-Peucker would drop it every time, and the map could
    # never learn the corner.
    anchors = [
        _cut_corner(old, map_arcs, arcs[k], new[k], epsilon)
        if inserted[k] and 0 < k < count - 1 and distances[k] > epsilon else None
        for k in range(count)
    ]
    middle += [
        ((arcs[k], 1, k), [foot_x + alpha * (x - foot_x), foot_y + alpha * (y - foot_y)])
        for k, ((x, y), (foot_x, foot_y)) in enumerate(
            (vertex, foot if anchor is None else anchor)
            for vertex, foot, anchor in zip(new, feet, anchors, strict=True)
        )
        if inserted[k]
    ]
    middle.sort()
    beyond_start = [new[k] for k in range(prepend) if distances[k] > tolerance]
    beyond_end = [new[k] for k in range(count - append, count) if distances[k] > tolerance]
    candidates = [*beyond_start, *(vertex for _, vertex in middle), *beyond_end]
    kept = [candidates[0]]
    for previous, point in itertools.pairwise(candidates):
        if math.dist(point, previous) > DUPLICATE_DISTANCE:
            kept.append(point)
    return kept


def _edge_lengths(points: np.ndarray) -> np.ndarray:
    edges = points[1:] - points[:-1]
    return np.sqrt(np.einsum("ij,ij->i", edges, edges))


def _arc_length(points: np.ndarray) -> float:
    return float(_edge_lengths(points).sum())


def _projection_span(points: np.ndarray, onto: np.ndarray) -> tuple[float, bool]:
    """Return the arc-length span of ``points`` projected on ``onto`` and if one is inside."""
    found = _project(points, onto)
    span = float(found.arc.max() - found.arc.min())
    length = _arc_length(onto)
    inside = bool(np.any((found.arc > MIN_OVERLAP) & (found.arc < length - MIN_OVERLAP)))
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
    points0 = _distinct(as_polyline(p0).points)
    points1 = _distinct(as_polyline(p1).points)
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
