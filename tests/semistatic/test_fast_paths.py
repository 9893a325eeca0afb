"""The mapper's shortcuts and compiled kernels give what their slow references give.

The compiled Douglas-Peucker (extraction and merge alike) is checked against GEOS on
seeded random inputs, and the association - which skips the similarities when the gate
alone fixes the optimal path - against eq. (4-5) computed in full, pair by pair, both on
its own and inside the whole mapper. (``hausdorff``, ``similarity``, ``association`` and
``visibility`` have one compiled implementation each, tested against their references in
their own test modules.)
"""

from __future__ import annotations

import dataclasses
import importlib
import itertools
import math

import numpy as np
import pytest
import shapely

from semistatic.association import (
    FAR_COST,
    ValidatedPairs,
    associate,
    box_gap,
    optimal_path,
    orient_ccw,
    sort_ccw,
)
from semistatic.extraction import douglas_peucker, split_breakpoints
from semistatic.hausdorff import restricted_hausdorff
from semistatic.mapper import PolylineMap
from semistatic.merge import DUPLICATE_DISTANCE, distinct_vertices
from semistatic.polyline import EMPTY_BOX, PackedPolylines, Polyline, as_polyline
from semistatic.similarity import similarity
from semistatic.types import Scan
from semistatic.visibility import MAX_END_EXTENSION, extend_ends
from tests.semistatic.conftest import NASTY_POLYLINES
from tests.semistatic.synthetic import box, cast_scan, scene, wall

# The package re-exports functions named like these modules: import the modules by name.
association_module = importlib.import_module("semistatic.association")
mapper_module = importlib.import_module("semistatic.mapper")

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
                if k == 0 or math.dist(row, points[k - 1]) > DUPLICATE_DISTANCE]
    np.testing.assert_array_equal(distinct_vertices(points), np.array(expected).reshape(-1, 2))


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
    assert optimal_path(costs) == _reference_optimal_path(costs)


def reference_associate(scans, maps, gate, *, viewpoint=None, mode="vertex"):
    """Eq. (4-5) in full: every feasible pair's similarity, the cell-by-cell recursion.

    The candidates and costs are the association's own definition (module notes of
    ``semistatic.association``): polylines with a partner whose box is within the gate,
    ``FAR_COST`` for a pair farther apart or without shape; no shortcut past the
    similarities.
    """
    scans, maps = [as_polyline(line) for line in scans], [as_polyline(line) for line in maps]
    order = list(range(len(maps))) if viewpoint is None else sort_ccw(maps, viewpoint).tolist()
    oriented = [maps[j] if viewpoint is None else orient_ccw(maps[j], viewpoint) for j in order]
    scan_boxes, map_boxes = PackedPolylines(scans).boxes, PackedPolylines(oriented).boxes
    near = np.array([[box_gap(scan_boxes, a, map_boxes, b) <= gate for b in range(len(maps))]
                     for a in range(len(scans))], dtype=bool).reshape(len(scans), len(maps))
    rows, columns = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    if not (rows.size and columns.size):
        return ValidatedPairs()
    costs = np.full((rows.size, columns.size), FAR_COST)
    for a, i in enumerate(rows):
        for b, k in enumerate(columns):
            if near[i, k]:
                costs[a, b] = min(similarity(scans[i], oriented[k]), FAR_COST)
    pairs, distances = [], []
    for a, b in _reference_optimal_path(costs):
        i, k = rows[a], columns[b]
        if near[i, k] and len(scans[i]) and len(oriented[k]):
            distance = restricted_hausdorff(scans[i], oriented[k], mode)
            if distance <= gate:
                pairs.append((int(i), order[k]))
                distances.append(distance)
    return ValidatedPairs(pairs, distances)


def test_map_entries_after_updates_are_valid_map_polylines():
    # The update replaces the entries it touches without re-validating them (its changes
    # are valid by construction): the validated constructor must accept them as they are.
    mapper = _hall_mapped(seed=3, updates=6, jitter=[0.1, 0.1, 0.05])
    assert len(mapper) >= 3
    for entry in mapper:
        assert dataclasses.replace(entry) == entry
        if entry.support is not None:
            np.testing.assert_array_equal(dataclasses.replace(entry).support, entry.support)


