"""The closed loop on a tiny world: it drives, maps, scores, and repeats itself exactly."""

import json

import numpy as np
import pytest

from scenarios.bench.runner import run_scenario
from scenarios.cli import main
from scenarios.results.outputs import summarize
from scenarios.spec.clock import Schedule
from scenarios.spec.load import load_scenario
from tests.scenarios.tiny_world import write_tiny


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tiny")
    path = write_tiny(folder)
    spec = load_scenario(path)
    return spec, run_scenario(spec)


def without_performance(metrics):
    return {key: value for key, value in metrics.items() if key != "performance"}


def test_schedule_fires_at_its_rate_without_drift():
    for rate in (12.5, 25.0, 50.0):
        schedule = Schedule(rate, 240.0)
        fired = sum(schedule.due(step) for step in range(1, 240 * 10 + 1))
        assert fired == round(rate * 10)


@pytest.mark.parametrize("physics", [240.0, 100.0, 1000.0])
@pytest.mark.parametrize("rate", [0.7, 7.0, 12.5, 25.0, 33.3, 50.0, 239.0, 240.0, 500.0])
def test_schedule_next_due_finds_every_step_due_fires(rate, physics):
    # The bench jumps from one firing to the next: the steps must be due()'s, one by one.
    schedule = Schedule(rate, physics)
    steps = [n for n in range(1, 5001) if schedule.due(n)]
    jumped = [schedule.next_due(0)]
    while jumped[-1] <= 5000:
        jumped.append(schedule.next_due(jumped[-1]))
    assert jumped[:-1] == steps
    assert schedule.next_due(2 * 5000 + 1) > 2 * 5000 + 1


def test_tiny_run_completes_its_laps_without_collision(tiny_run):
    spec, log = tiny_run
    metrics = summarize(log)
    assert metrics["safety"]["laps_completed"] == spec.laps
    assert metrics["safety"]["collisions"] == 0
    # The carton reaches into the warning field: the robot slows down, never stops.
    assert metrics["safety"]["slowdowns"] >= spec.laps
    assert metrics["safety"]["stops"] == 0
    localization = metrics["localization"]
    assert localization["rmse_xy_m"] < 0.005
    # The EKF estimates the LMS100's range bias, so its covariance is honest: NEES near 3.
    assert 1.0 < localization["nees_mean"] < 10.0


def test_tiny_run_maps_the_box_and_nothing_else(tiny_run):
    _, log = tiny_run
    metrics = summarize(log)
    assert metrics["detection"]["f1"] >= 0.9
    assert metrics["detection"]["false_objects_from_people"] == 0
    table = metrics["table1_cm"]
    assert table["polylines"] >= 1
    assert table["mean"]["max"] < 10.0  # the paper's bound


@pytest.mark.slow  # a second run; tests/scenarios/test_testbench.py repeats it in other ways
def test_same_seed_same_metrics_and_maps(tiny_run):
    spec, first = tiny_run
    second = run_scenario(spec)
    assert without_performance(summarize(first)) == without_performance(summarize(second))
    assert first.maps_after_lap == second.maps_after_lap
    np.testing.assert_array_equal(np.array(first.true_poses), np.array(second.true_poses))


def test_adaptive_policy_does_not_slow_for_the_known_box(tiny_run):
    spec, log = tiny_run
    assert spec.policy == "conservative"
    conservative = summarize(log)
    adaptive = summarize(run_scenario(load_scenario(spec.source, overrides=["policy=adaptive"])))
    # Lap 1 knows nothing yet; from lap 2 on the carton is a known semi-static object.
    assert adaptive["safety"]["slowed_time_s"][1] < conservative["safety"]["slowed_time_s"][1]
    assert adaptive["safety"]["lap_time_s"][1] < conservative["safety"]["lap_time_s"][1]
    assert adaptive["safety"]["collisions"] == 0


def test_run_command_writes_the_output_directory(capsys, tmp_path):
    path = write_tiny(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--laps", "2"]) == 0
    printed = capsys.readouterr().out
    assert f"results in {out}" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    for key in ("table1_cm", "detection", "localization", "safety", "performance"):
        assert key in metrics
    assert sorted(p.name for p in (out / "maps").iterdir()) == ["lap_01.geojson", "lap_02.geojson"]
    figures = {p.name for p in (out / "figures").iterdir()}
    assert {"polygonal_map.png", "ekf_corrections.png", "detection_scores.png"} <= figures
    assert (out / "table1.csv").read_text().splitlines()[0].startswith("environment,mean_avg")


@pytest.mark.slow
def test_adaptive_fields_still_stop_for_a_person_in_pal3b():
    spec = load_scenario("pal3b", overrides=["laps=2", "policy=adaptive"])
    metrics = summarize(run_scenario(spec))
    safety = metrics["safety"]
    # Lap 2 runs with adapted fields (the boxes are known), yet the worker stops the robot.
    assert safety["stops_per_lap"][1] >= 1
    assert safety["collisions"] == 0
    assert metrics["detection"]["false_objects_from_people"] == 0
    assert metrics["detection"]["f1"] >= 0.9
