"""Ray-wise extraction accuracy, the metric of PLE (Schaefer et al., IROS 2018).

For each returned reading of a scan, follow its own ray from the sensor to the first
polyline it crosses: the signed distance along the ray from the reading to that crossing
is the reading's error. A polyline that crosses a ray far in front of its reading (a
surface invented across a gap the laser saw through) costs as much as it should.

RMSE
    Root mean square error over the rays that cross a polyline.
coverage f
    The share of returned rays that cross a polyline.
vertices per scan
    What the map stores; accuracy is compared at equal vertex counts.

:func:`ray_errors` scores one scan, :func:`evaluate_scans` pools a log, and
:func:`tolerance_sweep` traces RMSE against vertices per scan for several extractors
(:data:`EXTRACTORS`: the paper's pipeline, the default, split-and-merge), and
:func:`at_vertex_count` scores one of them at a given vertex count.

Examples
--------
>>> angles = np.radians(np.arange(-10.0, 11.0, 1.0))
>>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0],
...             angle_increment=np.radians(1.0))
>>> errors = ray_errors(scan, [Polyline([[2.01, -1.0], [2.01, 1.0]])])
>>> bool(np.isfinite(errors).all()), round(float(errors[10]), 4)  # the straight-ahead ray
(True, 0.01)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from semistatic.baseline import extract_split_and_merge
from semistatic.extraction import extract_polylines, remove_invalid
from semistatic.params import MapperParams
from semistatic.polyline import Polyline
from semistatic.types import Scan, beam_directions

__all__ = [
    "EXTRACTORS",
    "RayScore",
    "at_vertex_count",
    "evaluate_scans",
    "paper_params",
    "ray_errors",
    "tolerance_sweep",
]

# A crossing exactly at a segment's end (a vertex on a reading's beam) must count: the
# segment parameter may round a few ulps outside [0, 1].
END_SLACK = 1e-9


def ray_errors(scan: Scan, polylines: Sequence[Polyline], max_range: float = math.inf
               ) -> np.ndarray:
    """Return, per beam, the distance along its ray from its reading to the first crossing.

    Parameters
    ----------
    scan
        The scan (sensor frame: rays start at the origin).
    polylines
        Polylines in the same sensor frame.
    max_range
        Readings beyond this (m) count as no return, as in extraction.

    Returns
    -------
    numpy.ndarray
        ``(N,)`` float: ``crossing distance - range`` (negative: the polyline lies in front
        of the reading) for returned readings whose ray crosses a polyline; ``nan`` for
        rays that cross none; ``inf`` for beams without a usable return.

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, 1.0, np.inf], angle_min=-0.01, angle_increment=0.01)
    >>> ray_errors(scan, [Polyline([[0.9, -1.0], [0.9, 0.0]])]).round(3)
    array([-0.1, -0.1,  inf])
    """
    count = scan.ranges.size
    errors = np.full(count, np.inf)
    valid = remove_invalid(scan, max_range)
    if not valid.any():
        return errors
    errors[valid] = np.nan
    segments = [np.asarray(line.points, dtype=float) for line in polylines if len(line) >= 2]
    if not segments:
        return errors
    starts = np.concatenate([points[:-1] for points in segments])
    edges = np.concatenate([np.diff(points, axis=0) for points in segments])
    cos, sin = beam_directions(count, scan.angle_min, scan.angle_increment)
    index = np.flatnonzero(valid)
    ux, uy = cos[index][:, None], sin[index][:, None]
    # Ray t u meets segment a + s e where t = cross(a, e) / cross(u, e) and
    # s = cross(a, u) / cross(u, e).
    with np.errstate(divide="ignore", invalid="ignore"):
        denominator = ux * edges[:, 1] - uy * edges[:, 0]
        t = (starts[:, 0] * edges[:, 1] - starts[:, 1] * edges[:, 0]) / denominator
        s = (starts[:, 0] * uy - starts[:, 1] * ux) / denominator
    hit = (denominator != 0.0) & (s >= -END_SLACK) & (s <= 1.0 + END_SLACK) & (t > 0.0)
    first = np.where(hit, t, np.inf).min(axis=1)
    crossed = np.isfinite(first)
    errors[index[crossed]] = first[crossed] - scan.ranges[index[crossed]]
    return errors


@dataclass(frozen=True)
class RayScore:
    """Ray-wise accuracy pooled over scans (see the module docstring).

    Attributes
    ----------
    scans
        Scans scored.
    rays
        Returned rays (usable readings).
    crossing
        Rays that cross a polyline.
    squared_error
        Sum of squared errors (m^2) over the crossing rays.
    vertices, polylines
        Totals over the scans.

    Examples
    --------
    >>> score = RayScore(scans=2, rays=100, crossing=98, squared_error=0.0098,
    ...                  vertices=40, polylines=10)
    >>> round(score.rmse, 3), score.coverage, score.vertices_per_scan
    (0.01, 0.98, 20.0)
    """

    scans: int
    rays: int
    crossing: int
    squared_error: float
    vertices: int
    polylines: int

    @property
    def rmse(self) -> float:
        """Return the RMSE (m) over the crossing rays (``nan`` when none cross)."""
        return math.sqrt(self.squared_error / self.crossing) if self.crossing else math.nan

    @property
    def coverage(self) -> float:
        """Return the share of returned rays that cross a polyline (``nan`` for none)."""
        return self.crossing / self.rays if self.rays else math.nan

    @property
    def vertices_per_scan(self) -> float:
        """Return the mean vertex count per scan (``nan`` for no scans)."""
        return self.vertices / self.scans if self.scans else math.nan


def evaluate_scans(
    scans: Iterable[Scan],
    extract: Callable[[Scan], Sequence[Polyline]],
    *,
    every: int = 1,
    max_range: float = math.inf,
) -> RayScore:
    """Return the pooled :class:`RayScore` of ``extract`` over every ``every``-th scan.

    Parameters
    ----------
    scans
        Scans (e.g. a CARMEN log from :func:`semistatic.logs.read_carmen`).
    extract
        Returns the polylines of a scan in its sensor frame.
    every
        Score one scan in ``every`` (the first, then every ``every``-th).
    max_range
        Readings beyond this (m) are not scored; give the extractor's ``max_range``.

    Examples
    --------
    >>> angles = np.radians(np.arange(-45.0, 46.0, 1.0))
    >>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0],
    ...             angle_increment=np.radians(1.0))
    >>> score = evaluate_scans([scan, scan], extract_polylines)
    >>> score.scans, score.coverage, score.vertices_per_scan, round(score.rmse, 9)
    (2, 1.0, 2.0, 0.0)
    """
    if not (isinstance(every, int) and every >= 1):
        raise ValueError(f"evaluate_scans: every must be an integer >= 1, got {every!r}")
    count = rays = crossing = vertices = polylines = 0
    squared = 0.0
    for number, scan in enumerate(scans):
        if number % every:
            continue
        lines = extract(scan)
        errors = ray_errors(scan, lines, max_range)
        returned = ~np.isinf(errors)
        crossed = errors[returned & ~np.isnan(errors)]
        count += 1
        rays += int(returned.sum())
        crossing += crossed.size
        squared += float(crossed @ crossed)
        vertices += sum(len(line) for line in lines)
        polylines += len(lines)
    return RayScore(count, rays, crossing, squared, vertices, polylines)


def paper_params(params: MapperParams) -> MapperParams:
    """Return ``params`` with the paper's extraction: outlier removal, 5 points, raw vertices.

    Examples
    --------
    >>> paper = paper_params(MapperParams())
    >>> paper.outlier_removal, paper.min_points, paper.vertex_placement
    (True, 5, 'raw')
    """
    return params.replace(outlier_removal=True, min_points=5, vertex_placement="raw")


def _default(params: MapperParams) -> Callable[[Scan], list[Polyline]]:
    return lambda scan: extract_polylines(scan, params)


def _paper(params: MapperParams) -> Callable[[Scan], list[Polyline]]:
    return _default(paper_params(params))


def _split_and_merge(params: MapperParams) -> Callable[[Scan], list[Polyline]]:
    return lambda scan: extract_split_and_merge(scan, params)


EXTRACTORS: dict[str, Callable[[MapperParams], Callable[[Scan], list[Polyline]]]] = {
    "paper": _paper,
    "default": _default,
    "split-and-merge": _split_and_merge,
}
"""Extractors compared by :func:`tolerance_sweep`, each built from ``MapperParams``:
``paper`` (outlier removal, 5-point intervals, raw Douglas-Peucker vertices), ``default``
(``extract_polylines`` as configured) and ``split-and-merge`` (the baseline, same
intervals as ``default``)."""


def tolerance_sweep(
    scans: Sequence[Scan],
    params: MapperParams,
    epsilons: Sequence[float],
    *,
    methods: Sequence[str] = tuple(EXTRACTORS),
    every: int = 1,
) -> dict[str, list[tuple[float, RayScore]]]:
    """Return, per method, the :class:`RayScore` at each tolerance of ``epsilons``.

    Parameters
    ----------
    scans
        The scans (a sequence: it is traversed once per method and tolerance).
    params
        Base thresholds; each point replaces ``epsilon``.
    epsilons
        Tolerances (m), each ``> 0``.
    methods
        Names in :data:`EXTRACTORS`.
    every
        Score one scan in ``every``.

    Examples
    --------
    >>> angles = np.radians(np.arange(-45.0, 46.0, 1.0))
    >>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0],
    ...             angle_increment=np.radians(1.0))
    >>> curve = tolerance_sweep([scan], MapperParams(), [0.01, 0.03], methods=["default"])
    >>> [(epsilon, score.vertices_per_scan) for epsilon, score in curve["default"]]
    [(0.01, 2.0), (0.03, 2.0)]
    """
    unknown = [name for name in methods if name not in EXTRACTORS]
    if unknown:
        raise ValueError(
            f"tolerance_sweep: unknown methods {unknown}; choose from {list(EXTRACTORS)}"
        )
    return {
        name: [
            (
                epsilon,
                evaluate_scans(
                    scans, EXTRACTORS[name](params.replace(epsilon=epsilon)),
                    every=every, max_range=params.max_range,
                ),
            )
            for epsilon in epsilons
        ]
        for name in methods
    }


# Bisection of the tolerance in :func:`at_vertex_count`: vertex counts are whole numbers per
# scan, so a few dozen halvings of a log-scale bracket pin the count as well as it can be.
VERTEX_MATCH_STEPS = 24
VERTEX_MATCH_BRACKET = (1e-4, 1.0)


def at_vertex_count(
    scans: Sequence[Scan],
    params: MapperParams,
    vertices_per_scan: float,
    *,
    method: str = "paper",
    every: int = 1,
) -> tuple[float, RayScore]:
    """Return the tolerance at which ``method`` stores ``vertices_per_scan``, and its score.

    Accuracy is only comparable at equal vertex counts (a tighter tolerance buys accuracy
    with vertices): this bisects the Douglas-Peucker tolerance, on a log scale within
    ``VERTEX_MATCH_BRACKET`` (m), until the method's mean vertex count is closest to
    ``vertices_per_scan``.

    Parameters
    ----------
    scans
        The scans (a sequence, traversed once per step).
    params
        Base thresholds; each step replaces ``epsilon``.
    vertices_per_scan
        The vertex count to match, ``> 0``.
    method
        A name in :data:`EXTRACTORS`.
    every
        Score one scan in ``every``.

    Examples
    --------
    >>> angles = np.radians(np.arange(-60.0, 61.0, 1.0))
    >>> scan = Scan(ranges=2.0 / np.cos(angles) + 0.02 * np.sin(7 * angles),
    ...             angle_min=angles[0], angle_increment=np.radians(1.0))
    >>> epsilon, score = at_vertex_count([scan], MapperParams(), 6.0, method="default")
    >>> score.vertices_per_scan
    6.0
    """
    if method not in EXTRACTORS:
        raise ValueError(
            f"at_vertex_count: unknown method {method!r}; choose from {list(EXTRACTORS)}"
        )
    if not vertices_per_scan > 0.0:
        raise ValueError(
            f"at_vertex_count: vertices_per_scan must be > 0, got {vertices_per_scan!r}"
        )

    def score(epsilon: float) -> RayScore:
        return evaluate_scans(scans, EXTRACTORS[method](params.replace(epsilon=epsilon)),
                              every=every, max_range=params.max_range)

    low, high = (math.log(bound) for bound in VERTEX_MATCH_BRACKET)
    best: tuple[float, float, RayScore] | None = None
    for _ in range(VERTEX_MATCH_STEPS):
        middle = 0.5 * (low + high)
        result = score(math.exp(middle))
        miss = abs(result.vertices_per_scan - vertices_per_scan)
        if best is None or miss < best[0]:
            best = (miss, math.exp(middle), result)
        # More vertices than wanted: the tolerance must grow.
        if result.vertices_per_scan > vertices_per_scan:
            low = middle
        else:
            high = middle
    assert best is not None  # VERTEX_MATCH_STEPS > 0
    return best[1], best[2]
