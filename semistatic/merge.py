"""Merge a scan polyline into its map polyline (joining map polylines: :mod:`semistatic.join`).

Paper Sec. 3.4 and docs/design.md#detail-7, #detail-8. The vertices of the scan polyline
are projected onto the map polyline and inserted by their arc-length position; where the
scan sees farther than the map at either end, the map is extended with the scan's
vertices; the result is simplified again with Douglas-Peucker.

Merging is also an averaging step, so that repeated observations of an unchanged object
converge instead of drifting or growing:

- a map polyline that summarises ``w`` observations moves toward the scan by
  ``alpha = 1 / (1 + w)`` (edge and end weights ``w``): each map vertex that faces the
  scan moves ``alpha`` of the way to its nearest point on the scan polyline, and each
  inserted scan vertex lies ``alpha`` of the way from its projection on the map to where
  the scan saw it.
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
>>> (line, _), = merge([wall], [[[[1.0, 0.02], [3.0, 0.02]]]], epsilon=0.03)  # seen farther
>>> line.points.round(3)
array([[0.  , 0.  ],
       [3.  , 0.02]])
>>> (line, _), = merge([wall], [[[[0.0, 0.02], [2.0, 0.02]]]], 0.03, edge_weights=[3.0],
...                    end_weights=[3.0])
>>> line.points.round(3)
array([[0.   , 0.005],
       [2.   , 0.005]])
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.extraction import douglas_peucker
from semistatic.fitting import MIN_CORNER_SINE
from semistatic.polyline import (
    PackedPolylines,
    Polyline,
    as_polyline,
    as_polylines,
    run_offsets,
)

__all__ = [
    "DUPLICATE_DISTANCE",
    "END_TOLERANCE_FACTOR",
    "Projection",
    "distinct_vertices",
    "merge",
    "project_onto",
    "transfer_weights",
]

# Default end tolerance in units of the Douglas-Peucker epsilon. Scan ends wander by beam
# spacing and noise (2-5 cm at a few metres for 0.5 deg beams); 3 * 3 cm covers that, so
# only a real partial view (or a real extension) counts as one.
END_TOLERANCE_FACTOR = 3.0

# Consecutive vertices closer than this (m) are one vertex (zero-length edges have no
# direction to project onto).
DUPLICATE_DISTANCE = 1e-9

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


@numba.njit(cache=True)
def _distinct(points: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Return a copy of ``(N, 2)`` ``points`` without consecutive repeats.

    Each vertex is compared with the one before it in the input.
    """
    return _kept_rows(points, _distinct_mask(points))


