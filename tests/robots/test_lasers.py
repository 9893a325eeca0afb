"""LaserSpec: the data-sheet presets and the validation of specs built in code."""

import dataclasses
import math

import pytest

from robots.lasers import LMS100, S300
from robots.presets import PRESETS
from scenarios.spec.scenario import Noise
from tests.spec_errors import raises_spec_error


def test_presets_match_their_data_sheets():
    # 270 deg at 0.5 deg: 540 steps, 541 beams including both edges.
    assert (LMS100.num_beams, S300.num_beams) == (541, 541)
    assert S300.period == pytest.approx(0.080)  # 80 ms scan time


@pytest.mark.parametrize(
    ("changes", "key", "message"),
    [
        ({"fov": 270.0}, "fov", r"<= 6.28.*, got 270.0 \(radians: math.radians\(270\)"),
        ({"fov": 0.0}, "fov", "must be > 0.0"),
        ({"angular_resolution": math.radians(90.0)}, "angular_resolution", "<= 0.78"),
        ({"fov": 0.005}, "angular_resolution", r"must not exceed fov \(0.005 rad\)"),
        ({"rate_hz": math.nan}, "rate_hz", "must be a finite number, got nan"),
        ({"rate_hz": 1000.0}, "rate_hz", r"<= 200.0, got 1000.0 \(scans per second"),
        ({"range_min": -0.1}, "range_min", ">= 0.0 and <= 10.0, got -0.1"),
        ({"range_min": 5.0, "range_max": 4.0}, "range_min", r"must be < range_max \(4.0 m\)"),
        ({"range_max": math.inf}, "range_max", "must be a finite number, got inf"),
        ({"range_max": 1000.0}, "range_max", "<= 500.0, got 1000.0"),
        ({"range_sigma": -0.01}, "range_sigma", ">= 0.0 and <= 10.0, got -0.01"),
        ({"range_bias_max": 2.0}, "range_bias_max", "<= 1.0, got 2.0"),
        ({"intensity_sigma": 1.5}, "intensity_sigma", r"<= 1.0, got 1.5 \(on the \[0, 1\]"),
        ({"dropout_prob": 1.0}, "dropout_prob", ">= 0.0 and < 1.0, got 1.0"),
        ({"name": ""}, "name", "non-empty"),
        ({"name": 3}, "name", "expected a string, got an integer 3"),
    ],
)
def test_spec_built_in_code_names_the_key(changes, key, message):
    with raises_spec_error(key, message):
        dataclasses.replace(LMS100, **changes)


def test_the_largest_noise_factors_keep_the_presets_valid():
    # A scenario may scale the preset's noise up to Noise's bounds; the scaled specs that
    # scenarios.bench.testbench builds must still pass their own bounds.
    fields = {field.name: field for field in dataclasses.fields(Noise)}
    range_factor = fields["range"].metadata["range"].le
    odometry_factor = fields["odometry"].metadata["range"].le
    for robot in PRESETS.values():
        robot.replace(encoder_slip_sigma=robot.encoder_slip_sigma * odometry_factor)
        for mount in (robot.safety_laser, robot.localization_laser):
            laser = mount.laser
            dataclasses.replace(laser, range_sigma=laser.range_sigma * range_factor)
