"""The scripts in examples/ run (short laps) and show what they claim."""

import runpy
from pathlib import Path

import numpy as np
import pytest

from scenarios.spec.load import load_scenario

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def example(name):
    return runpy.run_path(str(EXAMPLES / f"{name}.py"), run_name="example")


def test_every_example_is_tested():
    assert sorted(p.stem for p in EXAMPLES.glob("*.py")) == [
        "box_pushed_mid_lap", "custom_field_policy", "speed_and_zone",
    ]


@pytest.mark.slow
def test_a_box_pushed_mid_lap_is_first_kept_then_replaced(capsys):
    script = example("box_pushed_mid_lap")
    assert script["main"](["--laps", "2", "--push-at", "1.0"]) == 0
    printed = capsys.readouterr().out
    assert "carton_b pushed 0.3 m along the wall" in printed
    lap1, lap2 = printed.split("\nlap 1: ")[1].split("\nlap 2: ")
    # Lap 1 maps both cartons and nothing else; lap 2 ends with the pushed carton mapped
    # where it now stands and no false object (with issue 10's merge and extraction; the
    # paper's merge still had the old face in the map at the lap's end: fp 1).
    assert "fp 0, fn 0, F1 1.00" in lap1
    assert "fp 0, fn 0, F1 1.00" in lap2
    world = script["corridor"]()
    assert world.source == "<memory>"
    assert [box.name for box in world.boxes] == ["carton_a", "carton_b"]


@pytest.mark.slow
def test_a_custom_policy_is_compared_with_the_bundled_ones(capsys):
    script = example("custom_field_policy")
    assert script["main"](["--scenario", "pal1", "--laps", "2", "--reach", "0.8"]) == 0
    assert "short-warning-0.8m" in capsys.readouterr().out
    spec = load_scenario("pal1", overrides=["laps=2"])
    results = script["compare"](spec, ["conservative", script["ShortWarning"](0.5)])
    conservative, short = results["conservative"], results["short-warning-0.5m"]
    # A shorter braking zone: slower for less time, so every lap is shorter; still safe.
    assert all(s < c for s, c in zip(short["lap_time_s"], conservative["lap_time_s"], strict=True))
    assert sum(short["slowed_time_s"]) < sum(conservative["slowed_time_s"])
    assert short["collisions"] == conservative["collisions"] == 0


@pytest.mark.slow
def test_the_speed_and_zone_observer_sees_the_stop_for_the_person(tmp_path, capsys):
    script = example("speed_and_zone")
    out = tmp_path / "speed.png"
    assert script["main"](["--scenario", "pal3b", "--laps", "1", "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000
    assert "stops 1" in capsys.readouterr().out
    recorder, log = script["record"](load_scenario("pal3b", overrides=["laps=1"]))
    zone, speed = np.array(recorder.zone), np.array(recorder.speed)
    assert set(zone) == {"free", "warning", "protective"}
    # Stopped for the person: the speed falls to zero while the protective field holds.
    assert np.abs(speed[zone == "protective"]).min() < 0.01
    # Slowed in the warning field: the follower's speed times the slowdown factor.
    slowed = speed[zone == "warning"]
    assert np.median(slowed) == pytest.approx(0.4 * 0.4, abs=0.01)
    assert len(recorder.time) == round(log.sim_time_s / (1 / 240)) - 24  # minus settling
