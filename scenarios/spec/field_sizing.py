"""Every segment's protective field checked against the safety standard's formula.

For each path segment: the highest speed the path reaches there, the vehicle's stopping
distance from it (:class:`robots.stopping.StopModel`: the safety laser's multiple sampling
at the scenario's safety-scan rate, one control period, the braking deceleration), the
supplements (``Z_G`` and ``Z_R`` of the safety laser, ``Z_R`` only where a reflective post
stands within its range of the segment's swept protective field, ``Z_F`` from the
vehicle's ground clearance), hence the least length and width of the field
(:func:`robots.stopping.field_size`), and what the segment's field actually covers. A
field is *undersized* when it is shorter or narrower than that; ``semistatic check``
prints every margin, and a scenario with an undersized field is refused unless it says
``safety.undersized_fields = true`` (it studies them; the margins go to metrics.json).

Examples
--------
>>> from scenarios.spec.load import load_scenario
>>> from scenarios.spec.layout import robot_preset, scenario_world
>>> spec = load_scenario("warehouse")
>>> checks = field_checks(spec, scenario_world(spec), robot_preset(spec.robot))
>>> first = checks[0]
>>> first.segment, round(first.required_length, 3), round(first.required_width, 3)
('south_west', 0.9, 1.3)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from robots.follower import FollowerParams
from robots.presets import UGVSpec
from robots.stopping import (
    StopModel,
    Supplements,
    blind_reach,
    field_size,
    ground_clearance_supplement,
    response_time,
)
from scenarios.spec.clock import command_latency
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import path_segments, swept_area
from semistatic.errors import SpecError
from worlds.checks import build_spline
from worlds.spec import WorldSpec

__all__ = [
    "COVERAGE_STEP",
    "FieldCheck",
    "check_field_sizes",
    "field_checks",
    "required_size",
    "stop_model",
    "vehicle_deceleration",
]

COVERAGE_STEP = 0.005
"""Grid step (m) at which a field's actual length and width are measured."""

SLACK = 1e-6
"""Metres a field may miss the formula by (rounding), not more."""


def vehicle_deceleration(robot: UGVSpec, follower: FollowerParams | None = None) -> float:
    """Return the braking deceleration (m/s^2): the follower's limit or the motors', if lower.

    The motors' is what the wheel torque gives the whole mass, ``2 tau / (r m)``.

    Examples
    --------
    >>> from robots.presets import LGV, PIONEER3DX
    >>> vehicle_deceleration(PIONEER3DX), round(vehicle_deceleration(LGV), 3)
    (1.0, 1.0)
    """
    follower = FollowerParams() if follower is None else follower
    motors = 2.0 * robot.max_wheel_torque / (robot.wheel_radius * robot.total_mass)
    return min(follower.max_deceleration, motors)


def stop_model(spec: ScenarioSpec, robot: UGVSpec) -> StopModel:
    """Return how ``robot`` stops in ``spec``: its safety laser at the safety-scan rate.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> from robots.presets import LGV
    >>> model = stop_model(load_scenario("warehouse"), LGV)
    >>> round(model.reaction_time, 3), round(model.distance(1.0), 3)
    (0.16, 0.65)
    """
    laser = robot.safety_laser.laser
    return StopModel(
        scanner_response_s=response_time(1.0 / spec.rates.safety_hz, laser.multiple_sampling),
        command_latency_s=command_latency(spec.rates),
        control_period_s=1.0 / spec.rates.control_hz,
        deceleration=vehicle_deceleration(robot),
    )


def required_size(model: StopModel, supplements: Supplements, robot: UGVSpec,
                  speed: float) -> tuple[float, float]:
    """Return the least protective-field length and width (m) at ``speed`` (m/s).

    The formula's length, and at least the general supplement past the safety laser's
    blind zone (a field that ends where the laser sees nothing never triggers).
    """
    footprint = np.asarray(robot.footprint, dtype=float)
    length, width = field_size(model.distance(speed), supplements,
                               float(np.ptp(footprint[:, 1])))
    mount = robot.safety_laser
    blind = blind_reach(footprint, mount.x, mount.laser.range_min)
    if blind > 0.0:
        length = max(length, blind + supplements.general)
    return length, width


@dataclass(frozen=True)
class FieldCheck:
    """One segment's protective field against the formula (lengths in m, speed in m/s).

    ``actual_length`` is how far ahead of the vehicle's front the field reaches over the
    vehicle's whole width; ``actual_width`` its narrowest width (symmetric about the
    vehicle's centre line) over the required length, from where the field starts.
    Negative margins: the field is undersized.
    """

    segment: str
    speed: float
    required_length: float
    required_width: float
    actual_length: float
    actual_width: float
    supplements: Supplements

    @property
    def length_margin(self) -> float:
        """Return ``actual_length - required_length`` (m)."""
        return self.actual_length - self.required_length

    @property
    def width_margin(self) -> float:
        """Return ``actual_width - required_width`` (m)."""
        return self.actual_width - self.required_width

    @property
    def undersized(self) -> bool:
        """Return whether the field is shorter or narrower than the formula asks."""
        return self.length_margin < -SLACK or self.width_margin < -SLACK

    def as_metrics(self) -> dict:
        """Return the ``metrics.json`` entry of ``safety.field_margins_m``."""
        return {
            "speed": round(self.speed, 4),
            "required": round(self.required_length, 4),
            "actual": round(self.actual_length, 4),
            "required_width": round(self.required_width, 4),
            "actual_width": round(self.actual_width, 4),
            "margin": round(min(self.length_margin, self.width_margin), 4),
        }


