"""Polyline extraction from one laser scan (paper Sec. 3.1, docs/design.md#detail-1 to #detail-3).

The pipeline is a handful of passes over the beams (numpy, and numba where they fuse):

1. :func:`remove_invalid` - drop ``nan``/``inf`` readings and those outside
   ``[range_min, min(range_max, max_range)]``; they never reach any statistic.
2. :func:`remove_outliers` - drop isolated readings: ``|r_i - mu_i| > alpha sigma_i`` over
   the ``2k+1`` valid ranges centred on ``i`` (docs/design.md#detail-1).
3. :func:`split_breakpoints` - cut the beam sequence at the Borges & Aldon adaptive
   breakpoints and at gaps of missing readings (docs/design.md#detail-2).
4. :func:`douglas_peucker` - keep the vertices GEOS keeps (docs/design.md#detail-3).

:func:`extract_polylines` chains them; one compiled Douglas-Peucker (GEOS's recursion and
arithmetic) simplifies every interval of a scan, and the merge's polylines too.

Examples
--------
>>> angles = np.radians(np.arange(-45.0, 45.5, 0.5))
>>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0], angle_increment=np.radians(0.5))
>>> [line.scan_indices for line in extract_polylines(scan)]  # a straight wall x = 2
[array([  0, 180])]
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
from numba.extending import overload
from numpy.typing import ArrayLike

from semistatic.fitting import fit_polylines
from semistatic.frames import transform_points
from semistatic.params import MapperParams
from semistatic.polyline import PackedPolylines
from semistatic.types import Scan, beam_directions

__all__ = [
    "MAX_BRIDGED_GAP",
    "douglas_peucker",
    "extract_polylines",
    "remove_invalid",
    "remove_outliers",
    "split_breakpoints",
]

# A window whose standard deviation is below this (m) is flat: nothing in it is an outlier
# (guards sigma = 0, where rounding alone could make |r - mu| > alpha * sigma). It is far
# above the rounding of the window statistics and far below any scanner's range noise.
FLAT_WINDOW_SIGMA = 1e-6

# Number of consecutive missing beams (invalid or removed as outliers) that may still lie
# inside one polyline. One missing beam on a continuous surface is a dropout or an
# outlier: bridging it (when the adaptive test passes with the doubled angle) is what a
# safety map wants, since the robot cannot pass through a one-beam gap anyway. Two or
# more missing beams in a row always break the polyline: something real is there
# (an opening, glass, a far surface).
MAX_BRIDGED_GAP = 1

def remove_invalid(scan: Scan, max_range: float = math.inf) -> np.ndarray:
    """Return the boolean mask of usable beams of ``scan``.

    A beam is usable when its range is finite and inside
    ``[scan.range_min, min(scan.range_max, max_range)]``.

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, np.nan, -1.0, np.inf, 5.0], angle_min=0.0,
    ...             angle_increment=0.1, range_max=10.0)
    >>> remove_invalid(scan)
    array([ True, False, False, False,  True])
    >>> remove_invalid(scan, max_range=4.0)
    array([ True, False, False, False, False])
    """
    valid = scan.valid_mask()
    if max_range < scan.range_max:
        with np.errstate(invalid="ignore"):
            valid &= scan.ranges <= max_range
    return valid


def remove_outliers(ranges: ArrayLike, valid: ArrayLike, k: int, alpha: float) -> np.ndarray:
    """Return ``valid`` with isolated readings removed (docs/design.md#detail-1).

    For each valid reading ``r_i`` the mean ``mu_i`` and (population) standard deviation
    ``sigma_i`` are taken over the window of ``2k+1`` *valid* ranges centred on it
    (near the ends of the scan: the valid ranges available within ``k`` on each side).
    The reading is dropped when ``|r_i - mu_i| > alpha * sigma_i``. Invalid readings are
    never part of a window. A perfectly flat window (``sigma_i`` below
    ``FLAT_WINDOW_SIGMA``) removes nothing.

    Since ``r_i`` is part of its own window, ``|r_i - mu_i| / sigma_i <= sqrt(n - 1)`` for a
    window of ``n`` readings: ``alpha`` must be below ``sqrt(2k)`` for anything to be
    removed at all (e.g. ``k = 4`` for ``alpha = 2.5``).

    Parameters
    ----------
    ranges
        ``(N,)`` ranges in metres; entries where ``valid`` is false are ignored.
    valid
        ``(N,)`` boolean mask of readings to consider, e.g. from :func:`remove_invalid`.
    k
        Half window, ``k >= 1``.
    alpha
        Threshold in window standard deviations, ``> 0``.

    Returns
    -------
    numpy.ndarray
        ``(N,)`` boolean mask, a subset of ``valid``.

    Examples
    --------
    >>> ranges = np.array([2.0, 2.01, 1.99, 2.0, 5.0, 2.0, 2.01, 1.99, 2.0, np.inf])
    >>> remove_outliers(ranges, np.isfinite(ranges), k=4, alpha=2.5)
    array([ True,  True,  True,  True, False,  True,  True,  True,  True, False])
    """
    ranges = np.asarray(ranges, dtype=float).reshape(-1)
    valid = np.asarray(valid, dtype=bool).reshape(-1)
    if ranges.shape != valid.shape:
        raise ValueError(
            f"remove_outliers: ranges has {ranges.size} entries but valid has {valid.size}"
        )
    if not (int(k) == k and k >= 1):
        raise ValueError(f"remove_outliers: k must be an integer >= 1, got {k!r}")
    if not alpha > 0:
        raise ValueError(f"remove_outliers: alpha must be > 0, got {alpha!r}")
    index = np.flatnonzero(valid)
    kept = valid.copy()
    kept[index[_outliers(ranges[index], int(k), alpha)]] = False
    return kept


def _outliers(values: np.ndarray, k: int, alpha: float) -> np.ndarray:
    """Return which of the consecutive valid ``values`` :func:`remove_outliers` drops."""
    count = values.size
    if count < 2:
        return np.zeros(count, dtype=bool)
    # Window sums from cumulative sums: window i spans valid readings [low, high). Ranges
    # are centred first, which keeps the rounding of E[r^2] - E[r]^2 near 1e-10 m^2 even
    # for 80 m ranges: far below any real range noise.
    centred = values - np.add.reduce(values) / count  # == values.mean(), without its overhead
    sums = np.zeros(count + 1)
    np.cumsum(centred, out=sums[1:])
    squares = np.zeros(count + 1)
    np.cumsum(centred * centred, out=squares[1:])
    low, high, size = _windows(count, k)
    mean = (sums[high] - sums[low]) / size
    variance = (squares[high] - squares[low]) / size - mean * mean
    sigma = np.sqrt(np.maximum(variance, 0.0))
    return (np.abs(centred - mean) > alpha * sigma) & (sigma > FLAT_WINDOW_SIGMA)


@functools.lru_cache(maxsize=64)
def _windows(count: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the ``[low, high)`` bounds and sizes of the ``2k+1`` windows over ``count``."""
    position = np.arange(count)
    low = np.maximum(position - k, 0)
    high = np.minimum(position + k + 1, count)
    return _frozen(low), _frozen(high), _frozen(high - low)


def _frozen(array: np.ndarray) -> np.ndarray:
    """Return ``array`` made read-only (it is shared through a cache)."""
    array.flags.writeable = False
    return array


def split_breakpoints(
    scan: Scan, valid: ArrayLike, lam: float, sigma_r: float, min_points: int
) -> list[np.ndarray]:
    """Split the usable beams of ``scan`` into intervals of one object each.

    Consecutive usable beams ``m < n`` (``valid`` true, everything between them missing)
    belong to the same interval when both hold (docs/design.md#detail-2):

    - at most ``MAX_BRIDGED_GAP`` beams are missing between them, and
    - ``|p_n - p_m| <= r_m sin(dphi) / sin(lam - dphi) + 3 sigma_r`` with
      ``dphi = (n - m) * angle_increment`` (Borges & Aldon 2004). When ``dphi >= lam`` the
      threshold is infinite in theory but meaningless: that always breaks.

    Intervals with fewer than ``min_points`` beams are dropped. The scan is not treated as
    circular: its first and last beams are never joined.

    Parameters
    ----------
    scan
        The laser scan (its ranges and angles are used).
    valid
        ``(N,)`` boolean mask of usable beams, e.g. after :func:`remove_outliers`.
    lam
        Breakpoint angle lambda in radians, in ``(0, pi/2)``.
    sigma_r
        Range noise in metres, ``>= 0``.
    min_points
        Minimum number of beams an interval must have to be kept, ``>= 1``.

    Returns
    -------
    list of numpy.ndarray
        Increasing int64 beam-index arrays, one per interval, in scan order.

    Examples
    --------
    >>> scan = Scan(ranges=[2.0, 2.0, 2.0, 4.0, 4.0, 4.0], angle_min=0.0,
    ...             angle_increment=np.radians(1.0))
    >>> split_breakpoints(scan, np.ones(6, bool), np.radians(10.0), 0.01, min_points=2)
    [array([0, 1, 2]), array([3, 4, 5])]
    """
    valid = np.asarray(valid, dtype=bool).reshape(-1)
    if valid.shape != scan.ranges.shape:
        raise ValueError(
            f"split_breakpoints: valid has {valid.size} entries but the scan has "
            f"{scan.ranges.size} beams"
        )
    if not 0.0 < lam < math.pi / 2:
        raise ValueError(f"split_breakpoints: lam must be in (0, pi/2) rad, got {lam!r}")
    if not sigma_r >= 0.0:
        raise ValueError(f"split_breakpoints: sigma_r must be >= 0 m, got {sigma_r!r}")
    if min_points < 1:
        raise ValueError(f"split_breakpoints: min_points must be >= 1, got {min_points!r}")
    index = np.flatnonzero(valid)
    x, y = _end_points(scan, index)
    joined = _joined(scan, index, x, y, lam, sigma_r)
    cuts = np.flatnonzero(~joined) + 1
    starts = np.concatenate(([0], cuts))
    stops = np.concatenate((cuts, [index.size]))
    return [
        index[start:stop]
        for start, stop in zip(starts.tolist(), stops.tolist(), strict=True)
        if stop - start >= min_points
    ]


def _end_points(scan: Scan, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the sensor-frame x and y of the beams ``index``."""
    ranges = scan.ranges[index]
    cos, sin = beam_directions(scan.ranges.size, scan.angle_min, scan.angle_increment)
    return ranges * cos[index], ranges * sin[index]


def _joined(
    scan: Scan, index: np.ndarray, x: np.ndarray, y: np.ndarray, lam: float, sigma_r: float
) -> np.ndarray:
    """Return, for each pair of consecutive usable beams, whether they stay together."""
    # Only steps of 1 .. MAX_BRIDGED_GAP + 1 beams can join: their sines come from a table,
    # and any longer step reads the table's last row, whose threshold joins nothing.
    sines, denominators = _breakpoint_sines(scan.angle_increment, lam)
    return _joined_beams(scan.ranges, index, x, y, sines, denominators, sigma_r)


@numba.njit(cache=True)
def _joined_beams(
    ranges: np.ndarray, index: np.ndarray, x: np.ndarray, y: np.ndarray, sines: np.ndarray,
    denominators: np.ndarray, sigma_r: float,
) -> np.ndarray:  # pragma: no cover - compiled
    """Return :func:`_joined` with the breakpoint table of :func:`_breakpoint_sines`."""
    joined = np.empty(index.size - 1 if index.size > 1 else 0, np.bool_)
    for k in range(joined.size):
        # Only steps of 1 .. MAX_BRIDGED_GAP + 1 beams can join: their sines come from a
        # table, and any longer step reads the table's last row, which joins nothing.
        step = index[k + 1] - index[k]
        if step > MAX_BRIDGED_GAP + 2:
            step = MAX_BRIDGED_GAP + 2
        threshold = ranges[index[k]] * sines[step] / denominators[step] + 3.0 * sigma_r
        joined[k] = math.hypot(x[k + 1] - x[k], y[k + 1] - y[k]) <= threshold
    return joined


@numba.njit(cache=True)
def _extracted(
    ranges: np.ndarray, limits: np.ndarray, cos: np.ndarray, sin: np.ndarray,
    sines: np.ndarray, denominators: np.ndarray, sigma_r: float, min_points: int,
    epsilon: float, fitted: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Return :func:`_extracted_vertices`'s vertices, beams and bounds in one pass.

    :func:`remove_invalid`, :func:`split_breakpoints`, :func:`douglas_peucker` and (when
    ``fitted``) :func:`~semistatic.fitting.fit_polylines` on flat arrays, one kernel call
    per scan. A beam is usable when its range is finite and inside ``limits``
    (``[low, high]``); ``(0, 2)`` vertices and bounds ``[0]`` when nothing is extracted.
    """
    # Scalar loops, not array expressions: each numpy expression in a kernel compiles a
    # broadcasting loop of its own at first use.
    low, high = limits[0], limits[1]
    index = np.empty(ranges.size, np.int64)
    usable = 0
    for k in range(ranges.size):
        if math.isfinite(ranges[k]) and low <= ranges[k] <= high:
            index[usable] = k
            usable += 1
    index = index[:usable]
    x, y = np.empty(usable), np.empty(usable)
    for k in range(usable):
        x[k] = ranges[index[k]] * cos[index[k]]
        y[k] = ranges[index[k]] * sin[index[k]]
    joined = _joined_beams(ranges, index, x, y, sines, denominators, sigma_r)
    points = np.empty((usable, 2))
    beams = np.empty(usable, np.int64)
    line_ids = np.empty(usable, np.int64)
    ends = np.empty(usable, np.int64)
    lines, start, size = 0, 0, 0
    for stop in range(1, usable + 1 if usable >= min_points else 0):
        if stop < usable and joined[stop - 1]:
            continue
        if stop - start >= min_points:
            for k in range(start, stop):
                points[size, 0], points[size, 1] = x[k], y[k]
                beams[size], line_ids[size] = index[k], lines
                size += 1
            ends[lines] = size - 1
            lines += 1
        start = stop
    points = points[:size]
    # Every interval but the last ends where the next begins.
    kept = _douglas_peucker(points, ends[: lines - 1 if lines > 1 else 0], epsilon)
    if fitted and size:
        vertices, kept, vertex_lines = fit_polylines(points, line_ids[:size].copy(), kept,
                                                     epsilon)
    else:
        vertices = np.empty((kept.size, 2))
        vertex_lines = np.empty(kept.size, np.int64)
        for k in range(kept.size):
            vertices[k, 0], vertices[k, 1] = points[kept[k], 0], points[kept[k], 1]
            vertex_lines[k] = line_ids[kept[k]]
    vertex_beams = np.empty(kept.size, np.int64)
    # Every line keeps its last point: where the line number changes, a line ends.
    bounds = np.empty(lines + 1, np.int64)
    bounds[0] = 0
    count = 1
    for k in range(kept.size):
        vertex_beams[k] = beams[kept[k]]
        if k and vertex_lines[k] != vertex_lines[k - 1]:
            bounds[count] = k
            count += 1
    if kept.size:
        bounds[count] = kept.size
        count += 1
    return vertices, vertex_beams, bounds[:count]


@functools.lru_cache(maxsize=16)
def _range_limits(range_min: float, range_max: float, max_range: float) -> np.ndarray:
    """Return the usable ranges ``[range_min, min(range_max, max_range)]`` as an array."""
    return _frozen(np.array([range_min, min(range_max, max_range)], dtype=float))


@functools.lru_cache(maxsize=16)
def _breakpoint_sines(angle_increment: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``sin(dphi)`` and ``sin(lam - dphi)`` per beam step ``0 .. MAX_BRIDGED_GAP + 2``.

    ``dphi = step * angle_increment``, computed as in the adaptive breakpoint formula.
    A step that can never join (none, too long, or ``dphi >= lam``) gets ``-inf / 1``,
    a threshold no jump is below.
    """
    steps = np.arange(MAX_BRIDGED_GAP + 3)
    dphi = steps * angle_increment
    sines, denominators = np.sin(dphi), np.sin(lam - dphi)
    never = (steps == 0) | (steps > MAX_BRIDGED_GAP + 1) | (dphi >= lam)
    sines[never], denominators[never] = -np.inf, 1.0
    return _frozen(sines), _frozen(denominators)


@numba.njit(cache=True)
def _douglas_peucker(
    points: np.ndarray, ends: np.ndarray, epsilon: float
) -> np.ndarray:  # pragma: no cover - compiled
    """Return the positions :func:`douglas_peucker` keeps of many lines at once.

    ``points`` hold finite vertices of lines one after the other; line ``k`` ends at
    ``ends[k]`` (increasing int64; the last line at the last point), ``epsilon >= 0``.
    """
    keep = np.zeros(points.shape[0], np.bool_)
    sections = np.empty((points.shape[0] if points.shape[0] > 1 else 1, 2), np.int64)
    first = np.int64(0)  # not a constant: a literal 0 would compile a kernel of its own
    for line in range(ends.size + 1 if points.shape[0] else 0):
        last = ends[line] if line < ends.size else np.int64(points.shape[0] - 1)
        keep[first] = keep[last] = True
        sections[0, 0], sections[0, 1] = first, last
        pending = 1
        while pending:
            pending -= 1
            start, stop = sections[pending, 0], sections[pending, 1]
            if start + 1 >= stop:
                continue
            ax, ay = points[start, 0], points[start, 1]
            bx, by = points[stop, 0], points[stop, 1]
            ex, ey = bx - ax, by - ay
            length2 = ex * ex + ey * ey
            point_segment = ax == bx and ay == by
            length = math.sqrt(length2)
            farthest, index = -1.0, start
            for k in range(start + 1, stop):
                px, py = points[k, 0], points[k, 1]
                if point_segment:
                    distance = math.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
                else:
                    r = ((px - ax) * ex + (py - ay) * ey) / length2
                    if r <= 0.0:
                        distance = math.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
                    elif r >= 1.0:
                        distance = math.sqrt((px - bx) * (px - bx) + (py - by) * (py - by))
                    else:
                        distance = abs(((ay - py) * ex - (ax - px) * ey) / length2) * length
                if distance > farthest:
                    farthest, index = distance, k
            if farthest > epsilon:
                keep[index] = True
                sections[pending, 0], sections[pending, 1] = index, stop
                sections[pending + 1, 0], sections[pending + 1, 1] = start, index
                pending += 2
        first = last + 1
    count = 0
    for k in range(keep.size):
        count += keep[k]
    kept = np.empty(count, np.int64)
    count = 0
    for k in range(keep.size):
        if keep[k]:
            kept[count] = k
            count += 1
    return kept


# One line: _douglas_peucker without inner line ends.
_NO_ENDS = np.empty(0, dtype=np.int64)


def douglas_peucker(points: ArrayLike, epsilon: float) -> np.ndarray:
    """Return the sorted indices of the vertices Douglas-Peucker keeps.

    Keeps the first and last point, and recursively the farthest point of a section when
    its point-to-*segment* distance is strictly greater than ``epsilon`` (the first one on
    ties): exactly the vertices of
    ``shapely.simplify(LineString(points), epsilon, preserve_topology=False)``
    (docs/design.md#detail-3), repeated and collinear points included, by one compiled kernel:
    GEOS's recursion with GEOS's arithmetic (``Distance::pointToSegment`` operation for
    operation). Compiled kernels call this function too (the merge does): it compiles to
    the same kernel, without the checks.

    Parameters
    ----------
    points
        ``(N, 2)`` finite vertices.
    epsilon
        Tolerance in metres, ``>= 0``.

    Returns
    -------
    numpy.ndarray
        Increasing int64 indices into ``points`` (empty for no points, all for two or
        fewer).

    Examples
    --------
    >>> douglas_peucker([[0, 0], [1, 0.01], [2, 0], [2, 1]], epsilon=0.05)
    array([0, 2, 3])
    """
    points = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 2))
    if not epsilon >= 0.0:
        raise ValueError(f"douglas_peucker: epsilon must be >= 0 m, got {epsilon!r}")
    if not np.isfinite(points).all():
        raise ValueError("douglas_peucker: points must be finite; drop invalid readings first")
    return _douglas_peucker(points, _NO_ENDS, float(epsilon))


@overload(douglas_peucker, jit_options={"cache": True})
def _douglas_peucker_compiled(points, epsilon):  # pragma: no cover - compiled
    """Return :func:`douglas_peucker` for compiled callers: their points are valid already."""
    return lambda points, epsilon: _douglas_peucker(points, np.empty(0, np.int64), epsilon)


def extract_polylines(
    scan: Scan, params: MapperParams | None = None, *, pose: ArrayLike | None = None
) -> PackedPolylines:
    """Extract the polylines of one scan in the sensor frame or a map's (paper Sec. 3.1).

    Invalid readings are removed, then outliers, the remaining beams are split at
    breakpoints into intervals of at least ``params.min_points`` beams, and each interval
    is simplified with Douglas-Peucker at ``params.epsilon``.

    Parameters
    ----------
    scan
        The laser scan; only ranges and beam angles are used (not its pose).
    params
        Extraction thresholds; ``MapperParams()`` when omitted.
    pose
        Sensor pose ``(x, y, theta)`` in a map's frame: the polylines are returned in that
        frame (all vertices moved in one transform). Default: the sensor frame.

    Returns
    -------
    PackedPolylines
        A list of :class:`~semistatic.polyline.Polyline` in scan (counter-clockwise)
        order, with their vertices packed; each polyline's ``scan_indices`` are the beam
        indices of its vertices. Every usable reading of an interval lies within
        ``params.epsilon`` of its polyline. An all-no-return scan gives ``[]``.

    Examples
    --------
    >>> scan = Scan(ranges=[1.0] * 6 + [np.inf] * 3 + [3.0] * 6, angle_min=-0.07,
    ...             angle_increment=0.01)
    >>> [line.scan_indices.tolist() for line in extract_polylines(scan)]
    [[0, 5], [9, 14]]
    >>> extract_polylines(scan, pose=(1.0, 2.0, np.pi / 2))[0].points.round(3)
    array([[1.07 , 2.998],
           [1.02 , 3.   ]])
    """
    params = MapperParams() if params is None else params
    if pose is not None:
        pose = np.asarray(pose, dtype=float).reshape(3)
        # (Three Python floats: numpy's per-call cost would exceed the test itself.)
        if not all(map(math.isfinite, pose.tolist())):
            raise ValueError(f"extract_polylines: pose must be a finite (x, y, theta), got {pose}")
    vertices, beams, bounds = _extracted_vertices(scan, params)
    if pose is not None:
        # All vertices moved in one transform, into a fresh array the polylines can view.
        vertices = transform_points(pose, vertices)
    # (Finite: the readings kept are finite and in range, a fitted vertex falls back to a
    # reading's projection where lines are near parallel or a beam grazes them, and the
    # pose is finite.)
    return PackedPolylines.from_runs(vertices, bounds, beams, check_finite=False)


def _extracted_vertices(
    scan: Scan, params: MapperParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the vertices of :func:`extract_polylines` in one array.

    ``(vertices, beams, bounds)``: ``(K, 2)`` vertices (sensor frame) and ``(K,)`` beam
    indices of all polylines one after the other, polyline ``k`` spanning
    ``bounds[k]:bounds[k + 1]``. Both arrays are fresh, so slices of them can become
    polylines without copies (and the mapper moves all vertices in one transform).
    """
    ranges = scan.ranges
    if params.outlier_removal:
        # remove_outliers on the usable beams; the kernel skips the beams it drops.
        index = np.flatnonzero(remove_invalid(scan, params.max_range))
        ranges = ranges.copy()
        ranges[index[_outliers(ranges[index], params.outlier_k, params.outlier_alpha)]] = np.nan
        ranges.flags.writeable = False  # as the scan's: one compiled signature
    cos, sin = beam_directions(ranges.size, scan.angle_min, scan.angle_increment)
    sines, denominators = _breakpoint_sines(scan.angle_increment, params.breakpoint_lambda)
    vertices, beams, bounds = _extracted(
        ranges, _range_limits(scan.range_min, scan.range_max, params.max_range), cos, sin,
        sines, denominators, params.breakpoint_sigma_r, params.min_points, params.epsilon,
        params.vertex_placement == "fitted",
    )
    return vertices, beams, bounds
