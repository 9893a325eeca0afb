"""Ground truth geometry: footprints, the shapely ray reference, visible outlines."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from sim.client import SimClient
from sim.ground_truth import obstacle_footprints, reference_ranges, visible_outlines
from sim.people import People
from sim.world_builder import SimWorld
from tests.sim.random_scenes import simple_path
from worlds.spec import BoxSpec, PersonSpec, PostSpec, WallSpec, WorldSpec


def two_boxes() -> WorldSpec:
    """A 1 m box at x = 3 hiding the middle of a 4 m wide box at x = 6, and a low pallet."""
    return WorldSpec(
        "two boxes",
        walls=(),
        posts=(PostSpec(0.0, 3.0, radius=0.1),),
        boxes=(
            BoxSpec("front", (1.0, 1.0, 1.0), (3.0, 0.0, 0.0)),
            BoxSpec("back", (1.0, 4.0, 1.0), (6.0, 0.0, 0.0)),
            BoxSpec("pallet", (1.0, 1.0, 0.1), (0.0, -3.0, 0.0)),
        ),
        people=(),
        path=simple_path(),
    )


def test_footprints_leave_out_objects_below_the_scan_plane():
    assert sorted(obstacle_footprints(two_boxes())) == ["back", "front", "pallet", "post_0"]
    assert sorted(obstacle_footprints(two_boxes(), scan_height=0.3)) == [
        "back",
        "front",
        "post_0",
    ]
    assert obstacle_footprints(two_boxes())["post_0"].area == pytest.approx(math.pi * 0.01, 1e-5)


def test_footprints_of_a_sim_world_include_present_people_only():
    spec = WorldSpec(
        "people",
        walls=(WallSpec((5.0, -1.0), (5.0, 1.0)),),
        posts=(),
        boxes=(),
        people=(
            PersonSpec("now", ((1.0, 1.0), (2.0, 1.0)), per_lap=False),
            PersonSpec("later", ((1.0, -1.0), (2.0, -1.0)), start_time=10.0, per_lap=False),
        ),
        path=simple_path(),
    )
    with SimClient() as sim:
        world = SimWorld(sim, spec)
        People(world).update(0.0)
        footprints = obstacle_footprints(world)
        assert sorted(footprints) == ["now", "wall_0"]
        assert footprints["now"].centroid.coords[0] == pytest.approx((1.0, 1.0))
        assert sorted(obstacle_footprints(world, include_people=False)) == ["wall_0"]


def test_reference_ranges_hit_the_nearest_face_and_nothing_else():
    footprints = obstacle_footprints(two_boxes())
    angles = [0.0, math.atan2(1.5, 5.5), math.pi / 2, -math.pi / 2, math.pi]
    ranges = reference_ranges(footprints, (0.0, 0.0, 0.0), angles, 8.0)
    expected_oblique = 5.5 / math.cos(angles[1])  # passes above "front", meets "back"
    np.testing.assert_allclose(ranges, [2.5, expected_oblique, 2.9, 2.5, np.inf])


def test_reference_ranges_rotate_with_the_sensor_yaw_and_stop_at_range_max():
    footprints = obstacle_footprints(two_boxes())
    turned = reference_ranges(footprints, (0.0, 0.0, 0.3, math.pi / 2), [0.0], 8.0)
    assert turned[0] == pytest.approx(2.9)
    short = reference_ranges(footprints, (0.0, 0.0, 0.0), [0.0], 2.0)
    assert np.isinf(short[0])
    assert np.all(np.isinf(reference_ranges({}, (0.0, 0.0, 0.0), [0.0, 1.0], 9.0)))


def test_visible_outlines_follow_occlusion():
    visible = visible_outlines(two_boxes(), (0.0, 0.0, 0.0))
    assert visible["front"].length == pytest.approx(1.0, abs=0.02)  # only its near face
    # the back box shows the parts of its 4 m face not shadowed by the front box
    shadow_half_width = 0.5 * 5.5 / 2.5
    assert visible["back"].length == pytest.approx(4.0 - 2 * shadow_half_width, abs=0.03)
    near_face = shapely.LineString([(2.5, -0.5), (2.5, 0.5)])
    assert visible["front"].hausdorff_distance(near_face) < 0.01


def test_visible_outlines_respect_fov_range_and_height():
    everything = visible_outlines(two_boxes(), (0.0, 0.0, 0.0))
    assert sorted(everything) == ["back", "front", "pallet", "post_0"]
    ahead = visible_outlines(two_boxes(), (0.0, 0.0, 0.0), fov=math.radians(90))
    assert sorted(ahead) == ["back", "front"]
    near = visible_outlines(two_boxes(), (0.0, 0.0, 0.0), range_max=4.0)
    assert sorted(near) == ["front", "pallet", "post_0"]
    high = visible_outlines(two_boxes(), (0.0, 0.0, 0.0), scan_height=0.3)
    assert "pallet" not in high
    # a post seen from outside shows half its circumference, less the tangent cut
    assert everything["post_0"].length == pytest.approx(math.pi * 0.1, rel=0.05)
