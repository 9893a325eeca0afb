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
from typing import NamedTuple

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
    # Scan.valid_mask() without its errstate block (comparisons with nan do not warn).
    valid = np.isfinite(ranges)
    valid &= ranges >= scan.range_min
    valid &= ranges <= scan.range_max
    bright = valid & (scan.intensities >= intensity_threshold)
    indices = np.flatnonzero(bright)
    if indices.size == 0:
        return []
    max_jump = 2.0 * post_radius + 3.0 * range_sigma
    hit_ranges = ranges[indices]
    # A group starts at the first bright beam and after every gap or range jump.
    first_of_group = np.empty(indices.size, dtype=bool)
    first_of_group[0] = True
    np.greater(indices[1:] - indices[:-1], 1, out=first_of_group[1:])
    first_of_group[1:] |= np.abs(hit_ranges[1:] - hit_ranges[:-1]) > max_jump
    starts = np.flatnonzero(first_of_group)
    groups = _post_groups(
        indices,
        starts,
        ranges,
        angles,
        valid,
        scan.angle_increment,
        post_radius,
        range_sigma,
        min_beams,
    )
    if not groups:
        return []
    return _posts_from_groups(groups, ranges, angles, post_radius, range_sigma, bearing_sigma)


class _Group(NamedTuple):
    """One group of bright beams that passed the shape checks of a post."""

    beams: np.ndarray
    distance: float  # first estimate of the centre distance: nearest return + radius, m
    first_angle: float  # angles of the first and last bright beam
    last_angle: float
    low_miss: float  # angle of the missed beam before the group (the silhouette ends after it)
    high_miss: float  # angle of the missed beam after the group


def _post_groups(
    indices: np.ndarray,
    starts: np.ndarray,
    ranges: np.ndarray,
    angles: np.ndarray,
    valid: np.ndarray,
    increment: float,
    radius: float,
    range_sigma: float,
    min_beams: int,
) -> list[_Group]:
    """Return the groups of bright beams whose extent fits a post, in scan order.

    A group starts at each position ``starts`` of ``indices`` (the bright beams).
    """
    hit_ranges = ranges[indices]
    # Per-group nearest and farthest return in one pass; the checks are then on floats.
    nears = np.minimum.reduceat(hit_ranges, starts).tolist()
    fars = np.maximum.reduceat(hit_ranges, starts).tolist()
    stops = [*starts[1:].tolist(), indices.size]
    firsts = indices[starts].tolist()
    lasts = indices[np.asarray(stops) - 1].tolist()
    last_beam = ranges.size - 1
    groups = []
    for start, stop, first, last, near, far in zip(
        starts.tolist(), stops, firsts, lasts, nears, fars, strict=True
    ):
        if stop - start < min_beams:
            continue
        if first == 0 or last == last_beam:
            continue  # cut by the edge of the field of view: its centre is unknowable
        if far - near > radius + 3.0 * range_sigma:
            continue
        distance = near + radius
        half_width = math.asin(min(1.0, radius / distance))
        first_angle, last_angle = float(angles[first]), float(angles[last])
        if last_angle - first_angle > 2.0 * half_width + _WIDTH_SLACK_STEPS * increment:
            continue  # too wide for a post: a reflective strip, a shiny wall
        if stop - start < math.floor(2.0 * half_width / increment) - _MISSING_BEAMS_ALLOWED:
            continue  # too narrow: a post this close covers more beams (a speck, a glint)
        # A neighbour beam in front of the post hides part of it: the visible part's middle
        # is not the centre, and no honest small covariance exists, so the post is skipped.
        occluder_limit = near - _OCCLUDER_SIGMAS * range_sigma
        before, after = first - 1, last + 1
        if (valid[before] and ranges[before] < occluder_limit) or (
            valid[after] and ranges[after] < occluder_limit
        ):
            continue
        groups.append(
            _Group(
                indices[start:stop],
                distance,
                first_angle,
                last_angle,
                float(angles[first - 1]),
                float(angles[last + 1]),
            )
        )
    return groups


