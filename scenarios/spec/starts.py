"""What stands at each vehicle's start: room to stand, and posts that say where it stands.

A lap starts with every vehicle at the start of its route, where it localises from the
reflective posts before it drives (docs/design.md). Three things there stop lap 1 before
it starts, and the layout checks along the path (:mod:`worlds.checks`) cannot see them:

- the posts in view fit the post layout in more than one place (evenly spaced posts), or
  do not fix the pose at all: the EKF, which has no estimate yet, cannot localise;
- a person the scenario switches on stands or walks on a vehicle's start footprint;
- two fleet vehicles start on one segment, or their start footprints overlap.

:func:`check_starts` finds them from geometry alone, with the functions the run itself
uses: the posts each start pose sees (:func:`worlds.checks.visible_posts`, with the
localisation laser's range and field of view), observed without noise and matched by the
very filter a vehicle builds (:func:`start_localizer`, :meth:`robots.ekf.EKFLocalizer.
relocalize`). No PyBullet.

Examples
--------
>>> from scenarios.spec.load import load_scenario
>>> from scenarios.spec.layout import scenario_world
>>> spec = load_scenario("warehouse_fleet")
>>> check_starts(spec, scenario_world(spec))
>>> two = spec.vehicles[:1] + (dataclasses.replace(spec.vehicles[1], start_segment=""),)
>>> check_starts(dataclasses.replace(spec, vehicles=two), scenario_world(spec))
... # doctest: +ELLIPSIS
Traceback (most recent call last):
...
semistatic.errors.SpecError: ...warehouse_fleet.toml: vehicles[1].start_segment: vehicle \
'lgv2' starts on segment 'south_west' like vehicles[0] 'lgv1': ...
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import shapely

from robots.ekf import EKFLocalizer, EKFParams
from robots.landmarks import LandmarkObservation
from robots.lasers import LaserSpec
from robots.presets import UGVSpec
from scenarios.spec.layout import robot_preset
from scenarios.spec.routes import fleet_vehicles, vehicle_route
from scenarios.spec.scenario import ScenarioSpec
from semistatic.errors import SpecError
from semistatic.frames import compose, transform_points
from worlds.checks import build_spline, person_walk, visible_posts
from worlds.spec import WorldSpec

__all__ = ["VehicleStart", "check_starts", "landmark_noise", "start_localizer", "vehicle_starts"]

# Observations the start check hands the filter carry no noise; the filter still needs a
# stamp to record the fix at.
_START_STAMP = 0.0


@dataclasses.dataclass(frozen=True)
class VehicleStart:
    """One vehicle of a scenario where it starts: its index, name, robot and pose."""

    index: int
    name: str
    segment: str
    robot: UGVSpec
    pose: tuple[float, float, float]

    def footprint(self) -> shapely.Polygon:
        """Return the robot's footprint placed at the start pose (world frame)."""
        corners = np.asarray(self.robot.footprint, dtype=float)
        return shapely.Polygon(transform_points(np.asarray(self.pose), corners))


def landmark_noise(laser: LaserSpec) -> tuple[float, float]:
    """Return the ``(range, bearing)`` 1-sigma (m, rad) of a post seen by ``laser``.

    The range noise is the laser's (at least 1 mm), the bearing noise the quantisation of
    its angular resolution (uniform over one step).

    Examples
    --------
    >>> from robots.lasers import LMS100
    >>> [round(value, 5) for value in landmark_noise(LMS100)]
    [0.012, 0.00252]
    """
    return max(laser.range_sigma, 1e-3), laser.angular_resolution / math.sqrt(12.0)


def start_localizer(robot: UGVSpec, posts: Sequence[tuple[float, float]]) -> EKFLocalizer:
    """Return the EKF a vehicle ``robot`` localises with among ``posts`` (world x, y).

    The laser's systematic range error (constant per unit, uniform in +-b) is the
    filter's fourth state; without it the EKF is overconfident (NEES ~100 on pal1).

    Examples
    --------
    >>> from robots.presets import get_preset
    >>> ekf = start_localizer(get_preset("pioneer3dx"), [(0.0, 1.0), (2.0, 1.0), (1.0, -1.0)])
    >>> ekf.landmarks.shape, ekf.initialized
    ((3, 2), False)
    """
    mount = robot.localization_laser
    bias_sigma = mount.laser.range_bias_max / math.sqrt(3.0)
    return EKFLocalizer(
        [tuple(post) for post in posts],
        EKFParams(mount=tuple(mount.pose2d()), range_bias_sigma=bias_sigma),
    )


