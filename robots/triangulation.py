"""Robot pose from landmark bearings: ToTal three-object triangulation plus least squares.

ToTal (Pierlot & Van Droogenbroeck 2014, "A New Three Object Triangulation Algorithm for
Mobile Robot Positioning", IEEE T-RO 30(3)) finds the position of the observer from the
bearings of three known landmarks in closed form, with no trigonometry beyond three
cotangents. Its denominator ``D`` vanishes exactly when the observer lies on the circle
through the three landmarks (for collinear landmarks, on their line), where the bearings
do not determine the position; ``|D|`` measures how far the configuration is from that
and is used here, scaled by the landmark spread, as a reliability gate.

``triangulate`` runs ToTal on the most reliable triple, refines the pose by Gauss-Newton
over ALL bearings (a no-op on exact data with three landmarks) and returns the
first-order covariance ``(Jᵀ Σ⁻¹ J)⁻¹`` of the bearing noise, ``J`` being the Jacobian
of the predicted bearings with respect to the pose (square with three landmarks: plain
propagation ``J⁻¹ Σ J⁻ᵀ``). Bearings are in the frame whose pose is returned: give
sensor-frame bearings and you get the sensor pose.

Examples
--------
>>> import numpy as np
>>> landmarks = np.array([[0.0, 5.0], [5.0, 5.0], [5.0, -1.0]])
>>> truth = np.array([1.0, 1.0, 0.3])
>>> bearings = np.arctan2(landmarks[:, 1] - 1.0, landmarks[:, 0] - 1.0) - 0.3
>>> pose, cov = triangulate(bearings, landmarks, bearing_sigma=1e-3)
>>> pose.round(9)
array([1. , 1. , 0.3])
>>> bool(np.all(np.linalg.eigvalsh(cov) > 0))
True
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import wrap_angle

__all__ = ["DEFAULT_MIN_RELIABILITY", "TriangulationError", "total", "triangulate"]

# Stand-in for an infinite cotangent (two bearings equal modulo pi: the robot is on the
# line through two landmarks), as in the ToTal paper. The permutation choice in
# ``total`` keeps such terms out of the chosen labelling whenever possible.
COT_MAX = 1e8

# Default gate on ToTal's reliability |D| / s^2 (s^2: summed squared landmark offsets).
# Position errors grow as 1 / |D|; below this the robot is practically on the circle
# through the landmarks and the configuration is refused.
DEFAULT_MIN_RELIABILITY = 1e-6

# Two landmarks closer than this (m) are the same point: no triangle to work with.
_COINCIDENT_LANDMARKS = 1e-9

# Gauss-Newton refinement: stop when the step is below this (m or rad) or after the cap.
# Convergence is quadratic from ToTal's start, so the cap is never the binding limit.
_GN_STEP_TOLERANCE = 1e-9
_GN_MAX_ITERATIONS = 10

# ToTal starting triples are drawn from the first this-many landmarks only (at most 10
# triples): the refinement uses all of them anyway.
_MAX_TRIPLE_LANDMARKS = 5


class TriangulationError(ValueError):
    """The bearings do not determine the pose (degenerate or invalid configuration)."""


def _cot(angle: float) -> float:
    """Return ``cot(angle)``, clamped to ``±COT_MAX`` where it is infinite."""
    sine = math.sin(angle)
    if abs(sine) < 1.0 / COT_MAX:
        return math.copysign(COT_MAX, math.cos(angle) * (sine if sine != 0.0 else 1.0))
    return math.cos(angle) / sine


def _total_ordered(
    bearings: list[float], landmarks: list[list[float]]
) -> tuple[float, float, float]:
    """Run ToTal with the given labelling; return ``(x, y, D)``."""
    (x1, y1), (x2, y2), (x3, y3) = landmarks
    alpha1, alpha2, alpha3 = bearings
    # Step 1: landmark coordinates relative to landmark 2.
    x1p, y1p = x1 - x2, y1 - y2
    x3p, y3p = x3 - x2, y3 - y2
    # Step 2: the three cotangents.
    t12 = _cot(alpha2 - alpha1)
    t23 = _cot(alpha3 - alpha2)
    denominator = t12 + t23
    t31 = (1.0 - t12 * t23) / denominator if denominator != 0.0 else COT_MAX
    # Step 3: centres of the three circles (modified coordinates).
    x12p, y12p = x1p + t12 * y1p, y1p - t12 * x1p
    x23p, y23p = x3p - t23 * y3p, y3p + t23 * x3p
    x31p = (x3p + x1p) + t31 * (y3p - y1p)
    y31p = (y3p + y1p) - t31 * (x3p - x1p)
    # Step 4: k'31, then the denominator D (zero on the circle through the landmarks).
    k31p = x1p * x3p + y1p * y3p + t31 * (x1p * y3p - x3p * y1p)
    d = (x12p - x23p) * (y23p - y31p) - (y12p - y23p) * (x23p - x31p)
    if d == 0.0:
        return math.nan, math.nan, 0.0
    # Step 5: the robot position.
    return x2 + k31p * (y12p - y23p) / d, y2 + k31p * (x23p - x12p) / d, d


def total(bearings: ArrayLike, landmarks: ArrayLike) -> tuple[np.ndarray, float]:
    """Compute a pose from three bearings with ToTal; return it with its reliability.

    Parameters
    ----------
    bearings
        ``(3,)`` bearings of the landmarks in the robot frame, radians.
    landmarks
        ``(3, 2)`` landmark positions, world frame.

    Returns
    -------
    pose : np.ndarray
        ``(x, y, theta)``; ``nan`` entries when the configuration is exactly degenerate.
    reliability : float
        ``|D| / s^2``, ToTal's ``|D|`` made scale-free by the summed squared offsets of
        landmarks 1 and 3 from landmark 2: 0 on the circle through the landmarks.

    Examples
    --------
    >>> landmarks = [[0.0, 5.0], [5.0, 5.0], [5.0, -5.0]]
    >>> pose, reliability = total([np.pi / 2, np.pi / 4, -np.pi / 4], landmarks)
    >>> bool(np.abs(pose).max() < 1e-9), round(float(reliability), 3)
    (True, 0.222)
    """
    bearings = np.asarray(bearings, dtype=float).reshape(-1)
    landmarks = np.asarray(landmarks, dtype=float).reshape(-1, 2)
    if bearings.shape != (3,) or landmarks.shape != (3, 2):
        raise ValueError(
            f"total: needs 3 bearings and 3 landmarks, got {bearings.size} and "
            f"{landmarks.shape[0]}; use triangulate() for more"
        )
    pose, reliability = _total(bearings.tolist(), landmarks.tolist())
    return np.array(pose), reliability


def _total(
    bearings: list[float], landmarks: list[list[float]]
) -> tuple[tuple[float, float, float], float]:
    """Run ToTal on plain floats (the fast path of ``total``)."""
    nan_pose = (math.nan, math.nan, math.nan)
    sines = [abs(math.sin(bearings[j] - bearings[i])) for i, j in ((0, 1), (1, 2), (2, 0))]
    # All bearings equal modulo pi: the robot is on the line through collinear landmarks,
    # where ToTal's clamped cotangents would hide that D is really 0.
    if max(sines) < 1.0 / COT_MAX:
        return nan_pose, 0.0
    # Any landmark may play the role of landmark 2; take the labelling whose cotangents
    # are furthest from their poles (bearings equal modulo pi). Labelling (i, j, k) uses
    # the bearing differences j - i and k - j.
    orders = ((0, 1, 2), (1, 2, 0), (2, 0, 1))
    order = orders[max(range(3), key=lambda o: min(sines[o], sines[(o + 1) % 3]))]
    ordered_landmarks = [landmarks[i] for i in order]
    x, y, d = _total_ordered([bearings[i] for i in order], ordered_landmarks)
    (x1, y1), (x2, y2), (x3, y3) = ordered_landmarks
    spread = (x1 - x2) ** 2 + (y1 - y2) ** 2 + (x3 - x2) ** 2 + (y3 - y2) ** 2
    reliability = abs(d) / spread
    if not (math.isfinite(x) and math.isfinite(y)):
        return nan_pose, 0.0
    sin_sum = cos_sum = 0.0
    for (lx, ly), bearing in zip(landmarks, bearings, strict=True):
        heading = math.atan2(ly - y, lx - x) - bearing
        sin_sum += math.sin(heading)
        cos_sum += math.cos(heading)
    return (x, y, math.atan2(sin_sum, cos_sum)), reliability


def _bearing_jacobian(pose: np.ndarray, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return predicted bearings ``(N,)`` and their Jacobian ``(N, 3)`` wrt the pose."""
    dx = landmarks[:, 0] - pose[0]
    dy = landmarks[:, 1] - pose[1]
    range_sq = dx * dx + dy * dy
    predicted = np.arctan2(dy, dx) - pose[2]
    jacobian = np.column_stack([dy / range_sq, -dx / range_sq, -np.ones_like(dx)])
    return predicted, jacobian


