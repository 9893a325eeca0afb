"""Fitted vertices (semistatic.fitting) against SVD line fits and known geometry."""

import numpy as np
import pytest
import shapely

from semistatic.extraction import douglas_peucker, extract_polylines
from semistatic.fitting import fit_polylines, is_mixed_pixel, total_least_squares
from semistatic.params import MapperParams
from tests.semistatic.synthetic import box, box_corners, cast_scan, scene, wall


def fit_polyline(points, corners, epsilon):
    """The fit of one polyline: ``fit_polylines`` of one interval, vertices and positions."""
    points = np.asarray(points, dtype=float)
    vertices, kept, _ = fit_polylines(points, np.zeros(len(points), np.int64), corners, epsilon)
    return vertices, kept


def svd_line(points):
    centroid = points.mean(axis=0)
    _, _, rows = np.linalg.svd(points - centroid)
    return centroid, rows[0]


@pytest.mark.parametrize("seed", range(10))
def test_total_least_squares_matches_an_svd_fit(seed):
    rng = np.random.default_rng(seed)
    count = int(rng.integers(2, 40))
    direction = rng.normal(size=2)
    points = rng.normal(size=(1, 2)) + np.outer(rng.uniform(-2, 2, count), direction)
    points += rng.normal(0.0, 0.05, points.shape)
    centroid, unit = total_least_squares(points)
    expected_centroid, expected_unit = svd_line(points)
    np.testing.assert_allclose(centroid, expected_centroid, atol=1e-12)
    assert abs(unit @ expected_unit) == pytest.approx(1.0, abs=1e-9)


def test_total_least_squares_rejects_degenerate_input():
    with pytest.raises(ValueError, match="at least 2"):
        total_least_squares([[1.0, 2.0]])
    with pytest.raises(ValueError, match="all points are equal"):
        total_least_squares([[1.0, 2.0], [1.0, 2.0]])


def noisy_corner(rng, noise=0.01, step=0.05):
    """Readings of a right-angle corner at (2, 0) seen from the origin, in scan order."""
    along = np.arange(0.0, 0.8 + 1e-9, step)
    first = np.column_stack((2.0 + 0.0 * along, -0.8 + along))
    second = np.column_stack((2.0 + 0.6 * along[1:], 0.8 * along[1:]))
    return np.vstack((first, second)) + rng.normal(0.0, noise, (2 * along.size - 1, 2))


def test_an_inner_vertex_lands_nearer_the_true_corner_than_the_raw_reading():
    fitted_errors, raw_errors = [], []
    for seed in range(30):
        points = noisy_corner(np.random.default_rng(seed))
        corners = douglas_peucker(points, 0.03)
        vertices, kept = fit_polyline(points, corners, 0.03)
        inner = np.argmin(np.hypot(*(points[kept] - [2.0, 0.0]).T))
        fitted_errors.append(np.hypot(*(vertices[inner] - [2.0, 0.0])))
        raw_errors.append(np.hypot(*(points[kept][inner] - [2.0, 0.0])))
    fitted = np.sqrt(np.mean(np.square(fitted_errors)))
    raw = np.sqrt(np.mean(np.square(raw_errors)))
    assert fitted < 0.6 * raw


MIN_SINE = np.sin(np.radians(10.0))


def ray_weighted_line(points):
    """The line fitted along the beams: SVD, weights 1 / sine^2 of the SVD line's incidence."""
    _, direction = svd_line(points)
    sines = np.abs(points[:, 0] * direction[1] - points[:, 1] * direction[0]) / np.hypot(*points.T)
    weights = 1.0 / np.maximum(sines, MIN_SINE) ** 2
    centroid = weights @ points / weights.sum()
    _, _, rows = np.linalg.svd(np.sqrt(weights)[:, None] * (points - centroid))
    return centroid, rows[0]


def expected_end_vertex(edge, epsilon):
    """The end vertex of ``edge`` (readings, the end reading first) by weighted SVD and a 2x2
    solve."""
    centroid, direction = ray_weighted_line(edge)
    reading = edge[0]
    # beam: t * reading = centroid + s * direction
    t, _ = np.linalg.solve(np.column_stack((reading, -direction)), centroid)
    crossing = t * reading
    outward = np.sign((reading - edge[-1]) @ direction) * direction
    return crossing if (crossing - reading) @ outward <= epsilon else reading


