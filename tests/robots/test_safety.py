"""Tests for robots.safety: field sets, occupancy with min points, supervisor, scans."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from matplotlib.path import Path

from robots.safety import (
    FieldSet,
    FieldState,
    SafetyPolicy,
    SafetySupervisor,
    field_occupancy,
    scan_points_in_robot_frame,
)
from semistatic.frames import transform_points
from semistatic.types import Scan

# An S300-like safety laser: 270 deg at 0.5 deg, 12.5 Hz, mounted 0.3 m ahead of the base.
BEAMS = 541
ANGLE_MIN = -math.radians(135.0)
INCREMENT = math.radians(0.5)
SCAN_PERIOD = 0.08
MOUNT = (0.3, 0.0, 0.0)
WARNING = [(0.3, -0.6), (2.5, -0.6), (2.5, 0.6), (0.3, 0.6)]
PROTECTIVE = [(0.3, -0.45), (1.0, -0.45), (1.0, 0.45), (0.3, 0.45)]
FIELDS = FieldSet(WARNING, PROTECTIVE, name="corridor")


def scan_of_box_face(
    robot_x: float, half_width: float = 0.3, stamp: float = 0.0, mount=MOUNT
) -> Scan:
    """Scan of a flat box face across the robot's path at ``robot_x`` (robot frame)."""
    angles = ANGLE_MIN + INCREMENT * np.arange(BEAMS)
    distance = robot_x - mount[0]
    with np.errstate(divide="ignore"):
        ranges = distance / np.cos(angles)
    hits = (np.cos(angles) > 0.0) & (np.abs(ranges * np.sin(angles)) <= half_width)
    return Scan(
        ranges=np.where(hits, ranges, np.inf),
        angle_min=ANGLE_MIN,
        angle_increment=INCREMENT,
        range_min=0.05,
        range_max=30.0,
        stamp=stamp,
    )


def empty_scan(stamp: float = 0.0) -> Scan:
    return Scan(
        ranges=np.full(BEAMS, np.inf),
        angle_min=ANGLE_MIN,
        angle_increment=INCREMENT,
        range_min=0.05,
        range_max=30.0,
        stamp=stamp,
    )


def scan_with_noisy_beams(count: int, stamp: float = 0.0) -> Scan:
    """An empty scene except ``count`` adjacent straight-ahead beams reading 0.4 m."""
    ranges = np.full(BEAMS, np.inf)
    ahead = BEAMS // 2
    ranges[ahead : ahead + count] = 0.4
    return Scan(
        ranges=ranges,
        angle_min=ANGLE_MIN,
        angle_increment=INCREMENT,
        range_min=0.05,
        range_max=30.0,
        stamp=stamp,
    )


# --- FieldSet ---------------------------------------------------------------------------


def test_field_set_keeps_read_only_vertices_and_polygons():
    assert FIELDS.warning.shape == (4, 2)
    assert FIELDS.name == "corridor"
    assert FIELDS.warning_polygon.area == pytest.approx(2.2 * 1.2)
    with pytest.raises(ValueError, match="read-only"):
        FIELDS.protective[0, 0] = 9.0


def test_field_set_drops_a_closing_vertex_and_accepts_a_shared_edge():
    closed = [*WARNING, WARNING[0]]
    fields = FieldSet(closed, WARNING)  # identical fields share every edge
    assert fields.warning.shape == (4, 2)


@pytest.mark.parametrize(
    ("warning", "protective", "match"),
    [
        ([(0, 0), (1, 1), (1, 0), (0, 1)], PROTECTIVE, "warning must be a simple polygon"),
        (WARNING, [(0.3, 0), (0.9, 0.3), (0.9, 0), (0.3, 0.3)], "protective must be a simple"),
        (WARNING, [(0.3, -0.45), (3.0, -0.45), (3.0, 0.45)], "must lie inside the warning"),
        ([(0, 0), (1, 0)], PROTECTIVE, "at least 3 vertices"),
        ([(0, 0), (1, 0), (2, 0)], PROTECTIVE, "positive area"),
        ([(0, 0), (1, np.nan), (1, 1)], PROTECTIVE, "non-finite"),
        ([0.0, 1.0, 2.0], PROTECTIVE, r"\(K, 2\)"),
    ],
)
def test_field_set_rejects_bad_polygons(warning, protective, match):
    with pytest.raises(ValueError, match=match):
        FieldSet(warning, protective)


