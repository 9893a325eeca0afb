"""The polyline map update and the object life cycle (paper Sec. 3-4, docs/design.md#detail-10)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semistatic.extraction import extract_polylines
from semistatic.hausdorff import hausdorff
from semistatic.join import overlapping_groups
from semistatic.mapper import MapPolyline, PolylineMap
from semistatic.noise import noise_params
from semistatic.params import MapperParams
from semistatic.types import Scan
from semistatic.visibility import MIN_VISIBLE_FRACTION, extend_ends, visibility
from tests.semistatic.conftest import NASTY_SCANS
from tests.semistatic.synthetic import box, cast_scan, raycast, scene, wall

ORIGIN = np.zeros(3)
BOX = box((2.5, -1.0), 0.6, 0.4)
# The two faces of BOX seen from around the origin, in scan order.
BOX_TRUTH = np.array([[2.2, -1.2], [2.2, -0.8], [2.8, -0.8]])
WALL = wall((4.0, 2.0), (1.0, 2.0))
WALL_TRUTH = WALL[0]


def jitter(rng, spread=0.1, turn=0.03):
    step = [rng.uniform(-spread, spread), rng.uniform(-spread, spread), rng.uniform(-turn, turn)]
    return ORIGIN + np.array(step)


def build(world, scans=3, params=None, pose=ORIGIN):
    mapper = PolylineMap(params)
    for k in range(scans):
        mapper.update(cast_scan(world, pose, stamp=float(k)), pose)
    return mapper


def id_nearest(mapper, truth):
    return min(mapper.polylines().items(), key=lambda item: hausdorff(item[1], truth))[0]


def test_merge_converges_on_an_unchanged_box_and_wall():
    """Acceptance: 200 noisy observations keep one polyline per object, few vertices, 2 cm."""
    world = scene(BOX, WALL)
    noise_free = [len(line) for line in extract_polylines(cast_scan(world, ORIGIN))]
    assert sorted(noise_free) == [2, 3]
    limit = {"box": 2 * 3, "wall": 2 * 2}
    rng = np.random.default_rng(0)
    mapper = PolylineMap()
    most = {"box": 0, "wall": 0}
    for k in range(200):
        pose = jitter(rng)
        mapper.update(cast_scan(world, pose, noise=0.01, rng=rng, stamp=0.08 * k), pose)
        assert len(mapper) == 2
        box_id, wall_id = id_nearest(mapper, BOX_TRUTH), id_nearest(mapper, WALL_TRUTH)
        assert box_id != wall_id
        most["box"] = max(most["box"], len(mapper[box_id].polyline))
        most["wall"] = max(most["wall"], len(mapper[wall_id].polyline))
    assert most["box"] <= limit["box"]
    assert most["wall"] <= limit["wall"]
    assert hausdorff(mapper[box_id].polyline, BOX_TRUTH) < 0.02
    assert hausdorff(mapper[wall_id].polyline, WALL_TRUTH) < 0.02
    assert mapper[box_id].hits == 200
    assert mapper[box_id].status == "confirmed"


def test_each_map_edge_counts_the_observations_along_it():
    rng = np.random.default_rng(3)
    mapper = PolylineMap()
    for k in range(12):
        pose = jitter(rng)
        mapper.update(cast_scan(scene(BOX, WALL), pose, noise=0.01, rng=rng, stamp=0.08 * k),
                      pose)
    for entry in mapper:
        assert entry.support.shape == (len(entry.polyline) - 1,)
        # Every scan saw every face (the first one inserted it): one weight per scan.
        np.testing.assert_allclose(entry.edge_weights, entry.hits, atol=0.5)
    assert MapPolyline(0, BOX_TRUTH, hits=7).edge_weights.tolist() == [7.0, 7.0]
    with pytest.raises(ValueError, match="one weight >= 0 per edge"):
        MapPolyline(0, BOX_TRUTH, support=[1.0])


def test_join_follows_the_edges_seen_not_the_hits():
    """A stub cut off a long wall keeps the wall's hits; the box it overlaps stays put.

    (warehouse_fleet: a pallet's face merged onto such a stub and was lost.)
    """
    mapper = PolylineMap()
    mapper.restore(MapPolyline(0, BOX_TRUTH, "confirmed", 50, support=[50.0, 50.0]))
    # 3 cm off the box's front face, seen 4 times, with a wall's 1000 hits.
    stub = [[2.23, -1.2], [2.23, -0.95]]
    mapper.restore(MapPolyline(1, stub, "confirmed", 1000, support=[4.0]))
    assert mapper[1].weight == 4.0  # not its 1000 hits
    assert mapper[0].weight == 50.0
    mapper.update(cast_scan(scene(BOX), ORIGIN, stamp=1.0), ORIGIN)
    assert len(mapper) == 1
    (line,) = mapper.polylines().values()
    # Weighted by hits the joined face lay 2.8 cm out, on the stub.
    assert hausdorff(line, BOX_TRUTH) < 0.01


@pytest.mark.parametrize("seed", range(3))
def test_repeated_observations_refine_the_map_outline(seed):
    """Acceptance: 200 observations at 2 cm noise end within 0.5 cm, half the error at 5."""
    world = scene(BOX, WALL)
    params = noise_params(MapperParams(), 0.02)  # epsilon 6 cm: the shape, not the noise
    rng = np.random.default_rng(seed)
    mapper = PolylineMap(params)
    error = {}
    for k in range(1, 201):
        pose = jitter(rng)
        mapper.update(cast_scan(world, pose, noise=0.02, rng=rng, stamp=0.08 * k), pose)
        if k in (5, 200):
            assert len(mapper) == 2
            error[k] = max(
                hausdorff(mapper[id_nearest(mapper, truth)].polyline, truth)
                for truth in (BOX_TRUTH, WALL_TRUTH)
            )
    assert error[200] < 0.005
    assert error[200] <= 0.5 * error[5]


@pytest.mark.parametrize("miss_limit", [1, 3, 5])
def test_removed_object_is_deleted_after_exactly_k_visible_misses(miss_limit):
    params = MapperParams(miss_limit=miss_limit)
    mapper = build(scene(BOX, WALL), params=params)
    box_id = id_nearest(mapper, BOX_TRUTH)
    without_box = scene(WALL)
    for miss in range(1, miss_limit + 1):
        report = mapper.update(cast_scan(without_box, ORIGIN, stamp=10.0 + miss), ORIGIN)
        assert report.missed_ids == (box_id,)
        if miss < miss_limit:
            assert report.deleted_ids == ()
            assert mapper[box_id].status == "blank"
            assert mapper[box_id].misses == miss
        else:
            assert report.deleted_ids == (box_id,)
            assert box_id not in mapper
    assert len(mapper) == 1


def test_misses_count_only_consecutive_visible_scans():
    params = MapperParams(miss_limit=3)
    world = scene(BOX, WALL)
    mapper = build(world, params=params)
    box_id = id_nearest(mapper, BOX_TRUTH)
    for _ in range(2):
        mapper.update(cast_scan(scene(WALL), ORIGIN), ORIGIN)
    assert mapper[box_id].misses == 2
    report = mapper.update(cast_scan(world, ORIGIN), ORIGIN)
    assert box_id in {pair.map_id for pair in report.associated}
    assert (mapper[box_id].status, mapper[box_id].misses) == ("confirmed", 0)


def test_object_out_of_view_is_never_deleted():
    params = MapperParams(miss_limit=2)
    mapper = build(scene(BOX, WALL), params=params)
    box_id = id_nearest(mapper, BOX_TRUTH)
    facing_away = np.array([0.0, 0.0, math.radians(160.0)])  # the box is in the blind spot
    for k in range(10):
        report = mapper.update(cast_scan(scene(WALL), facing_away, stamp=k), facing_away)
        assert box_id not in report.missed_ids
    assert (mapper[box_id].status, mapper[box_id].misses) == ("confirmed", 0)


def test_object_out_of_range_is_never_deleted():
    params = MapperParams(miss_limit=2, max_range=2.0)
    world = scene(BOX, wall((1.5, -0.3), (1.5, 0.3)))
    mapper = build(world, params=MapperParams(miss_limit=2))
    mapper.params = params  # the box (2.2 m and farther) is now beyond the mapper's range
    box_id = id_nearest(mapper, BOX_TRUTH)
    for k in range(10):
        report = mapper.update(cast_scan(scene(wall((1.5, -0.3), (1.5, 0.3))), ORIGIN), ORIGIN)
        assert box_id not in report.missed_ids, k
    assert box_id in mapper


def test_occluded_object_is_never_deleted():
    params = MapperParams(miss_limit=2)
    mapper = build(scene(BOX, WALL), params=params)
    box_id = id_nearest(mapper, BOX_TRUTH)
    screen = wall((1.2, -1.0), (1.2, -0.2))  # in front of the box; the box itself is gone
    for k in range(10):
        report = mapper.update(cast_scan(scene(screen, WALL), ORIGIN, stamp=k), ORIGIN)
        assert box_id not in report.missed_ids
    assert box_id in mapper
    assert mapper[box_id].misses == 0


def test_new_object_is_reported_on_its_first_scan():
    mapper = build(scene(WALL))
    assert len(mapper) == 1
    world = scene(BOX, WALL)
    first = mapper.update(cast_scan(world, ORIGIN, stamp=5.0), ORIGIN)
    assert len(first.new_ids) == 1
    (box_id,) = first.new_ids
    assert hausdorff(mapper[box_id].polyline, BOX_TRUTH) < 0.05
    assert (mapper[box_id].status, mapper[box_id].hits, mapper[box_id].first_seen) == (
        "new",
        1,
        5.0,
    )
    second = mapper.update(cast_scan(world, ORIGIN, stamp=6.0), ORIGIN)
    assert second.new_ids == ()
    assert (mapper[box_id].status, mapper[box_id].hits, mapper[box_id].last_seen) == (
        "confirmed",
        2,
        6.0,
    )


def test_ids_are_never_reused():
    params = MapperParams(miss_limit=1)
    mapper = build(scene(BOX, WALL), params=params)
    box_id = id_nearest(mapper, BOX_TRUTH)
    mapper.update(cast_scan(scene(WALL), ORIGIN), ORIGIN)
    assert box_id not in mapper
    report = mapper.update(cast_scan(scene(BOX, WALL), ORIGIN), ORIGIN)
    (again,) = report.new_ids
    assert again > max(box_id, *(entry.id for entry in mapper if entry.id != again))


def test_association_only_leaves_the_map_unchanged():
    params = MapperParams(miss_limit=1)
    mapper = build(scene(BOX, WALL), params=params)
    before = {entry.id: entry for entry in mapper}
    rng = np.random.default_rng(1)
    pose = jitter(rng)
    report = mapper.associate(
        cast_scan(scene(WALL, box((1.0, -2.5), 0.3, 0.3)), pose, noise=0.01, rng=rng), pose
    )
    assert {entry.id: entry for entry in mapper} == before
    assert len(report.associated) == 1
    assert 0.0 < report.associated[0].distance < params.gate
    assert report.missed_ids == (id_nearest(mapper, BOX_TRUTH),)
    assert report.new_ids == report.deleted_ids == ()
    assert len(report.unassociated) == 1


def test_wall_seen_in_pieces_is_joined_when_seen_whole():
    params = MapperParams(hausdorff_restriction="projection")
    long_wall = wall((3.0, -2.0), (3.0, 2.0))
    pillar = box((1.5, 0.0), 0.2, 0.2)
    mapper = build(scene(long_wall, pillar), params=params)
    assert len(mapper) == 3  # two wall pieces and the pillar
    report = mapper.update(cast_scan(scene(long_wall), ORIGIN), ORIGIN)
    ((absorbed, survivor),) = report.joined
    assert survivor < absorbed  # the older id survives
    assert absorbed not in mapper
    assert id_nearest(mapper, long_wall[0]) == survivor
    assert hausdorff(mapper[survivor].polyline, long_wall[0]) < 0.05
    assert mapper[survivor].hits == 4 + 4  # both pieces, each seen again in this scan
    assert len(mapper) == 2  # the wall and the (now blank) pillar


def test_update_is_deterministic():
    world = scene(BOX, WALL)
    results = []
    for _ in range(2):
        rng = np.random.default_rng(9)
        mapper = PolylineMap()
        for k in range(20):
            pose = jitter(rng)
            mapper.update(cast_scan(world, pose, noise=0.01, rng=rng, stamp=k), pose)
        results.append({entry.id: entry.polyline.points.tolist() for entry in mapper})
    assert results[0] == results[1]


def test_timings_are_collected_per_stage():
    timings: dict[str, float] = {}
    PolylineMap().update(cast_scan(scene(BOX), ORIGIN), ORIGIN, timings=timings)
    assert set(timings) == {"extract", "associate", "merge", "join", "life_cycle"}
    assert all(value >= 0.0 for value in timings.values())


def test_empty_scan_on_an_empty_map():
    report = PolylineMap().update(cast_scan(scene(), ORIGIN), ORIGIN)
    assert report.scan_polylines == report.associated == report.new_ids == ()


def test_scan_with_no_return_misses_every_visible_object():
    params = MapperParams(miss_limit=1)
    mapper = build(scene(BOX, WALL), params=params)
    report = mapper.update(cast_scan(scene(), ORIGIN), ORIGIN)
    assert len(report.deleted_ids) == 2
    assert len(mapper) == 0


@pytest.mark.parametrize("name", sorted(NASTY_SCANS))
def test_nasty_scans_go_through_update(name):
    mapper = PolylineMap()
    mapper.add([[1.0, 0.2], [1.0, 0.6]])
    mapper.add([[1.5, -0.5]])
    for method in (mapper.associate, mapper.update):
        report = method(NASTY_SCANS[name], ORIGIN)
        assert set(report.deleted_ids) <= {0, 1}
    # nan readings tell nothing: they never make a polyline visible.
    if name == "all_nan":
        assert report.missed_ids == ()


def test_map_polyline_validation():
    with pytest.raises(ValueError, match="status"):
        MapPolyline(0, [[0.0, 0.0]], status="gone")
    with pytest.raises(ValueError, match="hits"):
        MapPolyline(0, [[0.0, 0.0]], hits=-1)
    mapper = PolylineMap()
    mapper.restore(MapPolyline(7, [[0.0, 0.0], [1.0, 0.0]]), next_id=12)
    assert mapper.next_id == 12
    with pytest.raises(ValueError, match="already"):
        mapper.restore(MapPolyline(7, [[0.0, 0.0]]))


def counts(polyline, scan, params=None):
    """The beam counts of one polyline: in view, unoccluded, seen through; and missing."""
    seen = visibility([polyline], scan, ORIGIN, MapperParams() if params is None else params)
    return (int(seen.in_view[0]), int(seen.unoccluded[0]), int(seen.seen_through[0]),
            bool(seen.missing[0]))


def should_be_visible(in_view, unoccluded):
    """docs/design.md#detail-10: enough beams, and most of those in view, see it unoccluded."""
    return unoccluded > 0 and unoccluded >= max(MapperParams().min_points,
                                                math.ceil(MIN_VISIBLE_FRACTION * in_view))


def test_expected_ranges_match_the_ray_caster():
    # Readings a hair beyond (before) the ranges the ray caster gives: every beam that
    # hits the polyline is unoccluded and seen through (occluded) exactly when the
    # polyline's expected range agrees with the ray caster's to 1e-9.
    rng = np.random.default_rng(4)
    angles = np.linspace(-2.3, 2.3, 300)
    params = MapperParams(visibility_margin=0.0, max_range=100.0)

    def scan(ranges):
        return Scan(ranges=ranges, angle_min=angles[0], angle_increment=angles[1] - angles[0],
                    range_max=100.0)

    polylines = [np.cumsum(rng.uniform(-1.0, 1.0, (4, 2)), axis=0) + rng.uniform(-3, 3, 2)
                 for _ in range(20)]
    references = [raycast(np.stack((points[:-1], points[1:]), axis=1), ORIGIN, angles)
                  for points in polylines]
    # A single vertex is hit by the one beam nearest to its bearing, at its distance.
    point = np.array([[2.0, 0.1]])
    single = np.full(angles.size, np.inf)
    single[np.argmin(np.abs(angles - math.atan2(0.1, 2.0)))] = math.hypot(2.0, 0.1)
    for points, reference in zip([*polylines, point], [*references, single], strict=True):
        hits = int(np.isfinite(reference).sum())
        beyond = counts(points, scan(reference * (1.0 + 1e-9)), params)
        before = counts(points, scan(reference * (1.0 - 1e-9)), params)
        assert beyond[:3] == (hits, hits, hits)
        assert before[:3] == (hits, 0, 0)
    assert sum(np.isfinite(reference).sum() for reference in references) > 500


def test_visibility_counts_in_view_unoccluded_and_seen_through_beams():
    line = np.array([[2.0, -0.5], [2.0, 0.5]])
    open_view = cast_scan(scene(wall((5.0, -3.0), (5.0, 3.0))), ORIGIN)
    in_view, unoccluded, seen_through, missing = counts(line, open_view)
    assert in_view == unoccluded == seen_through > 50
    assert should_be_visible(in_view, unoccluded)
    assert missing
    in_place = cast_scan(scene(line), ORIGIN)
    in_view, unoccluded, seen_through, missing = counts(line, in_place)
    assert in_view == unoccluded > 50
    assert seen_through == 0
    assert should_be_visible(in_view, unoccluded)
    assert not missing
    blocked = cast_scan(scene(wall((1.0, -0.2), (1.0, 0.2))), ORIGIN)
    in_view, unoccluded, _, missing = counts(line, blocked)
    assert 0 < unoccluded < 0.5 * in_view
    assert not should_be_visible(in_view, unoccluded)
    assert not missing
    assert counts(line, open_view, MapperParams(max_range=1.5)) == (0, 0, 0, False)
    nan_scan = Scan(ranges=np.full(541, np.nan), angle_min=-2.356, angle_increment=0.00873)
    assert counts(line, nan_scan)[1] == 0


def test_object_still_in_place_is_not_missed_when_association_fails():
    mapper = build(scene(BOX, WALL), params=MapperParams(miss_limit=1))
    box_id = id_nearest(mapper, BOX_TRUTH)
    # A gate no pair can pass: nothing is associated, but the box reads where it was.
    mapper.params = MapperParams(miss_limit=1, gate=1e-6)
    rng = np.random.default_rng(2)
    for k in range(5):
        report = mapper.update(cast_scan(scene(BOX, WALL), ORIGIN, noise=0.01, rng=rng), ORIGIN)
        assert report.associated == ()
        assert box_id not in report.missed_ids, k
    assert mapper[box_id].status == "confirmed"


def test_extend_ends_removes_the_beam_spacing_bias():
    # A wall seen at grazing incidence: raw ends stop short by half a beam gap on average.
    end = np.array([4.0, 1.0])
    world = wall((1.0, 1.0), tuple(end))
    rng = np.random.default_rng(8)
    raw, extended = [], []
    for _ in range(60):
        pose = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.1, 0.1), 0.0])
        scan = cast_scan(world, pose)
        (line,) = extract_polylines(scan)
        raw.append(line.transformed(pose).points[0, 0] - end[0])
        (longer,) = extend_ends([line], scan.angle_increment)
        longer = longer.transformed(pose)
        extended.append(longer.points[0, 0] - end[0])
    assert np.mean(raw) < -0.015
    assert abs(np.mean(extended)) < 0.005
    assert extend_ends([[[1.0, 1.0]]], 0.01)[0].points.tolist() == [[1.0, 1.0]]