@pytest.mark.parametrize("seed", range(10))
def test_end_vertices_are_the_beam_crossing_unless_it_reaches_past_the_end_reading(seed):
    # epsilon 1 cm at 1 cm noise: both rules are exercised over the seeds
    points = noisy_corner(np.random.default_rng(seed))
    vertices, kept = fit_polyline(points, douglas_peucker(points, 0.03), 0.01)
    first = points[kept[0] : kept[1] + 1]
    last = points[kept[-2] : kept[-1] + 1][::-1]
    np.testing.assert_allclose(vertices[0], expected_end_vertex(first, 0.01), atol=1e-9)
    np.testing.assert_allclose(vertices[-1], expected_end_vertex(last, 0.01), atol=1e-9)
    for vertex, reading in ((vertices[0], first[0]), (vertices[-1], last[0])):
        cross = vertex[0] * reading[1] - vertex[1] * reading[0]
        assert abs(cross) < 1e-12 * np.hypot(*reading) + 1e-12  # on the end reading's beam
        assert vertex @ reading > 0.0  # the same side of the sensor


def test_a_box_corner_seen_obliquely_does_not_stretch_the_face_past_it():
    # sim2's carton_bend at the end of the chicane: the scan's first beams graze the
    # box's near face beyond its corner, within epsilon of the far face's line, so one
    # polyline holds both; the first beam's crossing with the fitted face ran 8 cm past
    # the corner while the noise is 1 cm
    center, side = (3.6, -1.6), 0.5
    segments = scene(box(center, side, side))
    outline = shapely.Polygon(box_corners(center, side, side)).exterior
    corner = shapely.Point(center[0] + side / 2, center[1] + side / 2)
    for heading in (0.478, 0.5):
        for seed in range(30):
            pose = (4.064, -0.549, heading)
            scan = cast_scan(segments, pose, noise=0.01, rng=np.random.default_rng(seed))
            # the polyline that starts at the scan's first beam, or at the second where the
            # first grazes the near face as a one-reading hook (a mixed-pixel end: dropped);
            # others are isolated noise-split readings of the far face
            (line,) = [line for line in extract_polylines(scan) if line.scan_indices[0] <= 1]
            cos, sin = np.cos(heading), np.sin(heading)
            world = line.points @ np.array([[cos, sin], [-sin, cos]]) + pose[:2]
            first = scan.ranges[0] * np.array(
                [np.cos(heading + scan.angle_min), np.sin(heading + scan.angle_min)]
            ) + pose[:2]
            # the geometry under test: the first reading lies on the near face, by the corner
            assert first[0] < corner.x
            assert first[1] > corner.y - 0.03
            for end in (world[0], world[-1]):
                assert outline.distance(shapely.Point(end)) < 0.03


def test_adjacent_edges_one_line_fits_are_merged():
    rng = np.random.default_rng(0)
    points = np.column_stack((np.full(41, 3.0), np.linspace(-1.0, 1.0, 41)))
    points[:, 0] += rng.normal(0.0, 0.005, 41)
    vertices, kept = fit_polyline(points, [0, 10, 20, 30, 40], 0.03)
    assert kept.tolist() == [0, 40]
    assert np.abs(vertices[:, 0] - 3.0).max() < 0.01
    # a tolerance below the noise keeps the corners; collinear lines fall back to the
    # corner readings' projections instead of an ill-conditioned intersection
    vertices, kept = fit_polyline(points, [0, 10, 20, 30, 40], 1e-4)
    assert len(kept) > 2
    assert np.all(np.hypot(*(vertices - points[kept]).T) < 0.02)


def test_fit_polylines_rejects_bad_corners_and_intervals():
    points = [[1.0, 0.0], [1.0, 0.1], [1.0, 0.2]]
    with pytest.raises(ValueError, match="corners must increase"):
        fit_polyline(points, [0, 1], 0.03)
    with pytest.raises(ValueError, match="epsilon"):
        fit_polyline(points, [0, 2], 0.0)
    with pytest.raises(ValueError, match="corners must increase"):  # no corner ends line 0
        fit_polylines([*points, [1.0, 0.3]], [0, 0, 1, 1], [0, 3], 0.03)
    with pytest.raises(ValueError, match="line_ids"):  # an interval of one reading
        fit_polylines(points, [0, 0, 1], [0, 1, 2], 0.03)