# --- field_occupancy --------------------------------------------------------------------


def test_occupancy_counts_points_per_field():
    points = [[0.5, 0.0], [0.9, 0.4], [2.0, 0.0], [2.0, 0.55], [3.0, 0.0], [0.5, 1.0]]
    state = field_occupancy(points, FIELDS, min_points=1)
    assert state == FieldState(warning_count=4, protective_count=2, min_points=1)
    assert state.zone == "protective"


def test_occupancy_ignores_nan_and_handles_empty_input():
    assert field_occupancy(np.empty((0, 2)), FIELDS, 1).zone == "clear"
    assert field_occupancy(np.full((5, 2), np.nan), FIELDS, 1).warning_count == 0


def test_boundary_points_count_as_inside():
    state = field_occupancy([[1.0, 0.0], [2.5, 0.6]], FIELDS, 1)
    assert (state.warning_count, state.protective_count) == (2, 1)


def test_occupancy_matches_matplotlib_on_random_star_polygons():
    rng = np.random.default_rng(11)
    for _ in range(20):
        # Star-shaped around the origin (gaps < pi), hence simple.
        angles = np.linspace(-np.pi, np.pi, 9, endpoint=False) + rng.uniform(0.0, 0.6, 9)
        radii = rng.uniform(0.5, 2.0, 9)
        star = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
        fields = FieldSet(star, star * 0.3)
        points = rng.uniform(-2.0, 2.0, (500, 2))
        state = field_occupancy(points, fields, 1)
        assert state.warning_count == np.count_nonzero(Path(star).contains_points(points))
        assert state.protective_count == np.count_nonzero(Path(star * 0.3).contains_points(points))


@pytest.mark.parametrize("min_points", [0, -1, 1.5, True])
def test_occupancy_rejects_bad_min_points(min_points):
    with pytest.raises(ValueError, match="min_points must be an integer >= 1"):
        field_occupancy([[0.5, 0.0]], FIELDS, min_points)


def test_min_points_threshold_is_inclusive():
    points = [[0.5, 0.0], [0.5, 0.1], [0.5, 0.2]]
    assert field_occupancy(points, FIELDS, 3).zone == "protective"
    assert field_occupancy(points, FIELDS, 4).zone == "clear"


# --- scans in the robot frame -----------------------------------------------------------


def test_scan_points_are_mapped_through_the_mount():
    scan = Scan(ranges=[1.0, np.inf, 2.0], angle_min=0.0, angle_increment=np.pi / 2, range_max=5)
    # Laser 0.2 m behind the base, looking left.
    points = scan_points_in_robot_frame(scan, [-0.2, 0.0, np.pi / 2])
    np.testing.assert_allclose(points, [[-0.2, 1.0], [-0.2, -2.0]], atol=1e-12)


def test_all_invalid_scan_gives_no_points():
    assert scan_points_in_robot_frame(empty_scan(), MOUNT).shape == (0, 2)


# --- the acceptance scenarios: synthetic scans -----------------------------------------


@pytest.mark.parametrize(
    ("box_x", "zone", "scale"),
    [(0.8, "protective", 0.0), (2.0, "warning", 0.5), (4.0, "clear", 1.0)],
)
def test_box_ahead_stops_slows_or_is_ignored(box_x, zone, scale):
    supervisor = SafetySupervisor(FIELDS)
    output = supervisor.observe_scan(scan_of_box_face(box_x), MOUNT)
    assert output.zone == zone
    assert output.speed_scale == scale
    count = supervisor.last_occupancy.warning_count
    assert count == 0 if zone == "clear" else count > 10