def vehicle_starts(
    spec: ScenarioSpec, world: WorldSpec, robot: UGVSpec | None = None
) -> list[VehicleStart]:
    """Return every vehicle of ``spec`` at the start of its route through ``world``.

    ``robot`` replaces the robot of a scenario without ``[[vehicles]]`` (as the
    :class:`~scenarios.bench.testbench.Testbench`'s ``robot`` does).

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> from scenarios.spec.layout import scenario_world
    >>> spec = load_scenario("warehouse_fleet")
    >>> [(start.name, start.segment) for start in vehicle_starts(spec, scenario_world(spec))]
    [('lgv1', 'south_west'), ('lgv2', 'north_west'), ('lgv3', 'east')]
    """
    starts = []
    for index, vehicle in enumerate(fleet_vehicles(spec)):
        preset = robot if robot is not None and not spec.vehicles else \
            robot_preset(vehicle.robot, file=spec.source)
        route = vehicle_route(world, vehicle)
        pose = build_spline(route.path).pose(0.0)
        starts.append(VehicleStart(index, vehicle.name, route.path.segments[0].name, preset,
                                   tuple(float(value) for value in pose)))
    return starts


def _observations(world: WorldSpec, start: VehicleStart) -> tuple[list[int], list]:
    """Return the posts the localisation laser sees at ``start`` and their observations."""
    mount = start.robot.localization_laser
    laser = mount.laser
    sensor = compose(np.asarray(start.pose), mount.pose2d())
    _, seen = visible_posts(world, [sensor], post_range=laser.range_max,
                            field_of_view=laser.fov)
    range_sigma, bearing_sigma = landmark_noise(laser)
    covariance = np.diag([range_sigma**2, bearing_sigma**2])
    observations = []
    for post in seen.tolist():
        dx, dy = np.subtract(world.posts[post].xy, sensor[:2])
        observations.append(LandmarkObservation(
            math.hypot(dx, dy), math.atan2(dy, dx) - sensor[2], covariance, []))
    return seen.tolist(), observations


def _localisation_problem(world: WorldSpec, start: VehicleStart) -> str | None:
    """Return why ``start``'s vehicle cannot localise there, or ``None`` if it can."""
    seen, observations = _observations(world, start)
    ekf = start_localizer(start.robot, [post.xy for post in world.posts])
    if ekf.relocalize(observations, _START_STAMP):
        return None
    x, y, _ = start.pose
    where = f"vehicle {start.name!r} at its start ({x:.2f}, {y:.2f})"
    posts = ", ".join(f"posts[{post}]" for post in seen) or "none"
    matches = ekf.best_matches(observations)
    if len(seen) < 3 or not matches:
        return (f"{where} sees {len(seen)} post(s) that match the layout ({posts}); it "
                "needs >= 3 in view of its localisation laser to localise: add posts in "
                "view of the start")
    if len(matches) > 1:
        return (f"{where} cannot localise: the posts it sees ({posts}) fit the post layout "
                f"in {len(matches)} places (evenly spaced posts look alike from anywhere); "
                "space the posts irregularly, the gaps varying by a few tens of centimetres")
    return (f"{where} cannot localise: the posts it sees ({posts}) do not fix its pose (it "
            "stands on or near the circle through them, or on their line); move a post")


def check_starts(spec: ScenarioSpec, world: WorldSpec, robot: UGVSpec | None = None) -> None:
    """Raise :class:`SpecError` if a vehicle of ``spec`` cannot start lap 1 in ``world``.

    ``world`` is lap 1's, the scenario's people switched on; ``robot`` as in
    :func:`vehicle_starts`. The error names the scenario's ``vehicles[i]`` for vehicles
    that collide, the world's ``people[k]`` for a person on a start, and the world's
    ``posts`` for a start the vehicle cannot localise at.
    """
    starts = vehicle_starts(spec, world, robot)
    for later in starts:
        for earlier in starts[:later.index]:
            if later.segment == earlier.segment:
                raise SpecError(
                    spec.source, f"vehicles[{later.index}].start_segment",
                    f"vehicle {later.name!r} starts on segment {later.segment!r} like "
                    f"vehicles[{earlier.index}] {earlier.name!r}: they would stand on each "
                    "other; give each vehicle a start_segment of its own")
            if later.footprint().intersects(earlier.footprint()):
                raise SpecError(
                    spec.source, f"vehicles[{later.index}]",
                    f"vehicle {later.name!r} at its start overlaps vehicles[{earlier.index}] "
                    f"{earlier.name!r} at its start; start it on a segment further along")
    active = {person.name for person in world.active_people}
    for start in starts:
        footprint = start.footprint()
        for index, person in enumerate(world.people):
            if person.name in active and shapely.dwithin(person_walk(person), footprint,
                                                        person.radius):
                x, y, _ = start.pose
                raise SpecError(
                    world.source, f"people[{index}]",
                    f"person {person.name!r} (switched on by the scenario) stands or walks "
                    f"on vehicle {start.name!r} at its start ({x:.2f}, {y:.2f}); move its "
                    "waypoints clear of the vehicle's footprint there")
    for start in starts:
        problem = _localisation_problem(world, start)
        if problem is not None:
            raise SpecError(world.source, "posts", f"lap 1: {problem}")
