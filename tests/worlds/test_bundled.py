"""Every bundled world is a usable testbench: the acceptance geometry of issue 3.

The robot is a Pioneer 3-DX (base 0.455 m x 0.381 m, base_link at the wheel axle about the
body centre). The geometry comes from ``worlds.checks``: shapely every ``PATH_STEP`` metres
along the path; a segment's field at arc length ``s`` is its robot-frame polygon moved to
``path.pose(s)``. The last tests make sure those checks catch broken layouts.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import shapely

from robots.path import SplinePath
from worlds import bundled_worlds, load_world
from worlds.checks import (
    PIONEER_FOOTPRINT,
    Clearances,
    box_footprint_gaps,
    box_protective_gaps,
    box_warning_overlaps,
    fields_along_path,
    layout_problems,
    overlapping_solids,
    path_poses,
    people_in_obstacles,
    segment_indices,
    spline_of,
    static_in_warning,
    swept_footprint,
    visible_post_counts,
    wall_footprint_gaps,
)
from worlds.spec import BoxSpec, PersonSpec, WallSpec, WorldSpec

PATH_STEP = 0.05  # m between checked path poses
PATH_LENGTH_RANGE = (9.0, 12.0)  # m, "approximately 9-12 m" (paper Sec. 6)
FOOTPRINT_HALF_LENGTH = 0.455 / 2  # Pioneer 3-DX base, m
FOOTPRINT_HALF_WIDTH = 0.381 / 2
MIN_VISIBLE_POSTS = 3  # three-object triangulation needs three (paper Sec. 5.1)
POST_RANGE = 15.0  # m
FIELD_OF_VIEW = np.radians(270.0)
PROTECTIVE_CLEARANCE = 0.05  # m between a box and any protective field
FOOTPRINT_CLEARANCE = 0.10  # m between the swept robot footprint and boxes or walls
MIN_WARNING_OVERLAP = 0.01  # m2 of a box inside one warning field

# Protective fields by Sick's formula for the Pioneer at the worlds' 0.4 m/s, by hand:
# S_A = 2 scans of 80 ms at 0.4 m/s (0.064 m) + the follower's 1 m/s^2 ramp in 20 ms steps
# (19 steps 0.38 ... 0.02 m/s held 20 ms: 0.076 m) = 0.14 m; S_L = S_A + Z_G + Z_R + Z_F
# from the front of the URDF body (4.5 cm behind the centred footprint's), and at least
# Z_G past the LMS100's blind zone (mounted at x 0.12, nothing nearer than 0.5 m);
# S_B = the body's width + 2 (Z_G + Z_R + Z_F). Z_R only where a post (a retroreflector)
# stands within 1 m of the segment's swept protective field.
PIONEER_FRONT = FOOTPRINT_HALF_LENGTH - 0.045
STOPPING_DISTANCE = 0.4 * 0.16 + 0.02 * sum(0.4 - 0.02 * k for k in range(1, 20))
Z_G, Z_R, Z_F = 0.1, 0.2, 0.15  # general, reflector, ground clearance (6 cm < 12 cm)
REFLECTOR_RANGE = 1.0  # m
BLIND_ZONE_END = 0.12 + 0.5  # m ahead of the axle
FIELD_MARGIN = 0.01  # m a field may exceed the formula: sized by it, not drawn large

FOOTPRINT = shapely.box(
    -FOOTPRINT_HALF_LENGTH, -FOOTPRINT_HALF_WIDTH, FOOTPRINT_HALF_LENGTH, FOOTPRINT_HALF_WIDTH
)


def world_and_path(name: str) -> tuple[WorldSpec, SplinePath]:
    world = load_world(name)
    return world, spline_of(world.path)


PAPER_WORLDS = ("pal1", "pal3", "sim1", "sim2")  # the warehouse has its own tests


@pytest.fixture(params=PAPER_WORLDS)
def name(request: pytest.FixtureRequest) -> str:
    return request.param


def test_bundled_worlds_are_the_papers_environments_the_warehouse_and_the_occlusion_hall():
    assert bundled_worlds() == ("fault_hall", "fault_hall_pallet", "fault_hall_short",
                                "occlusion_hall", *PAPER_WORLDS, "warehouse")


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


def required_protective(near_reflector: bool) -> tuple[float, float]:
    """Return how far ahead of the axle (m) and how wide (m) the formula asks the field."""
    supplements = Z_G + Z_F + (Z_R if near_reflector else 0.0)
    reach = max(PIONEER_FRONT + STOPPING_DISTANCE + supplements, BLIND_ZONE_END + Z_G)
    return reach, 2.0 * FOOTPRINT_HALF_WIDTH + 2.0 * supplements


def test_fields_suit_a_pioneer_3dx(name):
    world, path = world_and_path(name)
    s, _ = path.sample(PATH_STEP)
    driven = segment_indices(world.path, s)
    _, placed = fields_along_path(world.path, PATH_STEP)
    posts = shapely.multipoints([post.xy for post in world.posts])
    for index, segment in enumerate(world.path.segments):
        swept = shapely.union_all([f for f, i in zip(placed, driven, strict=True) if i == index])
        reach, width = required_protective(swept.distance(posts) <= REFLECTOR_RANGE)
        protective = np.array(segment.protective)
        warning = np.array(segment.warning)
        assert protective[:, 0].min() >= FOOTPRINT_HALF_LENGTH, segment.name
        # A rectangle symmetric about the centre line, as long and wide as the formula asks.
        assert shapely.Polygon(protective).equals(shapely.box(*shapely.Polygon(protective).bounds))
        assert protective[:, 1].max() == pytest.approx(-protective[:, 1].min())
        assert reach <= protective[:, 0].max() <= reach + FIELD_MARGIN, segment.name
        assert width <= np.ptp(protective[:, 1]) <= width + FIELD_MARGIN, segment.name
        assert shapely.Polygon(warning).contains(shapely.Polygon(protective)), segment.name
        assert warning[:, 0].max() <= 1.4
        assert np.abs(warning[:, 1]).max() <= 1.0


def test_footprint_constant_is_the_pioneer_base():
    assert shapely.Polygon(PIONEER_FOOTPRINT).equals(FOOTPRINT)


def test_at_least_three_posts_visible_from_every_path_point(name):
    world = load_world(name)
    counts = visible_post_counts(
        world, path_poses(world.path, PATH_STEP), post_range=POST_RANGE, field_of_view=FIELD_OF_VIEW
    )
    assert counts.min() >= MIN_VISIBLE_POSTS, f"worst pose sees {counts.min()} posts"


def test_every_box_enters_some_warning_field(name):
    world = load_world(name)
    warning, _ = fields_along_path(world.path, PATH_STEP)
    overlaps = box_warning_overlaps(world, warning)
    assert list(overlaps) == [box.name for box in world.boxes]
    for box_name, area in overlaps.items():
        assert area > MIN_WARNING_OVERLAP, f"box {box_name} never enters a warning field"


def test_no_box_comes_near_a_protective_field(name):
    world = load_world(name)
    _, protective = fields_along_path(world.path, PATH_STEP)
    gaps = box_protective_gaps(world, protective)
    assert list(gaps) == [box.name for box in world.boxes]
    for box_name, gap in gaps.items():
        assert gap >= PROTECTIVE_CLEARANCE, f"box {box_name} is {gap:.3f} m from a protective field"


def test_static_environment_stays_out_of_warning_fields(name):
    world = load_world(name)
    warning, _ = fields_along_path(world.path, PATH_STEP)
    assert static_in_warning(world, warning) == []


def test_robot_footprint_clears_boxes_and_walls(name):
    world = load_world(name)
    swept = swept_footprint(world.path, PIONEER_FOOTPRINT, PATH_STEP)
    box_gaps = box_footprint_gaps(world, swept)
    assert len(box_gaps) == len(world.boxes)
    for box_name, gap in box_gaps.items():
        assert gap >= FOOTPRINT_CLEARANCE, f"box {box_name}"
    wall_gaps = wall_footprint_gaps(world, swept)
    assert wall_gaps.shape == (len(world.walls),)
    for index, gap in enumerate(wall_gaps):
        assert gap >= FOOTPRINT_CLEARANCE, f"walls[{index}]"


def test_boxes_and_posts_stand_free(name):
    assert overlapping_solids(load_world(name)) == []


def test_people_walk_in_free_space(name):
    assert people_in_obstacles(load_world(name)) == {}


def test_layout_has_no_problems_with_the_test_limits(name):
    limits = Clearances(
        protective=PROTECTIVE_CLEARANCE,
        footprint=FOOTPRINT_CLEARANCE,
        min_warning_overlap=MIN_WARNING_OVERLAP,
        min_visible_posts=MIN_VISIBLE_POSTS,
        post_range=POST_RANGE,
        field_of_view=float(FIELD_OF_VIEW),
        path_step=PATH_STEP,
    )
    assert Clearances() == limits  # the library defaults are the acceptance numbers
    assert layout_problems(load_world(name), footprint=PIONEER_FOOTPRINT, clearances=limits) == []


def walker_position(person: PersonSpec, t: float) -> np.ndarray:
    """Return where a non-looping person is at time ``t`` (s since the lap began)."""
    waypoints = np.asarray(person.waypoints)
    steps = np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
    walked = np.clip((t - person.start_time) * person.speed, 0.0, steps.sum())
    ends = np.cumsum(steps)
    leg = min(int(np.searchsorted(ends, walked)), len(steps) - 1)
    into = walked - (ends[leg] - steps[leg])
    return waypoints[leg] + (waypoints[leg + 1] - waypoints[leg]) * into / steps[leg]


def test_pal3_walker_works_in_the_robots_lane_then_leaves():
    world, path = world_and_path("pal3")
    (walker,) = world.people
    assert not walker.enabled
    assert walker.per_lap
    assert not walker.loop
    assert world.enable_people(walker.name).active_people[0].name == walker.name
    # While the walker is in the hallway they stay in the robot's lane (|y| < 0.55 m: the
    # protective half-width 0.3 m plus their radius), so the robot meets them head-on and
    # never from the side; then they leave the path for good.
    lane = 0.3 + walker.radius
    times = np.arange(0.0, 20.0, 0.02)
    y = np.array([walker_position(walker, t)[1] for t in times])
    in_lane = np.abs(y) < lane
    entered, left = times[in_lane][0], times[in_lane][-1]
    assert np.all(in_lane[(times >= entered) & (times <= left)])
    assert left - entered > 6.0
    path_line = shapely.LineString(path.point(np.linspace(0.0, path.length, 200)))
    assert path_line.distance(shapely.Point(walker.waypoints[-1])) > 2.0
    assert all(x == walker.waypoints[0][0] for x, _ in walker.waypoints)


def with_box(world: WorldSpec, index: int, **changes) -> WorldSpec:
    boxes = list(world.boxes)
    boxes[index] = dataclasses.replace(boxes[index], **changes)
    return dataclasses.replace(world, boxes=tuple(boxes))


def broken_layouts() -> dict[str, tuple[WorldSpec, set[tuple[str, str, tuple[str, ...]]]]]:
    """Return worlds that each break some checks, with the (check, subject, boxes) expected."""
    sim1, pal3 = load_world("sim1"), load_world("pal3")
    aisle = "box 'carton_aisle'"
    return {
        "box on the path": (
            with_box(sim1, 0, pose=(3.0, -0.3, 0.0)),
            {
                ("protective", aisle, ("carton_aisle",)),
                ("footprint", aisle, ("carton_aisle",)),
            },
        ),
        # Flush against the outer wall's face (y -1.45): the carton's north face lies on
        # the aisle warning field's edge (y -0.95) and barely touches it.
        "box against the wall": (
            with_box(sim1, 0, pose=(3.0, -1.2, 0.0)),
            {("warning", aisle, ("carton_aisle",))},
        ),
        "box in the wall": (
            with_box(sim1, 0, pose=(3.0, -1.3, 0.0)),
            {
                ("warning", aisle, ("carton_aisle",)),
                ("solids", aisle, ("carton_aisle",)),
            },
        ),
        "two posts left": (
            dataclasses.replace(sim1, posts=sim1.posts[:2]),
            {("posts", "path", ())},
        ),
        "wall stub on the aisle": (
            dataclasses.replace(sim1, walls=(*sim1.walls, WallSpec((4.5, -0.2), (4.5, 0.2)))),
            {("static", "walls[5]", ()), ("footprint", "walls[5]", ()), ("posts", "path", ())},
        ),
        # In the north office's door (x 2.0-3.0), where the walker goes, 0.55 m beyond the
        # offices' warning fields (|y| <= 0.85 along y = 0).
        "box in the walker's way": (
            dataclasses.replace(
                pal3, boxes=(*pal3.boxes, BoxSpec("crate", (0.4, 0.4, 0.5), (2.5, 1.6, 0.0)))
            ),
            {
                ("people", "person 'walker'", ("crate",)),
                ("warning", "box 'crate'", ("crate",)),
            },
        ),
    }


@pytest.mark.parametrize("case", sorted(broken_layouts()))
def test_layout_problems_name_each_broken_check(case):
    world, expected = broken_layouts()[case]
    problems = layout_problems(world)
    assert {(p.check, p.subject, p.boxes) for p in problems} == expected
    assert all(str(p).startswith(f"{p.subject}: ") for p in problems)


def test_a_box_hiding_posts_is_blamed():
    world = load_world("sim1")
    # Near the end of the path the robot sees 4 posts; a long crate before the north wall
    # hides the two posts on it.
    crate = BoxSpec("crate", (2.4, 0.3, 1.0), (7.5, 6.0, 0.0))
    hidden = dataclasses.replace(world, boxes=(crate,))
    problems = [p for p in layout_problems(hidden) if p.check == "posts"]
    assert problems
    assert problems[0].boxes == ("crate",)
    assert "see fewer than 3 posts" in problems[0].message


def test_clearances_change_the_verdict():
    world = load_world("sim1")
    _, protective = fields_along_path(world.path, PATH_STEP)
    closest = min(box_protective_gaps(world, protective).values())
    strict = Clearances(protective=closest + 0.01)
    assert [p.check for p in layout_problems(world, clearances=strict)] == ["protective"]
    gaps = box_footprint_gaps(world, swept_footprint(world.path, PIONEER_FOOTPRINT, PATH_STEP))
    nearest = min(gaps, key=gaps.get)
    # Its sides moved out by the nearest box's gap, the robot sweeps up to that box.
    wide_robot = np.array(PIONEER_FOOTPRINT) * [1.0, 1.0 + gaps[nearest] / FOOTPRINT_HALF_WIDTH]
    problems = layout_problems(world, footprint=wide_robot)
    assert [(p.check, p.boxes) for p in problems] == [("footprint", (nearest,))]
