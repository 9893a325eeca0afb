"""Map-accuracy regression over every bundled scenario (``pytest -m accuracy``, ~2-5 min).

Each scenario runs its full 5 laps. Hard bounds are the paper's and the issue's (Table 1
means under 10 cm, detection F1 >= 0.9, no collision, no object made of a person); the
golden figures in ``golden_accuracy.toml`` catch silent drifts.
"""

import tomllib
from pathlib import Path

import pytest

from scenarios.load import load_scenario, paper_scenarios
from scenarios.outputs import summarize
from scenarios.runner import run_scenario

GOLDEN = tomllib.loads((Path(__file__).parent / "golden_accuracy.toml").read_text())
PAPER_BOUND_CM = 10.0


@pytest.fixture(scope="module", params=paper_scenarios())
def metrics(request):
    return request.param, summarize(run_scenario(load_scenario(request.param)))


@pytest.mark.accuracy
def test_meets_the_papers_bound_and_detects_boxes_safely(metrics):
    _, result = metrics
    assert result["table1_cm"]["mean"]["max"] < PAPER_BOUND_CM
    assert result["detection"]["f1"] >= 0.9
    assert result["detection"]["false_objects_from_people"] == 0
    assert result["safety"]["collisions"] == 0
    assert result["safety"]["laps_completed"] == result["laps"]


@pytest.mark.accuracy
def test_matches_the_golden_figures(metrics):
    name, result = metrics
    golden, tolerance = GOLDEN[name], GOLDEN["tolerance"]
    table = result["table1_cm"]
    within_cm = {"abs": tolerance["table1_cm"]}
    assert table["mean"]["avg"] == pytest.approx(golden["table1_mean_avg_cm"], **within_cm)
    assert table["mean"]["max"] == pytest.approx(golden["table1_mean_max_cm"], **within_cm)
    assert table["std"]["avg"] == pytest.approx(golden["table1_std_avg_cm"], **within_cm)
    assert result["detection"]["f1"] == pytest.approx(golden["f1"], abs=tolerance["f1"])
