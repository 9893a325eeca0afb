"""Stopping distances measured in the closed loop agree with the analytic model."""

import pytest

from robots.presets import LGV, PIONEER3DX
from scenarios.results.stopping import measure_stop

SPEEDS = (0.2, 0.4, 0.6, 0.8, 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("robot", [PIONEER3DX, LGV], ids=lambda robot: robot.name)
def test_measured_stops_lie_within_5_percent_or_2_cm_of_the_model(robot):
    for speed in SPEEDS:
        stop = measure_stop(robot, speed)
        assert abs(stop.error) <= max(0.05 * stop.predicted, 0.02), stop
        assert stop.measured > 0.0
