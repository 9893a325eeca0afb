"""The warehouse world: size, a closed one-way loop, segments, posts, boxes, the worker."""

import numpy as np
import shapely

from robots.presets import LGV
from worlds import load_world
from worlds.checks import (
    Clearances,
    fields_along_path,
    layout_problems,
    path_poses,
    spline_of,
    visible_post_counts,
)

WORLD = load_world("warehouse")


def test_hall_is_about_40_by_25_m():
    walls = shapely.union_all([shapely.LineString([w.start, w.end]) for w in WORLD.walls])
    xmin, ymin, xmax, ymax = walls.bounds
    assert (xmax - xmin, ymax - ymin) == (40.0, 25.0)


def test_route_is_a_closed_loop_of_at_least_eight_segments_driven_one_way():
    path = spline_of(WORLD.path)
    assert path.closed
    assert len(WORLD.path.segments) >= 8
    np.testing.assert_allclose(path.pose(0.0), path.pose(path.length), atol=1e-9)
    # One way round, counter-clockwise: the signed area the loop encloses is positive.
    points = path.point(np.linspace(0.0, path.length, 2000))
    x, y = points.T
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0.0
    # Heading and curvature join smoothly at the seam (C2 periodic spline).
    assert abs(path.curvature(0.0) - path.curvature(path.length)) < 1e-6


def test_three_posts_in_view_everywhere_on_the_route():
    counts = visible_post_counts(WORLD, path_poses(WORLD.path, 0.05))
    assert counts.min() >= 3


def test_layout_passes_every_check_for_the_lgv():
    assert layout_problems(WORLD, footprint=np.array(LGV.footprint), clearances=Clearances()) == []


def test_every_box_is_in_a_warning_field_and_both_workers_cross_the_lane():
    warning, _ = fields_along_path(WORLD.path, 0.05)
    union = shapely.union_all(list(warning))
    for box in WORLD.boxes:
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * np.array(box.size[:2]) / 2
        footprint = shapely.Polygon(corners + np.array(box.pose[:2]))
        assert union.intersection(footprint).area > 0.01, box.name
    people = {person.name: person for person in WORLD.people}
    assert set(people) == {"worker", "hiding_worker"}
    lane = shapely.LineString(path_poses(WORLD.path, 0.05)[:, :2]).buffer(0.5)
    for person in people.values():
        assert lane.intersects(shapely.LineString(person.waypoints)), person.name
    # The hiding worker waits with their whole body outside every warning field.
    hiding = people["hiding_worker"]
    assert not union.intersects(shapely.Point(hiding.waypoints[0]).buffer(hiding.radius))
