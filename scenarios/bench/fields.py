"""A vehicle's safety fields at work: the field policy, the minimum field, the supervisor.

At every safety scan :class:`VehicleFields` asks the vehicle's field policy which readings
count (:mod:`scenarios.bench.policies`), adds every reading inside the *minimum
protective field*, and feeds the counts to the :class:`~robots.safety.SafetySupervisor`,
whose zone becomes the follower's speed scale. With ``safety.minimum_field =
"standard"`` the minimum field is what the standard's formula asks for at the speed the
wheel encoders measured since the last scan (:func:`robots.stopping.minimum_protective_field`
with the segment's supplements, :mod:`scenarios.spec.field_sizing`): ahead, beside and
behind the vehicle. With ``"fixed"`` it is the first ``safety.min_protective_depth`` of
the segment's protective field, which a scenario may use to show what that misses.

Two seeded faults (:class:`~scenarios.spec.scenario.Faults`) act here:
``faults.unguarded_minimum_field`` stops counting the minimum field's readings (the policy
alone decides), and ``faults.scanner_latency_s`` holds each of the supervisor's answers
back that many seconds (whole safety scans) before it reaches the vehicle
(:meth:`VehicleFields.reaching_vehicle`).

Examples
--------
>>> from robots.presets import PIONEER3DX
>>> from scenarios.spec.layout import scenario_world
>>> from scenarios.spec.load import load_scenario
>>> spec = load_scenario("pal1")
>>> fields = VehicleFields(spec, PIONEER3DX, scenario_world(spec))
>>> field = fields.minimum_field("niches", speed=0.4)
>>> round(field.bounds[2], 4)   # S_L = 0.14 + 0.1 + 0.2 + 0.15 m ahead of the bumper (0.1825)
0.7725
"""

from __future__ import annotations

from collections import deque

import numpy as np
import shapely

from robots.presets import UGVSpec
from robots.safety import SafetyOutput, SafetyPolicy, SafetySupervisor
from robots.stopping import minimum_protective_field
from scenarios.bench.bundled_policies import field_policy
from scenarios.bench.policies import (
    FieldView,
    checked_readings,
    checked_speed_cap,
    counted_occupancy,
)
from scenarios.bench.records import AppliedFields
from scenarios.spec.field_sizing import field_checks, required_size, stop_model
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment, path_segments
from semistatic.local_map import LocalMap
from worlds.spec import WorldSpec

__all__ = ["VehicleFields"]


