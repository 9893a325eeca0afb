"""Free-space cut: map polyline parts that a scan reads through are removed, nothing else."""

import math

import numpy as np
import pytest
import shapely

from semistatic.mapper import PolylineMap
from semistatic.params import MapperParams
from semistatic.polyline import Polyline
from semistatic.types import Scan
from semistatic.visibility import MIN_VISIBLE_FRACTION, MISSING_FRACTION, visibility
from tests.semistatic.synthetic import box, cast_scan, scene, wall

PARAMS = MapperParams()
ORIGIN = (0.0, 0.0, 0.0)
WALL = Polyline([[2.0, -1.0], [2.0, 1.0]])  # 2 m ahead of the origin


def wall_scan(through: slice, step: float = 0.02) -> Scan:
    """Beams every ``step`` rad over +-0.5 rad reading the wall, except ``through`` (4 m)."""
    count = round(1.0 / step) + 1
    angles = -0.5 + step * np.arange(count)
    ranges = 2.0 / np.cos(angles)
    ranges[through] = 4.0
    return Scan(ranges=ranges, angle_min=-0.5, angle_increment=step)


def free_space_cut(polyline, scan, pose=ORIGIN, params=PARAMS):
    """What the free-space cut leaves of one polyline (``None``: it cuts nothing)."""
    return visibility([polyline], scan, pose, params).pieces[0]


def test_a_run_of_beams_reading_through_cuts_out_that_part():
    scan = wall_scan(slice(30, 36))
    pieces = free_space_cut(WALL, scan)
    # Hand-computed reference: the beams cross the wall at y = 2 tan(angle); the cut runs
    # from half way between beams 29 and 30 to half way between beams 35 and 36.
    crossing = 2.0 * np.tan(-0.5 + 0.02 * np.arange(51))
    low, high = 0.5 * (crossing[29] + crossing[30]), 0.5 * (crossing[35] + crossing[36])
    expected = shapely.LineString(WALL.points).difference(
        shapely.LineString([[2.0, low], [2.0, high]])
    )
    result = shapely.MultiLineString([piece.points for piece in pieces])
    assert len(pieces) == 2
    assert shapely.hausdorff_distance(result, expected) < 1e-9


def test_nothing_read_through_cuts_nothing():
    assert free_space_cut(WALL, wall_scan(slice(0, 0))) is None


def test_one_beam_or_a_span_narrower_than_the_gate_cuts_nothing():
    # One beam through: noise, or a reading slipping past.
    assert free_space_cut(WALL, wall_scan(slice(30, 31))) is None
    # Two beams 0.005 rad apart span about 2 cm of the wall: below the 12 cm gate (a person
    # walking past, merged rather than cut).
    assert free_space_cut(WALL, wall_scan(slice(100, 102), step=0.005)) is None


def test_read_through_everywhere_leaves_nothing():
    assert free_space_cut(WALL, wall_scan(slice(None))) == []


def test_grazing_beams_past_an_end_cut_nothing():
    # A face seen almost edge-on (beams 3-5 deg off its line) from beside its end: a
    # centimetre of lateral error moves where those beams cross it by decimetres, so
    # reading past it is no evidence against it.
    face = Polyline([[0.5, 0.05], [3.0, 0.2]])
    angles = np.radians(np.arange(-5.0, 5.01, 0.5))
    scan = Scan(ranges=np.full(angles.size, 6.0), angle_min=angles[0],
                angle_increment=math.radians(0.5))
    assert free_space_cut(face, scan) is None


def pushed_box_map(params: MapperParams) -> list[shapely.LineString]:
    """Map a 0.5 m box against a wall at y = -1.0, then pushed 0.5 m east along it."""
    south_wall = wall((-3.0, -1.0), (6.0, -1.0))
    before = scene(south_wall, box((1.25, -0.75), 0.5, 0.5))
    after = scene(south_wall, box((1.75, -0.75), 0.5, 0.5))
    rng = np.random.default_rng(0)
    world = PolylineMap(params)
    for x in np.linspace(0.0, 1.5, 16):
        world.update(cast_scan(before, (x, 0.2, 0.0), noise=0.005, rng=rng), (x, 0.2, 0.0))
    for x in np.linspace(1.5, 0.0, 16):
        world.update(cast_scan(after, (x, 0.2, 0.0), noise=0.005, rng=rng), (x, 0.2, 0.0))
    return [shapely.LineString(line.points) for line in world.polylines().values()
            if len(line) >= 2]


# The old front face (y = -0.5, x 1.0-1.5), where the robot now reads the wall behind; its
# part within visibility_margin of that wall cannot be told from it and may stay.
VACATED = shapely.box(1.05, -0.6, 1.45, -0.4)


def test_a_box_pushed_along_its_wall_leaves_no_old_face_in_the_map():
    # The front face is collinear before and after the push, so no scan contradicts the
    # old map polyline's ends; the free space where the box stood is read through.
    lines = pushed_box_map(PARAMS)
    assert lines
    assert not any(line.intersects(VACATED) for line in lines)
    # The box is still mapped where it stands now: its front face at y = -0.5.
    front = shapely.LineString([[1.55, -0.5], [1.95, -0.5]])
    assert any(shapely.hausdorff_distance(front, line.intersection(front.buffer(0.05))) < 0.05
               for line in lines if line.intersects(front.buffer(0.05)))


def test_the_cut_is_an_option():
    # Without it the old face stays (the defect the cut removes).
    lines = pushed_box_map(PARAMS.replace(free_space_cut=False))
    assert any(line.intersects(VACATED) for line in lines)


