"""A person steps into the lane d metres ahead: safe above the prediction, reported below."""

import math

import pytest

from robots.presets import LGV, PIONEER3DX
from scenarios.results.emergence import emergence_trial, predicted_safe_emergence

SCAN_PERIOD = 0.08
CASES = [(PIONEER3DX, 0.4), (LGV, 1.0)]


def trigger_step(speed: float) -> float:
    """The sweep's step: the travel of one scan period, rounded up to 5 cm.

    The prediction takes the scanner's worst phase (the person enters just after a scan);
    the measured boundary lies up to one scan period of travel below it.
    """
    return math.ceil(speed * SCAN_PERIOD / 0.05) * 0.05


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "speed"), CASES, ids=[robot.name for robot, _ in CASES])
def test_the_measured_safe_emergence_distance_is_the_predicted_one(robot, speed):
    step = trigger_step(speed)
    predicted = predicted_safe_emergence(robot, speed)
    sweep = [round(predicted + k * step, 4) for k in (-2, -1, 0, 1)]
    trials = {d: emergence_trial(robot, speed, d) for d in sweep}
    contact = [d for d, trial in trials.items() if trial.contact]
    assert contact, "no contact even 2 steps below the prediction: the sweep shows nothing"
    boundary = min(d for d in sweep if d > max(contact))
    assert abs(boundary - predicted) <= step + 1e-9, (boundary, predicted, trials)
    # Below: every contact is an infraction in the run's record, never smoothed away.
    for d in contact:
        assert "contact" in {kind for kind, _ in trials[d].infractions}
    # Above: no contact in 10 more trials, 5 seeds under each of the paper's policies.
    above = round(predicted + step, 4)
    for policy in ("conservative", "adaptive"):
        for seed in range(1, 6):
            assert not emergence_trial(robot, speed, above, seed=seed, policy=policy).contact