def _posts_from_groups(
    groups: list[_Group],
    ranges: np.ndarray,
    angles: np.ndarray,
    radius: float,
    range_sigma: float,
    bearing_sigma: float,
) -> list[LandmarkObservation]:
    """Estimate the centre of every accepted group at once and return the observations.

    The groups' beams are stacked into ``(G, B)`` arrays padded to the largest group
    (``mask`` marks the real beams), so each estimation step is one numpy pass over all
    posts of the scan rather than one per post.
    """
    # A group's beams are consecutive: row g holds first_g, first_g + 1, ... and then
    # repeats first_g, so padding is a real (finite) hit that the mask keeps out of sums.
    firsts = np.array([int(group.beams[0]) for group in groups])
    sizes = np.array([group.beams.size for group in groups])
    offsets = np.arange(int(sizes.max()))
    mask = offsets < sizes[:, None]
    beams = firsts[:, None] + offsets * mask
    hits = _Hits(ranges[beams], angles[beams], mask)
    distance = [group.distance for group in groups]
    likelihood_sigma = max(range_sigma, _RANGE_SIGMA_FLOOR)
    for iteration in range(_CENTRE_ITERATIONS):
        lows, highs = [], []
        for group, centre in zip(groups, distance, strict=True):
            half_width = math.asin(min(1.0, radius / centre))
            low = group.last_angle - half_width
            high = group.first_angle + half_width
            # The neighbouring beams missed the post: its silhouette ends before them.
            low = max(low, group.low_miss + half_width)
            high = min(high, group.high_miss - half_width)
            if low > high:  # noise made the bounds cross: fall back to the hits alone
                low, high = sorted((group.last_angle - half_width, group.first_angle + half_width))
            lows.append(low)
            highs.append(high)
        bearing, bearing_variance = _centre_bearings(
            hits, np.array(lows), np.array(highs), radius, likelihood_sigma
        )
        bearing_variance = bearing_variance + bearing_sigma**2
        # Only the last round's range variance and cross term are reported.
        distance, range_variance, cross = _centre_ranges(
            hits,
            bearing,
            radius,
            range_sigma,
            bearing_variance,
            variances=iteration == _CENTRE_ITERATIONS - 1,
        )
        distance = distance.tolist()
    return [
        LandmarkObservation._trusted(
            centre, direction, np.array([[r_var, c], [c, b_var]]), group.beams
        )
        for group, centre, direction, r_var, c, b_var in zip(
            groups,
            distance,
            bearing.tolist(),
            range_variance.tolist(),
            cross.tolist(),
            bearing_variance.tolist(),
            strict=True,
        )
    ]


class _Hits:
    """The bright beams of G groups as padded ``(G, B)`` arrays, with what both passes reuse.

    ``mask`` marks real beams; padded entries repeat a real hit, so every value stays
    finite and multiplying by the 0/1 ``weight`` removes them from sums exactly.

    """

    def __init__(self, ranges: np.ndarray, angles: np.ndarray, mask: np.ndarray) -> None:
        self.ranges, self.angles, self.mask = ranges, angles, mask
        self.weight = mask.astype(float)
        self.count = mask.sum(axis=1)
        # (G, B, 1) views for the (G, B, candidates) arrays of the bearing likelihood.
        self.ranges_3d = ranges[:, :, None]
        self.weight_3d = self.weight[:, :, None]
        self.count_3d = self.count[:, None, None]
        self.sin_3d = np.sin(angles)[:, :, None]
        self.cos_3d = np.cos(angles)[:, :, None]


# The candidate grid of numpy.linspace(low, high, n): ramp * step + low, then the end.
# (linspace's special case for a step that underflows to 0 only matters for intervals
# below 1e-320 rad, which round to a point either way.)
_RAMP = np.arange(_BEARING_CANDIDATES, dtype=float)


