"""Every bundled world is a usable testbench: the acceptance geometry of issue 3.

The robot is a Pioneer 3-DX (base 0.455 m x 0.381 m, base_link at the wheel axle about the
body centre). Geometry is checked with shapely every ``PATH_STEP`` metres along the path;
a segment's field at arc length ``s`` is its robot-frame polygon moved to ``path.pose(s)``.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import shapely

from robots.path import SplinePath
from semistatic.frames import transform_points, wrap_angle
from worlds import bundled_worlds, load_world
from worlds.spec import PersonSpec, WorldSpec

PATH_STEP = 0.05  # m between checked path poses
PATH_LENGTH_RANGE = (9.0, 12.0)  # m, "approximately 9-12 m" (paper Sec. 6)
FOOTPRINT_HALF_LENGTH = 0.455 / 2  # Pioneer 3-DX base, m
FOOTPRINT_HALF_WIDTH = 0.381 / 2
MIN_VISIBLE_POSTS = 3  # three-object triangulation needs three (paper Sec. 5.1)
POST_RANGE = 15.0  # m
FIELD_OF_VIEW = np.radians(270.0)
PROTECTIVE_CLEARANCE = 0.05  # m between a box and any protective field
FOOTPRINT_CLEARANCE = 0.10  # m between the swept robot footprint and boxes or walls

FOOTPRINT = shapely.box(
    -FOOTPRINT_HALF_LENGTH, -FOOTPRINT_HALF_WIDTH, FOOTPRINT_HALF_LENGTH, FOOTPRINT_HALF_WIDTH
)


@cache
def world_and_path(name: str) -> tuple[WorldSpec, SplinePath]:
    world = load_world(name)
    return world, SplinePath(world.path.knots)


def path_poses(path: SplinePath) -> np.ndarray:
    return path.sample(PATH_STEP)[1]


def placed(polygon: shapely.Polygon, pose: np.ndarray) -> shapely.Polygon:
    """Return a robot-frame polygon moved to the world-frame ``pose``."""
    return shapely.Polygon(transform_points(pose, np.asarray(polygon.exterior.coords)))


def segment_indices(world: WorldSpec, path: SplinePath, s: np.ndarray) -> np.ndarray:
    """Return the segment driven at each arc length ``s`` (the last one owns the end)."""
    starts = np.array([path.knot_s[seg.start_knot] for seg in world.path.segments])
    return np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(starts) - 1)


@cache
def fields_along_path(name: str) -> tuple[list[shapely.Polygon], list[shapely.Polygon]]:
    """Return the warning and protective fields (world frame) at every checked pose."""
    world, path = world_and_path(name)
    s, poses = path.sample(PATH_STEP)
    segments = [world.path.segments[i] for i in segment_indices(world, path, s)]
    warning = [
        placed(seg.warning_polygon(), pose) for seg, pose in zip(segments, poses, strict=True)
    ]
    protective = [
        placed(seg.protective_polygon(), pose) for seg, pose in zip(segments, poses, strict=True)
    ]
    return warning, protective


def wall_polygons(world: WorldSpec) -> list[shapely.Polygon]:
    return [shapely.Polygon(wall.corners()) for wall in world.walls]


def box_polygons(world: WorldSpec) -> list[shapely.Polygon]:
    return [shapely.Polygon(box.corners()) for box in world.boxes]


def post_discs(world: WorldSpec) -> list[shapely.Polygon]:
    return [shapely.Point(post.xy).buffer(post.radius) for post in world.posts]


def visible_post_counts(world: WorldSpec, poses: np.ndarray) -> np.ndarray:
    """Return how many posts each pose sees: in range, in the field of view, unoccluded.

    The line of sight from the pose to a post's centre must not cross a wall or a box.
    """
    posts = np.array([post.xy for post in world.posts])
    offsets = posts[None, :, :] - poses[:, None, :2]
    distance = np.linalg.norm(offsets, axis=2)
    bearing = wrap_angle(np.arctan2(offsets[..., 1], offsets[..., 0]) - poses[:, 2:3])
    candidate = (distance <= POST_RANGE) & (np.abs(bearing) <= FIELD_OF_VIEW / 2)
    blockers = shapely.union_all(wall_polygons(world) + box_polygons(world))
    shapely.prepare(blockers)
    rows, cols = np.nonzero(candidate)
    starts = poses[rows, :2]
    sight = shapely.linestrings(np.stack([starts, posts[cols]], axis=1))
    clear = ~shapely.intersects(blockers, sight)
    counts = np.zeros(len(poses), dtype=int)
    np.add.at(counts, rows[clear], 1)
    return counts


def swept_footprint(path: SplinePath) -> shapely.Geometry:
    return shapely.union_all([placed(FOOTPRINT, pose) for pose in path_poses(path)])


@pytest.fixture(params=bundled_worlds())
def name(request: pytest.FixtureRequest) -> str:
    return request.param


def test_bundled_worlds_are_the_papers_environments():
    assert bundled_worlds() == ("pal1", "pal3", "sim1", "sim2")


def test_world_loads_with_its_name_and_source(name):
    world, _ = world_and_path(name)
    assert world.name == name
    assert world.source.endswith(f"{name}.toml")
    assert world.description
    assert 2 <= len(world.path.segments) <= 4
    assert 2 <= len(world.boxes) <= 4


def test_path_length_is_9_to_12_m(name):
    _, path = world_and_path(name)
    assert PATH_LENGTH_RANGE[0] <= path.length <= PATH_LENGTH_RANGE[1]


def test_path_curvature_is_gentle(name):
    _, path = world_and_path(name)
    s = np.linspace(0.0, path.length, 500)
    # A Pioneer at 0.4 m/s turning at 1 rad/s max: radius >= 0.4 m, keep well above.
    assert np.max(np.abs(path.curvature(s))) < 1.0


def test_fields_suit_a_pioneer_3dx(name):
    world, _ = world_and_path(name)
    for segment in world.path.segments:
        protective = np.array(segment.protective)
        warning = np.array(segment.warning)
        assert protective[:, 0].min() >= FOOTPRINT_HALF_LENGTH
        assert protective[:, 0].max() <= 0.6
        assert np.abs(protective[:, 1]).max() <= 0.3
        assert np.abs(protective[:, 1]).max() >= FOOTPRINT_HALF_WIDTH  # covers the body width
        assert warning[:, 0].max() <= 1.4
        assert np.abs(warning[:, 1]).max() <= 0.5


def test_at_least_three_posts_visible_from_every_path_point(name):
    world, path = world_and_path(name)
    counts = visible_post_counts(world, path_poses(path))
    assert counts.min() >= MIN_VISIBLE_POSTS, f"worst pose sees {counts.min()} posts"


def test_every_box_enters_some_warning_field(name):
    world, _ = world_and_path(name)
    warning, _ = fields_along_path(name)
    tree = shapely.STRtree(warning)
    for box, polygon in zip(world.boxes, box_polygons(world), strict=True):
        hits = tree.query(polygon, predicate="intersects")
        assert hits.size > 0, f"box {box.name} never enters a warning field"
        assert max(warning[i].intersection(polygon).area for i in hits) > 0.01


def test_no_box_comes_near_a_protective_field(name):
    world, _ = world_and_path(name)
    _, protective = fields_along_path(name)
    protective_union = shapely.union_all(protective)
    for box, polygon in zip(world.boxes, box_polygons(world), strict=True):
        gap = protective_union.distance(polygon)
        assert gap >= PROTECTIVE_CLEARANCE, f"box {box.name} is {gap:.3f} m from a protective field"


def test_static_environment_stays_out_of_warning_fields(name):
    world, _ = world_and_path(name)
    warning, _ = fields_along_path(name)
    static = shapely.union_all(wall_polygons(world) + post_discs(world))
    assert not any(static.intersects(field) for field in warning)


def test_robot_footprint_clears_boxes_and_walls(name):
    world, path = world_and_path(name)
    swept = swept_footprint(path)
    for box, polygon in zip(world.boxes, box_polygons(world), strict=True):
        assert swept.distance(polygon) >= FOOTPRINT_CLEARANCE, f"box {box.name}"
    for index, polygon in enumerate(wall_polygons(world)):
        assert swept.distance(polygon) >= FOOTPRINT_CLEARANCE, f"walls[{index}]"


def test_boxes_and_posts_stand_free(name):
    world, _ = world_and_path(name)
    walls = shapely.union_all(wall_polygons(world))
    solids = box_polygons(world) + post_discs(world)
    for index, polygon in enumerate(solids):
        assert walls.intersection(polygon).area == 0.0, f"solid {index} cuts a wall"
        for other in solids[index + 1 :]:
            assert polygon.intersection(other).area == 0.0


def test_people_walk_in_free_space(name):
    world, _ = world_and_path(name)
    obstacles = shapely.union_all(wall_polygons(world) + box_polygons(world) + post_discs(world))
    for person in world.people:
        walk = shapely.LineString(person.waypoints) if len(person.waypoints) > 1 else None
        body = (walk or shapely.Point(person.waypoints[0])).buffer(person.radius)
        assert not body.intersects(obstacles), f"person {person.name} walks into an obstacle"


def walker_position(person: PersonSpec, t: float) -> np.ndarray:
    """Return where a non-looping person is at time ``t`` (s since the lap began)."""
    waypoints = np.asarray(person.waypoints)
    steps = np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
    walked = np.clip((t - person.start_time) * person.speed, 0.0, steps.sum())
    ends = np.cumsum(steps)
    leg = min(int(np.searchsorted(ends, walked)), len(steps) - 1)
    into = walked - (ends[leg] - steps[leg])
    return waypoints[leg] + (waypoints[leg + 1] - waypoints[leg]) * into / steps[leg]


def test_pal3_walker_crosses_in_front_of_the_robot_and_leaves():
    world, path = world_and_path("pal3")
    (walker,) = world.people
    assert not walker.enabled
    assert walker.per_lap
    assert not walker.loop
    assert world.enable_people(walker.name).active_people[0].name == walker.name
    # The robot at its nominal speed from the lap start (no slow-down): the walker must
    # pass through its warning field without coming near its body, then leave the path.
    gaps, in_warning = [], False
    for t in np.arange(0.0, 12.0, 0.02):
        s = min(world.path.speed * t, path.length)
        pose = path.pose(s)
        segment = world.path.segments[int(segment_indices(world, path, np.array([s]))[0])]
        body = shapely.Point(walker_position(walker, t)).buffer(walker.radius)
        gaps.append(placed(FOOTPRINT, pose).distance(body))
        in_warning |= placed(segment.warning_polygon(), pose).intersects(body)
    assert in_warning
    assert min(gaps) > 0.3
    path_line = shapely.LineString(path.point(np.linspace(0.0, path.length, 200)))
    assert path_line.distance(shapely.Point(walker.waypoints[-1])) > 2.0
