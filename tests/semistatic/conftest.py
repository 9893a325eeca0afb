"""Shared fixtures for the semistatic tests: nasty inputs and synthetic laser scans.

``nasty_polyline`` and ``nasty_scan`` are parametrised over every degenerate input the
geometry must survive (empty, one point, repeated vertices, zero-length segments,
collinear vertices, a polyline folding back on itself; nan/inf/negative/out-of-range
ranges, a scan with no return at all, a scan with no beams). ``raycast_ranges`` casts
exact ranges against line segments so that tests can build scans of known scenes.
"""

from __future__ import annotations

import numpy as np
import pytest

from semistatic.types import Scan

NASTY_POLYLINES: dict[str, np.ndarray] = {
    "empty": np.empty((0, 2)),
    "one_point": np.array([[1.0, 2.0]]),
    "zero_length_segment": np.array([[0.5, 0.5], [0.5, 0.5]]),
    "duplicate_vertices": np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 1.0]]),
    "collinear": np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]),
    "folds_back": np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.0]]),
    "tiny_segment": np.array([[0.0, 0.0], [1e-12, 0.0], [1.0, 1.0]]),
}

_BEAMS = 21
_INCREMENT = np.radians(1.0)


def _ranges_with(bad_value: float, where: slice) -> np.ndarray:
    ranges = np.full(_BEAMS, 2.0)
    ranges[where] = bad_value
    return ranges


NASTY_SCANS: dict[str, Scan] = {
    "all_inf": Scan(ranges=np.full(_BEAMS, np.inf), angle_min=0.0, angle_increment=_INCREMENT),
    "all_nan": Scan(ranges=np.full(_BEAMS, np.nan), angle_min=0.0, angle_increment=_INCREMENT),
    "all_at_range_max": Scan(
        ranges=np.full(_BEAMS, 30.0),
        angle_min=0.0,
        angle_increment=_INCREMENT,
        range_max=20.0,
    ),
    "no_beams": Scan(ranges=np.empty(0), angle_min=0.0, angle_increment=_INCREMENT),
    "nan_block": Scan(
        ranges=_ranges_with(np.nan, slice(8, 12)), angle_min=0.0, angle_increment=_INCREMENT
    ),
    "inf_block": Scan(
        ranges=_ranges_with(np.inf, slice(8, 12)), angle_min=0.0, angle_increment=_INCREMENT
    ),
    "negative_block": Scan(
        ranges=_ranges_with(-2.0, slice(8, 12)), angle_min=0.0, angle_increment=_INCREMENT
    ),
    "below_range_min": Scan(
        ranges=_ranges_with(0.01, slice(8, 12)),
        angle_min=0.0,
        angle_increment=_INCREMENT,
        range_min=0.05,
    ),
    "alternating_nan": Scan(
        ranges=_ranges_with(np.nan, slice(0, None, 2)),
        angle_min=0.0,
        angle_increment=_INCREMENT,
    ),
}


@pytest.fixture(params=sorted(NASTY_POLYLINES))
def nasty_polyline(request: pytest.FixtureRequest) -> np.ndarray:
    """One degenerate polyline vertex array per parameter."""
    return NASTY_POLYLINES[request.param].copy()


@pytest.fixture(params=sorted(NASTY_SCANS))
def nasty_scan(request: pytest.FixtureRequest) -> Scan:
    """One scan with degenerate ranges per parameter."""
    return NASTY_SCANS[request.param]


def raycast_ranges(
    segments: np.ndarray, angles: np.ndarray, origin: tuple[float, float] = (0.0, 0.0)
) -> np.ndarray:
    """Return the exact range along each beam to the nearest of ``segments`` (inf: none).

    ``segments`` is ``(S, 2, 2)``: start and end point of each wall in the sensor frame
    (sensor heading along +x at ``origin``).
    """
    segments = np.asarray(segments, dtype=float)
    direction = np.column_stack((np.cos(angles), np.sin(angles)))  # (B, 2)
    start = segments[:, 0] - np.asarray(origin)  # (S, 2)
    edge = segments[:, 1] - segments[:, 0]  # (S, 2)
    # origin + r d = start + u e  ->  r d - u e = start  (Cramer's rule)
    denom = direction[:, None, 0] * -edge[None, :, 1] + edge[None, :, 0] * direction[:, None, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (start[None, :, 0] * -edge[None, :, 1] + edge[None, :, 0] * start[None, :, 1]) / denom
        u = (
            direction[:, None, 0] * start[None, :, 1] - direction[:, None, 1] * start[None, :, 0]
        ) / denom
    hit = (np.abs(denom) > 1e-12) & (r > 0.0) & (u >= 0.0) & (u <= 1.0)
    return np.where(hit, r, np.inf).min(axis=1)


# A room 8 m x 6 m around the sensor, a box, and a pillar: corners, occlusions, a jump.
ROOM_SEGMENTS = np.array(
    [
        [[-2.0, -3.0], [6.0, -3.0]],
        [[6.0, -3.0], [6.0, 3.0]],
        [[6.0, 3.0], [-2.0, 3.0]],
        [[-2.0, 3.0], [-2.0, -3.0]],
        [[2.0, -1.0], [3.0, -1.0]],  # box
        [[3.0, -1.0], [3.0, 0.0]],
        [[3.0, 0.0], [2.0, 0.0]],
        [[2.0, 0.0], [2.0, -1.0]],
        [[1.5, 1.5], [1.7, 1.5]],  # pillar
        [[1.7, 1.5], [1.7, 1.7]],
        [[1.7, 1.7], [1.5, 1.7]],
        [[1.5, 1.7], [1.5, 1.5]],
    ]
)


def room_scan(rng: np.random.Generator, noise: float = 0.01, beams: int = 541) -> Scan:
    """Return a 270 deg scan of ``ROOM_SEGMENTS`` with Gaussian range noise ``noise`` (m)."""
    increment = np.radians(270.0) / (beams - 1)
    angles = -np.radians(135.0) + increment * np.arange(beams)
    ranges = raycast_ranges(ROOM_SEGMENTS, angles) + rng.normal(0.0, noise, beams)
    return Scan(
        ranges=ranges, angle_min=-np.radians(135.0), angle_increment=increment, range_max=30.0
    )


@pytest.fixture
def noisy_room_scan() -> Scan:
    """A seeded 541-beam scan of the test room with 1 cm range noise."""
    return room_scan(np.random.default_rng(7))
