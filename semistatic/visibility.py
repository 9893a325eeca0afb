"""What a laser scan can see of a polyline: expected ranges, visibility and biased ends.

Two parts of the mapper reason about single beams rather than whole polylines:

- the object life cycle (DESIGN.md detail 10) deletes a map polyline only after it was
  missed while it *should have been visible*: :func:`expected_ranges` casts the scan's
  beams at the polyline, :func:`visible_beams` counts those in view, unoccluded and seen
  through, and :func:`should_be_visible` / :func:`is_missing` decide;
- :func:`extend_ends` removes the bias of a scan polyline's ends, which the last beam on
  an object leaves up to half a beam gap short of its true end;
- :func:`free_space_cut` removes the parts of a map polyline that the scan reads through
  (an object moved along its own face: the map's ends agree with the scan, its middle
  does not).

Examples
--------
>>> scan = Scan(ranges=np.full(21, 5.0), angle_min=-0.1, angle_increment=0.01)
>>> wall = [[2.0, -1.0], [2.0, 1.0]]
>>> visible_beams(wall, scan, (0.0, 0.0, 0.0))  # all 21 beams would hit it, none do
BeamCounts(in_view=21, unoccluded=21, seen_through=21)
>>> is_missing(wall, scan, (0.0, 0.0, 0.0), MapperParams())
True
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import untransform_points
from semistatic.params import MapperParams
from semistatic.polyline import Polyline, as_polyline
from semistatic.types import Scan, beam_directions

__all__ = [
    "MAX_END_EXTENSION",
    "MIN_VISIBLE_FRACTION",
    "MISSING_FRACTION",
    "BeamCounts",
    "expected_ranges",
    "extend_ends",
    "free_space_cut",
    "is_missing",
    "should_be_visible",
    "visible_beams",
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

# Consecutive beams that must read through a map polyline before free_space_cut removes
# that part: two, the fewest readings that make a polyline (MapperParams.min_points), so
# one noisy reading cuts nothing.
MIN_SEEN_THROUGH = 2

# Largest end extension (m) of extend_ends: at grazing incidence the gap to the next beam
# grows without bound, while the end it hides can only be this much farther on average.
MAX_END_EXTENSION = 0.10


def expected_ranges(points: ArrayLike, angles: ArrayLike) -> np.ndarray:
    """Return the range at which each beam would first hit a polyline (``inf``: no hit).

    Parameters
    ----------
    points
        ``(N, 2)`` polyline vertices in the sensor frame. A single vertex is hit only by
        the beam whose direction is nearest to it (within half a beam step).
    angles
        ``(B,)`` beam angles (rad) in the sensor frame, increasing.

    Examples
    --------
    >>> expected_ranges([[2.0, -1.0], [2.0, 1.0]], [-np.pi / 8, 0.0, np.pi / 2]).round(3)
    array([2.165, 2.   ,   inf])
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    angles = np.asarray(angles, dtype=float).reshape(-1)
    ranges = np.full(angles.size, math.inf)
    if points.shape[0] == 0 or angles.size == 0:
        return ranges
    if points.shape[0] == 1:
        bearing = math.atan2(points[0, 1], points[0, 0])
        beam = int(np.argmin(np.abs(np.angle(np.exp(1j * (angles - bearing))))))
        step = float(np.median(np.diff(angles))) if angles.size > 1 else math.inf
        if abs(math.remainder(angles[beam] - bearing, 2.0 * math.pi)) <= 0.5 * step:
            ranges[beam] = float(np.hypot(points[0, 0], points[0, 1]))
        return ranges
    return _edge_hits(points, np.cos(angles), np.sin(angles))


