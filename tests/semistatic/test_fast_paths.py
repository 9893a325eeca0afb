"""The mapper's shortcuts and compiled kernels give what their slow references give.

The compiled Douglas-Peucker (extraction and merge alike) is checked against GEOS on
seeded random inputs, and the whole mapper against itself with the association's
shortcut past the similarities (when the gate alone fixes the optimal path) switched off.
(``hausdorff``, ``similarity``, ``association`` and ``visibility`` have one compiled
implementation each, tested against their references in their own test modules.)
"""

from __future__ import annotations

import dataclasses
import importlib
import itertools
import math

import numpy as np
import pytest
import shapely

from semistatic.association import FAR_COST, _optimal_path
from semistatic.extraction import douglas_peucker
from semistatic.local_map import LocalMap
from semistatic.mapper import MapPolyline, PolylineMap, _replaced
from semistatic.polyline import EMPTY_BOX, Polyline, pack_vertices
from semistatic.similarity import similarity
from semistatic.types import Scan
from semistatic.visibility import extend_ends
from tests.semistatic.conftest import NASTY_POLYLINES
from tests.semistatic.synthetic import box, cast_scan, scene, wall

# The package re-exports functions named like these modules: import the modules by name.
merge_module = importlib.import_module("semistatic.merge")
extraction_module = importlib.import_module("semistatic.extraction")
association_module = importlib.import_module("semistatic.association")

# Both paths run the same arithmetic in a different order (numpy's complex abs, its dot
# product's summation): results agree to rounding.
ROUNDING = 1e-12


def _random_polyline(rng, count, spread=1.0):
    """A random walk of ``count`` vertices; every fourth one on a 0.1 grid (exact ties)."""
    points = np.cumsum(rng.normal(0.0, spread, (count, 2)), axis=0)
    return points.round(1) if rng.integers(4) == 0 else points


@pytest.mark.parametrize("seed", range(150))
def test_compiled_douglas_peucker_keeps_what_geos_keeps(seed):
    rng = np.random.default_rng(seed)
    count = int(rng.integers(1, 40))
    points = np.cumsum(rng.normal(0.0, rng.uniform(0.005, 0.5), (count, 2)), axis=0)
    if seed % 3 == 0:
        points = points.round(1)  # exact ties, repeated and collinear points
    epsilon = float(rng.choice([0.0, 0.03, 0.1, 0.3]))
    kept = douglas_peucker(points, epsilon)
    geometry = shapely.Point(points[0]) if count == 1 else shapely.LineString(points)
    expected = shapely.get_coordinates(shapely.simplify(geometry, epsilon, preserve_topology=False))
    np.testing.assert_array_equal(points[kept], expected)


@pytest.mark.parametrize("name", sorted(NASTY_POLYLINES))
def test_distinct_drops_exactly_the_consecutive_repeats(name):
    points = NASTY_POLYLINES[name]
    expected = [row for k, row in enumerate(points.tolist())
                if k == 0 or math.dist(row, points[k - 1]) > merge_module.DUPLICATE_DISTANCE]
    np.testing.assert_array_equal(
        merge_module._distinct(points), np.array(expected).reshape(-1, 2)
    )


def _reference_optimal_path(costs):
    """The DTW recursion of eq. (5) written out cell by cell (the original loop)."""
    n, m = costs.shape
    total = np.zeros((n, m))
    step = np.zeros((n, m), dtype=int)
    for i in range(n):
        for j in range(m):
            if i == 0 and j == 0:
                best, move = 0.0, 0
            elif i == 0:
                best, move = total[i, j - 1], 2
            elif j == 0:
                best, move = total[i - 1, j], 1
            else:
                best, move = total[i - 1, j - 1], 0
                if total[i - 1, j] < best:
                    best, move = total[i - 1, j], 1
                if total[i, j - 1] < best:
                    best, move = total[i, j - 1], 2
            total[i, j] = best + costs[i, j]
            step[i, j] = move
    path, i, j = [], n - 1, m - 1
    while True:
        path.append((i, j))
        if i == 0 and j == 0:
            return path[::-1]
        i, j = {0: (i - 1, j - 1), 1: (i - 1, j), 2: (i, j - 1)}[int(step[i, j])]


@pytest.mark.parametrize("seed", range(60))
def test_optimal_path_equals_the_cell_by_cell_recursion(seed):
    rng = np.random.default_rng(seed)
    shape = tuple(int(k) for k in rng.integers(1, 9, 2))
    costs = rng.integers(0, 3, shape).astype(float)  # many exact ties
    costs[rng.uniform(size=shape) < 0.4] = FAR_COST
    assert _optimal_path(costs) == _reference_optimal_path(costs)


