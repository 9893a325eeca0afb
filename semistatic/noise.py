"""Range noise of a laser, measured on its scans, and the thresholds that follow it.

A polyline must simplify the shape, not the noise: a Douglas-Peucker tolerance below the
noise keeps noise extremes as vertices, one far above it rounds off real corners. The
default tolerances are therefore multiples of the range noise: the laser spec's in
simulation (:func:`spec_noise_params`, applied by the scenario loader to the robot's safety
laser), the one :func:`estimate_range_noise` measures on a log in replay
(:func:`noise_params`).

Examples
--------
>>> noise_epsilon(0.01)  # 1 cm range noise
0.03
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from semistatic.extraction import remove_invalid
from semistatic.params import MapperParams
from semistatic.types import Scan

__all__ = [
    "NOISE_EPSILON_SIGMAS",
    "SAME_SURFACE_STEP",
    "SPEC_EPSILON_SIGMAS",
    "estimate_range_noise",
    "noise_epsilon",
    "noise_params",
    "spec_noise_params",
]

NOISE_EPSILON_SIGMAS = 3.0
"""Douglas-Peucker tolerance in noise sigmas: a straight wall's reading lies beyond 3 sigma
with probability 0.3 %, so noise alone seldom makes a vertex."""

SPEC_EPSILON_SIGMAS = 2.5
"""Douglas-Peucker tolerance in sigmas of a laser's *data-sheet* range noise. The data sheet
gives the noise along the beam; :func:`estimate_range_noise` (to which
``NOISE_EPSILON_SIGMAS`` applies) measures it across the surface, the beam's noise times
the cosine of the incidence: on simulated 1.2 cm scans of a corridor and of a room it
measured 0.83 and 1.04 cm. 2.5 data-sheet sigmas are about 3 measured ones; for the Sick
LMS100 (1.2 cm) they give the 3 cm the bundled paper scenarios always used."""

SAME_SURFACE_STEP = 0.3
"""Consecutive readings farther apart than this (m) lie on two surfaces (a depth jump), and
a triple with such a step is no sample of the noise. 0.3 m is the gap of one-degree beams
head-on at 17 m, or at 4 m at 75 deg incidence."""

# The median of |N(0, s)| is 0.6745 s; the distance of a reading from the chord of its two
# neighbours on a plane surface is e_i - (e_{i-1} + e_{i+1}) / 2: sqrt(1.5) times the noise.
_MEDIAN_ABS_TO_SIGMA = 1.0 / 0.6744897501960817
_CHORD_TO_READING = math.sqrt(1.5)


def noise_epsilon(sigma: float) -> float:
    """Return the Douglas-Peucker tolerance for range noise ``sigma`` (m).

    Examples
    --------
    >>> round(noise_epsilon(0.005), 4)  # the Intel log
    0.015
    """
    if not sigma >= 0.0:
        raise ValueError(f"noise_epsilon: sigma must be >= 0 m, got {sigma!r}")
    return NOISE_EPSILON_SIGMAS * sigma


def estimate_range_noise(scans: Iterable[Scan], max_range: float = math.inf) -> float:
    """Return the range noise sigma (m) of ``scans``, robust to corners and depth jumps.

    For every three consecutive valid readings (within ``max_range``) that lie on one
    surface (each step shorter than ``SAME_SURFACE_STEP``), the distance of the middle
    reading from the chord of the other two; on a plane surface it is normal with sigma
    ``sqrt(1.5)`` times the noise across the surface, so the noise is
    ``median / 0.6745 / sqrt(1.5)``. The median ignores the minority of triples at
    corners, on curved objects and at stray readings. The noise is the one across the
    surface, which is what the Douglas-Peucker tolerance is compared with.

    Returns ``nan`` when no triple qualifies.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> angles = np.radians(np.arange(-60.0, 60.0, 1.0))
    >>> rounds = [Scan(ranges=2.0 + rng.normal(0.0, 0.01, angles.size), angle_min=angles[0],
    ...                angle_increment=np.radians(1.0)) for _ in range(20)]
    >>> round(estimate_range_noise(rounds) * 100, 1)  # cm; a round wall seen from its centre
    1.0
    >>> estimate_range_noise([])
    nan
    """
    distances = []
    for scan in scans:
        kept = np.flatnonzero(remove_invalid(scan, max_range))
        middle = kept[1:-1][(np.diff(kept)[:-1] == 1) & (np.diff(kept)[1:] == 1)]
        if middle.size == 0:
            continue
        points = scan.points()
        before, at, after = points[middle - 1], points[middle], points[middle + 1]
        chord, offset = after - before, at - before
        length = np.hypot(chord[:, 0], chord[:, 1])
        cross = np.abs(offset[:, 0] * chord[:, 1] - offset[:, 1] * chord[:, 0])
        step_in = np.hypot(offset[:, 0], offset[:, 1])
        step_out = np.hypot(*(after - at).T)
        same = (step_in < SAME_SURFACE_STEP) & (step_out < SAME_SURFACE_STEP) & (length > 0.0)
        distances.append(cross[same] / length[same])
    if not distances or not (values := np.concatenate(distances)).size:
        return math.nan
    return float(np.median(values)) * _MEDIAN_ABS_TO_SIGMA / _CHORD_TO_READING


def noise_params(params: MapperParams, sigma: float) -> MapperParams:
    """Return ``params`` with the thresholds that depend on the range noise fitted to it.

    The Douglas-Peucker tolerance becomes :func:`noise_epsilon` of ``sigma`` (raised or
    lowered), the breakpoint noise ``max(breakpoint_sigma_r, sigma)`` (never lowered: it
    only has to exceed the noise). An unknown (``nan``) sigma changes nothing.

    Examples
    --------
    >>> fitted = noise_params(MapperParams(), 0.018)  # ACES: 1.8 cm
    >>> round(fitted.epsilon, 3), fitted.breakpoint_sigma_r
    (0.054, 0.018)
    >>> noise_params(MapperParams(), float("nan")) == MapperParams()
    True
    """
    if math.isnan(sigma):
        return params
    epsilon = noise_epsilon(sigma)
    if epsilon <= 0.0:
        return params
    return params.replace(epsilon=epsilon, breakpoint_sigma_r=max(params.breakpoint_sigma_r, sigma))


def spec_noise_params(params: MapperParams, sigma: float) -> MapperParams:
    """Return ``params`` with the noise thresholds of a laser whose data sheet gives ``sigma``.

    For simulation, where the laser's range noise is known: the Douglas-Peucker tolerance
    becomes :data:`SPEC_EPSILON_SIGMAS` times ``sigma`` and the breakpoint noise
    ``sigma`` itself. A noiseless laser (``sigma == 0``) keeps ``params``: a tolerance
    must stay above the numerical noise.

    Examples
    --------
    >>> lms100 = spec_noise_params(MapperParams(), 0.012)  # the defaults
    >>> lms100 == MapperParams()
    True
    >>> s300 = spec_noise_params(MapperParams(), 0.03)
    >>> round(s300.epsilon, 3), s300.breakpoint_sigma_r
    (0.075, 0.03)
    """
    if not sigma >= 0.0:
        raise ValueError(f"spec_noise_params: sigma must be >= 0 m, got {sigma!r}")
    if sigma == 0.0:
        return params
    return params.replace(epsilon=SPEC_EPSILON_SIGMAS * sigma, breakpoint_sigma_r=sigma)
