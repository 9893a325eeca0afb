"""A vehicle's safety fields at work: the field policy, the stop envelope, the supervisor.

At every safety scan :class:`VehicleFields` asks the vehicle's field policy which readings
count (:mod:`scenarios.bench.policies`), adds every reading inside the stop envelope at
the speed the wheel encoders measured since the last scan (:mod:`robots.stopping`), and
feeds the counts to the :class:`~robots.safety.SafetySupervisor`, whose zone becomes the
follower's speed scale.

Examples
--------
>>> from robots.presets import PIONEER3DX
>>> from scenarios.spec.load import load_scenario
>>> from scenarios.spec.segments import path_segments
>>> from worlds import load_world
>>> first = path_segments(load_world("pal1"))[0]
>>> fields = VehicleFields(load_scenario("pal1"), PIONEER3DX, first.fields, deceleration=1.0)
>>> round(fields.least_reach, 3)   # past the LMS100's 0.5 m blind zone ahead of the bumper
0.44
"""

from __future__ import annotations

import numpy as np

from robots.presets import UGVSpec
from robots.safety import FieldSet, SafetyOutput, SafetyPolicy, SafetySupervisor
from robots.stopping import blind_reach, stop_envelope, stopping_distance
from scenarios.bench.policies import (
    FieldView,
    checked_readings,
    counted_occupancy,
    field_policy,
)
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment
from semistatic.local_map import LocalMap

__all__ = ["VehicleFields"]


class VehicleFields:
    """The safety supervisor of one vehicle with its field policy and stop envelope.

    Parameters
    ----------
    spec
        The scenario (its ``safety`` settings, ``rates`` and ``policy``).
    robot
        The vehicle (footprint, safety laser).
    fields
        The fields of the segment the vehicle starts on.
    deceleration
        The braking deceleration of a protective stop (m/s^2): the follower's limit.

    Attributes
    ----------
    policy
        The field policy (a fresh bundled one, or the scenario's object).
    supervisor
        The :class:`~robots.safety.SafetySupervisor` (zone, stops, slowdowns).
    least_reach
        The envelope's least reach ahead of the footprint (m): ``min_protective_depth``,
        and past the safety laser's blind zone.
    """

    def __init__(self, spec: ScenarioSpec, robot: UGVSpec, fields: FieldSet,
                 deceleration: float) -> None:
        safety = spec.safety
        self.settings = safety
        self.policy = field_policy(spec.policy)
        self.supervisor = SafetySupervisor(
            fields,
            SafetyPolicy(warning_speed_scale=safety.slowdown,
                         release_delay=safety.release_delay,
                         min_points=safety.min_points),
        )
        # A stop request waits up to one safety scan period and one control period, then
        # the follower brakes at its deceleration limit.
        self.reaction_time = 1.0 / spec.rates.safety_hz + 1.0 / spec.rates.control_hz
        self.deceleration = float(deceleration)
        self.footprint = np.asarray(robot.footprint, dtype=float)
        # The envelope reaches at least min_protective_depth ahead, and past the safety
        # laser's blind zone: a reading it cannot see would never stop the vehicle.
        self.least_reach = max(
            safety.min_protective_depth,
            blind_reach(self.footprint, robot.safety_laser.x, robot.safety_laser.laser.range_min),
        )
        self._travelled = 0.0  # forward travel (m, encoders) since the last safety scan
        self._since = 0.0      # ... and that scan's time

    def reset(self, fields: FieldSet, stamp: float) -> None:
        """Start a lap at rest on a segment with ``fields`` at time ``stamp``."""
        self.supervisor.reset()
        self.supervisor.set_fields(fields)
        self._travelled, self._since = 0.0, stamp

    def travel(self, forward: float) -> None:
        """Add an odometry increment's forward travel (m)."""
        self._travelled += forward

    def stop_envelope(self, stamp: float):
        """Return the stop envelope at the speed measured since the last scan (robot frame)."""
        elapsed = stamp - self._since
        speed = self._travelled / elapsed if elapsed > 0.0 else 0.0
        self._travelled, self._since = 0.0, stamp
        reach = max(stopping_distance(speed, self.reaction_time, self.deceleration),
                    self.least_reach)
        return stop_envelope(self.footprint, reach if speed >= 0.0 else -reach,
                             self.settings.general_supplement)

    def supervise(self, points: np.ndarray, segment: PathSegment, stamp: float,
                  local_map: LocalMap, ekf_pose: np.ndarray) -> SafetyOutput:
        """Return the supervisor's answer to one scan's robot-frame ``points``."""
        supervisor = self.supervisor
        if supervisor.field_set is not segment.fields:
            supervisor.set_fields(segment.fields)
        envelope = self.stop_envelope(stamp)
        answer = self.policy.counted_readings(
            FieldView(points, segment, envelope, ekf_pose, local_map, self.settings))
        readings = checked_readings(self.policy, answer, len(points))
        occupancy = counted_occupancy(points, segment.fields, envelope, readings,
                                      supervisor.policy.min_points)
        return supervisor.update(occupancy, stamp)