def _hall():
    """A few boxes and walls around the origin."""
    parts = [wall((3.0, -1.0), (3.0, 1.0)), wall((-1.0, 2.5), (1.5, 2.5))]
    parts += [box((1.5, -2.0), 0.5, 0.3, yaw=0.3), box((-2.0, -1.0), 0.4, 0.4, yaw=1.0)]
    return scene(*parts)


def _hall_mapped(seed, updates, jitter):
    """A map of :func:`_hall` from ``updates`` noisy scans, poses within ``jitter`` of 0."""
    rng = np.random.default_rng(seed)
    world = _hall()
    mapper = PolylineMap()
    for k in range(updates):
        pose = rng.uniform(np.negative(jitter), jitter)
        mapper.update(cast_scan(world, pose, noise=0.01, rng=rng, stamp=0.1 * k), pose)
    return mapper


def _run(scans, poses):
    mapper = PolylineMap()
    reports = [mapper.update(scan, pose) for scan, pose in zip(scans, poses, strict=True)]
    return mapper, reports


def test_mapper_with_the_association_in_full_gives_the_same_map(monkeypatch):
    rng = np.random.default_rng(11)
    poses = [rng.uniform([-0.1, -0.1, -0.05], [0.1, 0.1, 0.05]) for _ in range(12)]
    world = _hall()
    scans = [
        cast_scan(world, pose, noise=0.01, rng=rng, stamp=0.1 * k) for k, pose in enumerate(poses)
    ]
    fast_map, fast_reports = _run(scans, poses)
    assert sum(len(report.associated) for report in fast_reports) >= 3 * len(scans[1:])
    monkeypatch.setattr(mapper_module, "associate", reference_associate)
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
    (moved,) = extend_ends([points], increment, viewpoint=viewpoint)
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


def _spied_similarity(monkeypatch):
    """Count the association's calls of ``similarity`` (it computes none on a forced path)."""
    calls = []
    monkeypatch.setattr(association_module, "similarity",
                        lambda *args, calls=calls: calls.append(args) or similarity(*args))
    return calls


def test_association_equals_the_full_recursion(monkeypatch):
    calls = _spied_similarity(monkeypatch)
    forced = []
    for seed in range(80):
        rng = np.random.default_rng(seed)
        maps = _scene_polylines(rng, int(rng.integers(1, 8)))
        scans = [line + rng.normal(0.0, 0.05, (1, 2)) for line in maps]
        keep = int(rng.integers(1, len(scans) + 1))
        scans = [scans[k] for k in rng.permutation(len(scans))[:keep]]
        scans += _scene_polylines(rng, int(rng.integers(0, 3)))
        gate = float(rng.choice([0.12, 0.5, 1.5]))
        viewpoint = (0.0, 0.0, float(rng.uniform(-math.pi, math.pi)))
        calls.clear()
        fast = associate(scans, maps, gate, viewpoint=viewpoint)
        forced.append(not calls)
        slow = reference_associate(scans, maps, gate, viewpoint=viewpoint)
        assert fast == slow, seed
        np.testing.assert_allclose(fast.distances, slow.distances, rtol=0.0, atol=1e-12)
    # Both kinds of input were met: paths the gate alone fixes, and paths that needed the
    # similarities.
    assert 10 <= sum(forced) <= len(forced) - 10


@pytest.mark.parametrize("seed", range(12))
def test_similarity_of_two_sets_equals_the_similarity_of_each_pair(seed):
    rng = np.random.default_rng(seed)
    count = int(rng.integers(1, 6))
    scans, maps = _scene_polylines(rng, count), _scene_polylines(rng, count)
    values = similarity(PackedPolylines(scans), PackedPolylines(maps))
    assert values.tolist() == [similarity(a, b) for a, b in zip(scans, maps, strict=True)]


def test_the_similarities_decide_only_where_the_gate_leaves_two_paths(monkeypatch):
    calls = _spied_similarity(monkeypatch)
    line = [[0.0, 0.0], [1.0, 0.0]]
    corner = [[0.0, 0.05], [0.5, 0.05], [0.5, 0.1]]
    # All four pairs can pass: the diagonal and the two L-shaped paths differ only by
    # the similarities, so they are computed.
    scans, maps = [line, corner], [np.add(line, [0.0, 0.03]), np.add(corner, [0.0, 0.02])]
    assert associate(scans, maps, 0.5) == reference_associate(scans, maps, 0.5)
    assert calls
    calls.clear()
    # Each polyline near only its counterpart: the diagonal, and no similarity.
    apart = [line, np.add(corner, [5.0, 0.0])]
    assert associate(apart, [maps[0], np.add(maps[1], [5.0, 0.0])], 0.5) == [(0, 0), (1, 1)]
    assert calls == []


