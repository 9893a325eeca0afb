"""Seeded faults (``[faults]``): off they change nothing, on they make the fault scenarios hit."""

import copy
import tomllib

import pytest

from scenarios.bench.runner import run_scenario
from scenarios.campaign.plan import world_document
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario
from semistatic.errors import SpecError
from tests.scenarios.tiny_world import write_tiny
from worlds.load import world_path

DEFAULTS = {"scanner_latency_s": 0.0, "braking_factor": 1.0, "unguarded_minimum_field": False}
"""Every fault key at its default (off)."""


def _metrics(spec) -> dict:
    metrics = summarize(run_scenario(spec))
    metrics.pop("performance")
    return metrics


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    path = write_tiny(tmp_path_factory.mktemp("tiny"))
    return path, _metrics(load_scenario(path, overrides=["laps=1"]))


@pytest.mark.parametrize(("key", "value"), DEFAULTS.items())
def test_a_fault_set_to_off_changes_nothing(tiny, key, value):
    path, plain = tiny
    spec = load_scenario(path, overrides=["laps=1", f"faults.{key}={str(value).lower()}"])
    assert spec.faults.active() == {}
    assert _metrics(spec) == plain
    assert "faults" not in plain


def test_metrics_name_the_faults_in_effect(tiny):
    path, _ = tiny
    spec = load_scenario(path, overrides=["laps=1", "faults.braking_factor=0.5"])
    assert summarize(run_scenario(spec))["faults"] == {"braking_factor": 0.5}


@pytest.mark.parametrize(("override", "key"), [
    ("faults.braking_factor=0", "faults.braking_factor"),
    ("faults.braking_factor=1.5", "faults.braking_factor"),
    ("faults.scanner_latency_s=-1", "faults.scanner_latency_s"),
    ("faults.unguarded_minimum_field=1", "faults.unguarded_minimum_field"),
    ("faults.x=1", "faults.x"),
])
def test_bad_fault_values_are_refused_naming_the_key(override, key):
    with pytest.raises(SpecError, match=f"--set: {key}: ") as error:
        load_scenario("occlusion_hall", overrides=[override])
    assert error.value.key == key


def test_an_unknown_fault_gets_a_suggestion():
    with pytest.raises(SpecError, match="did you mean 'braking_factor'"):
        load_scenario("occlusion_hall", overrides=["faults.breaking_factor=0.5"])


def _world_at(tmp_path, world, values, boxes=None):
    """Return ``world=...`` for bundled ``world`` with the worker's and boxes' keys set."""
    table = copy.deepcopy(tomllib.loads(world_path(world).read_text()))
    worker = next(person for person in table["people"] if person["name"] == "worker")
    worker.update(values)
    for box in table.get("boxes", []):
        box.update((boxes or {}).get(box["name"], {}))
    path = tmp_path / f"{world}_varied.toml"
    path.write_text(world_document(table))
    return f'world="{path}"'


def _contact(metrics) -> bool:
    return metrics["safety"]["min_separation_m"]["person"] <= 0.0


# One point inside each failure region (the scenario's header names the search box): the
# worker's keys (and boxes' keys), the world with the fault and without, and the overrides
# that switch the fault off. Measured (sobol grids of the boxes, docs in the headers):
HITS = {
    # The worker still stands in the lane when the slowed LGV comes: fault_hall_short,
    # contact; fault_hall with sized fields: no contact.
    "fault_short_field": ({"trigger_distance": 2.0871, "speed": 1.2571,
                           "dwell": [0.0, 0.4163, 0.0]},
                          None, ("fault_hall_short", "fault_hall"),
                          ["safety.minimum_field=standard", "safety.undersized_fields=false"]),
    # In lap 2 the worker passing close by the mapped pallet goes unseen: contact; with
    # the minimum field guarded, no contact.
    "fault_blind_policy": ({"trigger_distance": 2.1346, "speed": 1.2555, "start_time": 0.2664},
                           None, ("fault_hall_pallet", "fault_hall_pallet"),
                           ["faults.unguarded_minimum_field=false"]),
    # 0.16 s late: contact; on time: 0.0955 m.
    "fault_slow_scanner": ({"trigger_distance": 2.0536, "speed": 1.3514, "start_time": 0.2725},
                           None, ("fault_hall", "fault_hall"), ["faults.scanner_latency_s=0"]),
}


@pytest.mark.slow
@pytest.mark.parametrize("scenario", HITS)
def test_the_fault_scenario_hits_only_with_its_fault(tmp_path, scenario):
    values, boxes, (faulty, nominal), off = HITS[scenario]
    world = _world_at(tmp_path, faulty, values, boxes)
    assert _contact(summarize(run_scenario(load_scenario(scenario, overrides=[world]))))
    healthy = load_scenario(scenario,
                            overrides=[_world_at(tmp_path, nominal, values, boxes), *off])
    assert not _contact(summarize(run_scenario(healthy)))
