import math

import numpy as np
import pytest
import shapely

from semistatic.extraction import extract_polylines
from semistatic.logs.quality import (
    ExtractionQuality,
    extraction_quality,
    inlier_mask,
    point_polyline_distance,
    summarize_quality,
)
from semistatic.params import MapperParams
from semistatic.polyline import Polyline
from semistatic.types import Scan


def wall_scan(noise=0.0, rng=None, beams=91):
    """A straight wall at x = 2 seen over -45..45 deg."""
    angles = np.radians(np.linspace(-45, 45, beams))
    ranges = 2.0 / np.cos(angles)
    if noise:
        ranges = ranges + rng.normal(0, noise, beams)
    return Scan(ranges=ranges, angle_min=angles[0], angle_increment=angles[1] - angles[0])


@pytest.mark.parametrize("seed", range(4))
def test_point_polyline_distance_matches_shapely(seed):
    rng = np.random.default_rng(seed)
    vertices = rng.uniform(-3, 3, (int(rng.integers(2, 7)), 2))
    points = rng.uniform(-4, 4, (50, 2))
    line = shapely.LineString(vertices)
    expected = shapely.distance(shapely.points(points), line)
    np.testing.assert_allclose(point_polyline_distance(points, vertices), expected, atol=1e-12)


def test_point_polyline_distance_degenerate_polylines():
    np.testing.assert_allclose(point_polyline_distance([[3, 4]], [[0, 0]]), [5.0])
    np.testing.assert_allclose(point_polyline_distance([[1, 1]], [[0, 0], [0, 0], [2, 0]]), [1.0])
    with pytest.raises(ValueError, match="at least one vertex"):
        point_polyline_distance([[0, 0]], np.empty((0, 2)))


def test_polyline_through_every_reading_is_perfect():
    scan = wall_scan(noise=0.01, rng=np.random.default_rng(0))
    every = Polyline(scan.points(), np.arange(len(scan)))
    quality = extraction_quality(scan, [every], epsilon=0.001)
    assert quality.coverage == 1.0
    assert quality.rms_distance == 0.0
    assert quality.vertices == len(scan)


def test_noisy_wall_two_vertices():
    rng = np.random.default_rng(1)
    scan = wall_scan(noise=0.01, rng=rng, beams=2001)
    # The true wall, not a fit: the distance of each reading is its noise along x.
    truth = Polyline([[2.0, -3.0], [2.0, 3.0]], [0, len(scan) - 1])
    quality = extraction_quality(scan, [truth], epsilon=0.01)
    x_error = np.abs(scan.points()[:, 0] - 2.0)
    assert quality.rms_distance == pytest.approx(np.sqrt(np.mean(x_error**2)), rel=1e-9)
    assert quality.covered == np.count_nonzero(x_error <= 0.01)
    # About 68% of Gaussian noise with sigma 1 cm (along the beam) lies within 1 cm.
    assert 0.6 < quality.coverage < 0.8


def test_invalid_and_out_of_span_readings():
    scan = Scan(
        ranges=[1.0, 1.0, np.inf, 1.0, 1.0, 1.0, 9.0], angle_min=-0.03, angle_increment=0.01
    )
    pts = scan.points()
    line = Polyline(pts[[3, 5]], [3, 5])
    quality = extraction_quality(scan, [line], epsilon=0.01, max_range=5.0)
    assert quality.readings == 5  # inf and the 9 m reading beyond max_range are not valid
    assert quality.in_span == 3
    assert quality.covered == 3
    assert quality.coverage == pytest.approx(0.6)


def test_no_polylines_and_no_readings():
    scan = wall_scan()
    empty = extraction_quality(scan, [], epsilon=0.03)
    assert (empty.coverage, empty.in_span, empty.vertices, empty.polylines) == (0.0, 0, 0, 0)
    assert math.isnan(empty.rms_distance)
    blank = Scan(ranges=[np.inf] * 5, angle_min=0.0, angle_increment=0.1)
    assert math.isnan(extraction_quality(blank, [], epsilon=0.03).coverage)


def test_bad_polylines_are_rejected():
    scan = wall_scan()
    with pytest.raises(TypeError, match=r"polylines\[0\] must be a Polyline"):
        extraction_quality(scan, [np.zeros((2, 2))], epsilon=0.03)
    with pytest.raises(ValueError, match=r"spans beams 0\.\.500"):
        extraction_quality(scan, [Polyline([[0, 0], [1, 1]], [0, 500])], epsilon=0.03)
    with pytest.raises(ValueError, match="epsilon must be >= 0"):
        extraction_quality(scan, [], epsilon=-1.0)


def test_paper_pipeline_stays_within_epsilon_on_synthetic_scans():
    rng = np.random.default_rng(2)
    params = MapperParams(epsilon=0.03)
    for _ in range(5):
        scan = wall_scan(noise=0.01, rng=rng)
        quality = extraction_quality(scan, extract_polylines(scan, params), params.epsilon)
        # Douglas-Peucker's guarantee: every reading of an interval within epsilon.
        assert quality.max_distance <= params.epsilon
        assert quality.covered == quality.in_span


def test_summary_pools_readings():
    a = ExtractionQuality(10, 10, 10, 0.0, 0.0, 2, 1)
    b = ExtractionQuality(30, 20, 20, 0.02, 0.05, 6, 3)
    nothing = ExtractionQuality(0, 0, 0, math.nan, math.nan, 0, 0)
    summary = summarize_quality([a, b, nothing])
    assert summary.scans == 3
    assert summary.coverage == pytest.approx(30 / 40)
    assert summary.in_span_fraction == pytest.approx(30 / 40)
    assert summary.rms_distance == pytest.approx(math.sqrt(0.02**2 * 20 / 30))
    assert summary.max_distance == 0.05
    assert summary.vertices_per_scan == pytest.approx(8 / 3)
    with pytest.raises(ValueError, match="no scans"):
        summarize_quality([])


def test_inliers_keep_a_stray_reading_out_of_the_rms():
    ranges = np.full(21, 2.0)
    ranges[10] = 6.0  # a stray reading inside the wall's span
    scan = Scan(ranges=ranges, angle_min=-0.1, angle_increment=0.01)
    wall = Polyline(scan.points()[[0, 20]], [0, 20])
    everything = extraction_quality(scan, [wall], epsilon=0.01)
    assert everything.max_distance > 3.9
    assert everything.covered == 20
    inliers = inlier_mask(scan, MapperParams(outlier_k=4))
    assert not inliers[10]
    robust = extraction_quality(scan, [wall], epsilon=0.01, inliers=inliers)
    assert robust.covered == 20  # coverage still judges every valid reading
    assert robust.readings == 21
    assert robust.in_span == 20
    assert robust.max_distance < 0.01
    with pytest.raises(ValueError, match="inliers has 3 entries"):
        extraction_quality(scan, [wall], epsilon=0.01, inliers=[True, True, False])
