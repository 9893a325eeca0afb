"""Speed of polyline extraction (per stage) and of the two polyline metrics.

One 541-beam scan (270 deg at 0.5 deg, 1 cm range noise) of a room with a box and a
pillar. Prints the median time per stage of ``extract_polylines``, the ratio of
``douglas_peucker`` to ``shapely.simplify`` on the same points, and the median time of
``similarity`` / ``restricted_hausdorff`` on pairs of polylines of the same objects seen
in two scans. Run with
``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_extraction.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from benchmarks.timing import median_us as timed_median_us
from semistatic.evaluation import paper_params
from semistatic.extraction import (
    douglas_peucker,
    extract_polylines,
    remove_invalid,
    remove_outliers,
    split_breakpoints,
)
from semistatic.hausdorff import hausdorff, restricted_hausdorff
from semistatic.params import MapperParams
from semistatic.polyline import Polyline
from semistatic.similarity import similarity
from tests.semistatic.conftest import room_scan

pytestmark = pytest.mark.bench

REPEATS = 400


def median_us(run, repeats=REPEATS):
    """Return the median time of ``run()`` in microseconds (see ``benchmarks.timing``)."""
    return timed_median_us(run, repeats)


def test_extraction_stages():
    params = MapperParams()
    scan = room_scan(np.random.default_rng(0))
    valid = remove_invalid(scan, params.max_range)
    kept = remove_outliers(scan.ranges, valid, params.outlier_k, params.outlier_alpha)
    intervals = split_breakpoints(
        scan, kept, params.breakpoint_lambda, params.breakpoint_sigma_r, params.min_points
    )
    beams = np.concatenate(intervals)
    line_ids = np.repeat(np.arange(len(intervals)), [interval.size for interval in intervals])
    points = scan.points()[beams]
    stages = {
        "remove_invalid": lambda: remove_invalid(scan, params.max_range),
        "remove_outliers": lambda: remove_outliers(
            scan.ranges, valid, params.outlier_k, params.outlier_alpha
        ),
        "split_breakpoints": lambda: split_breakpoints(
            scan, kept, params.breakpoint_lambda, params.breakpoint_sigma_r, params.min_points
        ),
        "douglas_peucker (each interval)": lambda: [
            douglas_peucker(points[line_ids == line], params.epsilon)
            for line in range(len(intervals))
        ],
        "extract_polylines (total)": lambda: extract_polylines(scan, params),
    }
    lines = extract_polylines(scan, params)
    print(
        f"\n541-beam scan: {len(intervals)} intervals, {beams.size} points, "
        f"{sum(len(line) for line in lines)} vertices"
    )
    for name, run in stages.items():
        print(f"  {name:34s} {median_us(run):8.1f} us median")


def test_douglas_peucker_vs_shapely():
    params = MapperParams()
    scan = room_scan(np.random.default_rng(0))
    points = scan.points()[remove_invalid(scan)]
    intervals = extract_polylines(scan, params)
    ours = median_us(lambda: douglas_peucker(points, params.epsilon))
    theirs = median_us(
        lambda: shapely.get_coordinates(
            shapely.simplify(shapely.LineString(points), params.epsilon, preserve_topology=False)
        )
    )
    print(
        f"\nwhole scan as one line ({len(points)} points): douglas_peucker {ours:.1f} us, "
        f"shapely.simplify {theirs:.1f} us, ratio {ours / theirs:.2f}"
    )
    # Per interval, as the extraction needs it (it runs them all in one compiled pass).
    valid = remove_outliers(
        scan.ranges, remove_invalid(scan), params.outlier_k, params.outlier_alpha
    )
    split = split_breakpoints(
        scan, valid, params.breakpoint_lambda, params.breakpoint_sigma_r, params.min_points
    )
    stacked = scan.points()[np.concatenate(split)]
    line_ids = np.repeat(np.arange(len(split)), [interval.size for interval in split])
    ends = np.flatnonzero(np.diff(line_ids))
    runs = np.split(stacked, ends + 1)
    ours = median_us(lambda: [douglas_peucker(run, params.epsilon) for run in runs])
    theirs = median_us(
        lambda: shapely.get_coordinates(
            shapely.simplify(
                shapely.linestrings(stacked, indices=line_ids),
                params.epsilon,
                preserve_topology=False,
            )
        )
    )
    print(
        f"{len(intervals)} intervals: douglas_peucker on each {ours:.1f} us, "
        f"bare shapely.simplify {theirs:.1f} us, ratio {ours / theirs:.2f}"
    )


def _object_pairs():
    """Polylines of the same objects extracted from two noisy scans of the room."""
    first = extract_polylines(room_scan(np.random.default_rng(1)))
    second = extract_polylines(room_scan(np.random.default_rng(2)))
    return list(zip(first, second, strict=True))


def test_metric_speed():
    pairs = _object_pairs()
    sizes = [(len(a), len(b)) for a, b in pairs]
    print(f"\npairs of vertex counts: {sizes}")
    for name, metric in (
        ("similarity", similarity),
        ("hausdorff", hausdorff),
        ("restricted_hausdorff vertex", restricted_hausdorff),
        (
            "restricted_hausdorff projection",
            lambda a, b: restricted_hausdorff(a, b, mode="projection"),
        ),
    ):
        warm = [
            median_us(lambda a=a, b=b, metric=metric: metric(a, b), repeats=200) for a, b in pairs
        ]
        print(
            f"  {name:32s} median over pairs {np.median(warm):7.1f} us "
            f"(min {min(warm):.1f}, max {max(warm):.1f})"
        )
    # Cold similarity: new Polyline objects, so no cached tangent function.
    cold = [
        median_us(lambda a=a, b=b: similarity(Polyline(a.points), Polyline(b.points)), repeats=200)
        for a, b in pairs
    ]
    print(f"  {'similarity (no cache)':32s} median over pairs {np.median(cold):7.1f} us")


EXTRACTION_BUDGET_MS = 0.3


def test_default_extraction_of_a_541_beam_scan_within_budget():
    # default (fitted vertices, numba kernel) against the paper's pipeline on the same scan
    scan = room_scan(np.random.default_rng(0))
    default, paper = MapperParams(), paper_params(MapperParams())
    extract_polylines(scan, default)  # compile / load the cached kernel
    default_us = median_us(lambda: extract_polylines(scan, default), 2000)
    paper_us = median_us(lambda: extract_polylines(scan, paper), 2000)
    print(f"\nextract_polylines, 541 beams: default {default_us:.0f} us, paper {paper_us:.0f} us")
    assert default_us <= EXTRACTION_BUDGET_MS * 1000.0
