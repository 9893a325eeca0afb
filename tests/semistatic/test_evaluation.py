"""Ray-wise accuracy (semistatic.evaluation) against shapely, and seeded random scenes."""

import math

import numpy as np
import pytest
import shapely

from semistatic.evaluation import (
    EXTRACTORS,
    RayScore,
    at_vertex_count,
    evaluate_scans,
    ray_errors,
    tolerance_sweep,
)
from semistatic.extraction import extract_polylines
from semistatic.params import MapperParams
from semistatic.polyline import Polyline
from semistatic.types import Scan
from tests.semistatic.synthetic import box, cast_scan, raycast, scene, wall

FAR = 100.0


def shapely_errors(scan, polylines):
    """Distance along each ray to the nearest crossing, by GEOS intersections."""
    lines = shapely.MultiLineString([line.points for line in polylines])
    errors = np.full(scan.ranges.size, np.inf)
    for beam, (angle, reading) in enumerate(zip(scan.angles(), scan.ranges, strict=True)):
        if not np.isfinite(reading):
            continue
        ray = shapely.LineString([(0.0, 0.0), (FAR * math.cos(angle), FAR * math.sin(angle))])
        crossing = ray.intersection(lines)
        if crossing.is_empty:
            errors[beam] = np.nan
            continue
        distances = np.hypot(*shapely.get_coordinates(crossing).T)
        errors[beam] = distances.min() - reading
    return errors


@pytest.mark.parametrize("seed", range(10))
def test_ray_errors_match_geos_intersections(seed):
    rng = np.random.default_rng(seed)
    angles = np.radians(np.arange(-90.0, 90.0, 1.0)) + rng.uniform(0.0, 0.01)
    ranges = rng.uniform(0.5, 6.0, angles.size)
    ranges[rng.random(angles.size) < 0.1] = np.inf
    scan = Scan(ranges=ranges, angle_min=angles[0], angle_increment=np.radians(1.0))
    polylines = [Polyline(rng.uniform(-6.0, 6.0, (int(rng.integers(2, 6)), 2))) for _ in range(5)]
    got = ray_errors(scan, polylines)
    expected = shapely_errors(scan, polylines)
    np.testing.assert_array_equal(np.isinf(got), np.isinf(expected))
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
    both = np.isfinite(got)
    assert both.sum() > 20
    np.testing.assert_allclose(got[both], expected[both], atol=1e-9)


def test_ray_errors_edge_cases():
    scan = Scan(ranges=[np.inf, np.nan], angle_min=0.0, angle_increment=0.1)
    assert np.isinf(ray_errors(scan, [])).all()
    scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1)
    assert np.isnan(ray_errors(scan, [])).all()
    assert np.isnan(ray_errors(scan, [Polyline([[1.0, 1.0]])])).all()  # one vertex: no edge
    # a polyline behind the sensor is not crossed
    assert np.isnan(ray_errors(scan, [Polyline([[-1.0, -1.0], [-1.0, 1.0]])])).all()
    # max_range turns far readings into no return
    assert np.isinf(ray_errors(scan, [], max_range=1.5)[1])


def test_evaluate_scans_pools_squared_errors_and_counts():
    angles = np.radians(np.arange(-30.0, 31.0, 1.0))
    flat = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0], angle_increment=np.radians(1.0))
    shifted = [Polyline([[2.03, -2.0], [2.03, 2.0]])]
    score = evaluate_scans([flat, flat, flat], lambda scan: shifted, every=2)
    assert (score.scans, score.rays, score.crossing, score.vertices) == (2, 122, 122, 4)
    # along each ray the error is 0.03 / cos(angle)
    expected = np.sqrt(np.mean(np.square(0.03 / np.cos(angles))))
    assert score.rmse == pytest.approx(expected)
    assert math.isnan(RayScore(0, 0, 0, 0.0, 0, 0).rmse)
    with pytest.raises(ValueError, match="every"):
        evaluate_scans([flat], extract_polylines, every=0)


def test_tolerance_sweep_names_the_methods():
    with pytest.raises(ValueError, match="unknown methods"):
        tolerance_sweep([], MapperParams(), [0.03], methods=["ple"])