def drive_along_corridor(mapper, rng):
    corridor = scene(
        wall((-2.0, 1.5), (12.0, 1.5)), wall((-2.0, -1.5), (12.0, -1.5)), box((5.0, 1.0), 0.6, 0.4)
    )
    new_objects = 0
    for k, x in enumerate(np.arange(0.0, 8.0, 0.2)):
        pose = np.array([x, 0.05 * np.sin(x), 0.02 * np.cos(x)])
        report = mapper.update(cast_scan(corridor, pose, noise=0.01, rng=rng, stamp=k), pose)
        new_objects += len(report.new_ids)
    return new_objects


@pytest.mark.parametrize("mode", ["vertex", "projection"])
def test_corridor_drive_keeps_one_polyline_per_object(mode):
    mapper = PolylineMap(MapperParams(hausdorff_restriction=mode))
    drive_along_corridor(mapper, np.random.default_rng(6))
    walls = [entry.polyline.length for entry in mapper if entry.polyline.length > 5.0]
    # each 14 m wall is one polyline; its far ends, seen at grazing beams, fall short
    assert len(walls) == 2
    assert all(13.0 < length < 14.0 for length in walls)
    # The box: one polyline for the faces seen on the way in, one for its back face seen
    # on the way out (faces that only meet at a corner are not joined).
    assert len(mapper) <= 4
    assert all(entry.status == "confirmed" for entry in mapper)


def test_joins_use_the_projection_restriction_whatever_the_association_uses():
    # A copy of part of a long wall simplified to two vertices: what the vertex restriction
    # cannot recognise (docs/design.md#detail-5), so joining by it would leave wall fragments.
    long_wall, copy = [[0.0, 1.5], [14.0, 1.5]], [[5.0, 1.51], [7.0, 1.51]]
    assert overlapping_groups([long_wall, copy], [False, True], 0.12, "vertex") == []
    assert overlapping_groups([long_wall, copy], [False, True], 0.12, "projection") == [[0, 1]]
    mapper = PolylineMap(MapperParams(hausdorff_restriction="vertex"))
    drive_along_corridor(mapper, np.random.default_rng(6))
    assert len(mapper) <= 4