def test_many_intervals_are_fitted_as_each_alone():
    rng = np.random.default_rng(2)
    intervals = []
    for k in range(4):
        count = int(rng.integers(3, 12))
        angles = np.linspace(-0.3, 0.3, count) + k
        ranges = rng.uniform(1.0, 3.0) + 0.01 * rng.normal(size=count)
        intervals.append(np.column_stack((ranges * np.cos(angles), ranges * np.sin(angles))))
    corners = [douglas_peucker(points, 0.005) for points in intervals]
    starts = np.cumsum([0] + [len(points) for points in intervals[:-1]])
    together = fit_polylines(
        np.concatenate(intervals), np.repeat(np.arange(4), [len(p) for p in intervals]),
        np.concatenate([kept + start for kept, start in zip(corners, starts, strict=True)]),
        0.01,
    )
    for number, (points, kept, start) in enumerate(zip(intervals, corners, starts, strict=True)):
        vertices, alone = fit_polyline(points, kept, 0.01)
        mine = together[2] == number
        np.testing.assert_array_equal(together[0][mine], vertices)
        np.testing.assert_array_equal(together[1][mine], alone + start)


def test_fitted_box_outline_is_closer_to_the_truth_than_raw_vertices():
    # a box seen corner-on: two faces; error of the vertices to the box outline
    segments = scene(box((3.0, 0.0), 1.0, 0.8, yaw=0.5))
    corners = box_corners((3.0, 0.0), 1.0, 0.8, yaw=0.5)
    errors = {"fitted": [], "raw": []}
    for seed in range(20):
        scan = cast_scan(segments, (0.0, 0.0, 0.0), noise=0.01, rng=np.random.default_rng(seed))
        for placement, bucket in errors.items():
            lines = extract_polylines(scan, MapperParams(vertex_placement=placement))
            assert len(lines) == 1
            vertices = lines[0].points
            offsets = vertices[:, None, :] - corners[None]
            near = np.hypot(offsets[..., 0], offsets[..., 1]).min(axis=1)
            bucket.append(near[1:-1])  # inner vertices are box corners
    fitted = np.sqrt(np.mean(np.square(np.concatenate(errors["fitted"]))))
    raw = np.sqrt(np.mean(np.square(np.concatenate(errors["raw"]))))
    assert fitted < 0.6 * raw


def test_a_two_reading_object_becomes_a_polyline():
    # a 4 cm pole 3 m ahead, in front of a wall: two beams hit it
    segments = scene(wall((5.0, -3.0), (5.0, 3.0)), box((3.0, 0.0131), 0.04, 0.04))
    scan = cast_scan(segments, (0.0, 0.0, 0.0))
    hits = np.flatnonzero(scan.ranges < 3.1)
    assert hits.size == 2
    lines = extract_polylines(scan)
    assert [line.scan_indices.tolist() for line in lines if line.points[:, 0].max() < 3.1] == [
        hits.tolist()
    ]