@pytest.mark.parametrize("method", ["paper", "default"])
def test_at_vertex_count_finds_the_tolerance_of_a_vertex_budget(method):
    rng = np.random.default_rng(3)
    room = scene(box((0.0, 0.0), 8.0, 6.0), box((1.5, 1.0), 0.6, 0.4, yaw=0.3))
    scans = [cast_scan(room, (0.2 * k, -0.1 * k, 0.1 * k), noise=0.01, rng=rng)
             for k in range(4)]
    params = MapperParams()
    # the budget is what some tolerance gives, so it can be met exactly
    target = evaluate_scans(scans, EXTRACTORS[method](params.replace(epsilon=0.02)))
    epsilon, score = at_vertex_count(scans, params, target.vertices_per_scan, method=method)
    assert score.vertices_per_scan == pytest.approx(target.vertices_per_scan, abs=0.25)
    # the score is that of the tolerance returned, scored again from scratch
    again = evaluate_scans(scans, EXTRACTORS[method](params.replace(epsilon=epsilon)))
    assert again == score


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"vertices_per_scan": 0.0}, "vertices_per_scan"),
     ({"vertices_per_scan": 10.0, "method": "ple"}, "unknown method")],
)
def test_at_vertex_count_rejects_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        at_vertex_count([], MapperParams(), **kwargs)


def random_scene(rng):
    """Boxes, walls with openings, cylinders and thin poles around the origin."""
    parts, objects = [], []
    for _ in range(3):  # walls with an opening
        radius, heading = rng.uniform(4.0, 7.0), rng.uniform(-np.pi, np.pi)
        middle = radius * np.array([np.cos(heading), np.sin(heading)])
        along = np.array([-np.sin(heading), np.cos(heading)])
        gap = rng.uniform(0.3, 1.0)
        for sign in (-1.0, 1.0):
            start = middle + sign * along * gap / 2
            parts.append(wall(tuple(start), tuple(start + sign * along * rng.uniform(1.0, 3.0))))
            objects.append(parts[-1])
    for _ in range(3):  # boxes
        center = rng.uniform(-3.5, 3.5, 2)
        if np.hypot(*center) < 1.0:
            center *= 1.0 / np.hypot(*center)
        parts.append(box(tuple(center), *rng.uniform(0.2, 0.8, 2), yaw=rng.uniform(0, np.pi)))
        objects.append(parts[-1])
    for radius in (rng.uniform(0.1, 0.3), rng.uniform(0.01, 0.03), rng.uniform(0.01, 0.03)):
        center = rng.uniform(-3.5, 3.5, 2)  # a cylinder and two thin poles
        if np.hypot(*center) < 1.0:
            center *= 1.0 / np.hypot(*center)
        ring = np.asarray(shapely.Point(center).buffer(radius, quad_segs=8).exterior.coords)
        parts.append(np.stack((ring[:-1], ring[1:]), axis=1))
        objects.append(parts[-1])
    return scene(*parts), objects


NOISE = 0.01


@pytest.mark.parametrize("seed", range(20))
def test_random_scenes_no_ray_crossed_in_front_and_every_object_represented(seed):
    rng = np.random.default_rng(seed)
    segments, objects = random_scene(rng)
    pose = np.zeros(3)
    scan = cast_scan(segments, pose, noise=NOISE, rng=rng)
    polylines = extract_polylines(scan)
    errors = ray_errors(scan, polylines)
    crossed = np.isfinite(errors)
    # a polyline may sit in front of a reading only by the noise and the fit tolerance
    assert errors[crossed].min() > -(4.0 * NOISE + MapperParams().epsilon)
    # which object each beam hits, by casting at each object alone
    per_object = np.column_stack([raycast(part, pose, scan.angles()) for part in objects])
    nearest = np.where(np.isfinite(per_object.min(axis=1)), per_object.argmin(axis=1), -1)
    for number, part in enumerate(objects):
        hit = nearest == number
        runs = np.diff(np.flatnonzero(np.diff(np.concatenate(([0], hit.astype(int), [0])))))
        if not (runs[::2] >= 2).any():  # no two consecutive beams on it
            continue
        shape = shapely.MultiLineString(list(part))
        near = [line for line in polylines
                if shapely.distance(shapely.LineString(line.points), shape) < 4 * NOISE]
        assert near, f"object {number} (hit by {int(hit.sum())} beams) has no polyline"

