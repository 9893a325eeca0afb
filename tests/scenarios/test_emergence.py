"""A person steps into the lane d metres ahead: safe above the prediction, reported below."""

import pytest

from robots.presets import LGV, PIONEER3DX
from scenarios.results.emergence import emergence_trial, predicted_safe_emergence

STEP = 0.05
"""The trigger step (m) of the sweeps."""

CASES = [(PIONEER3DX, 0.4), (LGV, 1.0)]


@pytest.mark.slow
@pytest.mark.parametrize("policy", ["conservative", "adaptive"])
@pytest.mark.parametrize(("robot", "speed"), CASES, ids=lambda case: getattr(case, "name", ""))
def test_the_measured_safe_emergence_distance_is_the_predicted_one(robot, speed, policy):
    predicted = predicted_safe_emergence(robot, speed)
    sweep = [round(predicted + k * STEP, 4) for k in (-3, -2, -1, 0, 1)]
    trials = {d: emergence_trial(robot, speed, d, policy=policy) for d in sweep}
    contact = [d for d, trial in trials.items() if trial.contact]
    assert contact, "no contact even 3 steps below the prediction: the sweep shows nothing"
    boundary = min(d for d in sweep if d > max(contact))
    assert abs(boundary - predicted) <= STEP + 1e-9, (boundary, predicted, trials)
    # Below: every contact is an infraction in the run's record, never smoothed away.
    for d in contact:
        assert ("contact" in {kind for kind, _ in trials[d].infractions})
    # Above: no contact in any of 5 more seeds (10 trials with the other policy).
    above = round(predicted + STEP, 4)
    for seed in range(1, 6):
        assert not emergence_trial(robot, speed, above, seed=seed, policy=policy).contact