def wall_with_end_reading(end_range, rng, count=21):
    """Readings of the wall x = 2 on beams 1 deg apart, the last beam reading ``end_range``.

    ``end_range=None`` leaves the last beam on the wall too.
    """
    angles = np.radians(np.arange(count) - count // 2)
    ranges = 2.0 / np.cos(angles) + rng.normal(0.0, 0.003, count)
    if end_range is not None:
        ranges[-1] = end_range
    return np.column_stack((ranges * np.cos(angles), ranges * np.sin(angles)))


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("reverse", [False, True])
def test_a_mixed_pixel_at_an_end_is_left_out_and_no_edge_crosses_its_ray(seed, reverse):
    rng = np.random.default_rng(seed)
    # the last beam returns 25 cm beyond the wall: between its edge and the background
    wall_range = 2.0 / np.cos(np.radians(10.0))
    points = wall_with_end_reading(wall_range + 0.25, rng)
    if reverse:
        points = points[::-1].copy()
    mixed = 0 if reverse else points.shape[0] - 1
    vertices, kept = fit_polyline(points, douglas_peucker(points, 0.01), 0.01)
    assert mixed not in kept.tolist()
    ray = shapely.LineString([(0.0, 0.0), points[mixed]])
    assert not shapely.LineString(vertices).intersects(ray)
    # the polyline is the wall, ending on the beam of the reading next to the mixed pixel
    assert np.abs(vertices[:, 0] - 2.0).max() < 0.01
    neighbour = points[1] if reverse else points[-2]
    end = vertices[0] if reverse else vertices[-1]
    assert abs(end[0] * neighbour[1] - end[1] * neighbour[0]) < 1e-9


@pytest.mark.parametrize("end_offset", [-0.25, 0.0])
def test_an_end_reading_in_front_of_the_line_or_on_it_is_kept(end_offset):
    # in front of the wall (the far side of a mixed pixel belongs to a nearer surface,
    # which the reading would also fit) or on it: a surface the polyline must reach
    rng = np.random.default_rng(0)
    wall_range = 2.0 / np.cos(np.radians(10.0))
    points = wall_with_end_reading(wall_range + end_offset, rng)
    corners = douglas_peucker(points, 0.01)
    if end_offset:
        assert corners[-2] == points.shape[0] - 2  # a one-reading end edge
    _, kept = fit_polyline(points, corners, 0.01)
    assert kept[-1] == points.shape[0] - 1


def test_a_corner_whose_next_face_turns_across_the_beam_is_kept():
    # one reading on a face that turns 90 deg at the wall's end (a real box corner seen
    # by one beam): the step to it is far from its beam, so it is no mixed pixel
    rng = np.random.default_rng(1)
    points = wall_with_end_reading(None, rng)
    last_beam = np.arctan2(points[-1, 1], points[-1, 0]) + np.radians(1.0)
    corner = points[-1]
    # the next face: x grows from the corner along y = corner y
    hook = np.array([corner[1] / np.tan(last_beam), corner[1]])
    points = np.vstack((points, hook))
    assert not is_mixed_pixel(points, points.shape[0] - 1, points.shape[0] - 2, 0)
    corners = douglas_peucker(points, 0.01)
    assert corners[-2] == points.shape[0] - 2  # a one-reading end edge
    _, kept = fit_polyline(points, corners, 0.01)
    assert kept[-1] == points.shape[0] - 1


def test_is_mixed_pixel_rejects_positions_that_are_not_an_end_step():
    points = [[2.0, -0.1], [2.0, 0.0], [2.0, 0.1], [2.3, 0.2]]
    with pytest.raises(ValueError, match="next to corner"):
        is_mixed_pixel(points, end=3, corner=1, far=0)
    with pytest.raises(ValueError, match="next to corner"):
        is_mixed_pixel(points, end=1, corner=2, far=0)
    with pytest.raises(ValueError, match="lie in"):
        is_mixed_pixel(points, end=4, corner=3, far=0)


def test_a_wall_seen_obliquely_is_fitted_along_the_beams():
    # range noise lies along the beams: a wall seen from 10 to 80 deg incidence has its
    # grazing readings' noise mostly along the wall, and the fit that weights them by
    # 1 / sine^2 errs less along the rays than plain total least squares
    angles = np.radians(np.arange(10.0, 81.0, 1.0))
    beams = np.column_stack((np.cos(angles), np.sin(angles)))
    ranges = 2.0 / beams[:, 1]  # the wall y = 2
    fitted_rms, plain_rms = [], []
    for seed in range(30):
        noisy = ranges + np.random.default_rng(seed).normal(0.0, 0.02, ranges.size)
        points = noisy[:, None] * beams
        vertices, _ = fit_polyline(points, [0, points.shape[0] - 1], 0.1)
        for rms, (origin, direction) in (
            (fitted_rms, (vertices[0], vertices[1] - vertices[0])),
            (plain_rms, total_least_squares(points)),
        ):
            # each beam's crossing with the line against the true wall's
            t = (origin[0] * direction[1] - origin[1] * direction[0]) / (
                beams[:, 0] * direction[1] - beams[:, 1] * direction[0])
            rms.append(np.sqrt(np.mean((t - ranges) ** 2)))
    assert np.mean(fitted_rms) < 0.9 * np.mean(plain_rms)  # measured: 0.80
