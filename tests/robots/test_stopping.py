"""Stopping distance and stop envelope against closed forms and a stepped simulation."""

from __future__ import annotations

import numpy as np
import pytest

from robots.safety import points_inside
from robots.stopping import blind_reach, stop_envelope, stopping_distance


def stepped_stop(speed: float, reaction_time: float, deceleration: float, dt: float = 1e-5):
    """Distance travelled by explicit time stepping: constant speed, then braking."""
    travelled, t, v = 0.0, 0.0, speed
    while v > 0.0:
        if t >= reaction_time:
            v = max(0.0, v - deceleration * dt)
        travelled += v * dt
        t += dt
    return travelled


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


def distance_to_box(points, x0, x1, y0, y1):
    """Euclidean distance of each point to the axis-aligned box (0 inside)."""
    dx = np.maximum.reduce([x0 - points[:, 0], np.zeros(len(points)), points[:, 0] - x1])
    dy = np.maximum.reduce([y0 - points[:, 1], np.zeros(len(points)), points[:, 1] - y1])
    return np.hypot(dx, dy)


@pytest.mark.parametrize("reach", [0.0, 0.35, -0.2])
def test_the_envelope_of_a_box_is_the_box_swept_and_grown(reach):
    footprint = [(-0.27, -0.19), (0.18, -0.19), (0.18, 0.19), (-0.27, 0.19)]
    supplement = 0.1
    envelope = stop_envelope(footprint, reach, supplement)
    points = np.random.default_rng(3).uniform([-0.8, -0.6], [0.9, 0.6], size=(4000, 2))
    x0, x1 = -0.27 + min(reach, 0.0), 0.18 + max(reach, 0.0)
    distance = distance_to_box(points, x0, x1, -0.19, 0.19)
    inside = points_inside(envelope, points)
    # The buffer's arcs are polygons: only points within 1 mm of the rounded edge may differ.
    clear = np.abs(distance - supplement) > 1e-3
    np.testing.assert_array_equal(inside[clear], (distance <= supplement)[clear])


def test_blind_reach_is_where_a_forward_scanner_starts_to_see():
    footprint = [(-0.6, -0.4), (0.67, -0.1), (0.67, 0.1), (-0.6, 0.4)]
    assert blind_reach(footprint, mount_x=0.62, range_min=0.05) == 0.0
    assert blind_reach(footprint, mount_x=0.62, range_min=0.5) == pytest.approx(0.45)
