"""How well the polylines of a scan describe its readings: coverage, RMS, vertex count.

Used to judge an extractor on real logs, the paper pipeline
(:func:`semistatic.extraction.extract_polylines`) against the split-and-merge baseline
(:func:`semistatic.baseline.extract_split_and_merge`) alike. For one scan and its
polylines (sensor frame, with beam indices):

coverage
    The fraction of the scan's valid readings that lie inside a polyline's beam span
    (between the beam indices of its first and last vertex) **and** within ``epsilon``
    of that polyline. Readings dropped as outliers or in too short intervals count as
    not covered, so coverage also shows what an extractor throws away.
RMS distance
    The root mean square distance of the readings inside some polyline's beam span to
    that polyline (as a curve, point-to-segment): how far the simplification moves the
    surface. Pass ``inliers`` (e.g. :func:`inlier_mask`, the readings that survive the
    pipeline's outlier removal) to keep a single stray reading of several metres from
    dominating it.
vertices
    Vertices (and polylines) per scan: what the map has to store and associate.

Examples
--------
>>> from semistatic.polyline import Polyline
>>> scan = Scan(ranges=[1.0, 1.0, 1.02, 1.0, np.inf], angle_min=-0.02, angle_increment=0.01)
>>> wall = Polyline(scan.points()[[0, 3]], scan_indices=[0, 3])
>>> quality = extraction_quality(scan, [wall], epsilon=0.01)
>>> quality.covered, quality.readings, quality.vertices
(3, 4, 2)
>>> round(quality.rms_distance, 4)
0.01
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from semistatic.extraction import remove_invalid, remove_outliers
from semistatic.params import MapperParams
from semistatic.polyline import Polyline
from semistatic.types import Scan

__all__ = [
    "ExtractionQuality",
    "QualitySummary",
    "extraction_quality",
    "inlier_mask",
    "point_polyline_distance",
    "summarize_quality",
]

# Squared segment lengths below this (m^2) are treated as points (duplicate vertices).
DEGENERATE_SEGMENT_SQUARED = 1e-24


@dataclass(frozen=True)
class ExtractionQuality:
    """Extraction quality of one scan; see the module docstring for the definitions.

    Attributes
    ----------
    readings
        Valid readings of the scan (finite, within range limits and ``max_range``).
    covered
        Valid readings inside a polyline's beam span and within ``epsilon`` of it.
    in_span
        Valid readings inside some polyline's beam span (and among ``inliers`` when
        given).
    rms_distance, max_distance
        RMS and largest distance (m) of the ``in_span`` readings to their polyline
        (``nan`` when ``in_span`` is 0).
    vertices, polylines
        Total vertex count and number of polylines.

    Examples
    --------
    >>> ExtractionQuality(readings=10, covered=9, in_span=10, rms_distance=0.01,
    ...                   max_distance=0.04, vertices=4, polylines=2).coverage
    0.9
    """

    readings: int
    covered: int
    in_span: int
    rms_distance: float
    max_distance: float
    vertices: int
    polylines: int

    @property
    def coverage(self) -> float:
        """Return ``covered / readings`` (``nan`` for a scan without valid readings)."""
        return self.covered / self.readings if self.readings else math.nan


@dataclass(frozen=True)
class QualitySummary:
    """Extraction quality pooled over many scans.

    Attributes
    ----------
    scans
        Number of scans.
    coverage
        Covered readings over valid readings, all scans pooled.
    in_span_fraction
        In-span readings over valid readings, all scans pooled: the rest fell in
        intervals the extractor dropped (too short, outliers, no polyline).
    rms_distance
        RMS distance over all in-span readings of all scans.
    max_distance
        Largest in-span distance of any scan.
    vertices_per_scan, polylines_per_scan
        Means over the scans.

    Examples
    --------
    >>> one = ExtractionQuality(10, 9, 10, 0.01, 0.02, 4, 2)
    >>> summarize_quality([one, one]).vertices_per_scan
    4.0
    """

    scans: int
    coverage: float
    in_span_fraction: float
    rms_distance: float
    max_distance: float
    vertices_per_scan: float
    polylines_per_scan: float


def point_polyline_distance(points: ArrayLike, vertices: ArrayLike) -> np.ndarray:
    """Return the distance of each point to a polyline taken as a curve.

    Parameters
    ----------
    points
        ``(M, 2)`` query points.
    vertices
        ``(N, 2)`` polyline vertices, ``N >= 1`` (one vertex: distance to that point).

    Returns
    -------
    numpy.ndarray
        ``(M,)`` point-to-segment distances, minimised over the segments.

    Examples
    --------
    >>> point_polyline_distance([[1.0, 1.0], [3.0, 0.0], [-1.0, 0.0]], [[0, 0], [2, 0]])
    array([1., 1., 1.])
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    vertices = np.asarray(vertices, dtype=float).reshape(-1, 2)
    if len(vertices) == 0:
        raise ValueError("point_polyline_distance: the polyline needs at least one vertex")
    if len(vertices) == 1:
        return np.hypot(*(points - vertices[0]).T)
    start = vertices[:-1]  # (K, 2)
    direction = vertices[1:] - start
    length_squared = np.einsum("ij,ij->i", direction, direction)
    safe = np.where(length_squared < DEGENERATE_SEGMENT_SQUARED, 1.0, length_squared)
    offset = points[:, None, :] - start[None, :, :]  # (M, K, 2)
    along = np.einsum("mkj,kj->mk", offset, direction) / safe
    along = np.where(length_squared < DEGENERATE_SEGMENT_SQUARED, 0.0, np.clip(along, 0, 1))
    nearest = start[None, :, :] + along[..., None] * direction[None, :, :]
    distance = np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1))
    return distance.min(axis=1)


