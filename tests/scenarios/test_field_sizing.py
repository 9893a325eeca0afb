"""Protective fields sized by the standard's formula: the check, its margins, its refusals."""

import dataclasses

import pytest

from robots.presets import PIONEER3DX
from robots.stopping import Supplements
from scenarios.spec.field_sizing import field_checks, stop_model
from scenarios.spec.layout import robot_preset, scenario_world
from scenarios.spec.load import load_scenario
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import TINY_SCENARIO, TINY_WORLD, write_tiny

TINY_PROTECTIVE = "protective = [[0.18, -0.65], [0.78, -0.65], [0.78, 0.65], [0.18, 0.65]]"


def tiny_with(tmp_path, protective: str, scenario: str = TINY_SCENARIO):
    path = write_tiny(tmp_path, scenario=scenario)
    world = tmp_path / "tiny_world.toml"
    assert TINY_PROTECTIVE in TINY_WORLD
    world.write_text(TINY_WORLD.replace(TINY_PROTECTIVE, protective))
    return path


def hand_computed_length() -> float:
    """S_A at 0.4 m/s by hand: 2 scans of 80 ms, no command latency (12.5 Hz scans on the
    50 Hz control clock), then the follower's 1 m/s^2 ramp in 20 ms steps (19 steps
    0.38 ... 0.02 m/s held 20 ms: 0.02 * 3.8 = 0.076 m); supplements 0.1 + 0.2 + 0.15."""
    return 0.4 * 0.16 + 0.02 * sum(0.4 - 0.02 * k for k in range(1, 20)) + 0.45


def test_the_tiny_worlds_field_has_its_formula_margin(tmp_path):
    spec = load_scenario(str(write_tiny(tmp_path)))
    (check,) = field_checks(spec, scenario_world(spec), robot_preset(spec.robot))
    assert check.required_length == pytest.approx(hand_computed_length())
    assert check.required_width == pytest.approx(0.381 + 2 * 0.45)
    assert check.supplements == Supplements(general=0.1, reflector=0.2, ground_clearance=0.15)
    # The field reaches 0.78 m ahead of the axle, 0.6 m ahead of the bumper (x = 0.1825).
    assert check.actual_length == pytest.approx(0.78 - 0.1825, abs=2e-3)
    assert check.actual_width == pytest.approx(1.3, abs=1e-3)
    assert not check.undersized


def test_a_field_one_centimetre_short_is_refused_with_one_line(tmp_path, capsys):
    required = hand_computed_length()
    reach = 0.1825 + required - 0.01
    short = (f"protective = [[0.18, -0.65], [{reach:.4f}, -0.65], [{reach:.4f}, 0.65], "
             "[0.18, 0.65]]")
    status, _, err = run_cli(capsys, "check", tiny_with(tmp_path, short))
    assert status == 2
    assert_one_error_line(err, "path.segments[0].protective", "segment 'corridor' at 0.4 m/s",
                          f"{required:.3f} m long", f"this one is {required - 0.01:.3f} m long")


def test_a_scenario_studying_undersized_fields_runs_and_reports_the_margin(tmp_path, capsys):
    short = "protective = [[0.18, -0.3], [0.6, -0.3], [0.6, 0.3], [0.18, 0.3]]"
    scenario = TINY_SCENARIO + "\n[safety]\nundersized_fields = true\n"
    status, out, _ = run_cli(capsys, "check", tiny_with(tmp_path, short, scenario))
    assert status == 0
    assert "undersized (studied)" in out


def test_no_reflector_supplement_without_a_post_near_the_field(tmp_path):
    spec = load_scenario(str(write_tiny(tmp_path)))
    world = scenario_world(spec)
    far = dataclasses.replace(world, posts=tuple(p for p in world.posts if abs(p.y) < 1.0))
    (check,) = field_checks(spec, far, PIONEER3DX)
    assert check.supplements.reflector == 0.0
    assert check.required_width == pytest.approx(0.381 + 2 * 0.25)


def test_the_stop_model_follows_the_rates_and_the_laser():
    spec = load_scenario("warehouse", overrides=["safety.undersized_fields=true"])
    from robots.presets import LGV

    model = stop_model(spec, LGV)
    assert model.scanner_response_s == pytest.approx(2 / spec.rates.safety_hz)
    assert model.command_latency_s == 0.0
    assert model.deceleration == 1.0