def _centre_bearings(
    hits: _Hits,
    low: np.ndarray,
    high: np.ndarray,
    radius: float,
    range_sigma: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the posterior mean and variance of each centre bearing on ``[low, high]``.

    Row ``g`` is one post. The prior is uniform on the interval allowed by the hits and
    misses; the likelihood of a candidate bearing compares the measured ranges with
    those of the circle (centre distance profiled by least squares). With noisy ranges
    this stays near the middle of the interval; with precise ranges it locks onto the
    true centre. An empty interval (``low == high``) gives its point with zero variance.
    """
    candidates = _RAMP * ((high - low) / (_BEARING_CANDIDATES - 1))[:, None]
    candidates += low[:, None]
    candidates[:, -1] = high
    # Arrays are (G, beams, candidates): the candidates, the longest axis, vary fastest.
    # sin and cos of (beam angle - candidate) come from the angle difference identities:
    # (G, B) + (G, candidates) evaluations instead of full (G, B, candidates) ones (the
    # bulk of the work otherwise); they agree with the direct ones to ~1e-16.
    candidate_sin = np.sin(candidates)[:, None, :]
    candidate_cos = np.cos(candidates)[:, None, :]
    # The expressions of the docstring, evaluated in place into few (G, B, candidates)
    # buffers: the same operations in the same order, fewer temporaries.
    sine = hits.sin_3d * candidate_cos
    sine -= hits.cos_3d * candidate_sin
    cosine = hits.cos_3d * candidate_cos
    cosine += hits.sin_3d * candidate_sin
    ranges, weight, radius_sq = hits.ranges_3d, hits.weight_3d, radius * radius
    work = np.multiply(ranges, sine)
    work *= work
    np.subtract(radius_sq, work, out=work)
    np.maximum(work, 0.0, out=work)
    np.sqrt(work, out=work)  # the half chord of each beam
    # Centre distance for each candidate: the mean of the beams' individual estimates.
    work += ranges * cosine
    work *= weight
    distance = work.sum(axis=1, keepdims=True)
    distance /= hits.count_3d
    np.multiply(distance, sine, out=work)
    work *= work
    np.subtract(radius_sq, work, out=work)
    np.maximum(work, 0.0, out=work)
    np.sqrt(work, out=work)
    np.subtract(distance * cosine, work, out=work)  # the expected ranges
    np.subtract(ranges, work, out=work)
    work *= work
    work *= weight
    misfit = work.sum(axis=1)
    misfit /= range_sigma**2
    weights = np.exp(-0.5 * (misfit - misfit.min(axis=1, keepdims=True)))
    weights /= weights.sum(axis=1, keepdims=True)
    mean = np.einsum("gk,gk->g", weights, candidates)
    variance = np.einsum("gk,gk->g", weights, (candidates - mean[:, None]) ** 2)
    empty = ~(high > low)
    if empty.any():
        mean[empty], variance[empty] = 0.5 * (low[empty] + high[empty]), 0.0
    return mean, variance


def _centre_ranges(
    hits: _Hits,
    bearing: np.ndarray,
    radius: float,
    range_sigma: float,
    bearing_variance: np.ndarray,
    *,
    variances: bool = True,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Return each centre distance, its variance and its covariance with the bearing.

    With ``variances=False`` only the distance is computed (the other two are ``None``).

    Row ``g`` is one post seen in direction ``bearing[g]``. Each beam at angular offset
    ``delta`` from the centre direction, hitting at range ``r``, puts the centre at
    ``r cos(delta) + sqrt(R^2 - r^2 sin^2(delta))``. Beams near the post's silhouette are
    very sensitive to the range noise and to the bearing error (the square root's slope
    diverges there), so the beams are averaged with inverse-variance weights from
    first-order propagation of both.
    """
    hit_ranges = hits.ranges
    offsets = hits.angles - bearing[:, None]
    sine, cosine = np.sin(offsets), np.cos(offsets)
    across_sq = (hit_ranges * sine) ** 2
    # Keep the square root away from 0, where the slopes diverge (grazing beams).
    along = hit_ranges * cosine + np.sqrt(np.maximum(radius**2 - across_sq, 0.0))
    depth = np.sqrt(np.maximum(radius**2 - across_sq, (_GRAZING_DEPTH * radius) ** 2))
    slope_range = cosine - hit_ranges * sine**2 / depth
    slope_bearing = hit_ranges * sine + hit_ranges**2 * sine * cosine / depth
    variance = range_sigma**2 * slope_range**2 + bearing_variance[:, None] * slope_bearing**2
    weights = hits.weight / np.maximum(variance, _MIN_RANGE_VARIANCE)
    weights /= weights.sum(axis=1, keepdims=True)
    if not variances:
        return np.einsum("gb,gb->g", weights, along), None, None
    # The range noise is independent per beam; the bearing error is shared by all beams,
    # so it enters coherently and also correlates the range with the bearing estimate.
    coupling = np.einsum("gb,gb->g", weights, slope_bearing)
    range_variance = np.einsum("gb,gb->g", weights**2, slope_range**2) * range_sigma**2
    range_variance += coupling**2 * bearing_variance
    distance = np.einsum("gb,gb->g", weights, along)
    return distance, range_variance, coupling * bearing_variance


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
    jacobians = np.zeros((count, 2, columns))
    for m in range(count):
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
        projected = np.zeros((2, 2))
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
