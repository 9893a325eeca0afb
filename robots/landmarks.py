"""Reflective landmark posts: detection in a laser scan and association with the map.

The localization laser reads a high remission on the retro-reflective posts (paper
Sec. 5.1). ``detect_landmarks`` groups consecutive bright beams, checks that each group
has the angular and radial extent of a post of known radius and estimates the post's
CENTRE as a range-bearing observation in the sensor frame, with its 2x2 covariance.
``range_bearing_model`` is the point-landmark sensor model (with the laser mount offset)
that both ``associate_landmarks`` and the EKF use; ``associate_landmarks`` matches
observations to map landmarks with a Mahalanobis gate and refuses ambiguous matches.

Examples
--------
>>> import numpy as np
>>> from semistatic.types import Scan
>>> angles = np.radians(np.arange(-10.0, 10.5, 0.5))
>>> ranges = np.full(angles.size, 12.0)
>>> intensities = np.full(angles.size, 0.2)
>>> ranges[20], intensities[20] = 7.96, 0.95  # one beam hits a post 8 m ahead
>>> scan = Scan(ranges=ranges, angle_min=angles[0], angle_increment=angles[1] - angles[0],
...             intensities=intensities)
>>> [obs] = detect_landmarks(scan)
>>> round(obs.range, 3), round(obs.bearing, 3), obs.beam_indices.tolist()
(8.0, 0.0, [20])
>>> associate_landmarks([obs], [[8.0, 0.0], [0.0, 8.0]], (0.0, 0.0, 0.0), np.eye(3) * 1e-4)
[(0, 0)]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike

from robots.lasers import POST_INTENSITY_THRESHOLD
from semistatic.frames import wrap_angle, wrap_angle_compiled
from semistatic.types import Scan, beam_angles

__all__ = [
    "CHI2_2DOF_99",
    "LandmarkObservation",
    "associate_landmarks",
    "detect_landmarks",
    "mahalanobis_matrix",
    "mahalanobis_rows",
    "pairs_inside_gate",
    "range_bearing_model",
    "range_bearing_rows",
]


# 99% quantile of the chi-square distribution with 2 degrees of freedom
# (scipy.stats.chi2.ppf(0.99, 2)): the default Mahalanobis gate of a range-bearing pair.
CHI2_2DOF_99 = 9.210340371976182

# Default post geometry and sensor noise: the posts of ``worlds.spec.PostSpec`` (4 cm
# radius) seen by a Sick LMS100 (12 mm range noise, angular jitter far below a beam step).
DEFAULT_POST_RADIUS = 0.04
DEFAULT_RANGE_SIGMA = 0.012
DEFAULT_BEARING_SIGMA = 1e-3

# Centre estimation alternates bearing and range estimates; the second round uses the
# refined range in the angular half-width, which depends only weakly on it.
_CENTRE_ITERATIONS = 2

# Slack (in beam steps) on the angular extent a post may cover: the discretisation adds up
# to one step beyond the true angular width 2 * asin(radius / range).
_WIDTH_SLACK_STEPS = 1.0

# Candidate centre bearings evaluated across the feasible interval (a grid finer than a
# tenth of a millimetre at the post's surface for intervals of up to a beam step).
_BEARING_CANDIDATES = 41

# Range sigma used for the bearing likelihood when the caller claims noise-free ranges.
_RANGE_SIGMA_FLOOR = 1e-4

# When weighting, a grazing beam's depth into the post is floored at this fraction of the
# radius: its slopes stay finite (its weight small), its own estimate is unchanged.
_GRAZING_DEPTH = 0.05

# Floor on a single beam's centre-range variance (m^2) so weights stay finite.
_MIN_RANGE_VARIANCE = 1e-10

# A post of angular width 2w covers at least floor(2w / step) beams; this many of them
# may be lost (intensity noise at the silhouette) before a group is too narrow.
_MISSING_BEAMS_ALLOWED = 1

# A neighbouring beam shorter than the post's nearest return by this many range sigmas
# hit something in front of the post: the post is partly occluded.
_OCCLUDER_SIGMAS = 3.0


@dataclass(frozen=True, eq=False)
class LandmarkObservation:
    """The centre of one landmark post as seen from the laser (sensor frame).

    Parameters
    ----------
    range
        Distance from the laser origin to the post's centre, metres.
    bearing
        Direction of the centre, radians counter-clockwise from the laser's x axis.
    covariance
        ``(2, 2)`` covariance of ``(range, bearing)``.
    beam_indices
        Indices of the scan beams that hit the post.

    Examples
    --------
    >>> obs = LandmarkObservation(2.0, np.pi / 2, np.diag([1e-4, 1e-6]), [7, 8])
    >>> obs.point().round(6)
    array([0., 2.])
    """

    range: float
    bearing: float
    covariance: np.ndarray
    beam_indices: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "range", float(self.range))
        bearing = wrap_angle(float(self.bearing))
        object.__setattr__(self, "bearing", bearing)
        covariance = np.array(self.covariance, dtype=np.float64)
        if covariance.shape != (2, 2):
            raise ValueError(
                f"LandmarkObservation.covariance must be 2x2 (range, bearing), "
                f"got shape {covariance.shape}"
            )
        covariance.flags.writeable = False
        object.__setattr__(self, "covariance", covariance)
        indices = np.array(self.beam_indices, dtype=np.int64).reshape(-1)
        indices.flags.writeable = False
        object.__setattr__(self, "beam_indices", indices)
        if not (math.isfinite(self.range) and self.range > 0.0):
            raise ValueError(f"LandmarkObservation.range must be > 0, got {self.range}")

    def point(self) -> np.ndarray:
        """Return the centre as ``(x, y)`` in the sensor frame."""
        return np.array([self.range * math.cos(self.bearing), self.range * math.sin(self.bearing)])

    @classmethod
    def _trusted(
        cls, centre: float, bearing: float, covariance: np.ndarray, beams: np.ndarray
    ) -> LandmarkObservation:
        """Build an observation from values ``detect_landmarks`` made (floats, a fresh 2x2).

        The same fields as the constructor stores, without re-validating and copying
        what the detector computed itself (a quarter of its time on a scan of 5 posts).
        """
        if not (math.isfinite(centre) and centre > 0.0):
            raise ValueError(f"LandmarkObservation.range must be > 0, got {centre}")
        observation = object.__new__(cls)
        set_field = object.__setattr__
        set_field(observation, "range", centre)
        set_field(observation, "bearing", wrap_angle(bearing))
        covariance.flags.writeable = False
        set_field(observation, "covariance", covariance)
        beams = beams.view()  # a read-only view; the detector's index array stays its own
        beams.flags.writeable = False
        set_field(observation, "beam_indices", beams)
        return observation


def detect_landmarks(
    scan: Scan,
    *,
    intensity_threshold: float = POST_INTENSITY_THRESHOLD,
    post_radius: float = DEFAULT_POST_RADIUS,
    range_sigma: float = DEFAULT_RANGE_SIGMA,
    bearing_sigma: float = DEFAULT_BEARING_SIGMA,
    min_beams: int = 1,
) -> list[LandmarkObservation]:
    """Find the reflective posts in a scan and estimate their centres.

    Consecutive valid beams with ``intensity >= intensity_threshold`` form a group; a
    group is split where the range jumps by more than a post's diameter (two posts
    overlapping in angle). A group is a post only if its angular extent fits a cylinder
    of ``post_radius`` at that range (at most one beam step wider: a reflective strip
    is not a post; at most one beam narrower: a glint is not a post) and its range
    spread fits the radius. Groups touching the edge of the field of view, or next to a
    beam that hit something in front of them (partly occluded), are skipped: the
    visible part's middle is not the centre.

    The centre bearing is constrained to the interval of directions compatible with the
    beams that hit (within the post's half-width of the centre) and the neighbouring
    beams that missed it; within it, its posterior mean under the range likelihood of
    the circle (uniform prior) is taken. With noisy ranges that is near the interval's
    middle, with precise ranges it locks onto the true centre: either way tighter than
    the mean beam angle. The centre range is an inverse-variance weighted mean, over the
    hits, of ``r cos(delta) + sqrt(R^2 - r^2 sin^2(delta))`` (not ``min range + R``,
    biased long at grazing beams). The covariance propagates the range noise, the
    bearing posterior and ``bearing_sigma`` to first order.

    Parameters
    ----------
    scan
        A scan with ``intensities``.
    intensity_threshold
        Remission from which a return counts as reflective.
    post_radius
        Radius of the landmark posts, metres.
    range_sigma
        1-sigma range noise of one beam, metres.
    bearing_sigma
        1-sigma angular noise of the beam directions, radians.
    min_beams
        Groups with fewer bright beams are ignored.

    Returns
    -------
    list of LandmarkObservation
        In scan order.

    Examples
    --------
    >>> angles = np.radians(np.arange(-5.0, 5.5, 0.5))
    >>> ranges = np.full(angles.size, 4.0)
    >>> ranges[8:11] = [1.97, 1.96, 1.97]  # a post 2 m away, half a degree to the right
    >>> intensities = np.where(ranges < 3.0, 0.95, 0.1)
    >>> scan = Scan(ranges=ranges, angle_min=angles[0], angle_increment=angles[1] - angles[0],
    ...             intensities=intensities)
    >>> [obs] = detect_landmarks(scan, range_sigma=0.0)
    >>> round(obs.range, 2), round(float(np.degrees(obs.bearing)), 2)
    (2.0, -0.5)
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
    angles = beam_angles(ranges.size, scan.angle_min, scan.angle_increment)
    groups = _post_groups(
        ranges,
        scan.intensities,
        angles,
        float(scan.range_min),
        float(scan.range_max),
        float(intensity_threshold),
        float(scan.angle_increment),
        float(post_radius),
        float(range_sigma),
        int(min_beams),
    )
    if groups[0].size == 0:
        return []
    return _posts_from_groups(groups, ranges, angles, post_radius, range_sigma, bearing_sigma)


@numba.njit(cache=True)
def _post_groups(
    ranges, intensities, angles, range_min, range_max, intensity_threshold, increment,
    radius, range_sigma, min_beams,
):  # pragma: no cover - compiled
    """Return the groups of bright beams whose extent fits a post, in scan order.

    Consecutive valid beams at or above ``intensity_threshold`` form a group, split where
    the range jumps by more than a post's diameter (plus 3 range sigmas). Returns the
    accepted groups as arrays: first beam, beam count, first centre distance estimate
    (nearest return + radius), angles of the first and last bright beam and of the
    missed beams just outside them (the silhouette ends before those).
    """
    count = ranges.size
    max_jump = 2.0 * radius + 3.0 * range_sigma
    last_beam = count - 1
    firsts, sizes = np.empty(count, np.int64), np.empty(count, np.int64)
    distance, first_angle, last_angle = np.empty(count), np.empty(count), np.empty(count)
    low_miss, high_miss = np.empty(count), np.empty(count)
    accepted = 0
    i = 0
    while i < count:
        r = ranges[i]
        if not (math.isfinite(r) and range_min <= r <= range_max
                and intensities[i] >= intensity_threshold):
            i += 1
            continue
        # A group: the bright beams from i on, until a gap or a range jump.
        first, near, far = i, r, r
        while i + 1 < count:
            following = ranges[i + 1]
            if not (math.isfinite(following) and range_min <= following <= range_max
                    and intensities[i + 1] >= intensity_threshold):
                break
            if abs(following - ranges[i]) > max_jump:
                break
            i += 1
            near, far = min(near, following), max(far, following)
        last = i
        i += 1
        size = last - first + 1
        if size < min_beams:
            continue
        if first == 0 or last == last_beam:
            continue  # cut by the edge of the field of view: its centre is unknowable
        if far - near > radius + 3.0 * range_sigma:
            continue
        centre = near + radius
        half_width = math.asin(min(1.0, radius / centre))
        if angles[last] - angles[first] > 2.0 * half_width + _WIDTH_SLACK_STEPS * increment:
            continue  # too wide for a post: a reflective strip, a shiny wall
        if size < math.floor(2.0 * half_width / increment) - _MISSING_BEAMS_ALLOWED:
            continue  # too narrow: a post this close covers more beams (a speck, a glint)
        # A neighbour beam in front of the post hides part of it: the visible part's middle
        # is not the centre, and no honest small covariance exists, so the post is skipped.
        occluder_limit = near - _OCCLUDER_SIGMAS * range_sigma
        before, after = ranges[first - 1], ranges[last + 1]
        if (math.isfinite(before) and range_min <= before <= range_max
                and before < occluder_limit):
            continue
        if math.isfinite(after) and range_min <= after <= range_max and after < occluder_limit:
            continue
        firsts[accepted], sizes[accepted], distance[accepted] = first, size, centre
        first_angle[accepted], last_angle[accepted] = angles[first], angles[last]
        low_miss[accepted], high_miss[accepted] = angles[first - 1], angles[last + 1]
        accepted += 1
    return (firsts[:accepted], sizes[:accepted], distance[:accepted], first_angle[:accepted],
            last_angle[:accepted], low_miss[:accepted], high_miss[:accepted])


def _posts_from_groups(
    groups: tuple[np.ndarray, ...],
    ranges: np.ndarray,
    angles: np.ndarray,
    radius: float,
    range_sigma: float,
    bearing_sigma: float,
) -> list[LandmarkObservation]:
    """Estimate the centre of every accepted group and return the observations.

    Each round is two compiled passes over all posts of the scan (:func:`_bearing_exponents`
    and :func:`_centre_estimates`) with numpy's ``exp`` between them: numpy's vectorised
    ``exp`` rounds differently from the C library's in the last bit, and the kernels
    reproduce the former numpy arithmetic operation for operation, so the estimates are
    bit for bit those of the former numpy implementation (the closed loop's results stay
    identical).
    """
    firsts, sizes, distance, first_angle, last_angle, low_miss, high_miss = groups
    likelihood_sigma = max(range_sigma, _RANGE_SIGMA_FLOOR)
    # Python's ``x**2`` (C pow) and numpy's square both round the exact square correctly.
    radius_sq, likelihood_variance = radius**2, likelihood_sigma**2
    range_variance_beam, floor_sq = range_sigma**2, (_GRAZING_DEPTH * radius) ** 2
    for iteration in range(_CENTRE_ITERATIONS):
        lows, highs, candidates, exponents = _bearing_exponents(
            ranges, angles, firsts, sizes, first_angle, last_angle, low_miss, high_miss,
            distance, radius, radius_sq, likelihood_variance,
        )
        distance, range_variance, cross, bearing, bearing_variance = _centre_estimates(
            ranges, angles, firsts, sizes, lows, highs, candidates, np.exp(exponents),
            radius_sq, floor_sq, range_variance_beam, bearing_sigma**2,
            iteration == _CENTRE_ITERATIONS - 1,
        )
    covariance = np.empty((firsts.size, 2, 2))
    covariance[:, 0, 0], covariance[:, 1, 1] = range_variance, bearing_variance
    covariance[:, 0, 1] = covariance[:, 1, 0] = cross
    beams = np.arange(ranges.size)
    return [
        LandmarkObservation._trusted(centre, direction, covariance[g], beams[first:first + size])
        for g, (centre, direction, first, size) in enumerate(zip(
            distance.tolist(), bearing.tolist(), firsts.tolist(), sizes.tolist(), strict=True
        ))
    ]


@numba.njit(cache=True)
def _pairwise_sum(values):  # pragma: no cover - compiled
    """Return ``values.sum()`` summed in numpy's order (pairwise, 8 accumulators).

    Examples
    --------
    >>> values = np.random.default_rng(0).uniform(0.0, 1.0, 41) * 10.0 ** np.arange(-20, 21)
    >>> bool(_pairwise_sum(values) == values.sum())
    True
    """
    count = values.size
    if count < 8:
        total = 0.0
        for i in range(count):
            total += values[i]
        return total
    r0, r1, r2, r3 = values[0], values[1], values[2], values[3]
    r4, r5, r6, r7 = values[4], values[5], values[6], values[7]
    i = 8
    while i < count - count % 8:
        r0 += values[i]
        r1 += values[i + 1]
        r2 += values[i + 2]
        r3 += values[i + 3]
        r4 += values[i + 4]
        r5 += values[i + 5]
        r6 += values[i + 6]
        r7 += values[i + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < count:
        total += values[i]
        i += 1
    return total


@numba.njit(cache=True)
def _dot(a, b):  # pragma: no cover - compiled
    """Return ``a @ b`` (equal sizes) summed in the order of numpy's ``einsum``.

    That order: two lanes (even and odd indices), blocks of eight folded in from the
    last pair of the block, the remainder pair by pair, then the lanes added.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> a, b = rng.uniform(0.0, 1.0, 41) * 10.0 ** np.arange(-20, 21), rng.normal(size=41)
    >>> bool(_dot(a, b) == np.einsum("k,k->", a, b))
    True
    """
    count = a.size
    even, odd = 0.0, 0.0
    i = 0
    while count - i >= 8:
        even = a[i] * b[i] + (a[i + 2] * b[i + 2] + (a[i + 4] * b[i + 4] + (
            a[i + 6] * b[i + 6] + even)))
        odd = a[i + 1] * b[i + 1] + (a[i + 3] * b[i + 3] + (a[i + 5] * b[i + 5] + (
            a[i + 7] * b[i + 7] + odd)))
        i += 8
    while i < count:
        even = a[i] * b[i] + even
        if i + 1 < count:
            odd = a[i + 1] * b[i + 1] + odd
        i += 2
    return even + odd


@numba.njit(cache=True)
def _bearing_exponents(
    ranges, angles, firsts, sizes, first_angle, last_angle, low_miss, high_miss, distance,
    radius, radius_sq, range_variance,
):  # pragma: no cover - compiled
    """Return each post's feasible bearing interval, candidate grid and log-likelihoods.

    Post ``g`` covers beams ``firsts[g]`` to ``firsts[g] + sizes[g] - 1``; ``distance[g]``
    is the current estimate of its centre distance. The interval holds the bearings
    within the post's half-width of the hits whose silhouette ends before the
    neighbouring beams that missed. On it, ``_BEARING_CANDIDATES`` candidates (as
    ``numpy.linspace``); for each, the centre distance is profiled (the mean of the
    beams' individual estimates) and the range misfit of the circle computed. Returns
    ``lows, highs, candidates (G, K)`` and ``-misfit / 2`` shifted to a maximum of 0 (the
    caller exponentiates: the posterior weights up to a factor).
    """
    count = firsts.size
    lows, highs = np.empty(count), np.empty(count)
    candidates = np.empty((count, _BEARING_CANDIDATES))
    exponents = np.empty((count, _BEARING_CANDIDATES))
    padded = 0
    for g in range(count):
        padded = max(padded, sizes[g])
    beam_sin, beam_cos = np.empty(padded), np.empty(padded)
    for g in range(count):
        half_width = math.asin(min(1.0, radius / distance[g]))
        low = last_angle[g] - half_width
        high = first_angle[g] + half_width
        # The neighbouring beams missed the post: its silhouette ends before them.
        low = max(low, low_miss[g] + half_width)
        high = min(high, high_miss[g] - half_width)
        if low > high:  # noise made the bounds cross: fall back to the hits alone
            low = min(last_angle[g] - half_width, first_angle[g] + half_width)
            high = max(last_angle[g] - half_width, first_angle[g] + half_width)
        lows[g], highs[g] = low, high
        step = (high - low) / (_BEARING_CANDIDATES - 1)
        for k in range(_BEARING_CANDIDATES - 1):
            candidates[g, k] = k * step + low
        candidates[g, _BEARING_CANDIDATES - 1] = high
        first, size = firsts[g], sizes[g]
        for b in range(size):
            beam_sin[b], beam_cos[b] = math.sin(angles[first + b]), math.cos(angles[first + b])
        for k in range(_BEARING_CANDIDATES):
            candidate_sin = math.sin(candidates[g, k])
            candidate_cos = math.cos(candidates[g, k])
            # sin and cos of (beam angle - candidate) by the angle difference identities.
            centre = 0.0
            for b in range(size):
                sine = beam_sin[b] * candidate_cos - beam_cos[b] * candidate_sin
                cosine = beam_cos[b] * candidate_cos + beam_sin[b] * candidate_sin
                across = ranges[first + b] * sine
                centre += math.sqrt(max(radius_sq - across * across, 0.0)) + (
                    ranges[first + b] * cosine)
            centre /= size
            misfit = 0.0
            for b in range(size):
                sine = beam_sin[b] * candidate_cos - beam_cos[b] * candidate_sin
                cosine = beam_cos[b] * candidate_cos + beam_sin[b] * candidate_sin
                across = centre * sine
                expected = centre * cosine - math.sqrt(max(radius_sq - across * across, 0.0))
                residual = ranges[first + b] - expected
                misfit += residual * residual
            exponents[g, k] = misfit / range_variance
        best = exponents[g, 0]
        for k in range(1, _BEARING_CANDIDATES):
            best = min(best, exponents[g, k])
        for k in range(_BEARING_CANDIDATES):
            exponents[g, k] = -0.5 * (exponents[g, k] - best)
    return lows, highs, candidates, exponents


@numba.njit(cache=True)
def _centre_estimates(
    ranges, angles, firsts, sizes, lows, highs, candidates, likelihoods, radius_sq,
    floor_sq, range_variance, bearing_variance_floor, variances,
):  # pragma: no cover - compiled
    """Return each post's centre distance, its variances and the bearing's mean and variance.

    The bearing: the posterior mean and variance over the candidates of
    :func:`_bearing_exponents` (``likelihoods`` are their exponentials), plus
    ``bearing_variance_floor`` (the beams' own angular noise); an empty interval gives
    its point with zero posterior variance. The distance: each beam at angular offset
    ``delta`` from the centre direction, hitting at range ``r``, puts the centre at
    ``r cos(delta) + sqrt(R^2 - r^2 sin^2(delta))``; beams near the silhouette are very
    sensitive to range noise and bearing error (the root's slope diverges there), so the
    beams are averaged with inverse-variance weights from first-order propagation of
    both. The range noise is independent per beam; the bearing error is shared, so it
    enters coherently and correlates the range with the bearing. Without ``variances``
    only the distance and bearing are computed (the others are 0).

    Returns ``distance, range_variance, cross, bearing, bearing_variance``, one per post.
    Sums run in numpy's order over the posts' beams padded to the largest group.
    """
    count = firsts.size
    padded = 0
    for g in range(count):
        padded = max(padded, sizes[g])
    distance, range_variances = np.empty(count), np.zeros(count)
    cross, bearing, bearing_variance = np.zeros(count), np.empty(count), np.empty(count)
    weights = np.empty(_BEARING_CANDIDATES)
    spread = np.empty(_BEARING_CANDIDATES)
    along, slope_range, slope_bearing = np.zeros(padded), np.zeros(padded), np.zeros(padded)
    beam_weights, squares_w, squares_r = np.zeros(padded), np.zeros(padded), np.zeros(padded)
    for g in range(count):
        total = _pairwise_sum(likelihoods[g])
        for k in range(_BEARING_CANDIDATES):
            weights[k] = likelihoods[g, k] / total
        mean = _dot(weights, candidates[g])
        for k in range(_BEARING_CANDIDATES):
            offset = candidates[g, k] - mean
            spread[k] = offset * offset
        variance = _dot(weights, spread)
        if not highs[g] > lows[g]:
            mean, variance = 0.5 * (lows[g] + highs[g]), 0.0
        variance = variance + bearing_variance_floor
        bearing[g], bearing_variance[g] = mean, variance
        # The beams past the group's size stay 0: padding that changes no sum but its order.
        first, size = firsts[g], sizes[g]
        for b in range(size, padded):
            beam_weights[b], along[b], slope_bearing[b] = 0.0, 0.0, 0.0
            squares_w[b], squares_r[b] = 0.0, 0.0
        for b in range(size):
            hit = ranges[first + b]
            offset = angles[first + b] - mean
            sine, cosine = math.sin(offset), math.cos(offset)
            across_sq = (hit * sine) * (hit * sine)
            along[b] = hit * cosine + math.sqrt(max(radius_sq - across_sq, 0.0))
            # Keep the square root away from 0, where the slopes diverge (grazing beams).
            depth = math.sqrt(max(radius_sq - across_sq, floor_sq))
            slope_range[b] = cosine - hit * (sine * sine) / depth
            slope_bearing[b] = hit * sine + hit * hit * sine * cosine / depth
            beam_variance = range_variance * (slope_range[b] * slope_range[b]) + variance * (
                slope_bearing[b] * slope_bearing[b])
            beam_weights[b] = 1.0 / max(beam_variance, _MIN_RANGE_VARIANCE)
        total = _pairwise_sum(beam_weights)
        for b in range(size):
            beam_weights[b] /= total
        distance[g] = _dot(beam_weights, along)
        if not variances:
            continue
        coupling = _dot(beam_weights, slope_bearing)
        for b in range(size):
            squares_w[b] = beam_weights[b] * beam_weights[b]
            squares_r[b] = slope_range[b] * slope_range[b]
        range_variances[g] = _dot(squares_w, squares_r) * range_variance + (
            coupling * coupling) * variance
        cross[g] = coupling * variance
    return distance, range_variances, cross, bearing, bearing_variance


def range_bearing_model(
    pose: ArrayLike, landmarks: ArrayLike, mount: ArrayLike = (0.0, 0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Predict range and bearing of point landmarks from a robot pose, with Jacobians.

    The laser sits at ``mount = (x, y, yaw)`` in the robot frame (base_link), so the
    measurement is taken from the sensor pose ``pose ⊕ mount``.

    Parameters
    ----------
    pose
        Robot pose ``(x, y, theta)`` in the world frame.
    landmarks
        ``(M, 2)`` landmark positions in the world frame.
    mount
        Laser pose in the robot frame.

    Returns
    -------
    predicted : np.ndarray
        ``(M, 2)`` predicted ``(range, bearing)``, bearings wrapped to ``(-pi, pi]``.
    jacobians : np.ndarray
        ``(M, 2, 3)`` derivatives of ``(range, bearing)`` with respect to the robot pose.

    Examples
    --------
    >>> z, H = range_bearing_model([0.0, 0.0, 0.0], [[2.0, 0.0]], mount=[0.5, 0.0, 0.0])
    >>> z.round(6)
    array([[1.5, 0. ]])
    >>> H[0].round(6)
    array([[-1.      , -0.      , -0.      ],
           [ 0.      , -0.666667, -1.333333]])
    """
    x, y, theta = (float(v) for v in np.asarray(pose, dtype=float)[:3])
    mount_x, mount_y, mount_yaw = (float(v) for v in np.asarray(mount, dtype=float)[:3])
    points = np.asarray(landmarks, dtype=float).reshape(-1, 2)
    return range_bearing_rows(
        x, y, theta, mount_x, mount_y, mount_yaw,
        np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1]), 3,
    )


@numba.njit(cache=True)
def range_bearing_rows(
    x, y, theta, mount_x, mount_y, mount_yaw, landmark_x, landmark_y, columns
):  # pragma: no cover - compiled
    """Return :func:`range_bearing_model` for a pose and a mount given as floats.

    The EKF calls this at every update with its landmark coordinates split once into
    float64 arrays, so nothing is converted or validated per call. ``columns`` (>= 3) is
    the width of the state the Jacobians are taken against; columns past the pose are 0.

    Examples
    --------
    >>> z, H = range_bearing_rows(0.0, 0.0, 0.0, 0.5, 0.0, 0.0, np.array([2.0]),
    ...                           np.array([0.0]), 4)
    >>> z.round(6), H.shape
    (array([[1.5, 0. ]]), (1, 2, 4))
    """
    c, s = math.cos(theta), math.sin(theta)
    sensor_x = x + c * mount_x - s * mount_y
    sensor_y = y + s * mount_x + c * mount_y
    # Derivatives of the sensor position with respect to the robot heading.
    dsx_dtheta = -s * mount_x - c * mount_y
    dsy_dtheta = c * mount_x - s * mount_y
    count = landmark_x.size
    predicted = np.empty((count, 2))
    jacobians = np.empty((count, 2, columns))  # (np.zeros in 3-d compiles code of its own)
    for m in range(count):
        for row in range(2):
            for column in range(3, columns):
                jacobians[m, row, column] = 0.0
        dx = landmark_x[m] - sensor_x
        dy = landmark_y[m] - sensor_y
        range_sq = dx * dx + dy * dy
        distance = math.sqrt(range_sq)
        predicted[m, 0] = distance
        predicted[m, 1] = wrap_angle_compiled(math.atan2(dy, dx) - theta - mount_yaw)
        jacobians[m, 0, 0] = -dx / distance
        jacobians[m, 0, 1] = -dy / distance
        jacobians[m, 0, 2] = -(dx * dsx_dtheta + dy * dsy_dtheta) / distance
        jacobians[m, 1, 0] = dy / range_sq
        jacobians[m, 1, 1] = -dx / range_sq
        jacobians[m, 1, 2] = (dy * dsx_dtheta - dx * dsy_dtheta) / range_sq - 1.0
    return predicted, jacobians


def mahalanobis_matrix(
    observations: Sequence[LandmarkObservation],
    predicted: np.ndarray,
    jacobians: np.ndarray,
    robot_cov: ArrayLike,
) -> np.ndarray:
    """Return the ``(K, M)`` squared Mahalanobis distances of observations to landmarks.

    Uses the innovation covariance ``H P Hᵀ + R`` of each pair, the bearing innovation
    wrapped to ``(-pi, pi]``. ``predicted`` and ``jacobians`` come from
    ``range_bearing_model``.

    Examples
    --------
    >>> z, H = range_bearing_model([0.0, 0.0, 0.0], [[2.0, 0.0]])
    >>> obs = LandmarkObservation(2.1, 0.0, np.diag([0.01, 1e-4]), [0])
    >>> mahalanobis_matrix([obs], z, H, np.zeros((3, 3))).round(6)
    array([[1.]])
    """
    count = len(observations)
    if count == 0 or predicted.shape[0] == 0:
        return np.zeros((count, predicted.shape[0]))
    measured = np.array([(obs.range, obs.bearing) for obs in observations])
    noise = np.array([obs.covariance for obs in observations])
    return mahalanobis_rows(
        measured,
        noise,
        np.ascontiguousarray(predicted, dtype=np.float64),
        np.ascontiguousarray(jacobians, dtype=np.float64),
        np.ascontiguousarray(robot_cov, dtype=np.float64),
    )


@numba.njit(cache=True)
def mahalanobis_rows(measured, noise, predicted, jacobians, robot_cov):  # pragma: no cover
    """Return :func:`mahalanobis_matrix` for ``(K, 2)`` measurements and ``(K, 2, 2)`` noises.

    The EKF's entry point: it stacks the observations once per update. ``jacobians`` are
    ``(M, 2, D)`` against a state of ``D`` columns with the ``(D, D)`` covariance.

    Examples
    --------
    >>> z, H = range_bearing_model([0.0, 0.0, 0.0], [[2.0, 0.0]])
    >>> mahalanobis_rows(np.array([[2.1, 0.0]]), np.diag([0.01, 1e-4])[None], z, H,
    ...                  np.zeros((3, 3))).round(6)
    array([[1.]])
    """
    count, landmarks, columns = measured.shape[0], predicted.shape[0], robot_cov.shape[0]
    distances = np.empty((count, landmarks))
    for m in range(landmarks):
        # H P Hᵀ of this landmark.
        projected = np.empty((2, 2))  # every entry is written below
        for i in range(2):
            for j in range(2):
                total = 0.0
                for a in range(columns):
                    row = 0.0
                    for b in range(columns):
                        row += robot_cov[a, b] * jacobians[m, j, b]
                    total += jacobians[m, i, a] * row
                projected[i, j] = total
        for k in range(count):
            a = projected[0, 0] + noise[k, 0, 0]
            b = projected[0, 1] + noise[k, 0, 1]
            c = projected[1, 0] + noise[k, 1, 0]
            d = projected[1, 1] + noise[k, 1, 1]
            u = measured[k, 0] - predicted[m, 0]
            v = wrap_angle_compiled(measured[k, 1] - predicted[m, 1])
            distances[k, m] = (d * u * u - (b + c) * u * v + a * v * v) / (a * d - b * c)
    return distances


def associate_landmarks(
    observations: Sequence[LandmarkObservation],
    landmarks: ArrayLike,
    robot_pose: ArrayLike,
    robot_cov: ArrayLike,
    mount: ArrayLike = (0.0, 0.0, 0.0),
    *,
    gate: float = CHI2_2DOF_99,
) -> list[tuple[int, int]]:
    """Match observations to map landmarks by a Mahalanobis gate, refusing ambiguity.

    A pair ``(k, m)`` is returned only if landmark ``m`` is the sole landmark inside the
    gate of observation ``k`` AND ``k`` is the sole observation inside the gate of ``m``:
    with two candidates either way, a wrong match would corrupt the filter, so neither
    is used.

    Parameters
    ----------
    observations
        Detected posts (sensor frame).
    landmarks
        ``(M, 2)`` landmark map, world frame.
    robot_pose, robot_cov
        Current robot pose estimate and its ``(3, 3)`` covariance.
    mount
        Laser pose in the robot frame.
    gate
        Threshold on the squared Mahalanobis distance (default: chi-square 2 dof, 99%).

    Returns
    -------
    list of (int, int)
        ``(observation index, landmark index)`` pairs, by observation index.

    Examples
    --------
    >>> obs = LandmarkObservation(2.0, 0.0, np.diag([1e-4, 1e-4]), [0])
    >>> associate_landmarks([obs], [[2.0, 0.0], [2.0, 0.1]], [0, 0, 0], np.zeros((3, 3)))
    [(0, 0)]
    >>> associate_landmarks([obs], [[2.0, 0.0], [2.0, 0.01]], [0, 0, 0], np.zeros((3, 3)))
    []
    """
    predicted, jacobians = range_bearing_model(robot_pose, landmarks, mount)
    distances = mahalanobis_matrix(observations, predicted, jacobians, robot_cov)
    return pairs_inside_gate(distances, gate)


def pairs_inside_gate(distances: np.ndarray, gate: float) -> list[tuple[int, int]]:
    """Return the unambiguous ``(row, column)`` pairs of a gated distance matrix.

    Examples
    --------
    >>> pairs_inside_gate(np.array([[1.0, 50.0], [2.0, 60.0], [70.0, 3.0]]), 9.0)
    [(2, 1)]
    """
    inside = distances < gate
    if inside.size == 0:
        return []
    # Lists of a few rows: counting in C (list.count) beats five numpy reductions here.
    in_column = inside.sum(axis=0).tolist()
    pairs = []
    for row, flags in enumerate(inside.tolist()):
        if flags.count(True) == 1:
            column = flags.index(True)
            if in_column[column] == 1:
                pairs.append((row, column))
    return pairs
