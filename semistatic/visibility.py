"""What a laser scan sees of map polylines: visibility, free space, and unbiased ends.

Two parts of the mapper reason about single beams rather than whole polylines:

- :func:`visibility` casts the scan's beams at map polylines and compares each beam's
  reading with the range at which it would hit them. The object life cycle
  (docs/design.md#detail-10) deletes a map polyline only after it was missed while it
  *should have been visible*: in view, unoccluded, and read through
  (``Visibility.missing``). Where only part of a polyline is read through, that part is
  free space (an object moved along its own face: the map's ends agree with the scan,
  its middle does not): the free-space cut removes it (``Visibility.pieces``);
- :func:`extend_ends` removes the bias of scan polylines' ends, which the last beam on an
  object leaves up to half a beam gap short of its true end.

Both take a set of polylines and cast all beams in one compiled call (numba).

Examples
--------
>>> scan = Scan(ranges=np.full(21, 5.0), angle_min=-0.1, angle_increment=0.01)
>>> seen = visibility([[[2.0, -1.0], [2.0, 1.0]]], scan, (0.0, 0.0, 0.0), MapperParams())
>>> seen.in_view, seen.seen_through, seen.missing  # all 21 beams would hit it, none do
(array([21]), array([21]), array([ True]))
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import untransform_points
from semistatic.params import MapperParams
from semistatic.polyline import PackedPolylines, Polyline, as_polylines
from semistatic.types import Scan, beam_directions

__all__ = [
    "MAX_END_EXTENSION",
    "MIN_SEEN_THROUGH",
    "MIN_VISIBLE_FRACTION",
    "MISSING_FRACTION",
    "Visibility",
    "extend_ends",
    "visibility",
]

# A map polyline should have been visible when at least this fraction of the beams that
# would hit it in range are not occluded (and at least ``min_points`` beams, enough for
# extraction to produce a polyline from them).
MIN_VISIBLE_FRACTION = 0.5

# An unassociated map polyline that should have been visible is missed when at least this
# fraction of its unoccluded beams read clearly beyond it (it is not there any more).
MISSING_FRACTION = 0.5

# Beams (nearly) parallel to an edge do not hit it.
PARALLEL_TOLERANCE = 1e-12

# Consecutive beams that must read through a map polyline before the free-space cut removes
# that part: two, the fewest readings that make a polyline (MapperParams.min_points), so
# one noisy reading cuts nothing.
MIN_SEEN_THROUGH = 2

# Largest end extension (m) of extend_ends: at grazing incidence the gap to the next beam
# grows without bound, while the end it hides can only be this much farther on average.
MAX_END_EXTENSION = 0.10


def _point_ranges(points: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Return the range at which each beam would hit a polyline of fewer than two vertices.

    ``points``: ``(N, 2)`` vertices in the sensor frame, ``N <= 1``; a single vertex is
    hit only by the beam whose direction is nearest to it (within half a beam step), at
    its distance (``inf``: no hit). ``angles``: ``(B,)`` increasing beam angles (rad) in
    the sensor frame.
    """
    ranges = np.full(angles.size, math.inf)
    if points.shape[0] == 0 or angles.size == 0:
        return ranges
    bearing = math.atan2(points[0, 1], points[0, 0])
    beam = int(np.argmin(np.abs(np.angle(np.exp(1j * (angles - bearing))))))
    step = float(np.median(np.diff(angles))) if angles.size > 1 else math.inf
    if abs(math.remainder(angles[beam] - bearing, 2.0 * math.pi)) <= 0.5 * step:
        ranges[beam] = float(np.hypot(points[0, 0], points[0, 1]))
    return ranges