@numba.njit(cache=True)
def _distinct_mask(points: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Return which of ``points`` :func:`_distinct` keeps."""
    keep = np.empty(points.shape[0], np.bool_)
    if keep.size:
        keep[0] = True
    for k in range(1, points.shape[0]):
        dx, dy = points[k, 0] - points[k - 1, 0], points[k, 1] - points[k - 1, 1]
        keep[k] = dx * dx + dy * dy > DUPLICATE_DISTANCE**2
    return keep


@numba.njit(cache=True)
def _project(
    points: np.ndarray, vertices: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """Project ``(K, 2)`` points onto distinct ``(N >= 2, 2)`` vertices (no checks).

    Returns the fields of :class:`Projection`: arc, foot, distance, before, after.
    """
    count = points.shape[0]
    last = vertices.shape[0] - 2
    starts = np.empty(last + 2)
    starts[0] = 0.0
    for edge in range(last + 1):
        starts[edge + 1] = starts[edge] + math.sqrt(_squared_edge(vertices, edge))
    arc, foot, distance = np.empty(count), np.empty((count, 2)), np.empty(count)
    before, after = np.zeros(count, np.bool_), np.zeros(count, np.bool_)
    for k in range(count):
        px, py = points[k, 0], points[k, 1]
        best, index, best_t, best_raw = math.inf, 0, 0.0, 0.0
        for edge in range(last + 1):
            ax, ay = vertices[edge, 0], vertices[edge, 1]
            ex, ey = vertices[edge + 1, 0] - ax, vertices[edge + 1, 1] - ay
            raw = ((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey)
            t = 0.0 if raw < 0.0 else 1.0 if raw > 1.0 else raw
            gx, gy = px - ax - t * ex, py - ay - t * ey
            squared_distance = gx * gx + gy * gy
            if squared_distance < best:  # strict: the lowest segment wins ties
                best, index, best_t, best_raw = squared_distance, edge, t, raw
        ax, ay = vertices[index, 0], vertices[index, 1]
        ex, ey = vertices[index + 1, 0] - ax, vertices[index + 1, 1] - ay
        arc[k] = starts[index] + best_t * math.sqrt(ex * ex + ey * ey)
        foot[k, 0], foot[k, 1] = ax + best_t * ex, ay + best_t * ey
        distance[k] = math.sqrt(best)
        before[k] = index == 0 and best_raw <= 0.0
        after[k] = index == last and best_raw >= 1.0
    return arc, foot, distance, before, after


@numba.njit(cache=True)
def _squared_edge(vertices: np.ndarray, edge: int) -> float:  # pragma: no cover - compiled
    ex, ey = vertices[edge + 1, 0] - vertices[edge, 0], vertices[edge + 1, 1] - vertices[edge, 1]
    return ex * ex + ey * ey


@numba.njit(cache=True)
def _edge_length(vertices: np.ndarray, edge: int) -> float:  # pragma: no cover - compiled
    return math.hypot(vertices[edge + 1, 0] - vertices[edge, 0],
                      vertices[edge + 1, 1] - vertices[edge, 1])


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
    # Copies: one argument type, writeable, for every caller of the kernels.
    points = np.array(points, dtype=float).reshape(-1, 2)
    vertices = _distinct(np.array(as_polyline(polyline).points))
    if vertices.shape[0] < 2:
        raise ValueError(
            "project_onto: the polyline needs at least two distinct vertices, "
            f"got {vertices.shape[0]}"
        )
    return Projection(*_project(points, vertices))


def distinct_vertices(points: ArrayLike) -> np.ndarray:
    """Return ``(N, 2)`` vertices without consecutive repeats (closer than 1e-9 m).

    Each vertex is compared with the one before it in the input: zero-length edges have
    no direction to project onto.

    Examples
    --------
    >>> distinct_vertices([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    array([[0., 0.],
           [1., 0.]])
    """
    return _distinct(np.array(points, dtype=float).reshape(-1, 2))  # writeable, as in merge


@numba.njit(cache=True)
def _extend_with_point(
    vertices: np.ndarray, point: np.ndarray, tolerance: float
) -> np.ndarray:  # pragma: no cover - compiled
    """Return ``vertices`` extended by ``point`` when it lies beyond an end by > tolerance."""
    _, _, distance, before, after = _project(point.reshape(1, 2), vertices)
    if distance[0] > tolerance and (before[0] or after[0]):
        extended = np.empty((vertices.shape[0] + 1, 2))
        at = 1 if before[0] else 0  # where the vertices go
        _put_rows(vertices, 0, vertices.shape[0], extended, at)
        _put_rows(point.reshape(1, 2), 0, 1, extended, 0 if before[0] else vertices.shape[0])
        return extended
    return vertices.copy()


@numba.njit(cache=True, inline="always")
def _put_rows(
    source: np.ndarray, start: int, stop: int, target: np.ndarray, at: int
) -> None:  # pragma: no cover - compiled
    """Copy rows ``start:stop`` of ``source`` to ``target`` from row ``at`` on.

    (Loops rather than slice assignment, whose shape checks compile an error formatter;
    inlined, since constant arguments would compile one kernel per value.)
    """
    for k in range(stop - start):
        target[at + k, 0], target[at + k, 1] = source[start + k, 0], source[start + k, 1]


@numba.njit(cache=True)
def _run_length(flags: np.ndarray) -> int:  # pragma: no cover - compiled
    """Return the length of the leading run of true values."""
    count = 0
    while count < flags.size and flags[count]:
        count += 1
    return count


@numba.njit(cache=True)
def _trailing_run_length(flags: np.ndarray) -> int:  # pragma: no cover - compiled
    """Return the length of the trailing run of true values."""
    count = 0
    while count < flags.size and flags[flags.size - 1 - count]:
        count += 1
    return count


@numba.njit(cache=True)
def _reverse(values: np.ndarray) -> None:  # pragma: no cover - compiled
    """Reverse a 1-d array in place."""
    for k in range(values.size // 2):
        values[k], values[values.size - 1 - k] = values[values.size - 1 - k], values[k]


@numba.njit(cache=True)
def _reverse_rows(points: np.ndarray) -> None:  # pragma: no cover - compiled
    """Reverse the rows of an ``(N, 2)`` array in place."""
    last = points.shape[0] - 1
    for k in range(points.shape[0] // 2):
        for axis in range(2):
            points[k, axis], points[last - k, axis] = points[last - k, axis], points[k, axis]


def merge(
    map_polylines: PackedPolylines | Sequence[Polyline | ArrayLike],
    observations: Sequence[Sequence[Polyline | ArrayLike]],
    epsilon: float,
    *,
    edge_weights: ArrayLike | None = None,
    end_weights: ArrayLike | None = None,
    end_tolerance: float | None = None,
    counts: ArrayLike | None = None,
) -> list[tuple[Polyline, np.ndarray]]:
    """Merge what one observation saw of each map polyline into it (docs/design.md#detail-7).

    ``observations[k]`` are the scan polylines one scan associated with
    ``map_polylines[k]``: usually one, several when an occluder cut the object in pieces.
    They are merged into it in turn, all against the same map weights, since together
    they are one observation; every map polyline is merged in one compiled call.

    The map is averaged edge by edge: ``edge_weights`` holds one weight per edge of the
    map polylines, how many observations saw that edge so far; each scan edge is one
    more. Where the scan lies along a map edge, the map moves toward it by the scan's
    share of the weight there, ``1 / (1 + w)`` (weight
    ``0`` replaces the overlapping part by the scan's). Every edge of the result weighs
    what of the map and of the scan lies along it (length-weighted where
    re-simplification joins edges), so a well observed face converges while a face seen
    only lately - or a chord that bridged a gap to an extension, which no observation
    supports: weight 0 - follows the views that see it. A whole-polyline weight (the hit
    count) would freeze such a face at its first view.

    The ends are averaged as the whole polyline's: ``end_weights[k]`` (e.g. the hit
    count of ``map_polylines[k]``) is what an end, and a polyline that is a single vertex,
    weighs against a scan's end. An end keeps the reach that many views gave it against
    a few that stop short of it by beam spacing, whatever the weight of its last edge.

    Parameters
    ----------
    map_polylines
        The map polylines; each keeps its direction.
    observations
        Per map polyline, the scan polylines associated with it, in the same frame; each
        is reversed where it runs the other way along the map polyline. With ``counts``:
        all of them in one sequence (e.g. a :class:`PackedPolylines` taken from a scan's,
        which is not packed again), map polyline by map polyline.
    epsilon
        Douglas-Peucker tolerance (m) of the re-simplification, ``> 0``.
    edge_weights
        The weights ``>= 0`` of the edges of all map polylines, one polyline after the
        other (``len(line) - 1`` each, none for fewer than two vertices). Default: 1 (one
        observation) each.
    end_weights
        Per map polyline, the weight ``>= 0`` of its ends. Default: 1 each.
    end_tolerance
        Ends closer than this (m) are the same end seen again and are averaged; farther
        scan ends extend the map. Default ``END_TOLERANCE_FACTOR * epsilon``.
    counts
        Per map polyline, how many of the (flat) ``observations`` are its own, in order.
        Default: ``observations`` is nested, one sequence per map polyline.

    Returns
    -------
    list of (Polyline, numpy.ndarray)
        Per map polyline, the merged polyline and its edge weights (read-only). Its scan
        indices are the vertex order (``0..N-1``), since its vertices no longer come from
        one scan. A map polyline whose observation has no vertices comes back as itself,
        with its weights; a single-vertex scan polyline only extends the map when it lies
        beyond an end.

    Examples
    --------
    >>> box = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
    >>> [(line.points.tolist(), weights.tolist())  # the scan saw more
    ...  for line, weights in merge([box], [[[[1.0, 0.5], [1.0, 1.6]]]], epsilon=0.03)]
    [([[0.0, 0.0], [1.0, 0.0], [1.0, 1.6]], [1.0, 1.3125])]
    >>> (line, _), = merge([box], [[[[0.4, 0.01], [0.6, -0.01]]]], 0.03)  # a partial view
    >>> len(line)
    3
    >>> wall = [[0.0, 0.0], [4.0, 0.0]]
    >>> parts = [[[0.0, 0.02], [1.5, 0.02]], [[2.5, 0.02], [4.0, 0.02]]]  # a pillar between
    >>> [line.points.round(3).tolist() for line, _ in merge([wall], [parts], 0.03)]
    [[[0.0, 0.01], [4.0, 0.01]]]
    >>> chord = [[0.8, 0.0], [1.0, -0.1], [1.0, -1.0]]  # a chord no view supported, a face
    >>> corner_seen = [[0.85, 0.0], [1.0, 0.0], [1.0, -1.0]]
    >>> [(line.points.round(3).tolist(), weights.round(2).tolist()) for line, weights
    ...  in merge([chord], [[corner_seen]], 0.03, edge_weights=[0.0, 20.0], end_weights=[20.0])]
    [([[0.802, 0.0], [1.0, 0.0], [1.0, -1.0]], [1.0, 19.0])]
    >>> [line.points.round(3).tolist()  # one weight for the whole polyline: the chord stays
    ...  for line, _ in merge([chord], [[corner_seen]], 0.03, edge_weights=[20.0, 20.0],
    ...                       end_weights=[20.0])]
    [[[0.802, 0.0], [1.0, -0.1], [1.0, -1.0]]]
    >>> [line.points.round(3).tolist() for line, _ in merge([wall], parts, 0.03, counts=[2])]
    [[[0.0, 0.01], [4.0, 0.01]]]
    """
    if not epsilon > 0.0:
        raise ValueError(f"merge: epsilon must be > 0 m, got {epsilon!r}")
    tolerance = END_TOLERANCE_FACTOR * epsilon if end_tolerance is None else end_tolerance
    if not tolerance >= 0.0:
        raise ValueError(f"merge: end_tolerance must be >= 0 m, got {end_tolerance!r}")
    lines = as_polylines(map_polylines)
    if counts is None:
        parts = as_polylines([part for line_parts in observations for part in line_parts])
        per_line = list(map(len, observations))
    else:
        parts = as_polylines(observations)
        per_line = counts if type(counts) is list else np.asarray(counts).reshape(-1).tolist()
        if not (
            all(isinstance(count, int) and count >= 0 for count in per_line)
            and sum(per_line) == len(parts)
        ):
            raise ValueError(
                f"merge: counts must be integers >= 0 that add up to the {len(parts)} "
                f"observations, got {counts!r}"
            )
    if len(per_line) != len(lines):
        raise ValueError(
            f"merge: need one observation per map polyline, got {len(lines)} polylines and "
            f"{len(per_line)} observations"
        )
    # (Over Python ints: a map's few dozen polylines cost less so than numpy's calls.)
    edge_counts = [max(stop - start - 1, 0)
                   for start, stop in itertools.pairwise(lines.offsets.tolist())]
    weight_offsets = run_offsets(edge_counts, len(edge_counts))
    weights = _checked_weights("edge_weights", edge_weights, int(weight_offsets[-1]),
                               "edge of the map polylines")
    point_weights = _checked_weights("end_weights", end_weights, len(lines), "map polyline")
    # Polyline k's parts are pieces first_parts[k] to first_parts[k + 1] - 1 of parts.
    first_parts = run_offsets(per_line, len(per_line))
    merged, merged_offsets, merged_weights, merged_weight_offsets, changed = _merge_all(
        lines.points, lines.offsets, weights, weight_offsets, parts.points, parts.offsets,
        first_parts, point_weights, tolerance, epsilon,
    )
    # (Averages of finite vertices with finite weights: finite.)
    views = PackedPolylines.from_runs(merged[: merged_offsets[-1]], merged_offsets,
                                      check_finite=False)
    bounds, merged_bounds = weight_offsets.tolist(), merged_weight_offsets.tolist()
    # (Read-only after the call: the kernel's signature takes writeable arrays.)
    weights.flags.writeable = merged_weights.flags.writeable = False
    # (Indexed, not zipped: the map's polylines are looked up only where nothing changed.)
    return [
        (views[k], merged_weights[merged_bounds[k] : merged_bounds[k + 1]]) if is_changed
        else (lines[k], weights[bounds[k] : bounds[k + 1]])
        for k, is_changed in enumerate(changed.tolist())
    ]


def _checked_weights(name: str, given: ArrayLike | None, count: int, what: str) -> np.ndarray:
    """Return a copy of ``count`` weights ``>= 0`` as float64 (default: 1 each), or say why not."""
    if given is None:
        return np.ones(count)
    weights = np.array(given, dtype=float).reshape(-1)
    if weights.shape != (count,):
        raise ValueError(f"merge: {name} needs one value per {what} ({count}), got {weights.size}")
    # (NaN fails too. Over Python floats: a merge's few dozen weights cost less so than a
    # numpy reduction.)
    if not all(map((0.0).__le__, weights.tolist())):
        raise ValueError(f"merge: {name} must be >= 0, got {given!r}")
    return weights


def transfer_weights(
    polyline: Polyline | ArrayLike, source: Polyline | ArrayLike, weights: ArrayLike,
    tolerance: float,
) -> np.ndarray:
    """Return the edge weights ``polyline`` takes over from ``source`` (e.g. a piece of it).

    Each edge of ``polyline`` takes the weight of the ``source`` edge its midpoint lies
    on, within ``tolerance`` (m) and inside the source's extent; elsewhere 0.
    ``weights`` holds one value per edge of ``source``.

    Examples
    --------
    >>> box = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
    >>> transfer_weights([[0.5, 0.0], [1.0, 0.0], [1.0, 0.5], [1.0, 2.0]], box, [7.0, 9.0], 0.05)
    array([7., 9., 0.])
    """
    # Writeable copies: the kernels take the argument types the merge gives them.
    points = np.array(as_polyline(polyline).points)
    vertices = np.array(as_polyline(source).points)
    weights = np.array(weights, dtype=float).reshape(-1)
    if weights.size != max(vertices.shape[0] - 1, 0):
        raise ValueError(
            f"transfer_weights: need one weight per source edge ({max(vertices.shape[0] - 1, 0)}),"
            f" got {weights.size}"
        )
    distinct, distinct_weights = _distinct_weighted(vertices, weights)
    along = _edges_along(points, distinct, float(tolerance))
    return _weights_of(along, distinct_weights)


@numba.njit(cache=True)
def _merge_all(
    points: np.ndarray, offsets: np.ndarray, weights: np.ndarray, weight_offsets: np.ndarray,
    part_points: np.ndarray, part_offsets: np.ndarray, first_parts: np.ndarray,
    point_weights: np.ndarray, tolerance: float, epsilon: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """Merge each packed map polyline with its packed parts in turn (:func:`merge`).

    ``weights``: the packed edge weights of the map polylines (each edge of a part is one
    observation of the surface it lies along: weight 1); ``point_weights``: the weight of
    each map polyline that is one vertex (a part's single vertex weighs 1). Returns the
    merged vertices one polyline after the other, their offsets, their edge weights, the
    weights' offsets and which polylines changed (an observation without vertices changes
    nothing).

    Per map polyline, ``line_weights`` are its edge weights before this observation (the
    map's side of each average: the parts of one observation all weigh against them),
    ``line_totals`` those with the parts of this observation merged so far.

    One piece of ~170 lines because numba re-optimises a callee's whole code inside each
    caller (see the merge proper below): every level of kernels between this one and the
    helpers at the bottom costs their compilation again. Measured (CPU seconds to compile
    this kernel from an empty cache, 2 shared cores under load, paired runs): split into
    a kernel per part (one scan polyline, the merge proper, the direction and contradicted
    ends, the ends, the candidate vertices), mean 18.3 -> 22.3 s over 3 runs (+22%); the
    same parts inlined into it (``inline="always"``), median 18.2 -> 22.0 s over 6 runs
    (+18%, every run slower).
    """
    count = offsets.size - 1
    merged = np.empty((max(points.shape[0] + part_points.shape[0], 1), 2))
    merged_weights = np.empty(max(points.shape[0] + part_points.shape[0], 1))
    merged_offsets = np.zeros(count + 1, np.int64)
    merged_weight_offsets = np.zeros(count + 1, np.int64)
    changed = np.zeros(count, np.bool_)
    stored, stored_weights = 0, 0
    for k in range(count):
        line = points[offsets[k] : offsets[k + 1]].copy()
        line_weights = weights[weight_offsets[k] : weight_offsets[k + 1]].copy()
        line_totals = line_weights.copy()
        for part in range(first_parts[k], first_parts[k + 1]):
            scan = part_points[part_offsets[part] : part_offsets[part + 1]].copy()
            if not scan.shape[0]:
                continue  # an empty scan polyline leaves the map polyline itself
            old, old_weights, old_totals = _distinct_with(line, line_weights, line_totals)
            new, new_weights = _distinct_weighted(scan, np.ones(max(scan.shape[0] - 1, 0)))
            if old.shape[0] == 0:
                line, line_weights, line_totals = new, np.zeros(new_weights.size), new_weights
            elif old.shape[0] == 1 and new.shape[0] == 1:
                line = old.copy()
                alpha = _share(1.0, point_weights[k])
                line[0, 0] += alpha * (new[0, 0] - old[0, 0])
                line[0, 1] += alpha * (new[0, 1] - old[0, 1])
                line_weights, line_totals = np.empty(0), np.empty(0)
            elif old.shape[0] == 1:
                # A point has no extent to average: the scan's shape wins, the point may
                # extend it.
                line = _extend_with_point(new, old[0], tolerance)
                line_totals = _weights_of(_edges_along(line, new, tolerance), new_weights)
                line_weights = np.zeros(line_totals.size)
            elif new.shape[0] == 1:
                line = _extend_with_point(old, new[0], tolerance)
                along = _edges_along(line, old, tolerance)
                line_weights = _weights_of(along, old_weights)
                line_totals = _weights_of(along, old_totals)
            else:
                # The merge proper (docs/design.md#detail-7), written out here rather than as a
                # kernel of its own: numba re-optimises a callee's whole code inside each
                # caller, so one level less halves the compilation of everything below.
                # First the scan's direction along the map, and the map's ends the scan
                # contradicts cut off (once).
                end_weight = point_weights[k]
                cut = True
                source, source_weights, source_totals = old, old_weights, old_totals
                while True:
                    arcs, feet, distances, before, after = _project(new, old)
                    if arcs[0] > arcs[-1] or (
                        arcs[0] == arcs[-1]
                        and (new[-1, 0] - new[0, 0]) * (old[-1, 0] - old[0, 0])
                        + (new[-1, 1] - new[0, 1]) * (old[-1, 1] - old[0, 1])
                        < 0.0
                    ):
                        # In place (all are this merge's own): copies of reversed views
                        # would compile numpy's strided copy per array type.
                        _reverse_rows(new)
                        _reverse_rows(feet)
                        _reverse(new_weights)
                        _reverse(arcs)
                        _reverse(distances)
                        _reverse(before)
                        _reverse(after)
                    if not cut:
                        break
                    cut = False
                    uncontradicted = _contradicted(old, new, arcs, distances, before, after,
                                                   tolerance)
                    if uncontradicted.shape[0] == 0:
                        break
                    old = uncontradicted
                    along = _edges_along(old, source, tolerance)
                    old_weights = _weights_of(along, source_weights)
                    old_totals = _weights_of(along, source_totals)
                scan_arcs, scan_feet, scan_distances, scan_before, scan_after = _project(old, new)
                map_arcs = _arc_starts(old)
                scan_starts = _arc_starts(new)
                # Map vertices facing the scan move toward it, by the scan's share of the
                # weight there.
                moved = old.copy()
                for v in range(old.shape[0]):
                    if not (scan_before[v] or scan_after[v]) and scan_distances[v] <= tolerance:
                        alpha = _share(new_weights[_edge_at(scan_starts, scan_arcs[v])],
                                       _vertex_weight(old_weights, v))
                        moved[v, 0] += alpha * (scan_feet[v, 0] - old[v, 0])
                        moved[v, 1] += alpha * (scan_feet[v, 1] - old[v, 1])
                # Scan vertices facing the map are inserted, pulled toward the map by its
                # weight.
                inserted = np.empty(new.shape[0], np.bool_)
                for v in range(new.shape[0]):
                    inserted[v] = not (before[v] or after[v])
                scan_count = new.shape[0]
                prepend, append = 0, 0

                # Start: by how much does the scan reach beyond the map's start?
                reach = distances[0] if before[0] else -arcs[0]
                if reach > tolerance:
                    prepend = _run_length(before)
                elif reach >= -tolerance:
                    alpha = _share(new_weights[0], end_weight)
                    moved[0, 0] = old[0, 0] + alpha * (new[0, 0] - old[0, 0])
                    moved[0, 1] = old[0, 1] + alpha * (new[0, 1] - old[0, 1])
                    inserted[0] = False
                # End: the same, mirrored.
                reach = distances[-1] if after[-1] else arcs[-1] - map_arcs[-1]
                if reach > tolerance:
                    append = _trailing_run_length(after)
                elif reach >= -tolerance:
                    alpha = _share(new_weights[-1], end_weight)
                    moved[-1, 0] = old[-1, 0] + alpha * (new[-1, 0] - old[-1, 0])
                    moved[-1, 1] = old[-1, 1] + alpha * (new[-1, 1] - old[-1, 1])
                    inserted[-1] = False

                # Map vertices first on equal arc length, then scan vertices in scan order:
                # listed in that order, a stable sort by arc length keeps it.
                total = old.shape[0]
                for v in range(scan_count):
                    total += inserted[v]
                keys, middle = np.empty(total), np.empty((total, 2))
                for v in range(old.shape[0]):
                    keys[v] = map_arcs[v]
                _put_rows(moved, 0, old.shape[0], middle, 0)
                row = old.shape[0]
                for v in range(scan_count):
                    if not inserted[v]:
                        continue
                    # An inner scan vertex farther than epsilon from a map edge that cuts a
                    # corner is averaged with the corner the map's faces imply, not with its
                    # foot on the chord: pulled toward the chord, it would lie within epsilon
                    # of it once the map stands for a few observations, Douglas-Peucker would
                    # drop it every time, and the map could never learn the corner.
                    anchor_x, anchor_y = feet[v, 0], feet[v, 1]
                    if 0 < v < scan_count - 1 and distances[v] > epsilon:
                        found, corner_x, corner_y = _cut_corner(old, map_arcs, arcs[v], new[v],
                                                                epsilon)
                        if found:
                            anchor_x, anchor_y = corner_x, corner_y
                    keys[row] = arcs[v]
                    alpha = _share(_vertex_weight(new_weights, v),
                                   old_weights[_edge_at(map_arcs, arcs[v])])
                    middle[row, 0] = anchor_x + alpha * (new[v, 0] - anchor_x)
                    middle[row, 1] = anchor_y + alpha * (new[v, 1] - anchor_y)
                    row += 1
                # The candidates before Douglas-Peucker (>= 2 rows), and per candidate edge
                # the weights of ``old`` and the totals with the scan's added where each lies
                # along them (0 where nothing does).
                candidates = np.empty((prepend + total + append, 2))
                size = 0
                for v in range(prepend):
                    if distances[v] > tolerance:
                        _put_rows(new, v, v + 1, candidates, size)
                        size += 1
                # Insertion sort by arc length, stable (a handful of vertices).
                for v in range(1, total):
                    key, x, y = keys[v], middle[v, 0], middle[v, 1]
                    at = v
                    while at > 0 and keys[at - 1] > key:
                        keys[at] = keys[at - 1]
                        middle[at, 0], middle[at, 1] = middle[at - 1, 0], middle[at - 1, 1]
                        at -= 1
                    keys[at], middle[at, 0], middle[at, 1] = key, x, y
                _put_rows(middle, 0, total, candidates, size)
                size += total
                for v in range(scan_count - append, scan_count):
                    if distances[v] > tolerance:
                        _put_rows(new, v, v + 1, candidates, size)
                        size += 1
                keep = np.empty(size, np.bool_)
                keep[0] = True
                for v in range(1, size):
                    gap = math.hypot(candidates[v, 0] - candidates[v - 1, 0],
                                     candidates[v, 1] - candidates[v - 1, 1])
                    keep[v] = gap > DUPLICATE_DISTANCE
                candidates = _kept_rows(candidates, keep)
                along = _edges_along(candidates, old, tolerance)
                totals = _weights_of(along, old_totals)
                totals += _weights_of(_edges_along(candidates, new, tolerance), new_weights)
                line, line_weights = candidates, _weights_of(along, old_weights)
                line_totals = totals
            # Simplified again (docs/design.md#detail-3); one vertex stays as it is.
            kept = douglas_peucker(line, epsilon)
            line_weights = _kept_weights(line, line_weights, kept)
            line_totals = _kept_weights(line, line_totals, kept)
            line = _rows_at(line, kept)
            changed[k] = True
        if stored + line.shape[0] > merged.shape[0]:
            grown = np.empty((2 * (stored + line.shape[0]), 2))
            _put_rows(merged, 0, stored, grown, 0)
            merged = grown
        line_weights = line_totals
        if stored_weights + line_weights.size > merged_weights.size:
            grown_weights = np.empty(2 * (stored_weights + line_weights.size))
            for edge in range(stored_weights):
                grown_weights[edge] = merged_weights[edge]
            merged_weights = grown_weights
        _put_rows(line, 0, line.shape[0], merged, stored)
        for edge in range(line_weights.size):
            merged_weights[stored_weights + edge] = line_weights[edge]
        stored += line.shape[0]
        stored_weights += line_weights.size
        merged_offsets[k + 1] = stored
        merged_weight_offsets[k + 1] = stored_weights
    return merged, merged_offsets, merged_weights, merged_weight_offsets, changed


@numba.njit(cache=True)
def _arc_starts(vertices: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Return the arc-length position of each vertex, summed edge by edge."""
    arcs = np.empty(vertices.shape[0])
    arcs[0] = 0.0
    for k in range(1, vertices.shape[0]):
        arcs[k] = arcs[k - 1] + _edge_length(vertices, k - 1)
    return arcs


@numba.njit(cache=True)
def _cut_at(vertices: np.ndarray, arc: float, keep_head: bool) -> np.ndarray:  # pragma: no cover
    """Return the part of a polyline before (``keep_head``) or after arc length ``arc``."""
    position = 0.0
    for k in range(vertices.shape[0] - 1):
        length = _edge_length(vertices, k)
        if position + length >= arc:
            t = (arc - position) / length if length > 0.0 else 0.0
            cut_x = vertices[k, 0] + t * (vertices[k + 1, 0] - vertices[k, 0])
            cut_y = vertices[k, 1] + t * (vertices[k + 1, 1] - vertices[k, 1])
            if keep_head:
                part = np.empty((k + 2, 2))
                _put_rows(vertices, 0, k + 1, part, 0)
                part[k + 1, 0], part[k + 1, 1] = cut_x, cut_y
                return part
            part = np.empty((vertices.shape[0] - k, 2))
            part[0, 0], part[0, 1] = cut_x, cut_y
            _put_rows(vertices, k + 1, vertices.shape[0], part, 1)
            return part
        position += length
    return vertices.copy() if keep_head else vertices[-1:].copy()


@numba.njit(cache=True)
def _past_edge(
    vertices: np.ndarray, arc: float, point: np.ndarray, tolerance: float, forward: bool
) -> bool:  # pragma: no cover - compiled
    """Return whether ``point`` continues the map edge at arc length ``arc`` past its end.

    True when ``point`` projects on that edge's line more than ``tolerance`` beyond the
    edge's end vertex (before its start vertex when not ``forward``): the scan goes on
    where the map turns. A point beside the edge (a noisy end) does not count.
    """
    position = 0.0
    edges = vertices.shape[0] - 1
    for number in range(edges):
        length = _edge_length(vertices, number)
        if position + length < arc and number < edges - 1:
            position += length
            continue
        if length == 0.0:
            return False
        ux = (vertices[number + 1, 0] - vertices[number, 0]) / length
        uy = (vertices[number + 1, 1] - vertices[number, 1]) / length
        along = (point[0] - vertices[number, 0]) * ux + (point[1] - vertices[number, 1]) * uy
        return along > length + tolerance if forward else along < -tolerance
    return False


@numba.njit(cache=True)
def _contradicted(
    old: np.ndarray, new: np.ndarray, arcs: np.ndarray, distances: np.ndarray,
    before: np.ndarray, after: np.ndarray, tolerance: float,
) -> np.ndarray:  # pragma: no cover - compiled
    """Return ``old`` without the ends the scan contradicts (empty if none is).

    ``arcs`` ... ``after``: the projection of ``new`` onto ``old``. Where the scan, past
    the last (first) of its vertices that agree with the map (within ``tolerance``), runs
    on straight beyond the end of the map edge they agree on while the map turns away,
    the two disagree on where the surface goes: the map's end beyond that point is what
    the scan no longer sees there (a moved object's old face, hidden inside the new
    footprint). It is cut, and the scan's continuation then extends the map like any
    longer view. Averaging the two instead would pull scan vertices onto the old face and
    draw an edge across the object.
    """
    nothing = np.empty((0, 2))
    first, last = -1, -1
    for k in range(distances.size):
        if distances[k] <= tolerance:
            last = k
            if first < 0:
                first = k
    if first < 0:
        return nothing
    # (Flags as runtime values: a constant argument would compile a kernel per value.)
    tail, head = False, False
    for k in range(last + 1, arcs.size):
        forward = k > last
        tail = distances[k] > tolerance and not after[k] and _past_edge(
            old, arcs[last], new[k], tolerance, forward
        )
        if tail:
            break
    for k in range(first):
        forward = k > first
        head = distances[k] > tolerance and not before[k] and _past_edge(
            old, arcs[first], new[k], tolerance, forward
        )
        if head:
            break
    if not (tail or head):
        return nothing
    cut = old
    if tail:
        cut = _cut_at(cut, arcs[last], tail)
    if head:
        cut = _cut_at(cut, arcs[first], not head)
    cut = _distinct(cut)
    return cut if cut.shape[0] >= 2 else nothing


@numba.njit(cache=True)
def _cut_corner(
    vertices: np.ndarray, map_arcs: np.ndarray, arc: float, point: np.ndarray, epsilon: float
) -> tuple[bool, float, float]:  # pragma: no cover - compiled
    """Return the corner a map edge cuts off where the scan sees it: ``(found, x, y)``.

    The map edge at arc length ``arc`` is a chord across a corner when the lines of the
    edges before and after it meet within ``epsilon`` of ``point`` (the scan's vertex
    there): the map's own faces run on to where the scan sees them meet. Their
    intersection is returned. A corner's first views can cut it like that: one face seen
    at grazing incidence from afar, with a reading or two on it.
    """
    edge = _last_at_most(map_arcs, arc)
    if not 1 <= edge <= vertices.shape[0] - 3:
        return False, 0.0, 0.0
    ax, ay = vertices[edge - 1, 0], vertices[edge - 1, 1]
    bx, by = vertices[edge, 0], vertices[edge, 1]
    cx, cy = vertices[edge + 1, 0], vertices[edge + 1, 1]
    dx, dy = vertices[edge + 2, 0], vertices[edge + 2, 1]
    ux, uy, vx, vy = bx - ax, by - ay, dx - cx, dy - cy
    cross = ux * vy - uy * vx
    if abs(cross) <= MIN_CORNER_SINE * math.hypot(ux, uy) * math.hypot(vx, vy):
        return False, 0.0, 0.0  # nearly parallel faces meet nowhere useful
    t = ((cx - ax) * vy - (cy - ay) * vx) / cross
    corner_x, corner_y = ax + t * ux, ay + t * uy
    found = math.hypot(corner_x - point[0], corner_y - point[1]) <= epsilon
    return found, corner_x, corner_y


@numba.njit(cache=True)
def _share(scan_weight: float, map_weight: float) -> float:  # pragma: no cover - compiled
    """Return how far the map moves toward the scan: the scan's share of the weight."""
    total = scan_weight + map_weight
    return scan_weight / total if total > 0.0 else 0.5


@numba.njit(cache=True)
def _edge_at(starts: np.ndarray, arc: float) -> int:  # pragma: no cover - compiled
    """Return the edge at arc length ``arc`` of a polyline with vertex arcs ``starts``."""
    return min(max(_last_at_most(starts, arc), 0), starts.size - 2)


@numba.njit(cache=True)
def _last_at_most(starts: np.ndarray, arc: float) -> int:  # pragma: no cover - compiled
    """Return ``np.searchsorted(starts, arc, side="right") - 1`` for ascending ``starts``.

    The same bisection as numpy's (a NaN ``arc`` sorts last), without compiling its
    library implementation into every caller.
    """
    low, high = 0, starts.size
    while low < high:
        middle = (low + high) // 2
        if arc < starts[middle]:
            high = middle
        else:
            low = middle + 1
    return low - 1


@numba.njit(cache=True)
def _vertex_weight(weights: np.ndarray, vertex: int) -> float:  # pragma: no cover - compiled
    """Return a vertex's weight: the mean of its edges' (an end vertex: its one edge's)."""
    if vertex == 0:
        return weights[0]
    if vertex == weights.size:
        return weights[-1]
    return 0.5 * (weights[vertex - 1] + weights[vertex])


@numba.njit(cache=True)
def _edges_along(
    points: np.ndarray, source: np.ndarray, tolerance: float
) -> np.ndarray:  # pragma: no cover - compiled
    """Return per edge of ``points`` the ``source`` edge it lies along, or -1.

    An edge lies along the ``source`` edge its midpoint projects onto, within
    ``tolerance`` and inside the source's extent; elsewhere it lies along none (nothing of
    ``source`` supports it: weight 0). ``source`` has distinct vertices.
    """
    edges = max(points.shape[0] - 1, 0)
    found = np.full(edges, -1, np.int64)
    if edges == 0 or source.shape[0] < 2:
        return found
    middles = np.empty((edges, 2))
    for k in range(edges):
        middles[k, 0] = 0.5 * (points[k, 0] + points[k + 1, 0])
        middles[k, 1] = 0.5 * (points[k, 1] + points[k + 1, 1])
    arcs, _, distances, before, after = _project(middles, source)
    starts = _arc_starts(source)
    for k in range(edges):
        if distances[k] <= tolerance and not (before[k] or after[k]):
            found[k] = _edge_at(starts, arcs[k])
    return found


@numba.njit(cache=True)
def _weights_of(edges: np.ndarray, weights: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Return ``weights[edges]``, 0 where an edge is -1 (none)."""
    found = np.zeros(edges.size)
    for k in range(edges.size):
        if edges[k] >= 0:
            found[k] = weights[edges[k]]
    return found


@numba.njit(cache=True)
def _kept_weights(
    points: np.ndarray, weights: np.ndarray, kept: np.ndarray
) -> np.ndarray:  # pragma: no cover - compiled
    """Return the edge weights of ``points[kept]``: each its edges' length-weighted mean."""
    found = np.zeros(max(kept.size - 1, 0))
    for k in range(kept.size - 1):
        total, length = 0.0, 0.0
        for edge in range(kept[k], kept[k + 1]):
            piece = _edge_length(points, edge)
            total += weights[edge] * piece
            length += piece
        found[k] = total / length if length > 0.0 else weights[kept[k]]
    return found


@numba.njit(cache=True)
def _distinct_with(
    points: np.ndarray, weights: np.ndarray, totals: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Return :func:`_distinct_weighted` of ``points`` with two weight arrays."""
    keep = _distinct_mask(points)
    return _kept_rows(points, keep), _kept_edges(weights, keep), _kept_edges(totals, keep)


@numba.njit(cache=True)
def _distinct_weighted(
    points: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Return :func:`_distinct` of ``points`` and the weights of the edges left."""
    keep = _distinct_mask(points)
    # A repeated vertex ends a zero-length edge: that edge goes with it.
    return _kept_rows(points, keep), _kept_edges(weights, keep)


# Masks and index arrays applied by loops: numpy's boolean and fancy indexing each compile
# a library implementation per array type, again in every kernel that calls the helper.
@numba.njit(cache=True)
def _kept_rows(points: np.ndarray, keep: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Return ``points[keep]`` for ``(N, 2)`` points and an ``(N,)`` boolean mask."""
    size = 0
    for k in range(keep.size):
        size += keep[k]
    kept = np.empty((size, 2))
    row = 0
    for k in range(keep.size):
        if keep[k]:
            kept[row, 0], kept[row, 1] = points[k, 0], points[k, 1]
            row += 1
    return kept


@numba.njit(cache=True)
def _kept_edges(weights: np.ndarray, keep: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Return ``weights[keep[1:]]``: the weights of the edges ending at kept vertices."""
    size = 0
    for k in range(1, keep.size):
        size += keep[k]
    kept = np.empty(size)
    at = 0
    for k in range(1, keep.size):
        if keep[k]:
            kept[at] = weights[k - 1]
            at += 1
    return kept


@numba.njit(cache=True)
def _rows_at(points: np.ndarray, indices: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Return ``points[indices]`` for ``(N, 2)`` points and ``(K,)`` in-range indices."""
    rows = np.empty((indices.size, 2))
    for k in range(indices.size):
        rows[k, 0], rows[k, 1] = points[indices[k], 0], points[indices[k], 1]
    return rows

