"""Stopping distances and field sizes: closed forms, stepped simulations, Sick's figures."""

from __future__ import annotations

import numpy as np
import pytest

from robots.safety import points_inside
from robots.stopping import (
    StopModel,
    Supplements,
    blind_reach,
    field_size,
    ground_clearance_supplement,
    minimum_protective_field,
    required_field,
    response_time,
    stopping_distance,
)


def stepped_stop(speed: float, reaction_time: float, deceleration: float, dt: float = 1e-5):
    """Distance travelled by explicit time stepping: constant speed, then braking."""
    travelled, t, v = 0.0, 0.0, speed
    while v > 0.0:
        if t >= reaction_time:
            v = max(0.0, v - deceleration * dt)
        travelled += v * dt
        t += dt
    return travelled


def follower_ramp(speed: float, deceleration: float, period: float) -> float:
    """Distance of a command lowered by ``a T`` every period and held: summed command by command."""
    travelled, command = 0.0, speed
    while True:
        command = max(0.0, command - deceleration * period)
        if command == 0.0:
            return travelled
        travelled += command * period


@pytest.mark.parametrize(("speed", "reaction", "decel"), [
    (0.4, 0.1, 1.0), (1.0, 0.18, 1.0), (1.5, 0.3, 0.5), (0.05, 0.0, 2.0),
])
def test_stopping_distance_matches_a_stepped_stop(speed, reaction, decel):
    assert stopping_distance(speed, reaction, decel) == pytest.approx(
        stepped_stop(speed, reaction, decel), abs=1e-4)


def test_stopping_distance_takes_the_speed_magnitude_and_rejects_bad_parameters():
    assert stopping_distance(-0.5, 0.2, 1.0) == stopping_distance(0.5, 0.2, 1.0)
    with pytest.raises(ValueError, match="deceleration must be > 0"):
        stopping_distance(1.0, 0.1, 0.0)
    with pytest.raises(ValueError, match="reaction_time must be >= 0"):
        stopping_distance(1.0, -0.1, 1.0)


def test_response_time_is_multiple_sampling_scan_periods():
    # Sick S300: 80 ms basic response time at 2x multiple sampling of 40 ms scans, and
    # +40 ms per further sample (the operating instructions' table).
    assert response_time(0.04, 2) == pytest.approx(0.08)
    assert [round(response_time(0.04, n), 3) for n in (3, 4, 16)] == [0.12, 0.16, 0.64]
    with pytest.raises(ValueError, match="multiple_sampling"):
        response_time(0.04, 0)


@pytest.mark.parametrize("speed", [0.013, 0.2, 0.4, 0.55, 1.0, 1.49])
@pytest.mark.parametrize("period", [0.02, 0.005])
def test_braking_is_the_followers_ramp(speed, period):
    model = StopModel(scanner_response_s=0.16, command_latency_s=0.0, control_period_s=period,
                      deceleration=1.0)
    assert model.braking_distance(speed) == pytest.approx(follower_ramp(speed, 1.0, period),
                                                          abs=1e-12)
    # It tends to the continuous v^2 / 2a less half a period of travel.
    assert model.braking_distance(speed) == pytest.approx(
        speed**2 / 2.0 - speed * period / 2.0, abs=period * 1.0)
    assert model.distance(speed) == pytest.approx(0.16 * speed + follower_ramp(speed, 1.0, period))


def test_stop_model_without_a_control_period_brakes_continuously():
    model = StopModel(0.1, 0.02, 0.0, 2.0)
    assert model.distance(1.0) == pytest.approx(stepped_stop(1.0, 0.12, 2.0), abs=1e-4)
    with pytest.raises(ValueError, match="deceleration"):
        StopModel(0.1, 0.0, 0.02, 0.0)


def test_field_size_is_sicks_formula():
    # S_L = S_A + Z_G + Z_R + Z_F, S_B = F_B + 2 (Z_G + Z_R + Z_F), by hand.
    supplements = Supplements(general=0.1, reflector=0.2, ground_clearance=0.15)
    length, width = field_size(0.68, supplements, vehicle_width=0.8)
    assert length == pytest.approx(0.68 + 0.45)
    assert width == pytest.approx(0.8 + 0.9)
    with pytest.raises(ValueError, match="reflector"):
        Supplements(general=0.1, reflector=-0.2, ground_clearance=0.0)


def test_ground_clearance_supplement_is_the_flat_rate_below_120_mm():
    assert ground_clearance_supplement(0.0) == ground_clearance_supplement(0.119) == 0.15
    assert ground_clearance_supplement(0.12) == ground_clearance_supplement(0.3) == 0.0


def test_required_field_starts_at_the_front_and_centres_on_the_footprint():
    footprint = [(-0.6, -0.3), (0.67, -0.1), (0.67, 0.3), (-0.6, 0.3)]  # y in [-0.3, 0.3]
    field = required_field(footprint, 1.0, 1.2)
    assert field.bounds == pytest.approx((0.67, -0.6, 1.67, 0.6))


def distance_to_box(points, x0, x1, y0, y1):
    dx = np.maximum.reduce([x0 - points[:, 0], np.zeros(len(points)), points[:, 0] - x1])
    dy = np.maximum.reduce([y0 - points[:, 1], np.zeros(len(points)), points[:, 1] - y1])
    return np.hypot(dx, dy)


def test_minimum_field_is_the_required_field_and_the_grown_footprint():
    footprint = [(-0.27, -0.19), (0.18, -0.19), (0.18, 0.19), (-0.27, 0.19)]
    field = minimum_protective_field(footprint, length=0.6, width=1.28, general_supplement=0.1)
    points = np.random.default_rng(3).uniform([-0.6, -0.9], [1.0, 0.9], size=(5000, 2))
    ahead = (points[:, 0] >= 0.18) & (points[:, 0] <= 0.78) & (np.abs(points[:, 1]) <= 0.64)
    around = distance_to_box(points, -0.27, 0.18, -0.19, 0.19)
    clear = np.abs(around - 0.1) > 1e-3  # the buffer's arcs are polygons
    inside = points_inside(field, points)
    np.testing.assert_array_equal(inside[clear], (ahead | (around <= 0.1))[clear])


def test_blind_reach_is_where_a_forward_scanner_starts_to_see():
    footprint = [(-0.6, -0.4), (0.67, -0.1), (0.67, 0.1), (-0.6, 0.4)]
    assert blind_reach(footprint, mount_x=0.62, range_min=0.05) == 0.0
    assert blind_reach(footprint, mount_x=0.62, range_min=0.5) == pytest.approx(0.45)