@pytest.mark.parametrize("value", ["yes", 1])
def test_the_option_is_validated(value):
    with pytest.raises(ValueError, match="free_space_cut"):
        MapperParams(free_space_cut=value)


def geos_expected_ranges(points, scan, pose):
    """Range at which each beam first meets ``points`` (map frame), by GEOS intersection."""
    line = shapely.LineString(points)
    origin = shapely.Point(pose[0], pose[1])
    ranges = np.full(scan.ranges.size, np.inf)
    for beam, angle in enumerate(pose[2] + scan.angles()):
        far = (pose[0] + 100.0 * math.cos(angle), pose[1] + 100.0 * math.sin(angle))
        hit = line.intersection(shapely.LineString([(pose[0], pose[1]), far]))
        if not hit.is_empty:
            ranges[beam] = min(origin.distance(part) for part in shapely.get_parts(hit))
    return ranges


@pytest.mark.parametrize("seed", range(12))
def test_beam_counts_of_many_polylines_match_geos(seed):
    # Several polylines in one compiled pass, anywhere around the sensor (behind it,
    # across the +-pi cut, included), against ray intersections by GEOS.
    rng = np.random.default_rng(seed)
    world = scene(box(tuple(rng.uniform(-3.0, 3.0, 2)), 1.0, 0.6, rng.uniform(0, 3)),
                  wall((-4.0, 2.5), (4.0, 2.5)))
    pose = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(-math.pi, math.pi)])
    scan = cast_scan(world, pose, noise=0.01, rng=rng)
    lines = [Polyline(rng.uniform(-4.0, 4.0, (int(rng.integers(2, 6)), 2))) for _ in range(4)]
    params = MapperParams()
    seen = visibility(lines, scan, pose, params)
    for k, line in enumerate(lines):
        expected = geos_expected_ranges(line.points, scan, pose)
        in_view = (expected >= scan.range_min) & (expected <= min(scan.range_max,
                                                                  params.max_range))
        margin = params.visibility_margin
        unoccluded = in_view & (scan.ranges >= expected - margin)
        seen_through = unoccluded & (scan.ranges > expected + margin)
        counts = (seen.in_view[k], seen.unoccluded[k], seen.seen_through[k])
        assert counts == (in_view.sum(), unoccluded.sum(), seen_through.sum())
        # docs/design.md#detail-10: should have been visible, and read through.
        visible = unoccluded.sum() >= max(params.min_points,
                                          math.ceil(MIN_VISIBLE_FRACTION * in_view.sum()))
        read_through = seen_through.sum() >= MISSING_FRACTION * unoccluded.sum()
        assert seen.missing[k] == (unoccluded.any() and visible and read_through)


def test_many_polylines_are_cut_as_each_alone():
    # In one pass, the wall between others gets the hand-computed cut of the first test
    # and the others are cut nowhere.
    far, point = Polyline([[9.0, -1.0], [9.0, 1.0]]), Polyline([[2.0, 0.3]])
    scan = wall_scan(slice(30, 36))
    seen = visibility([far, point, WALL, far], scan, ORIGIN, PARAMS)
    assert [seen.pieces[k] for k in (0, 1, 3)] == [None, None, None]
    crossing = 2.0 * np.tan(-0.5 + 0.02 * np.arange(51))
    low, high = 0.5 * (crossing[29] + crossing[30]), 0.5 * (crossing[35] + crossing[36])
    pieces = np.array([piece.points for piece in seen.pieces[2]])
    np.testing.assert_allclose(pieces, [[[2.0, -1.0], [2.0, low]], [[2.0, high], [2.0, 1.0]]],
                               atol=1e-12)
    # Each alone: the same pieces and counts.
    np.testing.assert_array_equal(
        np.array([piece.points for piece in free_space_cut(WALL, scan)]), pieces
    )
    for k, line in enumerate((far, point, WALL, far)):
        alone = visibility([line], scan, ORIGIN, PARAMS)
        assert (alone.in_view[0], alone.unoccluded[0], alone.seen_through[0],
                alone.missing[0]) == (seen.in_view[k], seen.unoccluded[k],
                                      seen.seen_through[k], seen.missing[k])


def test_beams_past_a_corner_level_with_its_face_cut_nothing():
    # warehouse_fleet's carton_south: the sensor comes level with the box's west face and
    # its beams pass the corner by millimetres, along that face, to the rack behind. The
    # map's corner lies 1.1 cm off the true one (within epsilon), so those beams cross the
    # map's south face a few millimetres from the corner at a steep angle: not evidence
    # against the west face, which must stay.
    true_box = box((3.0, 0.845), 0.6, 0.51)
    rack = wall((0.0, 1.65), (6.0, 1.65))
    mapped = Polyline([[3.3, 1.1], [3.3, 0.59], [2.689, 0.59], [2.689, 1.1]])
    pose = (2.696, 0.0, 0.0)
    scan = cast_scan(scene(true_box, rack), pose)
    # Reference (GEOS): some beams cross the mapped polyline and read the rack far beyond.
    angles = scan.angle_min + scan.angle_increment * np.arange(scan.ranges.size)
    line = shapely.LineString(mapped.points)
    through = 0
    for angle, reading in zip(angles, scan.ranges, strict=True):
        ray = shapely.LineString([pose[:2], [pose[0] + 10.0 * math.cos(angle),
                                             pose[1] + 10.0 * math.sin(angle)]])
        crossing = ray.intersection(line)
        if not crossing.is_empty and np.isfinite(reading):
            first = min(math.dist(pose[:2], point.coords[0])
                        for point in getattr(crossing, "geoms", [crossing]))
            through += reading > first + PARAMS.visibility_margin
    assert through >= 2
    assert free_space_cut(mapped, scan, pose) is None