def triangulate(
    bearings: ArrayLike,
    landmarks: ArrayLike,
    bearing_sigma: ArrayLike,
    *,
    min_reliability: float = DEFAULT_MIN_RELIABILITY,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimate a pose and its covariance from the bearings of three or more landmarks.

    Parameters
    ----------
    bearings
        ``(N,)`` bearings in the robot (or sensor) frame, radians, ``N >= 3``.
    landmarks
        ``(N, 2)`` positions of the observed landmarks, world frame, same order.
    bearing_sigma
        1-sigma bearing noise, radians: a scalar or one value per bearing.
    min_reliability
        Gate on ToTal's scale-free ``|D|`` of the best triple.

    Returns
    -------
    pose : np.ndarray
        ``(x, y, theta)`` of the frame the bearings are measured in.
    covariance : np.ndarray
        ``(3, 3)`` first-order covariance from the bearing noise.

    Raises
    ------
    TriangulationError
        Fewer than three landmarks, non-finite input, coincident landmarks, or a
        configuration below the reliability gate (robot on the circle through the
        landmarks, or on the line through collinear landmarks).

    Examples
    --------
    >>> landmarks = [[0.0, 5.0], [5.0, 5.0], [5.0, -1.0], [-3.0, -2.0]]
    >>> truth = np.array([1.0, 2.0, -0.4])
    >>> bearings = [np.arctan2(y - 2.0, x - 1.0) + 0.4 for x, y in landmarks]
    >>> pose, cov = triangulate(bearings, landmarks, bearing_sigma=0.002)
    >>> pose.round(9), bool(np.sqrt(cov[0, 0]) < 0.02)
    (array([ 1. ,  2. , -0.4]), True)
    >>> on_their_line = [[1.0, 0.0], [2.0, 0.0], [-1.0, 0.0]]
    >>> triangulate([0.0, 0.0, np.pi], on_their_line, 0.01)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robots.triangulation.TriangulationError: triangulate: degenerate configuration ...
    """
    bearings = np.asarray(bearings, dtype=float).reshape(-1)
    landmarks = np.asarray(landmarks, dtype=float).reshape(-1, 2)
    count = bearings.size
    if count < 3 or landmarks.shape[0] != count:
        raise TriangulationError(
            f"triangulate: needs at least 3 bearings with one landmark each, got "
            f"{count} bearings and {landmarks.shape[0]} landmarks"
        )
    sigma = np.broadcast_to(np.asarray(bearing_sigma, dtype=float), (count,))
    if not (np.all(np.isfinite(bearings)) and np.all(np.isfinite(landmarks))):
        raise TriangulationError("triangulate: bearings and landmarks must be finite")
    if not np.all(sigma > 0.0):
        raise ValueError(f"triangulate: bearing_sigma must be > 0 rad, got {bearing_sigma}")
    separation = np.linalg.norm(landmarks[:, None, :] - landmarks[None, :, :], axis=-1)
    if np.min(separation + np.diag(np.full(count, np.inf))) < _COINCIDENT_LANDMARKS:
        raise TriangulationError(
            "triangulate: two landmarks coincide; pass distinct landmark positions"
        )
    bearing_list, landmark_list = bearings.tolist(), landmarks.tolist()
    best_pose, best_reliability = (math.nan, math.nan, math.nan), -1.0
    for triple in itertools.combinations(range(min(count, _MAX_TRIPLE_LANDMARKS)), 3):
        pose, reliability = _total(
            [bearing_list[i] for i in triple], [landmark_list[i] for i in triple]
        )
        if reliability > best_reliability:
            best_pose, best_reliability = pose, reliability
    if not best_reliability >= min_reliability:
        raise TriangulationError(
            f"triangulate: degenerate configuration (reliability |D|/s^2 = "
            f"{best_reliability:.3g} < min_reliability = {min_reliability:.3g}): the robot "
            "is on or near the circle through the landmarks (or on the line through "
            "collinear ones); wait for other landmarks to come into view"
        )
    pose = np.array(best_pose)
    weights = 1.0 / sigma
    for _ in range(_GN_MAX_ITERATIONS):
        predicted, jacobian = _bearing_jacobian(pose, landmarks)
        weighted = jacobian * weights[:, None]
        residual = wrap_angle(bearings - predicted) * weights
        step = np.linalg.solve(weighted.T @ weighted, weighted.T @ residual)
        pose += step
        if np.max(np.abs(step)) < _GN_STEP_TOLERANCE:
            break
    pose[2] = wrap_angle(pose[2])
    _, jacobian = _bearing_jacobian(pose, landmarks)
    weighted = jacobian * weights[:, None]
    covariance = np.linalg.inv(weighted.T @ weighted)
    return pose, 0.5 * (covariance + covariance.T)