def test_a_typical_update_computes_no_similarity(monkeypatch):
    calls = _spied_similarity(monkeypatch)
    mapper = _hall_mapped(seed=4, updates=4, jitter=[0.05, 0.05, 0.02])
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
    lines = PackedPolylines.from_runs(points.copy(), bounds, np.arange(points.shape[0]))
    for k, (start, stop) in enumerate(itertools.pairwise(bounds)):
        part = points[start:stop]
        expected = (*part.min(axis=0).tolist(), *part.max(axis=0).tolist())
        assert lines[k].box == expected
        assert tuple(lines.boxes[k].tolist()) == expected
        assert Polyline(part).box == expected
    assert Polyline(np.empty((0, 2))).box == EMPTY_BOX


@pytest.mark.parametrize("seed", range(30))
def test_near_boxes_equal_shapely_box_distances(seed):
    rng = np.random.default_rng(seed)
    lines = PackedPolylines(
        [rng.normal(0.0, 1.0, (2, 2)) * 0.3 + rng.normal(0.0, 1.0, 2) for _ in range(6)]
        + [np.empty((0, 2))]
    )
    boxes = [line.box for line in lines]
    gate = float(rng.uniform(0.05, 0.5))
    shapes = [shapely.box(*box) if box != EMPTY_BOX else None for box in boxes]
    expected = [
        [a is not None and b is not None and shapely.distance(a, b) <= gate for b in shapes]
        for a in shapes
    ]
    count = len(lines)
    assert [[box_gap(lines.boxes, a, lines.boxes, b) <= gate for b in range(count)]
            for a in range(count)] == expected


def test_keep_box_prefilter_changes_nothing():
    rng = np.random.default_rng(5)
    world = _hall()
    area = shapely.box(2.0, -0.8, 3.2, 0.8)  # around the wall x = 3
    poses = [rng.uniform([-0.1, -0.1, -0.05], [0.1, 0.1, 0.05]) for _ in range(8)]
    scans = [cast_scan(world, pose, noise=0.01, rng=rng) for pose in poses]

    def keep(line):
        geometry = shapely.Point(line.points[0]) if len(line) == 1 else shapely.LineString(
            line.points)
        return bool(area.intersects(geometry))

    def run(keep_box):
        mapper = PolylineMap(keep=keep, keep_box=keep_box)
        reports = [mapper.update(scan, pose) for scan, pose in zip(scans, poses, strict=True)]
        return mapper, reports

    filtered, filtered_reports = run(area.bounds)
    # Something is kept, and something is dropped by the box alone: an unassociated scan
    # polyline farther from the box than an end extension can reach.
    reach = MAX_END_EXTENSION
    xmin, ymin, xmax, ymax = np.add(area.bounds, [-reach, -reach, reach, reach]).tolist()
    assert len(filtered) > 0
    assert any(
        (box := report.scan_polylines[index].box)[0] > xmax or box[2] < xmin
        or box[1] > ymax or box[3] < ymin
        for report in filtered_reports for index in report.unassociated
    )
    unfiltered, unfiltered_reports = run(None)
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
    usable = np.isfinite(ranges)
    index = np.flatnonzero(usable)
    x, y = scan.points()[index].T
    lam, sigma_r = math.radians(float(rng.uniform(3.0, 15.0))), 0.01
    step = np.diff(index)
    dphi = step * scan.angle_increment
    with np.errstate(divide="ignore", invalid="ignore"):
        threshold = ranges[index[:-1]] * np.sin(dphi) / np.sin(lam - dphi) + 3.0 * sigma_r
    jump = np.hypot(np.diff(x), np.diff(y))
    expected = (step <= 2) & (dphi < lam) & (jump <= threshold)  # MAX_BRIDGED_GAP = 1
    # Consecutive usable beams stay together exactly when they share an interval.
    intervals = split_breakpoints(scan, usable, lam, sigma_r, min_points=1)
    interval_of = np.empty(ranges.size, np.int64)
    for number, beams in enumerate(intervals):
        interval_of[beams] = number
    joined = np.diff(interval_of[index]) == 0
    np.testing.assert_array_equal(joined, expected)
    assert joined.any()
    assert not joined.all()
