"""The first, per-group implementation of landmark detection: the reference for the fast one.

``robots.landmarks.detect_landmarks`` estimates every post of a scan in two compiled
passes per round; this module keeps the original loop over groups (one numpy pass per post and
iteration), which is easier to read against the docstring of ``detect_landmarks``. The
tests and ``benchmarks/test_bench_navigation.py`` compare the two.
"""

from __future__ import annotations

import math

import numpy as np

from robots.landmarks import (
    _BEARING_CANDIDATES,
    _CENTRE_ITERATIONS,
    _GRAZING_DEPTH,
    _MIN_RANGE_VARIANCE,
    _MISSING_BEAMS_ALLOWED,
    _OCCLUDER_SIGMAS,
    _RANGE_SIGMA_FLOOR,
    _WIDTH_SLACK_STEPS,
    DEFAULT_BEARING_SIGMA,
    DEFAULT_POST_RADIUS,
    DEFAULT_RANGE_SIGMA,
    LandmarkObservation,
)
from robots.lasers import POST_INTENSITY_THRESHOLD
from semistatic.types import Scan


def detect_landmarks_reference(
    scan: Scan,
    *,
    intensity_threshold: float = POST_INTENSITY_THRESHOLD,
    post_radius: float = DEFAULT_POST_RADIUS,
    range_sigma: float = DEFAULT_RANGE_SIGMA,
    bearing_sigma: float = DEFAULT_BEARING_SIGMA,
    min_beams: int = 1,
) -> list[LandmarkObservation]:
    """Find the posts one group at a time: ``robots.landmarks.detect_landmarks`` as first written.

    The per-group loop that the batched implementation replaced, kept verbatim as the
    reference it must reproduce (same posts and beams, values to rounding).
    """
    if scan.intensities is None:
        raise ValueError(
            "detect_landmarks: the scan has no intensities; posts are found by their "
            "remission, so build the Scan with intensities=..."
        )
    if not post_radius > 0.0:
        raise ValueError(f"detect_landmarks: post_radius must be > 0 m, got {post_radius}")
    if range_sigma < 0.0 or bearing_sigma < 0.0:
        raise ValueError(
            "detect_landmarks: range_sigma and bearing_sigma must be >= 0, "
            f"got {range_sigma}, {bearing_sigma}"
        )
    ranges = scan.ranges
    angles = scan.angles()
    valid = scan.valid_mask()
    bright = valid & (scan.intensities >= intensity_threshold)
    indices = np.flatnonzero(bright)
    if indices.size == 0:
        return []
    max_jump = 2.0 * post_radius + 3.0 * range_sigma
    breaks = (np.diff(indices) > 1) | (np.abs(np.diff(ranges[indices])) > max_jump)
    groups = np.split(indices, np.flatnonzero(breaks) + 1)
    observations = []
    for group in groups:
        if group.size < min_beams:
            continue
        observation = _post_from_group(
            group,
            ranges,
            angles,
            valid,
            scan.angle_increment,
            post_radius,
            range_sigma,
            bearing_sigma,
        )
        if observation is not None:
            observations.append(observation)
    return observations


def _post_from_group(
    group: np.ndarray,
    ranges: np.ndarray,
    angles: np.ndarray,
    valid: np.ndarray,
    increment: float,
    radius: float,
    range_sigma: float,
    bearing_sigma: float,
) -> LandmarkObservation | None:
    """Return the post observation of one group of bright beams, or None if not a post."""
    hit_ranges = ranges[group]
    hit_angles = angles[group]
    first, last = int(group[0]), int(group[-1])
    if first == 0 or last == ranges.size - 1:
        return None  # cut by the edge of the field of view: its centre is unknowable
    near = float(hit_ranges.min())
    if hit_ranges.max() - near > radius + 3.0 * range_sigma:
        return None
    distance = near + radius
    half_width = math.asin(min(1.0, radius / distance))
    if hit_angles[-1] - hit_angles[0] > 2.0 * half_width + _WIDTH_SLACK_STEPS * increment:
        return None  # too wide for a post: a reflective strip, a shiny wall
    if group.size < math.floor(2.0 * half_width / increment) - _MISSING_BEAMS_ALLOWED:
        return None  # too narrow: a post this close covers more beams (a speck, a glint)
    # A neighbour beam in front of the post hides part of it: the visible part's middle
    # is not the centre, and no honest small covariance exists, so the post is skipped.
    occluder_limit = near - _OCCLUDER_SIGMAS * range_sigma
    for neighbour in (first - 1, last + 1):
        if valid[neighbour] and ranges[neighbour] < occluder_limit:
            return None
    for _ in range(_CENTRE_ITERATIONS):
        half_width = math.asin(min(1.0, radius / distance))
        low, high = hit_angles[-1] - half_width, hit_angles[0] + half_width
        # The neighbouring beams missed the post: its silhouette ends before them.
        low = max(low, angles[first - 1] + half_width)
        high = min(high, angles[last + 1] - half_width)
        if low > high:  # noise made the bounds cross: fall back to the hits alone
            low, high = sorted((hit_angles[-1] - half_width, hit_angles[0] + half_width))
        bearing, bearing_variance = _centre_bearing(
            hit_ranges, hit_angles, low, high, radius, max(range_sigma, _RANGE_SIGMA_FLOOR)
        )
        bearing_variance += bearing_sigma**2
        distance, range_variance, cross = _centre_range(
            hit_ranges, hit_angles - bearing, radius, range_sigma, bearing_variance
        )
    covariance = np.array([[range_variance, cross], [cross, bearing_variance]])
    return LandmarkObservation(distance, bearing, covariance, group)