def test_replaced_entry_equals_dataclasses_replace():
    entry = MapPolyline(4, Polyline([[0.0, 0.0], [1.0, 0.0]]), "new", 2, 1, 0.5, 0.7)
    changes = {"status": "confirmed", "hits": 3, "misses": 0, "last_seen": 1.5}
    assert _replaced(entry, **changes) == dataclasses.replace(entry, **changes)
    assert entry.status == "new"  # the original is untouched


def _hall():
    """A few boxes and walls around the origin."""
    parts = [wall((3.0, -1.0), (3.0, 1.0)), wall((-1.0, 2.5), (1.5, 2.5))]
    parts += [box((1.5, -2.0), 0.5, 0.3, yaw=0.3), box((-2.0, -1.0), 0.4, 0.4, yaw=1.0)]
    return scene(*parts)


def _run(scans, poses):
    mapper = PolylineMap()
    reports = [mapper.update(scan, pose) for scan, pose in zip(scans, poses, strict=True)]
    return mapper, reports


def test_mapper_without_the_forced_association_path_gives_the_same_map(monkeypatch):
    rng = np.random.default_rng(11)
    poses = [rng.uniform([-0.1, -0.1, -0.05], [0.1, 0.1, 0.05]) for _ in range(12)]
    world = _hall()
    scans = [
        cast_scan(world, pose, noise=0.01, rng=rng, stamp=0.1 * k) for k, pose in enumerate(poses)
    ]
    fast_map, fast_reports = _run(scans, poses)
    assert sum(len(report.associated) for report in fast_reports) >= 3 * len(scans[1:])
    monkeypatch.setattr(association_module, "_FORCED_PATHS", False)
    slow_map, slow_reports = _run(scans, poses)
    for fast, slow in zip(fast_reports, slow_reports, strict=True):
        assert [(a.scan_index, a.map_id) for a in fast.associated] == [
            (a.scan_index, a.map_id) for a in slow.associated
        ]
        np.testing.assert_allclose(
            [a.distance for a in fast.associated], [a.distance for a in slow.associated], atol=1e-9
        )
        assert (fast.new_ids, fast.joined, fast.missed_ids) == (
            slow.new_ids,
            slow.joined,
            slow.missed_ids,
        )
    assert list(fast_map.entries) == list(slow_map.entries)
    for map_id, entry in fast_map.entries.items():
        other = slow_map[map_id]
        assert (entry.status, entry.hits, entry.misses) == (other.status, other.hits, other.misses)
        np.testing.assert_allclose(entry.polyline.points, other.polyline.points, atol=1e-9)


def _reference_extend_ends(points, angle_increment, viewpoint, limit=0.10):
    """extend_ends as first written: list geometry, one end at a time."""
    relative = [[x - viewpoint[0], y - viewpoint[1]] for x, y in points]
    extended = [list(point) for point in points]
    for end, inner, beam_step in ((0, 1, -angle_increment), (-1, -2, angle_increment)):
        outward = [relative[end][0] - relative[inner][0], relative[end][1] - relative[inner][1]]
        norm = math.hypot(*outward)
        if norm == 0.0:
            continue
        outward = [outward[0] / norm, outward[1] / norm]
        beam = math.atan2(relative[end][1], relative[end][0]) + beam_step
        direction = (math.cos(beam), math.sin(beam))
        across = direction[0] * outward[1] - direction[1] * outward[0]
        if abs(across) <= 1e-12:
            continue
        along_edge = (relative[end][0] * direction[1] - relative[end][1] * direction[0]) / across
        along_beam = (relative[end][0] * outward[1] - relative[end][1] * outward[0]) / across
        if along_edge <= 0.0 or along_beam <= 0.0:
            continue
        shift = min(0.5 * along_edge, limit)
        if shift > 0.0:
            x, y = points[end]
            extended[end] = [x + shift * outward[0], y + shift * outward[1]]
    return np.array(extended)


@pytest.mark.parametrize("seed", range(40))
def test_extend_ends_equals_the_list_reference(seed):
    rng = np.random.default_rng(seed)
    viewpoint = rng.normal(0.0, 1.0, 2)
    points = viewpoint + np.cumsum(rng.normal(0.0, 1.0, (int(rng.integers(2, 6)), 2)), axis=0)
    if seed % 7 == 0:
        points[1] = points[0]  # a zero-length end edge is left alone
    increment = math.radians(float(rng.choice([0.25, 0.5, 1.0])))
    moved = extend_ends(points, increment, viewpoint=viewpoint)
    np.testing.assert_array_equal(
        moved.points, _reference_extend_ends(points.tolist(), increment, viewpoint)
    )