def _edge_hits(points: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """Return :func:`expected_ranges` of ``N >= 2`` vertices for beam directions (cos, sin)."""
    return _edge_crossings(points, cos, sin)[0]


def _edge_crossings(
    points: np.ndarray, cos: np.ndarray, sin: np.ndarray, *, arcs: bool = False
) -> tuple[np.ndarray, _Crossings | None]:
    """Return each beam's first hit on ``N >= 2`` vertices: range and, with ``arcs``, where.

    Where (:class:`_Crossings`): the arc-length position of the hit along the polyline,
    its distance along the hit edge to that edge's nearer end, and the sine of the angle
    between beam and edge (``nan`` for no hit).
    """
    starts = points[:-1]
    edges = np.diff(points, axis=0)
    dx, dy = cos[:, None], sin[:, None]
    denominator = dx * edges[:, 1] - dy * edges[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        along_beam = (starts[:, 0] * edges[:, 1] - starts[:, 1] * edges[:, 0]) / denominator
        along_edge = (starts[:, 0] * dy - starts[:, 1] * dx) / denominator
    hit = (
        (np.abs(denominator) > PARALLEL_TOLERANCE)
        & (along_beam > 0.0)
        & (along_edge >= 0.0)
        & (along_edge <= 1.0)
    )
    ranges = np.where(hit, along_beam, math.inf)
    if not arcs:
        return ranges.min(axis=1), None
    edge = ranges.argmin(axis=1)
    beams = np.arange(ranges.shape[0])
    lengths = np.hypot(edges[:, 0], edges[:, 1])
    position = np.concatenate(([0.0], np.cumsum(lengths)))[edge] + (
        along_edge[beams, edge] * lengths[edge]
    )
    first = ranges[beams, edge]
    hit_any = np.isfinite(first)
    fraction = along_edge[beams, edge]
    to_end = np.minimum(fraction, 1.0 - fraction) * lengths[edge]
    sine = np.abs(denominator[beams, edge]) / np.where(lengths[edge] > 0.0, lengths[edge], 1.0)
    return first, _Crossings(
        np.where(hit_any, position, math.nan),
        np.where(hit_any, to_end, math.nan),
        np.where(hit_any, sine, math.nan),
    )


class _Crossings(NamedTuple):
    """Where beams cross a polyline (see :func:`_edge_crossings`)."""

    arc: np.ndarray
    to_end: np.ndarray
    sine: np.ndarray


def _beams_in_sector(points: np.ndarray, scan: Scan) -> tuple[int, int]:
    """Return the beams ``[first, stop)`` of ``scan`` that can hit polyline ``points``.

    ``points`` are ``N >= 2`` vertices in the sensor frame. A straight edge subtends the
    bearings between its ends, so no beam outside the vertices' bearing interval hits
    the polyline; one beam more on each side absorbs rounding. An edge that crosses the
    cut behind the sensor (bearing jump above pi) gets every beam.
    """
    count = scan.ranges.size
    bearings = np.arctan2(points[:, 1], points[:, 0]).tolist()
    if any(abs(b - a) > math.pi for a, b in itertools.pairwise(bearings)):
        return 0, count
    low = (min(bearings) - scan.angle_min) / scan.angle_increment
    high = (max(bearings) - scan.angle_min) / scan.angle_increment
    return max(0, math.floor(low) - 1), min(count, math.ceil(high) + 2)


def extend_ends(
    polyline: Polyline | ArrayLike,
    angle_increment: float,
    *,
    viewpoint: ArrayLike = (0.0, 0.0),
    limit: float = MAX_END_EXTENSION,
) -> Polyline:
    """Return a scan polyline with each end moved half a beam gap outward.

    The last beam that hits an object stops short of its true end, which lies somewhere
    before the next beam would have crossed the object's edge line: on average half that
    gap further. At grazing incidence the gap is many centimetres (9 cm at 3 m and 16 deg
    for 0.5 deg beams), so maps built from raw ends shrink objects by half of it. Moving
    each end along its edge by half the gap to the neighbouring beam (at most ``limit``)
    removes that bias; an end cut by an occluder or the field of view is only extended
    along a surface that goes on anyway.

    Parameters
    ----------
    polyline
        Scan polyline in scan (counter-clockwise) order, in any frame.
    angle_increment
        Beam step of the scan (rad).
    viewpoint
        Sensor position ``(x, y)`` (a pose's heading is ignored) in the polyline's frame;
        default the origin, i.e. a polyline in the sensor frame.
    limit
        Largest extension (m).

    Examples
    --------
    >>> wall = [[2.0, 0.0], [2.0, 1.0]]  # seen head-on from the origin
    >>> extend_ends(wall, np.radians(1.0)).points.round(4)
    array([[ 2.    , -0.0175],
           [ 2.    ,  1.022 ]])
    """
    line = as_polyline(polyline)
    origin = np.asarray(viewpoint, dtype=float).reshape(-1)[:2].tolist()
    return _extended(line, angle_increment, origin[0], origin[1], limit)


def _extended(
    line: Polyline, angle_increment: float, origin_x: float, origin_y: float, limit: float
) -> Polyline:
    """Return :func:`extend_ends` of ``line`` seen from ``(origin_x, origin_y)``."""
    rows, moved = _extended_rows(line.points.tolist(), angle_increment, origin_x, origin_y, limit)
    return _observed(line, rows, moved)


def _observed(line: Polyline, rows: list[list[float]], moved: bool) -> Polyline:
    """Return ``line`` with the vertex rows of :func:`_extended_rows` (itself if unmoved)."""
    if not moved:
        return line
    # Finite vertices moved by a finite shift: nothing to check.
    return Polyline._trusted(np.array(rows, dtype=np.float64), line.scan_indices)


def _extended_rows(
    rows: list[list[float]], angle_increment: float, origin_x: float, origin_y: float, limit: float
) -> tuple[list[list[float]], bool]:
    """Return :func:`extend_ends` of vertex ``rows`` (a new list) and whether an end moved."""
    if len(rows) < 2:
        return rows, False
    rows = list(rows)
    moved = False
    for end, inner, beam_step in ((0, 1, -angle_increment), (-1, -2, angle_increment)):
        (x, y), (inner_x, inner_y) = rows[end], rows[inner]
        relative_x, relative_y = x - origin_x, y - origin_y
        outward_x = relative_x - (inner_x - origin_x)
        outward_y = relative_y - (inner_y - origin_y)
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
            rows[end] = [x + shift * outward_x, y + shift * outward_y]
            moved = True
    return rows, moved


class BeamCounts(NamedTuple):
    """Beams of one scan that concern one map polyline (see :func:`visible_beams`).

    Examples
    --------
    >>> BeamCounts(in_view=10, unoccluded=8, seen_through=1).unoccluded
    8
    """

    in_view: int
    """Beams that would hit the polyline within the usable range."""
    unoccluded: int
    """Of those, beams that read at least about the expected range."""
    seen_through: int
    """Of those, beams that read clearly beyond it (or no return): it is not there."""


def visible_beams(
    polyline: Polyline | ArrayLike,
    scan: Scan,
    pose: ArrayLike,
    *,
    max_range: float = math.inf,
    margin: float = 0.15,
) -> BeamCounts:
    """Count the beams of ``scan`` that would hit ``polyline``, unoccluded and seen through.

    A beam is *in view* when it would hit the polyline within ``[range_min,
    min(range_max, max_range)]``. It is *unoccluded* when, moreover, the scan read at least
    about that range, ``r >= expected - margin``, and it *sees through* the polyline when
    it read clearly beyond it, ``r > expected + margin`` (``inf``, no return, counts for
    both). A ``nan`` reading tells nothing and counts as occluded.

    Parameters
    ----------
    polyline
        Map polyline in the frame of ``pose``.
    scan
        The scan (ranges and beam angles are used).
    pose
        Sensor pose ``(x, y, theta)`` in the map frame.
    max_range, margin
        Mapper range limit and occlusion margin (m).

    Returns
    -------
    BeamCounts

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, 2.0, 3.0, 3.0], angle_min=-0.15, angle_increment=0.1)
    >>> tuple(visible_beams([[2.0, -1.0], [2.0, 1.0]], scan, (0.0, 0.0, 0.0)))
    (4, 3, 2)
    """
    points = untransform_points(pose, as_polyline(polyline).points)
    states = _beam_states(points, scan, max_range, margin)
    return BeamCounts(
        int(states.in_view.sum()), int(states.unoccluded.sum()), int(states.seen_through.sum())
    )


class _BeamStates(NamedTuple):
    """Per-beam masks of :func:`visible_beams`, over consecutive beams of a scan."""

    in_view: np.ndarray
    unoccluded: np.ndarray
    seen_through: np.ndarray
    expected: np.ndarray
    ranges: np.ndarray
    crossings: _Crossings | None


def _beam_states(
    points: np.ndarray, scan: Scan, max_range: float, margin: float, *, arcs: bool = False
) -> _BeamStates:
    """Return :func:`visible_beams`'s per-beam masks for sensor-frame vertices ``points``.

    Over consecutive beams (only those of the polyline's sector when it has an edge: the
    others cannot hit it), with the expected and read ranges; ``crossings`` (with
    ``arcs``, for ``N >= 2`` vertices) says where each beam crosses the polyline.
    """
    arc = None
    if points.shape[0] < 2:
        expected, ranges = expected_ranges(points, scan.angles()), scan.ranges
    else:
        # Only the beams of the polyline's sector can hit it: the others expect inf.
        first, stop = _beams_in_sector(points, scan)
        cos, sin = beam_directions(scan.ranges.size, scan.angle_min, scan.angle_increment)
        expected, arc = _edge_crossings(points, cos[first:stop], sin[first:stop], arcs=arcs)
        ranges = scan.ranges[first:stop]
    limit = min(scan.range_max, max_range)
    in_view = np.isfinite(expected) & (expected >= scan.range_min) & (expected <= limit)
    with np.errstate(invalid="ignore"):
        unoccluded = in_view & (ranges >= expected - margin)
        seen_through = unoccluded & (ranges > expected + margin)
    return _BeamStates(in_view, unoccluded, seen_through, expected, ranges, arc)


def free_space_cut(
    polyline: Polyline | ArrayLike, scan: Scan, pose: ArrayLike, params: MapperParams
) -> list[Polyline]:
    """Return the parts of a map polyline that ``scan`` does not read through.

    Where at least ``MIN_SEEN_THROUGH`` consecutive beams see through the polyline (read
    clearly beyond it, as in :func:`visible_beams` with ``params.visibility_margin``), the
    space there is free: the polyline is cut from half way to the crossing of the beam
    before that run to half way to the crossing of the beam after it (to its end where
    that beam misses it).

    It works at the scale of the association gate (``params.gate``), below which the
    mapper follows a change by merging: only a span at least the gate wide is cut (one
    beam, noise or a person walking cut nothing), and a piece shorter than the gate left
    between cuts goes with them. The polyline is known to within ``params.epsilon``
    across, so a beam counts only if it would read through it wherever it lay within
    that: crossing an edge farther than ``epsilon / tan(angle)`` from the edge's ends,
    and reading beyond it by ``epsilon / sin(angle)`` more than the margin (a grazing
    beam, or one passing a corner by a centimetre, cuts nothing). The same beams make
    :func:`is_missing` delete a polyline that is read through almost everywhere; this
    removes the part of one that is still there elsewhere (an object moved along its own
    face, a door that opened in a wall).

    Parameters
    ----------
    polyline
        Map polyline in the frame of ``pose``.
    scan
        The scan (ranges and beam angles are used).
    pose
        Sensor pose ``(x, y, theta)`` in the map frame.
    params
        ``max_range`` and ``visibility_margin`` are used.

    Returns
    -------
    list of Polyline
        ``[polyline]`` itself when nothing is cut, else the remaining pieces in the
        polyline's order (scan indices: vertex order), possibly none.

    Examples
    --------
    >>> wall = [[2.0, -1.0], [2.0, 1.0]]  # a wall 2 m ahead; beams 0.1 rad apart
    >>> angles = np.arange(-0.4, 0.45, 0.1)
    >>> ranges = 2.0 / np.cos(angles)
    >>> ranges[5:7] = 4.0  # two beams read through it, 0.2 and 0.4 m left of centre
    >>> scan = Scan(ranges=ranges, angle_min=-0.4, angle_increment=0.1)
    >>> [piece.points.round(3).tolist()
    ...  for piece in free_space_cut(wall, scan, (0.0, 0.0, 0.0), MapperParams())]
    [[[2.0, -1.0], [2.0, 0.1]], [[2.0, 0.512], [2.0, 1.0]]]
    """
    line = as_polyline(polyline)
    points = untransform_points(pose, line.points)
    if points.shape[0] < 2:
        return [line]
    states = _beam_states(points, scan, params.max_range, params.visibility_margin, arcs=True)
    crossing = states.crossings
    # Read through wherever within epsilon across the polyline lay (see above).
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = np.sqrt(1.0 - crossing.sine**2)
        robust = (
            states.seen_through
            & (crossing.to_end * crossing.sine >= params.epsilon * cosine)
            & (states.ranges
               > states.expected + params.visibility_margin + params.epsilon / crossing.sine)
        )
    cuts = _seen_through_spans(robust, crossing.arc, line.length, params.gate)
    if not cuts:
        return [line]
    pieces, start = [], 0.0
    for low, high in cuts:
        if low > start:
            pieces.append((start, low))
        start = max(start, high)
    if start < line.length:
        pieces.append((start, line.length))
    return [_arc_piece(line, low, high) for low, high in pieces if high - low >= params.gate]


def _seen_through_spans(
    seen_through: np.ndarray, arc: np.ndarray, length: float, min_span: float
) -> list[tuple[float, float]]:
    """Return the sorted arc-length spans, ``min_span`` or longer, that seen-through runs cut."""
    flags = seen_through.tolist()
    positions = arc.tolist()
    count = len(flags)
    spans = []
    start = 0
    while start < count:
        if not flags[start]:
            start += 1
            continue
        stop = start
        while stop + 1 < count and flags[stop + 1]:
            stop += 1
        if stop - start + 1 >= MIN_SEEN_THROUGH:
            run = positions[start : stop + 1]
            low, high = min(run), max(run)
            # Each end of the run reaches half way to its neighbour's crossing, or the
            # polyline's end on the side where that neighbour misses it.
            for end, neighbour in ((start, start - 1), (stop, stop + 1)):
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
                spans.append((low, high))
        start = stop + 1
    return sorted(spans)


def _arc_piece(line: Polyline, low: float, high: float) -> Polyline:
    """Return the part of ``line`` between arc-length positions ``low < high``."""
    points = line.points
    arcs = np.concatenate(([0.0], np.cumsum(line.edge_lengths)))
    ends = [np.interp(value, arcs, points[:, axis]) for value in (low, high) for axis in (0, 1)]
    inside = points[(arcs > low) & (arcs < high)]
    rows = np.vstack(([ends[0], ends[1]], inside, [ends[2], ends[3]]))
    return Polyline(rows)


def should_be_visible(
    polyline: Polyline | ArrayLike, scan: Scan, pose: ArrayLike, params: MapperParams
) -> bool:
    """Return whether ``scan`` should have seen ``polyline`` (DESIGN.md detail 10).

    True when at least ``params.min_points`` beams, and at least ``MIN_VISIBLE_FRACTION``
    of the beams in view, see it unoccluded (:func:`visible_beams` with
    ``params.max_range`` and ``params.visibility_margin``).

    Examples
    --------
    >>> scan = Scan(ranges=np.full(21, 5.0), angle_min=-0.1, angle_increment=0.01)
    >>> should_be_visible([[2.0, -1.0], [2.0, 1.0]], scan, (0.0, 0.0, 0.0), MapperParams())
    True
    >>> should_be_visible([[2.0, -1.0], [2.0, 1.0]], scan, (0.0, 0.0, np.pi), MapperParams())
    False
    """
    counts = visible_beams(
        polyline, scan, pose, max_range=params.max_range, margin=params.visibility_margin
    )
    return _visible(counts, params)


def _visible(counts: BeamCounts, params: MapperParams) -> bool:
    needed = max(params.min_points, math.ceil(MIN_VISIBLE_FRACTION * counts.in_view))
    return counts.unoccluded > 0 and counts.unoccluded >= needed


def is_missing(
    polyline: Polyline | ArrayLike, scan: Scan, pose: ArrayLike, params: MapperParams
) -> bool:
    """Return whether ``polyline`` should have been seen and the scan reads through it.

    This is a miss of the life cycle: :func:`should_be_visible`, and most
    (``MISSING_FRACTION``) of its unoccluded beams read clearly beyond it. A polyline the
    scan reads right where it is has not gone, even when the association failed to pair
    it (a box first seen from one side and now from another, a partial view the gate
    rejects): counting that as a miss would delete an object that is still there.

    Examples
    --------
    >>> wall = [[2.0, -1.0], [2.0, 1.0]]
    >>> far = Scan(ranges=np.full(21, 5.0), angle_min=-0.1, angle_increment=0.01)
    >>> at_the_wall = Scan(ranges=2.0 / np.cos(far.angles()), angle_min=-0.1,
    ...                    angle_increment=0.01)
    >>> is_missing(wall, far, (0.0, 0.0, 0.0), MapperParams())
    True
    >>> is_missing(wall, at_the_wall, (0.0, 0.0, 0.0), MapperParams())
    False
    """
    counts = visible_beams(
        polyline, scan, pose, max_range=params.max_range, margin=params.visibility_margin
    )
    return _visible(counts, params) and counts.seen_through >= MISSING_FRACTION * counts.unoccluded
