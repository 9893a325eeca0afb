"""What each bundled field policy saves on the paper's scenarios, and that none touches anyone.

``pytest -m accuracy`` (with the map-accuracy goldens; ~10 min): every paper scenario runs
its five laps under the three bundled policies on seed 0. The guarded policy frees the
warning field of known boxes except where a person could hide behind one; it must keep
at least :data:`KEPT_SHARE` of the adaptive policy's time saving over the five scenarios
together, and no run may touch a person or a box.
"""

import dataclasses

import pytest

from scenarios.bench.runner import run_scenario
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario, paper_scenarios
from scenarios.spec.scenario import POLICIES

KEPT_SHARE = 0.70
"""The share of the adaptive policy's saving the guarded policy keeps, at least."""


@pytest.fixture(scope="module")
def totals():
    results = {}
    for name in paper_scenarios():
        spec = load_scenario(name)
        for policy in POLICIES:
            results[name, policy] = summarize(run_scenario(dataclasses.replace(spec,
                                                                               policy=policy)))
    return results


def _total(results, policy):
    return sum(results[name, policy]["safety"]["total_time_s"] for name in paper_scenarios())


@pytest.mark.accuracy
def test_guarded_keeps_most_of_the_adaptive_saving(totals):
    conservative = _total(totals, "conservative")
    adaptive = conservative - _total(totals, "adaptive")
    guarded = conservative - _total(totals, "guarded")
    assert adaptive > 0.0
    assert guarded >= KEPT_SHARE * adaptive, (
        f"guarded saves {guarded:.1f} s, adaptive {adaptive:.1f} s of {conservative:.1f} s")


@pytest.mark.accuracy
def test_no_policy_touches_anyone_in_the_paper_scenarios(totals):
    for (name, policy), metrics in totals.items():
        safety = metrics["safety"]
        contacts = [item for item in safety["infractions"] if item["kind"] == "contact"]
        assert contacts == [], f"{name} under {policy}: {contacts}"
        assert safety["collisions"] == 0
        assert safety["laps_completed"] == metrics["laps"]