def test_single_noisy_beam_is_ignored_but_a_cluster_is_not():
    supervisor = SafetySupervisor(FIELDS, SafetyPolicy(min_points=3))
    assert supervisor.observe_scan(scan_with_noisy_beams(1), MOUNT).zone == "clear"
    assert supervisor.observe_scan(scan_with_noisy_beams(2, stamp=1.0), MOUNT).zone == "clear"
    assert supervisor.observe_scan(scan_with_noisy_beams(3, stamp=2.0), MOUNT).zone == "protective"
    # Without the filter the single beam would have stopped the robot.
    strict = SafetySupervisor(FIELDS, SafetyPolicy(min_points=1))
    assert strict.observe_scan(scan_with_noisy_beams(1), MOUNT).zone == "protective"


def run_scans(supervisor, occupied_until, box_x, total=30):
    """Feed 12.5 Hz scans: the box at ``box_x`` while stamp <= occupied_until, then empty."""
    zones = []
    for k in range(total):
        stamp = k * SCAN_PERIOD
        occupied = stamp <= occupied_until + 1e-9
        scan = scan_of_box_face(box_x, stamp=stamp) if occupied else empty_scan(stamp)
        zones.append((stamp, supervisor.observe_scan(scan, MOUNT).zone))
    return zones


@pytest.mark.parametrize(
    ("delay", "first_clear"),
    # Last occupied scan at 0.72 s; release at the first scan >= 0.72 s + delay.
    [(0.0, 0.80), (0.3, 1.04), (0.5, 1.28), (1.0, 1.76)],
)
def test_release_delay_is_honoured(delay, first_clear):
    supervisor = SafetySupervisor(FIELDS, SafetyPolicy(release_delay=delay))
    zones = run_scans(supervisor, occupied_until=0.72, box_x=0.8)
    for stamp, zone in zones:
        assert zone == ("protective" if stamp < first_clear - 1e-9 else "clear"), stamp
    assert supervisor.stops == 1
    assert supervisor.slowdowns == 0


def test_events_are_counted_not_ticks():
    supervisor = SafetySupervisor(FIELDS, SafetyPolicy(release_delay=0.2))
    protective = FieldState(10, 10, 3)
    warning = FieldState(10, 0, 3)
    clear = FieldState(0, 0, 3)
    sequence = [
        protective, protective, clear, protective,  # flicker within the delay: one stop
        clear, clear, clear, clear,  # released
        warning, warning, warning,  # one slowdown
        protective,  # escalation: a second stop
        warning, warning, warning, warning,  # protective released into warning: same event
        clear, clear, clear, clear,
        warning,  # a new slowdown
    ]  # fmt: skip
    zones = [supervisor.update(state, k * 0.1).zone for k, state in enumerate(sequence)]
    assert zones[:4] == ["protective"] * 4
    assert zones[7] == "clear"
    assert supervisor.stops == 2
    assert supervisor.slowdowns == 2
    assert zones[-1] == "warning"


def test_warning_is_held_too():
    supervisor = SafetySupervisor(FIELDS, SafetyPolicy(release_delay=0.5))
    zones = run_scans(supervisor, occupied_until=0.4, box_x=2.0, total=15)
    assert [zone for stamp, zone in zones if stamp < 0.9 - 1e-9] == ["warning"] * 12
    assert zones[12][1] == "clear"  # 0.96 s: 0.56 s after the last warning
    assert supervisor.slowdowns == 1


def test_speed_scale_follows_the_policy():
    supervisor = SafetySupervisor(FIELDS, SafetyPolicy(warning_speed_scale=0.3))
    assert supervisor.update(FieldState(5, 0, 3), 0.0).speed_scale == 0.3
    assert supervisor.speed_scale == 0.3


def test_fields_switch_per_segment():
    wide = FIELDS
    narrow = FieldSet(
        [(0.3, -0.2), (1.5, -0.2), (1.5, 0.2), (0.3, 0.2)],
        [(0.3, -0.2), (0.6, -0.2), (0.6, 0.2), (0.3, 0.2)],
    )
    # A pallet beside the path, 0.3-0.5 m to the left, 0.8 m ahead.
    points = np.column_stack([np.full(10, 0.8), np.linspace(0.3, 0.5, 10)])
    supervisor = SafetySupervisor(wide, SafetyPolicy(release_delay=0.0))
    assert supervisor.observe(points, 0.0).zone == "protective"
    supervisor.set_fields(narrow)
    assert supervisor.field_set is narrow
    assert supervisor.observe(points, 0.08).zone == "clear"