def _centre_bearing(
    hit_ranges: np.ndarray,
    hit_angles: np.ndarray,
    low: float,
    high: float,
    radius: float,
    range_sigma: float,
) -> tuple[float, float]:
    """Return the posterior mean and variance of the centre bearing on ``[low, high]``.

    The prior is uniform on the interval allowed by the hits and misses; the likelihood
    of a candidate bearing compares the measured ranges with those of the circle
    (centre distance profiled by least squares). With noisy ranges this stays near the
    middle of the interval; with precise ranges it locks onto the true centre.
    """
    if not high > low:
        return 0.5 * (low + high), 0.0
    candidates = np.linspace(low, high, _BEARING_CANDIDATES)
    offsets = hit_angles[None, :] - candidates[:, None]
    sine, cosine = np.sin(offsets), np.cos(offsets)
    chord_sq = np.maximum(radius**2 - (hit_ranges * sine) ** 2, 0.0)
    # Centre distance for each candidate: the mean of the beams' individual estimates.
    distance = (hit_ranges * cosine + np.sqrt(chord_sq)).mean(axis=1, keepdims=True)
    expected = distance * cosine - np.sqrt(np.maximum(radius**2 - (distance * sine) ** 2, 0.0))
    misfit = ((hit_ranges - expected) ** 2).sum(axis=1) / range_sigma**2
    weights = np.exp(-0.5 * (misfit - misfit.min()))
    weights /= weights.sum()
    mean = float(weights @ candidates)
    return mean, float(weights @ (candidates - mean) ** 2)


def _centre_range(
    hit_ranges: np.ndarray,
    offsets: np.ndarray,
    radius: float,
    range_sigma: float,
    bearing_variance: float,
) -> tuple[float, float, float]:
    """Return the centre distance, its variance and its covariance with the bearing.

    Each beam at angular offset ``delta`` from the centre direction, hitting at range
    ``r``, puts the centre at ``r cos(delta) + sqrt(R^2 - r^2 sin^2(delta))``. Beams near
    the post's silhouette are very sensitive to the range noise and to the bearing
    error (the square root's slope diverges there), so the beams are averaged with
    inverse-variance weights from first-order propagation of both.
    """
    sine, cosine = np.sin(offsets), np.cos(offsets)
    across_sq = (hit_ranges * sine) ** 2
    # Keep the square root away from 0, where the slopes diverge (grazing beams).
    along = hit_ranges * cosine + np.sqrt(np.maximum(radius**2 - across_sq, 0.0))
    depth = np.sqrt(np.maximum(radius**2 - across_sq, (_GRAZING_DEPTH * radius) ** 2))
    slope_range = cosine - hit_ranges * sine**2 / depth
    slope_bearing = hit_ranges * sine + hit_ranges**2 * sine * cosine / depth
    variance = range_sigma**2 * slope_range**2 + bearing_variance * slope_bearing**2
    weights = 1.0 / np.maximum(variance, _MIN_RANGE_VARIANCE)
    weights /= weights.sum()
    # The range noise is independent per beam; the bearing error is shared by all beams,
    # so it enters coherently and also correlates the range with the bearing estimate.
    coupling = float(weights @ slope_bearing)
    range_variance = float(weights**2 @ slope_range**2) * range_sigma**2
    range_variance += coupling**2 * bearing_variance
    return float(weights @ along), range_variance, coupling * bearing_variance