def _scene_polylines(rng, count):
    """Short random polylines (1-5 vertices, some of zero length) in a 4 m square."""
    lines = []
    for _ in range(count):
        start = rng.uniform(-2.0, 2.0, 2)
        points = start + np.cumsum(rng.normal(0.0, 0.4, (int(rng.integers(1, 6)), 2)), axis=0)
        if rng.integers(10) == 0:
            points[:] = points[0]  # no shape: similarity inf
        lines.append(points)
    return lines


def test_forced_association_path_equals_the_full_recursion(monkeypatch):
    forced = []
    costs = association_module._similarity_costs
    for seed in range(80):
        rng = np.random.default_rng(seed)
        maps = _scene_polylines(rng, int(rng.integers(1, 8)))
        scans = [line + rng.normal(0.0, 0.05, (1, 2)) for line in maps]
        keep = int(rng.integers(1, len(scans) + 1))
        scans = [scans[k] for k in rng.permutation(len(scans))[:keep]]
        scans += _scene_polylines(rng, int(rng.integers(0, 3)))
        gate = float(rng.choice([0.12, 0.5, 1.5]))
        viewpoint = (0.0, 0.0, float(rng.uniform(-math.pi, math.pi)))
        calls = []
        monkeypatch.setattr(association_module, "_similarity_costs",
                            lambda *args, calls=calls: calls.append(1) or costs(*args))
        monkeypatch.setattr(association_module, "_FORCED_PATHS", True)
        fast = association_module.associate_with_distances(scans, maps, gate, viewpoint=viewpoint)
        forced.append(not calls)
        monkeypatch.setattr(association_module, "_FORCED_PATHS", False)
        slow = association_module.associate_with_distances(scans, maps, gate, viewpoint=viewpoint)
        assert fast == slow, seed
    # Both branches were exercised: paths fixed by the gate alone, and paths that needed
    # the similarities.
    assert 10 <= sum(forced) <= len(forced) - 10


@pytest.mark.parametrize("seed", range(12))
def test_similarity_costs_equal_the_similarity_of_each_pair(seed):
    rng = np.random.default_rng(seed)
    scans = _scene_polylines(rng, int(rng.integers(1, 5)))
    maps = _scene_polylines(rng, int(rng.integers(1, 5)))
    feasible = rng.random((len(scans), len(maps))) < 0.7
    scan_points, scan_bounds = pack_vertices(scans)
    map_points, map_bounds = pack_vertices(maps)
    costs = association_module._similarity_costs(
        feasible, scan_points, scan_bounds, map_points, map_bounds
    )
    for a, scan in enumerate(scans):
        for b, line in enumerate(maps):
            value = similarity(scan, line)
            expected = value if feasible[a, b] and value < FAR_COST else FAR_COST
            assert costs[a, b] == expected, (a, b)


def test_forced_path_needs_one_best_path():
    two_ways = np.ones((2, 2), dtype=bool)
    line = Polyline([[0.0, 0.0], [1.0, 0.0]])
    # All four pairs can pass: the diagonal and the two L-shaped paths differ only by the
    # similarities, so they must be computed.
    points = np.concatenate((line.points, line.points))
    bounds = np.array([0, 2, 4])
    forced = association_module._forced_kernel
    assert not forced(two_ways, points, bounds, points, bounds)[1]
    diagonal = np.eye(2, dtype=bool)
    path, fixed = forced(diagonal, points, bounds, points, bounds)
    assert fixed
    assert path.tolist() == [[0, 0], [1, 1]]


def test_a_typical_update_computes_no_similarity(monkeypatch):
    calls = []
    monkeypatch.setattr(association_module, "_similarity_costs",
                        lambda *args: calls.append(args) or np.zeros(args[0].shape))
    rng = np.random.default_rng(4)
    world = _hall()
    mapper = PolylineMap()
    for k in range(4):
        pose = rng.uniform([-0.05, -0.05, -0.02], [0.05, 0.05, 0.02])
        mapper.update(cast_scan(world, pose, noise=0.01, rng=rng, stamp=0.1 * k), pose)
    assert len(mapper) >= 3
    assert calls == []


def test_update_rejects_a_non_finite_pose():
    scan = cast_scan(_hall(), np.zeros(3))
    with pytest.raises(ValueError, match="pose must be a finite"):
        PolylineMap().update(scan, (0.0, math.nan, 0.0))