def test_switching_fields_keeps_a_held_stop():
    supervisor = SafetySupervisor(FIELDS, SafetyPolicy(release_delay=1.0))
    supervisor.observe_scan(scan_of_box_face(0.8), MOUNT)
    supervisor.set_fields(FieldSet(PROTECTIVE, PROTECTIVE))
    assert supervisor.observe_scan(empty_scan(0.08), MOUNT).zone == "protective"


def test_reset_and_time_order():
    supervisor = SafetySupervisor(FIELDS)
    supervisor.update(FieldState(9, 9, 3), 1.0)
    with pytest.raises(ValueError, match="before the previous one"):
        supervisor.update(FieldState(0, 0, 3), 0.5)
    supervisor.reset()
    assert (supervisor.zone, supervisor.speed_scale, supervisor.stops) == ("clear", 1.0, 0)
    assert supervisor.update(FieldState(0, 0, 3), 0.5).zone == "clear"


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"warning_speed_scale": 0.0}, r"warning_speed_scale must be in \(0, 1\]"),
        ({"warning_speed_scale": 1.5}, r"warning_speed_scale must be in \(0, 1\]"),
        ({"release_delay": -0.1}, "release_delay must be >= 0"),
        ({"release_delay": math.inf}, "release_delay must be >= 0"),
        ({"min_points": 0}, "min_points must be an integer >= 1"),
        ({"min_points": 2.5}, "min_points must be an integer >= 1"),
    ],
)
def test_bad_policy_is_rejected(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SafetyPolicy(**kwargs)


def test_bounding_box_prefilter_counts_as_the_exact_predicate_alone():
    # Points on the boxes' edges, on the polygons' vertices and edges, nan rows and points
    # far away: the prefilter must keep every point the predicate counts.
    rng = np.random.default_rng(12)
    fields = FieldSet(
        [(0.0, -1.0), (3.0, -1.2), (3.5, 0.0), (2.5, 1.0), (0.0, 0.8)],
        [(0.2, -0.5), (1.5, -0.5), (1.5, 0.5), (0.2, 0.5)],
    )
    vertices = np.vstack([fields.warning, fields.protective])
    edges = (vertices + np.roll(vertices, -1, axis=0)) / 2.0
    box_edges = [[3.5, 0.3], [0.0, 0.0], [1.0, -1.2], [1.0, 1.0], [1.5, 0.0], [0.2, 0.5]]
    points = np.vstack(
        [vertices, edges, box_edges, [[np.nan, np.nan]], rng.uniform(-1.0, 4.5, (400, 2))]
    )
    state = field_occupancy(points, fields, 1)
    valid = ~np.isnan(points[:, 0])
    x, y = points[valid, 0], points[valid, 1]
    expected = (
        int(np.count_nonzero(shapely.intersects_xy(fields.warning_polygon, x, y))),
        int(np.count_nonzero(shapely.intersects_xy(fields.protective_polygon, x, y))),
    )
    assert (state.warning_count, state.protective_count) == expected
    assert state.protective_count > 10


def test_scan_points_are_the_scan_end_points_to_the_last_bit():
    # Cached beam directions must give exactly Scan.points() of the valid beams.
    rng = np.random.default_rng(13)
    for count in (5, 541):
        ranges = rng.uniform(0.0, 12.0, count)
        ranges[rng.random(count) < 0.2] = np.inf
        ranges[rng.random(count) < 0.05] = np.nan
        scan = Scan(
            ranges=ranges, angle_min=-2.3, angle_increment=0.0087, range_min=0.1, range_max=10.0
        )
        expected = transform_points(MOUNT, scan.points()[scan.valid_mask()])
        np.testing.assert_array_equal(scan_points_in_robot_frame(scan, MOUNT), expected)