def extraction_quality(
    scan: Scan,
    polylines: Sequence[Polyline],
    epsilon: float,
    *,
    max_range: float = math.inf,
    inliers: ArrayLike | None = None,
) -> ExtractionQuality:
    """Measure how well ``polylines`` (sensor frame) describe the readings of ``scan``.

    Parameters
    ----------
    scan
        The laser scan the polylines were extracted from.
    polylines
        :class:`~semistatic.polyline.Polyline` objects in the scan's sensor frame whose
        ``scan_indices`` are beam indices of ``scan``.
    epsilon
        A reading within this distance (m) of its polyline counts as covered.
    max_range
        Readings beyond this (m) are not valid (as ``MapperParams.max_range``).
    inliers
        Optional ``(N,)`` boolean mask: only these readings enter ``in_span``, the RMS
        and the maximum distance (coverage still counts every valid reading).

    Returns
    -------
    ExtractionQuality

    Examples
    --------
    >>> scan = Scan(ranges=[2.0, 2.0], angle_min=0.0, angle_increment=0.1)
    >>> extraction_quality(scan, [], epsilon=0.03).coverage
    0.0
    """
    if not epsilon >= 0:
        raise ValueError(f"extraction_quality: epsilon must be >= 0 m, got {epsilon!r}")
    valid = remove_invalid(scan, max_range)
    points = scan.points()
    best = np.full(len(scan), np.inf)
    vertices = 0
    for number, line in enumerate(polylines):
        if not isinstance(line, Polyline):
            raise TypeError(
                f"extraction_quality: polylines[{number}] must be a Polyline (its beam "
                f"indices give its span), got {type(line).__name__}"
            )
        vertices += len(line)
        if len(line) == 0:
            continue
        first, last = int(line.scan_indices[0]), int(line.scan_indices[-1])
        if not 0 <= min(first, last) <= max(first, last) < len(scan):
            raise ValueError(
                f"extraction_quality: polylines[{number}] spans beams {first}..{last} but "
                f"the scan has {len(scan)}; pass polylines extracted from this scan"
            )
        span = np.arange(min(first, last), max(first, last) + 1)
        span = span[valid[span]]
        distance = point_polyline_distance(points[span], line.points)
        best[span] = np.minimum(best[span], distance)
    in_span = valid & np.isfinite(best)
    covered = int(np.count_nonzero(best[in_span] <= epsilon))
    if inliers is not None:
        inliers = np.asarray(inliers, dtype=bool).reshape(-1)
        if inliers.shape != valid.shape:
            raise ValueError(
                f"extraction_quality: inliers has {inliers.size} entries but the scan has "
                f"{valid.size} beams"
            )
        in_span &= inliers
    distances = best[in_span]
    return ExtractionQuality(
        readings=int(valid.sum()),
        covered=covered,
        in_span=int(distances.size),
        rms_distance=float(np.sqrt(np.mean(distances**2))) if distances.size else math.nan,
        max_distance=float(distances.max()) if distances.size else math.nan,
        vertices=vertices,
        polylines=len(polylines),
    )


def inlier_mask(scan: Scan, params: MapperParams | None = None) -> np.ndarray:
    """Return the readings the paper pipeline keeps: valid and not outliers.

    The same two steps start both :func:`~semistatic.extraction.extract_polylines` and
    the split-and-merge baseline, so the mask suits either as ``inliers``.

    Examples
    --------
    >>> scan = Scan(ranges=[2.0] * 4 + [6.0] + [2.0] * 4 + [np.inf], angle_min=0.0,
    ...             angle_increment=0.01)
    >>> inlier_mask(scan, MapperParams(outlier_k=4)).astype(int)
    array([1, 1, 1, 1, 0, 1, 1, 1, 1, 0])
    """
    params = MapperParams() if params is None else params
    valid = remove_invalid(scan, params.max_range)
    return remove_outliers(scan.ranges, valid, params.outlier_k, params.outlier_alpha)


def summarize_quality(qualities: Iterable[ExtractionQuality]) -> QualitySummary:
    """Pool per-scan qualities: coverage and RMS over all readings, means per scan.

    Examples
    --------
    >>> a = ExtractionQuality(10, 10, 10, 0.0, 0.0, 2, 1)
    >>> b = ExtractionQuality(30, 20, 30, 0.02, 0.05, 6, 3)
    >>> summary = summarize_quality([a, b])
    >>> summary.coverage, round(summary.rms_distance, 5), summary.polylines_per_scan
    (0.75, 0.01732, 2.0)
    """
    qualities = list(qualities)
    if not qualities:
        raise ValueError("summarize_quality: no scans to summarise")
    readings = sum(q.readings for q in qualities)
    in_span = sum(q.in_span for q in qualities)
    squared = sum(q.rms_distance**2 * q.in_span for q in qualities if q.in_span)
    maxima = [q.max_distance for q in qualities if q.in_span]
    return QualitySummary(
        scans=len(qualities),
        coverage=sum(q.covered for q in qualities) / readings if readings else math.nan,
        in_span_fraction=in_span / readings if readings else math.nan,
        rms_distance=math.sqrt(squared / in_span) if in_span else math.nan,
        max_distance=max(maxima) if maxima else math.nan,
        vertices_per_scan=sum(q.vertices for q in qualities) / len(qualities),
        polylines_per_scan=sum(q.polylines for q in qualities) / len(qualities),
    )