@pytest.mark.parametrize("seed", range(30))
def test_polyline_boxes_equal_numpy_bounds(seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(0.0, 3.0, (int(rng.integers(2, 30)), 2))
    cuts = sorted(set(rng.integers(1, points.shape[0], 3).tolist()))
    bounds = [0, *cuts, points.shape[0]]
    lines = Polyline._split(points.copy(), np.arange(points.shape[0]), bounds)
    for line, (start, stop) in zip(lines, itertools.pairwise(bounds), strict=True):
        part = points[start:stop]
        expected = (*part.min(axis=0).tolist(), *part.max(axis=0).tolist())
        assert line.box == expected
        assert Polyline(part).box == expected
    assert Polyline(np.empty((0, 2))).box == EMPTY_BOX


@pytest.mark.parametrize("seed", range(30))
def test_near_boxes_equal_shapely_box_distances(seed):
    rng = np.random.default_rng(seed)
    lines = [Polyline(rng.normal(0.0, 1.0, (2, 2)) * 0.3 + rng.normal(0.0, 1.0, 2))
             for _ in range(6)] + [Polyline(np.empty((0, 2)))]
    boxes = [line.box for line in lines]
    gate = float(rng.uniform(0.05, 0.5))
    shapes = [shapely.box(*box) if box != EMPTY_BOX else None for box in boxes]
    expected = [
        [a is not None and b is not None and shapely.distance(a, b) <= gate for b in shapes]
        for a in shapes
    ]
    assert (association_module.box_gaps(boxes, boxes) <= gate).tolist() == expected


def test_keep_box_prefilter_changes_nothing(monkeypatch):
    rng = np.random.default_rng(5)
    world = _hall()
    area = [(2.0, -0.8), (3.2, -0.8), (3.2, 0.8), (2.0, 0.8)]  # around the wall x = 3
    poses = [rng.uniform([-0.1, -0.1, -0.05], [0.1, 0.1, 0.05]) for _ in range(8)]
    scans = [cast_scan(world, pose, noise=0.01, rng=rng) for pose in poses]

    def run():
        local = LocalMap(safety_areas=[area])
        reports = [local.update(scan, pose) for scan, pose in zip(scans, poses, strict=True)]
        return local, reports

    filtered, filtered_reports = run()
    # Something is kept, and something is dropped by the box alone.
    assert len(filtered) > 0
    box_drops = [
        set(r.unassociated) - set(filtered._map._maybe_kept(r.scan_polylines, r.unassociated))
        for r in filtered_reports
    ]
    assert any(box_drops)
    monkeypatch.setattr(PolylineMap, "_maybe_kept", lambda self, lines, indices: list(indices))
    unfiltered, unfiltered_reports = run()
    assert [r.new_ids for r in filtered_reports] == [r.new_ids for r in unfiltered_reports]
    assert list(filtered.entries) == list(unfiltered.entries)
    for map_id, entry in filtered.entries.items():
        np.testing.assert_array_equal(entry.polyline.points, unfiltered[map_id].polyline.points)


def test_association_with_polylines_extracted_by_another_map_is_the_same():
    rng = np.random.default_rng(8)
    world = _hall()
    poses = [rng.uniform([-0.1, -0.1, -0.05], [0.1, 0.1, 0.05]) for _ in range(6)]
    scans = [cast_scan(world, pose, noise=0.01, rng=rng) for pose in poses]
    builder, reference = PolylineMap(), PolylineMap()
    reference.update(scans[0], poses[0])
    for scan, pose in zip(scans, poses, strict=True):
        report = builder.update(scan, pose)
        expected = reference.associate(scan, pose)
        reused = reference.associate(scan, pose, scan_polylines=report.scan_polylines)
        assert expected.associated == reused.associated
        assert expected.missed_ids == reused.missed_ids
        assert len(expected.associated) >= 1


@pytest.mark.parametrize("seed", range(20))
def test_breakpoint_table_equals_the_adaptive_formula(seed):
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.5, 6.0, 361)
    ranges[rng.integers(0, 361, 40)] = np.inf  # gaps of one and more beams
    scan = Scan(ranges=ranges, angle_min=-math.pi / 2, angle_increment=math.radians(0.5))
    index = np.flatnonzero(np.isfinite(ranges))
    x, y = extraction_module._end_points(scan, index)
    lam, sigma_r = math.radians(float(rng.uniform(3.0, 15.0))), 0.01
    step = np.diff(index)
    dphi = step * scan.angle_increment
    with np.errstate(divide="ignore", invalid="ignore"):
        threshold = ranges[index[:-1]] * np.sin(dphi) / np.sin(lam - dphi) + 3.0 * sigma_r
    jump = np.hypot(np.diff(x), np.diff(y))
    expected = (step <= extraction_module.MAX_BRIDGED_GAP + 1) & (dphi < lam) & (jump <= threshold)
    joined = extraction_module._joined(scan, index, x, y, lam, sigma_r)
    np.testing.assert_array_equal(joined, expected)
    assert joined.any()
    assert not joined.all()