@numba.njit(cache=True)
def _arc_positions(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Return the arc-length position of each vertex ``(xs, ys)`` (``0`` at the first)."""
    arcs = np.empty(xs.size)
    arcs[0] = 0.0
    for k in range(1, xs.size):
        arcs[k] = arcs[k - 1] + math.hypot(xs[k] - xs[k - 1], ys[k] - ys[k - 1])
    return arcs


@numba.njit(cache=True)
def _first_crossing(
    xs: np.ndarray, ys: np.ndarray, arcs: np.ndarray, cos: float, sin: float
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """Return where the beam ``(cos, sin)`` from the origin first hits polyline ``(xs, ys)``.

    Sensor-frame vertices (``N >= 2``) with their :func:`_arc_positions`. Returns the
    range (``inf``: no hit), the arc-length position of the hit, its distance along the
    hit edge to that edge's nearer end and the sine of the angle between beam and edge
    (the last three ``nan`` for no hit). The lowest edge wins ties.
    """
    best, best_edge, best_fraction, best_denominator = math.inf, -1, 0.0, 0.0
    for edge in range(xs.size - 1):
        start_x, start_y = xs[edge], ys[edge]
        edge_x, edge_y = xs[edge + 1] - start_x, ys[edge + 1] - start_y
        denominator = cos * edge_y - sin * edge_x
        if not abs(denominator) > PARALLEL_TOLERANCE:
            continue  # (nearly) parallel: no hit
        along_beam = (start_x * edge_y - start_y * edge_x) / denominator
        along_edge = (start_x * sin - start_y * cos) / denominator
        if along_beam > 0.0 and 0.0 <= along_edge <= 1.0 and along_beam < best:
            best, best_edge = along_beam, edge
            best_fraction, best_denominator = along_edge, denominator
    if best_edge < 0:
        return math.inf, math.nan, math.nan, math.nan
    length = math.hypot(xs[best_edge + 1] - xs[best_edge], ys[best_edge + 1] - ys[best_edge])
    to_end = min(best_fraction, 1.0 - best_fraction) * length
    sine = abs(best_denominator) / (length if length > 0.0 else 1.0)
    return best, arcs[best_edge] + best_fraction * length, to_end, sine


def extend_ends(
    polylines: PackedPolylines | Sequence[Polyline | ArrayLike],
    angle_increment: float,
    *,
    viewpoint: ArrayLike = (0.0, 0.0),
    limit: float = MAX_END_EXTENSION,
) -> PackedPolylines:
    """Return scan polylines with each end moved half a beam gap outward.

    The last beam that hits an object stops short of its true end, which lies somewhere
    before the next beam would have crossed the object's edge line: on average half that
    gap further. At grazing incidence the gap is many centimetres (9 cm at 3 m and 16 deg
    for 0.5 deg beams), so maps built from raw ends shrink objects by half of it. Moving
    each end along its edge by half the gap to the neighbouring beam (at most ``limit``)
    removes that bias; an end cut by an occluder or the field of view is only extended
    along a surface that goes on anyway. A polyline of fewer than two vertices, or an end
    edge of zero length, stays as it is.

    Parameters
    ----------
    polylines
        Scan polylines of one scan, each in scan (counter-clockwise) order, in any frame.
    angle_increment
        Beam step of the scan (rad).
    viewpoint
        Sensor position ``(x, y)`` (a pose's heading is ignored) in the polylines' frame;
        default the origin, i.e. polylines in the sensor frame.
    limit
        Largest extension (m).

    Returns
    -------
    PackedPolylines
        The polylines with their ends moved, scan indices kept.

    Examples
    --------
    >>> wall = [[2.0, 0.0], [2.0, 1.0]]  # seen head-on from the origin
    >>> [line.points.round(4).tolist() for line in extend_ends([wall, [[1.0, 1.0]]],
    ...                                                        np.radians(1.0))]
    [[[2.0, -0.0175], [2.0, 1.022]], [[1.0, 1.0]]]
    """
    lines = as_polylines(polylines)
    origin_x, origin_y = np.asarray(viewpoint, dtype=float).reshape(-1)[:2].tolist()
    points = lines.points.copy()  # the ends move in place
    _extended_ends(points, lines.offsets, angle_increment, origin_x, origin_y, limit)
    # Finite vertices moved by finite shifts (a nan or inf argument moves nothing: every
    # comparison with nan fails), a fresh array of valid polylines.
    return PackedPolylines.from_runs(points, lines.offsets, lines.scan_indices,
                                     check_finite=False)


@dataclass(frozen=True, eq=False)
class Visibility:
    """What one scan saw of each of a set of map polylines (see :func:`visibility`).

    Examples
    --------
    >>> seen = Visibility(np.array([10]), np.array([8]), np.array([1]), [None], min_points=2)
    >>> seen.missing
    array([False])
    """

    in_view: np.ndarray
    """``(K,)`` beams that would hit each polyline within the usable range."""
    unoccluded: np.ndarray
    """Of those, the beams that read at least about the expected range."""
    seen_through: np.ndarray
    """Of those, the beams that read clearly beyond it (or no return): it is not there."""
    pieces: list[PackedPolylines | None]
    """What the free-space cut leaves of each polyline, ``None`` where it cuts nothing."""
    min_points: int
    """The fewest unoccluded beams in which a polyline counts as visible."""

    @cached_property
    def missing(self) -> np.ndarray:
        """Return which polylines should have been seen, and the scan reads through them.

        A polyline should have been visible (docs/design.md#detail-10) when at least
        ``min_points`` beams, and at least ``MIN_VISIBLE_FRACTION`` of the beams in view,
        see it unoccluded; it is missing when moreover most (``MISSING_FRACTION``) of its
        unoccluded beams read clearly beyond it. A polyline the scan reads right where it
        is has not gone, even when the association failed to pair it (a box first seen
        from one side and now from another, a partial view the gate rejects): counting
        that as a miss would delete an object that is still there.

        Examples
        --------
        >>> Visibility(np.array([10, 10, 10]), np.array([8, 8, 4]), np.array([1, 6, 4]),
        ...            [None] * 3, min_points=2).missing  # there, gone, hidden behind
        array([False,  True, False])
        """
        # Over Python ints: a map's few dozen polylines cost less so than numpy's calls.
        return np.array([
            unoccluded > 0
            and unoccluded >= max(self.min_points, math.ceil(MIN_VISIBLE_FRACTION * in_view))
            and seen_through >= MISSING_FRACTION * unoccluded
            for in_view, unoccluded, seen_through in zip(
                self.in_view.tolist(), self.unoccluded.tolist(), self.seen_through.tolist(),
                strict=True,
            )
        ], dtype=bool)


def visibility(
    polylines: PackedPolylines | Sequence[Polyline | ArrayLike],
    scan: Scan,
    pose: ArrayLike,
    params: MapperParams,
    *,
    cut: bool = True,
) -> Visibility:
    """Return what ``scan``, taken from ``pose``, saw of each map polyline.

    A beam is *in view* of a polyline when it would hit it within ``[range_min,
    min(range_max, params.max_range)]``. It is *unoccluded* when, moreover, the scan read
    at least about that range, ``r >= expected - margin``, and it *sees through* the
    polyline when it read clearly beyond it, ``r > expected + margin`` (``inf``, no
    return, counts for both), ``margin`` being ``params.visibility_margin``. A ``nan``
    reading tells nothing and counts as occluded.

    With ``cut``, the free-space cut: where at least ``MIN_SEEN_THROUGH`` consecutive beams
    see through a polyline, the space there is free, and the polyline is cut from half way
    to the crossing of the beam before that run to half way to the crossing of the beam
    after it (to its end where that beam misses it). It works at the scale of the
    association gate (``params.gate``), below which the mapper follows a change by
    merging: only a span at least the gate wide is cut (one beam, noise or a person
    walking cut nothing), and a piece shorter than the gate left between cuts goes with
    them. The polyline is known to within ``params.epsilon`` across, so a beam counts only
    if it would read through it wherever it lay within that: crossing an edge farther than
    ``epsilon / tan(angle)`` from the edge's ends, reading beyond it by
    ``epsilon / sin(angle)`` more than the margin, and passing every vertex by ``epsilon``
    or more (a grazing beam, or one passing a corner by a centimetre, cuts nothing). The
    same beams make a polyline read through almost everywhere missing; the cut removes the
    part of one that is still there elsewhere (an object moved along its own face, a door
    that opened in a wall). Polylines of fewer than two vertices are cut nowhere.

    Parameters
    ----------
    polylines
        Map polylines in the frame of ``pose``.
    scan
        The scan (ranges and beam angles are used).
    pose
        Sensor pose ``(x, y, theta)`` in the map frame.
    params
        ``max_range``, ``visibility_margin``, ``min_points``, ``epsilon`` and ``gate``
        are used.
    cut
        Whether to find the free-space cuts (else every ``pieces`` entry is ``None``).

    Returns
    -------
    Visibility
        The beam counts of each polyline, which are missing, and the free-space cut's
        pieces (in each polyline's order, scan indices the vertex order; possibly none).

    Examples
    --------
    >>> wall = [[2.0, -1.0], [2.0, 1.0]]  # a wall 2 m ahead; beams 0.1 rad apart
    >>> angles = np.arange(-0.4, 0.45, 0.1)
    >>> ranges = 2.0 / np.cos(angles)
    >>> ranges[5:7] = 4.0  # two beams read through it, 0.2 and 0.4 m left of centre
    >>> scan = Scan(ranges=ranges, angle_min=-0.4, angle_increment=0.1)
    >>> seen = visibility([wall, [[9.0, -1.0], [9.0, 1.0]]], scan, (0.0, 0.0, 0.0),
    ...                   MapperParams())
    >>> [piece.points.round(3).tolist() for piece in seen.pieces[0]], seen.pieces[1]
    ([[[2.0, -1.0], [2.0, 0.1]], [[2.0, 0.512], [2.0, 1.0]]], None)
    >>> seen.in_view, seen.unoccluded, seen.seen_through  # the far wall: behind the near one
    (array([9, 3]), array([9, 0]), array([2, 0]))
    >>> seen.missing
    array([False, False])
    """
    lines = as_polylines(polylines)
    x, y, theta = np.asarray(pose, dtype=float).reshape(3).tolist()
    limit = min(scan.range_max, params.max_range)
    margin = params.visibility_margin
    cos, sin = beam_directions(scan.ranges.size, scan.angle_min, scan.angle_increment)
    counts, piece_counts, spans = _through_polylines(
        lines.points, lines.offsets, x, y, theta, scan.ranges, cos, sin, scan.angle_min,
        scan.angle_increment, scan.range_min, limit, margin, params.epsilon, params.gate,
        cut,
    )
    sizes = (lines.offsets[1:] - lines.offsets[:-1]).tolist()
    for k in [k for k, size in enumerate(sizes) if size < 2]:
        counts[k] = _point_counts(lines[k], scan, pose, limit, margin)
    pieces: list[PackedPolylines | None] = [None] * len(sizes)
    stored = 0
    # (Only the polylines the scan cut are looked at: most are not, most scans.)
    for k, number in enumerate(piece_counts.tolist()):
        if number >= 0:
            line = lines[k]
            pieces[k] = PackedPolylines([
                _arc_piece(line, low, high)
                for low, high in spans[stored : stored + number].tolist()
            ])
            stored += number
    return Visibility(counts[:, 0], counts[:, 1], counts[:, 2], pieces, params.min_points)


def _point_counts(
    line: Polyline, scan: Scan, pose: ArrayLike, limit: float, margin: float
) -> tuple[int, int, int]:
    """Return the beam counts of a polyline of fewer than two vertices."""
    points = untransform_points(pose, line.points)
    expected = _point_ranges(points, scan.angles())
    in_view = np.isfinite(expected) & (expected >= scan.range_min) & (expected <= limit)
    with np.errstate(invalid="ignore"):
        unoccluded = in_view & (scan.ranges >= expected - margin)
        seen_through = unoccluded & (scan.ranges > expected + margin)
    return int(in_view.sum()), int(unoccluded.sum()), int(seen_through.sum())


@numba.njit(cache=True)
def _extended_ends(
    points: np.ndarray, offsets: np.ndarray, angle_increment: float, origin_x: float,
    origin_y: float, limit: float,
) -> None:  # pragma: no cover - compiled
    """Move the ends of the polylines packed in ``points`` in place (:func:`extend_ends`).

    Polyline ``p`` is ``points[offsets[p]:offsets[p + 1]]``.
    """
    for p in range(offsets.size - 1):
        first, last = offsets[p], offsets[p + 1] - 1
        if last - first < 1:
            continue
        for side in range(2):
            end, inner = (first, first + 1) if side == 0 else (last, last - 1)
            beam_step = -angle_increment if side == 0 else angle_increment
            x, y = points[end, 0], points[end, 1]
            relative_x, relative_y = x - origin_x, y - origin_y
            outward_x = relative_x - (points[inner, 0] - origin_x)
            outward_y = relative_y - (points[inner, 1] - origin_y)
            norm = math.hypot(outward_x, outward_y)
            if norm == 0.0:
                continue
            outward_x, outward_y = outward_x / norm, outward_y / norm
            # Where does the neighbouring beam cross the line of the end edge?
            beam = math.atan2(relative_y, relative_x) + beam_step
            direction_x, direction_y = math.cos(beam), math.sin(beam)
            across = direction_x * outward_y - direction_y * outward_x
            if abs(across) <= PARALLEL_TOLERANCE:
                continue
            along_edge = (relative_x * direction_y - relative_y * direction_x) / across
            along_beam = (relative_x * outward_y - relative_y * outward_x) / across
            if along_edge <= 0.0 or along_beam <= 0.0:
                continue
            shift = min(0.5 * along_edge, limit)  # half the gap to that beam, at most limit
            if shift > 0.0:
                points[end, 0], points[end, 1] = x + shift * outward_x, y + shift * outward_y


@numba.njit(cache=True)
def _through_polylines(
    points: np.ndarray, offsets: np.ndarray, pose_x: float, pose_y: float,
    pose_theta: float, ranges: np.ndarray, cos: np.ndarray, sin: np.ndarray,
    angle_min: float, angle_increment: float, range_min: float, limit: float, margin: float,
    epsilon: float, gate: float, cut: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Return the beam counts and free-space cuts of polylines packed in ``points``.

    Polyline ``p`` is ``points[offsets[p]:offsets[p + 1]]`` (map frame, sensor at
    ``pose``). Returns ``(P, 3)`` counts (in view,
    unoccluded, seen through; zeros for fewer than two vertices), ``(P,)`` piece counts
    (``-1``: not cut, always without ``cut``) and the ``(K, 2)`` arc-length spans of the
    pieces, polyline after polyline.
    """
    count = offsets.size - 1
    beams = ranges.size
    # Filled by loops: np.zeros and np.full of these shapes would each compile library
    # code for this kernel alone at first use.
    counts = np.empty((count, 3), np.int64)
    piece_counts = np.empty(count, np.int64)
    for p in range(count):
        counts[p, 0] = counts[p, 1] = counts[p, 2] = 0
        piece_counts[p] = -1
    pieces = np.empty((count + 4, 2))
    stored = 0
    robust = np.zeros(beams, np.bool_)
    positions = np.empty(beams)
    spans = np.empty((beams, 2))
    c, s = math.cos(pose_theta), math.sin(pose_theta)
    for p in range(count):
        start, size = offsets[p], offsets[p + 1] - offsets[p]
        if size < 2:
            continue
        xs, ys = np.empty(size), np.empty(size)
        for k in range(size):
            dx, dy = points[start + k, 0] - pose_x, points[start + k, 1] - pose_y
            xs[k], ys[k] = dx * c + dy * s, dy * c - dx * s
        first, stop = _sector(xs, ys, beams, angle_min, angle_increment)
        arcs = _arc_positions(xs, ys)
        length = arcs[size - 1]
        in_view = unoccluded = seen_through = 0
        for beam in range(first, stop):
            expected, arc, to_end, sine = _first_crossing(xs, ys, arcs, cos[beam], sin[beam])
            reading = ranges[beam]
            positions[beam - first] = arc
            robust[beam - first] = False
            if not (math.isfinite(expected) and range_min <= expected <= limit):
                continue
            in_view += 1
            if not reading >= expected - margin:
                continue
            unoccluded += 1
            if not reading > expected + margin:
                continue
            seen_through += 1
            # Read through wherever within epsilon across the polyline lay.
            squared_cosine = 1.0 - sine * sine
            robust[beam - first] = (
                squared_cosine >= 0.0
                and to_end * sine >= epsilon * math.sqrt(squared_cosine)
                and reading > expected + margin + epsilon / sine
                and _clears_corners(xs, ys, cos[beam], sin[beam], reading, epsilon)
            )
        counts[p, 0], counts[p, 1], counts[p, 2] = in_view, unoccluded, seen_through
        if not cut:
            continue
        found = _seen_through_spans(robust, positions, max(stop - first, 0), length, gate, spans)
        if found == 0:
            continue
        # The pieces before, between and after the cuts, each at least the gate long.
        kept, begin = 0, 0.0
        for k in range(found + 1):
            end = spans[k, 0] if k < found else length
            if end > begin and end - begin >= gate:
                if stored == pieces.shape[0]:
                    grown = np.empty((2 * stored, 2))
                    for row in range(stored):  # (a slice assignment compiles shape checks)
                        grown[row, 0], grown[row, 1] = pieces[row, 0], pieces[row, 1]
                    pieces = grown
                pieces[stored, 0], pieces[stored, 1] = begin, end
                stored += 1
                kept += 1
            if k < found:
                begin = max(begin, spans[k, 1])
        piece_counts[p] = kept
    return counts, piece_counts, pieces[:stored]


@numba.njit(cache=True)
def _clears_corners(
    xs: np.ndarray, ys: np.ndarray, cos: float, sin: float, reading: float, epsilon: float
) -> bool:  # pragma: no cover - compiled
    """Return whether the beam passes every vertex by ``epsilon`` or more.

    A vertex is known to within ``epsilon`` in every direction, not only across the edge
    the beam crosses: a beam that passes a box's corner by a centimetre, in line with the
    face beyond it (the sensor level with that face), crosses the map's other face a
    centimetre from the corner at a steep angle and reads the rack behind. Counted, it
    cut the whole face off (warehouse_fleet: carton_south's west face, lost as a vehicle
    came level with it). The same holds at a polyline's end (a face cut there before).
    Only the vertices along the beam before its reading count.
    """
    for k in range(xs.size):
        along = xs[k] * cos + ys[k] * sin
        if 0.0 < along < reading and abs(xs[k] * sin - ys[k] * cos) < epsilon:
            return False
    return True


@numba.njit(cache=True)
def _sector(
    xs: np.ndarray, ys: np.ndarray, beams: int, angle_min: float, angle_increment: float
) -> tuple[int, int]:  # pragma: no cover - compiled
    """Return the beams ``[first, stop)`` that can hit sensor-frame vertices ``(xs, ys)``.

    A straight edge subtends the bearings between its ends, so no beam outside the
    vertices' bearing interval hits the polyline; one beam more on each side absorbs
    rounding. An edge that crosses the cut behind the sensor (bearing jump above pi)
    gets every beam.
    """
    low = high = previous = math.atan2(ys[0], xs[0])
    for k in range(1, xs.size):
        bearing = math.atan2(ys[k], xs[k])
        if abs(bearing - previous) > math.pi:
            return 0, beams
        low, high, previous = min(low, bearing), max(high, bearing), bearing
    first = math.floor((low - angle_min) / angle_increment) - 1
    stop = math.ceil((high - angle_min) / angle_increment) + 2
    return max(0, first), min(beams, stop)


@numba.njit(cache=True)
def _seen_through_spans(
    flags: np.ndarray, positions: np.ndarray, count: int, length: float, min_span: float,
    spans: np.ndarray,
) -> int:  # pragma: no cover - compiled
    """Write the sorted arc-length spans that seen-through runs cut into ``spans``.

    Runs of at least ``MIN_SEEN_THROUGH`` of the first ``count`` beams' ``flags``; each end
    of a run reaches half way to its neighbour's crossing (``positions``, ``nan`` for a
    miss), or the polyline's end (``0`` or ``length``) on the side where that neighbour
    misses it. Only spans ``min_span`` or longer are kept; returns how many.
    """
    found = 0
    start = 0
    while start < count:
        if not flags[start]:
            start += 1
            continue
        stop = start
        while stop + 1 < count and flags[stop + 1]:
            stop += 1
        if stop - start + 1 >= MIN_SEEN_THROUGH:
            low, high = positions[start], positions[start]
            for k in range(start + 1, stop + 1):
                low, high = min(low, positions[k]), max(high, positions[k])
            for side in range(2):
                end, neighbour = (start, start - 1) if side == 0 else (stop, stop + 1)
                at_low = positions[end] == low
                other = positions[neighbour] if 0 <= neighbour < count else math.nan
                if math.isnan(other):
                    bound = 0.0 if at_low else length
                else:
                    bound = 0.5 * (positions[end] + other)
                if at_low:
                    low = min(low, bound)
                else:
                    high = max(high, bound)
            if high - low >= min_span:
                # Insertion into the sorted spans (by start, then end).
                k = found
                while k > 0 and (spans[k - 1, 0] > low
                                 or (spans[k - 1, 0] == low and spans[k - 1, 1] > high)):
                    # Element by element: a row assignment compiles numba's broadcasting
                    # and its error formatting (1.5 s of a first run's compilation).
                    spans[k, 0], spans[k, 1] = spans[k - 1, 0], spans[k - 1, 1]
                    k -= 1
                spans[k, 0], spans[k, 1] = low, high
                found += 1
        start = stop + 1
    return found


def _arc_piece(line: Polyline, low: float, high: float) -> Polyline:
    """Return the part of ``line`` between arc-length positions ``low < high``."""
    points = line.points
    arcs = np.concatenate(([0.0], np.cumsum(line.edge_lengths)))
    ends = [np.interp(value, arcs, points[:, axis]) for value in (low, high) for axis in (0, 1)]
    inside = points[(arcs > low) & (arcs < high)]
    rows = np.vstack(([ends[0], ends[1]], inside, [ends[2], ends[3]]))
    return Polyline(rows)