class VehicleFields:
    """The safety supervisor of one vehicle with its field policy and minimum field.

    Parameters
    ----------
    spec
        The scenario (its ``safety`` settings, ``rates`` and ``policy``).
    robot
        The vehicle (footprint, safety laser).
    route
        The world with the path the vehicle drives (its segments' fields and speed).

    Attributes
    ----------
    policy
        The field policy (a fresh bundled one, or the scenario's object).
    supervisor
        The :class:`~robots.safety.SafetySupervisor` (zone, stops, slowdowns).
    model
        The vehicle's :class:`~robots.stopping.StopModel`.
    """

    def __init__(self, spec: ScenarioSpec, robot: UGVSpec, route: WorldSpec) -> None:
        safety = spec.safety
        self.settings = safety
        self.robot = robot
        self.policy = field_policy(spec.policy)
        segments = path_segments(route)
        self.supervisor = SafetySupervisor(
            segments[0].fields,
            SafetyPolicy(warning_speed_scale=safety.slowdown,
                         release_delay=safety.release_delay,
                         min_points=safety.min_points,
                         multiple_sampling=robot.safety_laser.laser.multiple_sampling),
        )
        self.model = stop_model(spec, robot)
        self.footprint = np.asarray(robot.footprint, dtype=float)
        self._supplements = {check.segment: check.supplements
                             for check in field_checks(spec, route, robot)}
        self._fixed = {segment.name: _first_depth(segment, safety.min_protective_depth)
                       for segment in segments}
        self._walls = tuple(wall.corners() for wall in route.walls)
        self._travelled = 0.0  # forward travel (m, encoders) since the last safety scan
        self._since = 0.0      # ... and that scan's time
        faults = spec.faults
        self._guarded = not faults.unguarded_minimum_field
        # The seeded latency in whole scans: the supervisor only answers at scans.
        self._latency_scans = round(faults.scanner_latency_s * spec.rates.safety_hz)
        self._pending: deque[SafetyOutput] = deque()
        self._judged: tuple | None = None  # the last scan's fields, for applied()

    def reset(self, segment: PathSegment, stamp: float) -> None:
        """Start a lap at rest on ``segment`` at time ``stamp``."""
        self.supervisor.reset()
        self.supervisor.set_fields(segment.fields)
        self._travelled, self._since = 0.0, stamp
        self._pending.clear()

    def travel(self, forward: float) -> None:
        """Add an odometry increment's forward travel (m)."""
        self._travelled += forward

    def minimum_field(self, segment: str, speed: float) -> shapely.Geometry:
        """Return the minimum protective field on ``segment`` at ``speed`` (robot frame)."""
        if self.settings.minimum_field == "fixed":
            return self._fixed[segment]
        supplements = self._supplements[segment]
        length, width = required_size(self.model, supplements, self.robot, speed)
        return minimum_protective_field(self.footprint, length, width, supplements.general)

    def measured_speed(self, stamp: float) -> float:
        """Return the speed (m/s) the encoders measured since the last call; restart."""
        elapsed = stamp - self._since
        speed = self._travelled / elapsed if elapsed > 0.0 else 0.0
        self._travelled, self._since = 0.0, stamp
        return speed

    def supervise(self, points: np.ndarray, segment: PathSegment, stamp: float,
                  local_map: LocalMap, ekf_pose: np.ndarray) -> SafetyOutput:
        """Return the supervisor's answer to one scan's robot-frame ``points``.

        The speed scale is the supervisor's, capped by the policy's ``speed_cap``.
        """
        supervisor, policy = self.supervisor, self.policy
        if supervisor.field_set is not segment.fields:
            supervisor.set_fields(segment.fields)
        minimum = self.minimum_field(segment.name, abs(self.measured_speed(stamp)))
        view = FieldView(points, segment, minimum, ekf_pose, local_map, self.settings,
                         self._walls)
        readings = checked_readings(policy, policy.counted_readings(view), len(points))
        occupancy = counted_occupancy(points, segment.fields,
                                      minimum if self._guarded else None, readings,
                                      supervisor.policy.min_points)
        output = supervisor.update(occupancy, stamp)
        cap = checked_speed_cap(policy, policy.speed_cap(view))
        if cap is not None and cap < output.speed_scale:
            output = SafetyOutput(cap, output.zone)
        self._judged = (segment, minimum, points, readings, output.zone)
        return output

    def applied(self, speed_scale: float) -> AppliedFields:
        """Return the fields the last :meth:`supervise` judged against (for recordings).

        ``speed_scale`` is what reached the vehicle (:meth:`reaching_vehicle`). Built only
        when an observer asks for it: the run itself never needs these arrays.
        """
        segment, minimum, points, readings, zone = self._judged
        mask = None if readings is None else readings.protective
        ignored = points[~mask] if mask is not None else np.zeros((0, 2))
        outline = np.zeros((0, 2))
        if self._guarded and not minimum.is_empty:
            # The union of a rectangle and a buffered footprint: one polygon in practice.
            shell = minimum if minimum.geom_type == "Polygon" else minimum.convex_hull
            outline = shapely.get_coordinates(shell.exterior)[:-1]
        return AppliedFields(
            warning=np.asarray(segment.fields.warning, dtype=float),
            protective=np.asarray(segment.fields.protective, dtype=float),
            minimum=outline, ignored=ignored, zone=zone, speed_scale=float(speed_scale),
        )

    def reaching_vehicle(self, output: SafetyOutput) -> SafetyOutput:
        """Return the answer that reaches the vehicle now, ``output`` being the latest.

        Without ``faults.scanner_latency_s`` that is ``output``; with it, the answer of
        that many scans ago (clear while none is that old yet: the lap started at rest).
        """
        if not self._latency_scans:
            return output
        self._pending.append(output)
        if len(self._pending) <= self._latency_scans:
            return SafetyOutput(1.0, "clear")
        return self._pending.popleft()


def _first_depth(segment: PathSegment, depth: float) -> shapely.Geometry:
    """Return the part of the segment's protective field within ``depth`` of its start."""
    polygon = segment.fields.protective_polygon
    x_min, y_min, _, y_max = polygon.bounds
    return polygon.intersection(shapely.box(x_min - 1.0, y_min - 1.0, x_min + depth, y_max + 1.0))