def _coverage(field: shapely.Polygon, front: float, centre: float, vehicle_width: float,
              length: float) -> tuple[float, float]:
    """Return the field's reach ahead of ``front`` over the vehicle's width and least width.

    The width is symmetric about the vehicle's centre line, the narrowest over ``length``
    ahead of ``front`` from where the field starts.
    """
    half = 0.5 * vehicle_width
    ys = np.linspace(centre - half, centre + half,
                     max(3, int(np.ceil(vehicle_width / COVERAGE_STEP)) + 1))
    x_min, y_min, x_max, y_max = field.bounds
    # One GEOS call for all lines across the field (as many one by one cost ~25 us each).
    rows = _crossings(field, [[(front - 1.0, y), (x_max + 1.0, y)] for y in ys.tolist()])
    if rows is None:
        return 0.0, 0.0
    reach = min(float(x_end) - front for x_end in rows[:, 2].tolist())
    start = max(front, float(x_min))
    xs = np.linspace(start, max(start, front + min(length, reach)),
                     max(3, int(np.ceil(length / COVERAGE_STEP)) + 1))
    columns = _crossings(field, [[(x, y_min - 1.0), (x, y_max + 1.0)] for x in xs.tolist()])
    if columns is None:
        return max(0.0, reach), 0.0
    # Width symmetric about the vehicle's centre line: the smaller side, twice.
    narrowest = min(
        2.0 * min(centre - low, high - centre)
        for low, high in zip(columns[:, 1].tolist(), columns[:, 3].tolist(), strict=True)
    )
    return max(0.0, reach), max(0.0, narrowest)


def _crossings(field: shapely.Polygon, lines: list) -> np.ndarray | None:
    """Return the ``(N, 4)`` bounds of the field's part on each line, ``None`` if one misses it."""
    parts = shapely.intersection(field, shapely.linestrings(np.array(lines, dtype=float)))
    if shapely.is_empty(parts).any():
        return None
    return shapely.bounds(parts)


def field_checks(spec: ScenarioSpec, world: WorldSpec, robot: UGVSpec) -> list[FieldCheck]:
    """Return every segment's protective field checked against the formula."""
    model = stop_model(spec, robot)
    laser = robot.safety_laser.laser
    footprint = np.asarray(robot.footprint, dtype=float)
    front = float(footprint[:, 0].max())
    centre = 0.5 * float(footprint[:, 1].min() + footprint[:, 1].max())
    path = build_spline(world.path)
    posts = shapely.multipoints([post.xy for post in world.posts]) if world.posts else None
    speed = float(world.path.speed)
    checks = []
    for segment in path_segments(world, path):
        protective = np.asarray(segment.fields.protective, dtype=float)
        near_reflector = posts is not None and bool(
            shapely.distance(swept_area(path, protective, segment.start_s, segment.end_s),
                             posts) <= laser.reflector_range)
        supplements = Supplements(
            general=laser.general_supplement,
            reflector=laser.reflector_supplement if near_reflector else 0.0,
            ground_clearance=ground_clearance_supplement(robot.ground_clearance),
        )
        length, width = required_size(model, supplements, robot, speed)
        actual_length, actual_width = _coverage(segment.fields.protective_polygon, front,
                                                centre, float(np.ptp(footprint[:, 1])), length)
        checks.append(FieldCheck(segment.name, speed, length, width, actual_length,
                                 actual_width, supplements))
    return checks


def check_field_sizes(spec: ScenarioSpec, world: WorldSpec, robot: UGVSpec) -> list[FieldCheck]:
    """Return the checks; raise :class:`SpecError` for the first undersized field.

    Unless the scenario studies undersized fields (``safety.undersized_fields``).
    """
    checks = field_checks(spec, world, robot)
    if spec.safety.undersized_fields:
        return checks
    for index, check in enumerate(checks):
        if check.undersized:
            raise SpecError(
                world.source, f"path.segments[{index}].protective",
                f"segment '{check.segment}' at {check.speed:g} m/s needs a protective field "
                f"{check.required_length:.3f} m long and {check.required_width:.3f} m wide "
                f"(stopping distance and supplements), this one is {check.actual_length:.3f} m "
                f"long and {check.actual_width:.3f} m wide; enlarge it, lower path.speed, or "
                "set safety.undersized_fields = true in the scenario to study it",
            )
    return checks
