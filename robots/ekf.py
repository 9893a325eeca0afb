"""EKF localizer on reflective landmark posts (paper Sec. 5.1), built on filterpy.

The state is the robot pose ``(x, y, theta)`` in the world frame. Prediction COMPOUNDS
the odometry increment ``u = (dx, dy, dtheta)`` measured in the robot frame,
``x' = x ⊕ u`` (a reference-frame transformation, not a velocity model), with the
Jacobians ``F = ∂(x ⊕ u)/∂x`` and ``J_u = ∂(x ⊕ u)/∂u`` and process noise
``Q = J_u Σ_u J_uᵀ``. The correction uses point landmarks observed in range and bearing
by a laser mounted at ``mount = (x, y, yaw)`` in base_link: every observation is matched
to the map with a per-observation NIS (Mahalanobis) gate that also refuses ambiguous
matches, then all accepted pairs enter ONE stacked filterpy update with the bearing
residuals wrapped. filterpy's update is in Joseph form; the covariance is additionally
symmetrised and, should it ever lose positive definiteness, eigenvalue-floored.

After a long landmark outage (no accepted update for ``outage_timeout`` seconds) or when
the position sigma has grown beyond ``max_position_sigma``, the filter re-localises from
scratch: observations are matched to the map by their mutual distances (which do not
depend on the pose), and the pose is triangulated (ToTal + least squares) from the
bearings of the matched posts. Every update is recorded (correction ``x_post - x_prior``
and 1-sigma bounds, as plotted in the paper's Figure 5).

A laser's range error has a white part and a systematic part, constant per instrument
(an LMS100: 12 mm 1-sigma and up to +-30 mm). Fusing many posts per scan shrinks the
covariance far below the systematic part, and since the posts do not surround the robot
evenly (270 deg field of view) the bias shifts the pose: the filter turns overconfident.
With ``EKFParams.range_bias_sigma > 0`` the state gains a fourth component, the range
bias ``b`` (measured range ``= |post - sensor| + b``), estimated along with the pose;
its prior is ``N(0, range_bias_sigma**2)`` and it may follow a slow random walk
(``range_bias_walk``). ``pose``, ``covariance`` and ``history`` still describe the pose
only; ``range_bias`` and ``range_bias_sigma`` give the bias. A re-localisation (or
``initialize``) replaces the pose and its covariance but KEEPS the bias estimate and its
variance: the bias belongs to the laser, not to the pose, and triangulation uses
bearings only, so the new pose is independent of the bias (zero cross-covariance).

Examples
--------
>>> import numpy as np
>>> from robots.landmarks import LandmarkObservation
>>> ekf = EKFLocalizer([[4.0, 0.0], [0.0, 4.0]])
>>> ekf.initialize([0.0, 0.0, 0.0], np.diag([0.01, 0.01, 0.001]), stamp=0.0)
>>> ekf.predict([1.0, 0.0, 0.0], np.diag([1e-4, 1e-4, 1e-5]))
>>> seen = LandmarkObservation(3.0, 0.0, np.diag([1e-4, 1e-6]), [0])
>>> ekf.update([seen], stamp=0.1)
[(0, 0)]
>>> ekf.pose.round(3)
array([1., 0., 0.])
>>> ekf.history[-1].correction.round(6) + 0.0  # the prediction was right: no correction
array([0., 0., 0.])
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numba
import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from numpy.typing import ArrayLike

from robots.landmarks import (
    CHI2_2DOF_99,
    LandmarkObservation,
    mahalanobis_rows,
    pairs_inside_gate,
    range_bearing_rows,
)
from robots.triangulation import DEFAULT_MIN_RELIABILITY, TriangulationError, triangulate
from semistatic.errors import MEMORY, SpecError
from semistatic.frames import wrap_angle
from semistatic.validation import bounds, check_fields

__all__ = ["EKFLocalizer", "EKFParams", "EKFRecord"]

_TWO_PI = 2.0 * math.pi

# Smallest eigenvalue kept in the state covariance when it has to be repaired (m^2, rad^2):
# far below any physical uncertainty, far above round-off.
_MIN_COVARIANCE_EIGENVALUE = 1e-12

# Re-localisation: at most this many observations (the nearest) are used to generate
# hypotheses; the verification step still uses all of them.
_MAX_HYPOTHESIS_OBSERVATIONS = 6

# Minimum matched posts for a re-localisation (three object triangulation).
_MIN_TRIANGULATION_POSTS = 3


def _residual(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Subtract stacked ``(range, bearing)`` vectors, wrapping the bearing rows to [-pi, pi).

    A handful of rows per update: Python floats, whose ``%`` rounds exactly as
    ``numpy.remainder`` (both are C ``fmod`` with the sign fixed), cost less than numpy's
    per-call overhead.

    Examples
    --------
    >>> _residual(np.array([[2.0], [3.0]]), np.array([[1.5], [-3.0]])).ravel().round(6)
    array([ 0.5     , -0.283185])
    """
    difference = measured - predicted
    rows = difference.reshape(-1)  # a view: the subtraction made a fresh contiguous array
    rows[1::2] = [(bearing + math.pi) % _TWO_PI - math.pi for bearing in rows[1::2].tolist()]
    return difference


@dataclass(frozen=True)
class EKFParams:
    """Settings of the EKF localizer; the defaults suit an LMS100 on a slow UGV.

    Parameters
    ----------
    mount
        Laser pose ``(x, y, yaw)`` in base_link (``LaserMount.pose2d()``).
    translation_sigma
        Odometry noise model used when ``predict`` gets no increment covariance:
        1-sigma translation error (m) per square-root metre travelled, on x and y.
    rotation_sigma
        1-sigma heading error (rad) per square-root radian turned.
    rotation_per_distance_sigma
        1-sigma heading error (rad) per square-root metre travelled.
    min_increment_sigma
        Floor on each increment sigma (m, rad), so that standing still keeps ``Q > 0``.
    nis_gate
        Per-observation gate on the normalised innovation squared (chi-square 2 dof).
    outage_timeout
        Seconds without an accepted update after which the filter re-localises by
        triangulation as soon as three posts are matched.
    max_position_sigma
        Largest position 1-sigma (m) tolerated before re-localising; also the largest a
        triangulation may have to be accepted.
    min_reliability
        ToTal reliability gate passed to ``triangulate``.
    relocalization_tolerance
        Tolerance (m) when matching observed post-to-post distances to the map, and
        when counting posts that agree with a re-localisation hypothesis.
    record_history
        Keep an ``EKFRecord`` of every update (Figure 5 of the paper).
    range_bias_sigma
        Prior 1-sigma (m) of the laser's systematic range error. ``0`` (default) keeps
        the 3-state filter; ``> 0`` estimates the bias as a fourth state. For a bias
        drawn uniformly in ``[-a, a]`` (a data-sheet "systematic error +-a") use
        ``a / sqrt(3)``, e.g. 0.0173 m for an LMS100 (+-30 mm).
    range_bias_walk
        Random-walk density of the bias, m per square-root second (its variance grows by
        ``range_bias_walk**2 * dt``); ``0`` (default) models a constant bias. Needs
        ``range_bias_sigma > 0``.

    Examples
    --------
    >>> EKFParams().increment_covariance([0.5, 0.0, 0.0]).diagonal().round(6)
    array([2.0e-04, 2.0e-04, 5.1e-05])
    >>> EKFParams(outage_timeout=0.0)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: outage_timeout: must be > 0.0 and <= 3600.0, \
got 0.0 (seconds without landmarks before re-localising, e.g. 5)
    >>> EKFParams(range_bias_walk=1e-4)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: range_bias_walk: 0.0001 needs the bias state: set \
range_bias_sigma...
    """

    # Noise figures are bounded by what odometry and lasers of real vehicles show (a few
    # per cent); the upper bounds leave room for a hundred times worse.
    mount: tuple[float, float, float] = field(
        default=(0.0, 0.0, 0.0),
        metadata=bounds(ge=-20.0, le=20.0, fix="(x, y, yaw) in base_link: LaserMount.pose2d()"),
    )
    translation_sigma: float = field(
        default=0.02, metadata=bounds(ge=0.0, le=1.0, fix="metres per square-root metre")
    )
    rotation_sigma: float = field(
        default=0.02, metadata=bounds(ge=0.0, le=1.0, fix="radians per square-root radian")
    )
    rotation_per_distance_sigma: float = field(
        default=0.01, metadata=bounds(ge=0.0, le=1.0, fix="radians per square-root metre")
    )
    min_increment_sigma: float = field(
        default=1e-4,
        metadata=bounds(gt=0.0, le=0.1, fix="a small odometry noise floor such as 1e-4"),
    )
    nis_gate: float = field(
        default=CHI2_2DOF_99,
        metadata=bounds(
            gt=0.0, le=100.0, fix="a chi-square quantile, e.g. 9.21 for 99% with 2 dof"
        ),
    )
    outage_timeout: float = field(
        default=5.0,
        metadata=bounds(
            gt=0.0, le=3600.0, fix="seconds without landmarks before re-localising, e.g. 5"
        ),
    )
    max_position_sigma: float = field(
        default=0.5, metadata=bounds(gt=0.0, le=100.0, fix="metres, e.g. 0.5")
    )
    min_reliability: float = field(
        default=DEFAULT_MIN_RELIABILITY,
        metadata=bounds(ge=0.0, le=1.0, fix="ToTal's |D| / s^2, dimensionless, e.g. 1e-6"),
    )
    relocalization_tolerance: float = field(
        default=0.1, metadata=bounds(gt=0.0, le=10.0, fix="metres, e.g. 0.1")
    )
    record_history: bool = True
    range_bias_sigma: float = field(
        default=0.0,
        metadata=bounds(ge=0.0, le=1.0, fix="metres, e.g. 0.0173 for an LMS100; 0 for no bias"),
    )
    range_bias_walk: float = field(
        default=0.0, metadata=bounds(ge=0.0, le=1.0, fix="m per square-root second")
    )

    def __post_init__(self) -> None:
        check_fields(self)
        if self.range_bias_walk > 0.0 and self.range_bias_sigma == 0.0:
            raise SpecError(
                MEMORY,
                "range_bias_walk",
                f"{self.range_bias_walk} needs the bias state: set range_bias_sigma > 0 "
                "(e.g. 0.0173 m for an LMS100) or the walk to 0",
            )

    def increment_covariance(self, increment: ArrayLike) -> np.ndarray:
        """Return the default ``(3, 3)`` covariance of an odometry increment.

        Variances grow linearly with the distance travelled and the angle turned
        (a random walk), with a small floor.
        """
        dx, dy, dtheta = (float(v) for v in np.asarray(increment, dtype=float)[:3])
        distance = math.hypot(dx, dy)
        floor = self.min_increment_sigma**2
        translation = self.translation_sigma**2 * distance + floor
        rotation = (
            self.rotation_sigma**2 * abs(dtheta)
            + self.rotation_per_distance_sigma**2 * distance
            + floor
        )
        return np.diag([translation, translation, rotation])


@dataclass(frozen=True, eq=False)
class EKFRecord:
    """One correction of the filter (or a re-initialisation), for plots and metrics.

    Parameters
    ----------
    stamp
        Time of the update, seconds.
    prior, posterior
        Pose before and after the correction.
    correction
        ``posterior - prior`` with the heading difference wrapped.
    sigma
        1-sigma bounds of the pose, ``sqrt(diag(P_post))[:3]``.
    landmarks
        Map indices of the landmarks used.
    nis
        Normalised innovation squared of each used observation (empty for a
        re-initialisation).
    reinitialized
        True when the pose came from triangulation rather than an EKF update.
    range_bias, range_bias_sigma
        Range-bias estimate and its 1-sigma after the update, metres (both 0 when the
        filter has no bias state).
    """

    stamp: float
    prior: np.ndarray
    posterior: np.ndarray
    correction: np.ndarray
    sigma: np.ndarray
    landmarks: tuple[int, ...]
    nis: tuple[float, ...]
    reinitialized: bool = False
    range_bias: float = 0.0
    range_bias_sigma: float = 0.0


class _CompoundingEKF(ExtendedKalmanFilter):
    """filterpy EKF whose state prediction compounds the odometry increment."""

    def predict_x(self, u: np.ndarray = 0) -> None:
        # Python floats: the same IEEE operations as on numpy scalars, without their cost.
        x, y, theta = self.x[:3, 0].tolist()
        dx, dy, dtheta = u.tolist()
        c, s = math.cos(theta), math.sin(theta)
        state = self.x.copy()  # a range-bias row, if any, is constant during prediction
        state[0, 0] = x + c * dx - s * dy
        state[1, 0] = y + s * dx + c * dy
        state[2, 0] = wrap_angle(theta + dtheta)
        self.x = state


@dataclass
class _Hypothesis:
    """A re-localisation candidate: sensor pose and the observation-landmark pairs."""

    sensor_pose: np.ndarray
    pairs: list[tuple[int, int]] = field(default_factory=list)


class EKFLocalizer:
    """Track the robot pose from odometry increments and landmark observations.

    Parameters
    ----------
    landmarks
        ``(M, 2)`` map of the landmark posts, world frame.
    params
        Filter settings.

    Examples
    --------
    >>> ekf = EKFLocalizer([[3.0, 0.0], [0.0, 3.0], [-3.0, 0.0]])
    >>> ekf.initialized
    False
    >>> seen = [
    ...     LandmarkObservation(3.0, 0.0, np.diag([1e-4, 1e-6]), [0]),
    ...     LandmarkObservation(3.0, np.pi / 2, np.diag([1e-4, 1e-6]), [1]),
    ...     LandmarkObservation(3.0, np.pi, np.diag([1e-4, 1e-6]), [2]),
    ... ]
    >>> ekf.step([0.0, 0.0, 0.0], None, seen, stamp=0.0)  # initialises by triangulation
    [(0, 0), (1, 1), (2, 2)]
    >>> bool(np.abs(ekf.pose).max() < 1e-9), ekf.history[-1].reinitialized
    (True, True)

    With a range-bias state, ranges 2 cm too long from posts all around are explained by
    the bias, not by moving the robot:

    >>> biased = EKFLocalizer(
    ...     [[3.0, 0.0], [0.0, 3.0], [-3.0, 0.0], [0.0, -3.0]], EKFParams(range_bias_sigma=0.02)
    ... )
    >>> biased.initialize([0.0, 0.0, 0.0], np.diag([1e-2, 1e-2, 1e-4]), stamp=0.0)
    >>> long = [
    ...     LandmarkObservation(3.02, angle, np.diag([1e-4, 1e-6]), [k])
    ...     for k, angle in enumerate([0.0, np.pi / 2, np.pi, -np.pi / 2])
    ... ]
    >>> for tick in range(25):
    ...     _ = biased.update(long, stamp=0.1 * tick)
    >>> round(biased.range_bias, 3), round(biased.range_bias_sigma, 4)
    (0.02, 0.001)
    >>> biased.pose.round(6) + 0.0
    array([0., 0., 0.])
    """

    def __init__(self, landmarks: ArrayLike, params: EKFParams | None = None) -> None:
        self.params = EKFParams() if params is None else params
        self.landmarks = np.array(landmarks, dtype=np.float64).reshape(-1, 2)
        self.landmarks.flags.writeable = False
        self._landmark_distances = np.linalg.norm(
            self.landmarks[:, None, :] - self.landmarks[None, :, :], axis=-1
        )
        self._mount = np.array(self.params.mount)
        self._mount_floats = tuple(float(v) for v in self.params.mount)
        # The landmark coordinates as the per-update range-bearing model takes them.
        self._landmark_x = np.ascontiguousarray(self.landmarks[:, 0])
        self._landmark_y = np.ascontiguousarray(self.landmarks[:, 1])
        # The state is (x, y, theta) or, with a range-bias state, (x, y, theta, b).
        self._has_bias = self.params.range_bias_sigma > 0.0
        self._dim = 4 if self._has_bias else 3
        # The prediction's matrices, allocated once and refilled in place at every call:
        # F is the identity but for the heading column, J_u keeps its zero entries, and Q
        # has no bias row or column. filterpy reads them only inside its predict.
        self._state_jacobian = np.eye(self._dim)
        self._increment_jacobian = np.eye(3)
        self._process_noise = np.zeros((self._dim, self._dim))
        self._filter = _CompoundingEKF(dim_x=self._dim, dim_z=2)
        if self._has_bias:
            self._filter.P[3, 3] = self.params.range_bias_sigma**2
        # Time up to which the bias random walk has been added to the bias variance.
        self._bias_stamp: float | None = None
        self.initialized = False
        # Time of the last accepted update; None: start the outage timer at the next one.
        self.last_update_stamp: float | None = None
        self.history: list[EKFRecord] = []

    # ------------------------------------------------------------------ state access
    @property
    def pose(self) -> np.ndarray:
        """Return the current pose estimate ``(x, y, theta)`` (a copy)."""
        return self._filter.x[:3, 0].copy()

    @property
    def covariance(self) -> np.ndarray:
        """Return the current ``(3, 3)`` pose covariance (a copy)."""
        return self._filter.P[:3, :3].copy()

    @property
    def state_covariance(self) -> np.ndarray:
        """Return the covariance of the whole state: ``(3, 3)``, or ``(4, 4)`` with the bias last.

        Examples
        --------
        >>> EKFLocalizer([[1.0, 0.0]], EKFParams(range_bias_sigma=0.01)).state_covariance.shape
        (4, 4)
        """
        return self._filter.P.copy()

    @property
    def range_bias(self) -> float:
        """Return the estimated range bias of the laser, m (0 without a bias state).

        Examples
        --------
        >>> EKFLocalizer([[1.0, 0.0]]).range_bias  # a 3-state filter
        0.0
        """
        return float(self._filter.x[3, 0]) if self._has_bias else 0.0

    @property
    def range_bias_sigma(self) -> float:
        """Return the 1-sigma of the range-bias estimate, m (0 without a bias state).

        Examples
        --------
        >>> EKFLocalizer([[1.0, 0.0]], EKFParams(range_bias_sigma=0.01)).range_bias_sigma
        0.01
        """
        return math.sqrt(self._filter.P[3, 3]) if self._has_bias else 0.0

    def position_sigma(self) -> float:
        """Return the 1-sigma of the position along its most uncertain direction, m."""
        return _largest_sigma(self._filter.P)

    def initialize(self, pose: ArrayLike, cov: ArrayLike, stamp: float | None = None) -> None:
        """Set the pose and its ``(3, 3)`` covariance, e.g. from a known start pose.

        ``stamp`` counts as the time of the last accepted update (the outage timer
        starts there); with ``None`` it starts at the next ``update``. A range-bias
        estimate and its variance are kept (the bias belongs to the laser, not to the
        pose); the new pose is taken as independent of it.
        """
        pose = np.asarray(pose, dtype=float).reshape(3)
        cov = np.asarray(cov, dtype=float).reshape(3, 3)
        if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(cov))):
            raise ValueError("EKFLocalizer.initialize: pose and cov must be finite")
        heading = wrap_angle(float(pose[2]))
        if self._has_bias:
            if stamp is not None:
                self._propagate_bias(float(stamp))
            bias, bias_variance = self._filter.x[3, 0], self._filter.P[3, 3]
            self._filter.x = np.array([[pose[0]], [pose[1]], [heading], [bias]])
            state_cov = np.zeros((4, 4))
            state_cov[:3, :3] = self._repair_covariance(cov)
            state_cov[3, 3] = bias_variance  # no cross terms: see the module docstring
            self._filter.P = state_cov
        else:
            self._filter.x = np.array([[pose[0]], [pose[1]], [heading]])
            self._filter.P = self._repair_covariance(cov)
        self.initialized = True
        self.last_update_stamp = None if stamp is None else float(stamp)

    # ------------------------------------------------------------------ prediction
    def predict(self, increment: ArrayLike, increment_cov: ArrayLike | None = None) -> None:
        """Compound an odometry increment ``(dx, dy, dtheta)`` given in the robot frame.

        ``increment_cov`` is its ``(3, 3)`` covariance; ``None`` uses the noise model of
        ``EKFParams``. Does nothing before the filter is initialised.
        """
        if not self.initialized:
            return
        u = np.asarray(increment, dtype=float).reshape(3)
        sigma_u = (
            self.params.increment_covariance(u)
            if increment_cov is None
            else np.asarray(increment_cov, dtype=float)
        )
        dx, dy, _ = u.tolist()
        theta = float(self._filter.x[2, 0])
        c, s = math.cos(theta), math.sin(theta)
        # The bias (if any) is untouched by driving: identity row/column in F, none in Q
        # (its random walk is added by time, at the updates).
        state_jacobian = self._state_jacobian
        state_jacobian[0, 2] = -s * dx - c * dy
        state_jacobian[1, 2] = c * dx - s * dy
        self._filter.F = state_jacobian
        increment_jacobian = self._increment_jacobian
        increment_jacobian[0, 0], increment_jacobian[0, 1] = c, -s
        increment_jacobian[1, 0], increment_jacobian[1, 1] = s, c
        pose_noise = increment_jacobian @ sigma_u @ increment_jacobian.T
        if self._has_bias:
            self._process_noise[:3, :3] = pose_noise
            self._filter.Q = self._process_noise
        else:
            self._filter.Q = pose_noise
        self._filter.predict(u)

    # ------------------------------------------------------------------ correction
    def update(
        self, observations: Sequence[LandmarkObservation], stamp: float
    ) -> list[tuple[int, int]]:
        """Correct the pose with landmark observations taken at ``stamp``.

        Re-localises by triangulation instead when the filter is not initialised, the
        last accepted update is older than ``outage_timeout`` or the position sigma
        exceeds ``max_position_sigma`` (and enough posts are matched).

        Returns
        -------
        list of (int, int)
            The ``(observation index, landmark index)`` pairs that were used.
        """
        stamp = float(stamp)
        if self._has_bias:
            self._propagate_bias(stamp)
        if self.last_update_stamp is None:
            self.last_update_stamp = stamp
        lost = (
            not self.initialized
            or stamp - self.last_update_stamp > self.params.outage_timeout
            or self.position_sigma() > self.params.max_position_sigma
        )
        if lost and len(observations) >= _MIN_TRIANGULATION_POSTS:
            pairs = self.relocalize(observations, stamp)
            if pairs:
                return pairs
        if not self.initialized or not observations:
            return []
        prior = self._filter.x[:3, 0].copy()
        x, y, theta = prior.tolist()
        predicted, jacobians = range_bearing_rows(
            x, y, theta, *self._mount_floats, self._landmark_x, self._landmark_y, self._dim
        )
        if self._has_bias:
            # range = |post - sensor| + b: d(range)/db = 1, d(bearing)/db = 0.
            predicted[:, 0] += self._filter.x[3, 0]
            jacobians[:, 0, 3] = 1.0
        # Every observation's measurement and noise, stacked once for the gate and the update.
        measured_all = np.array([(obs.range, obs.bearing) for obs in observations])
        noise_all = np.array([obs.covariance for obs in observations])
        nis = mahalanobis_rows(
            measured_all, noise_all, predicted, jacobians, np.ascontiguousarray(self._filter.P)
        )
        pairs = pairs_inside_gate(nis, self.params.nis_gate)
        if not pairs:
            return []
        obs_index = [k for k, _ in pairs]
        landmark_index = [m for _, m in pairs]
        measured, expected, jacobian, noise = _stacked_pairs(
            measured_all, noise_all, predicted, jacobians,
            np.array(obs_index, dtype=np.int64), np.array(landmark_index, dtype=np.int64),
        )
        self._filter.update(
            measured,
            lambda _x: jacobian,
            lambda _x: expected,
            R=noise,
            residual=_residual,
        )
        self._filter.x[2, 0] = wrap_angle(float(self._filter.x[2, 0]))
        self._filter.P = self._repair_covariance(self._filter.P)
        self.last_update_stamp = stamp
        if self.params.record_history:
            used_nis = [nis.item(k, m) for k, m in pairs]
            self._record(stamp, prior, landmark_index, used_nis, False)
        return pairs

    def step(
        self,
        increment: ArrayLike,
        increment_cov: ArrayLike | None,
        observations: Sequence[LandmarkObservation],
        stamp: float,
    ) -> list[tuple[int, int]]:
        """Predict with an odometry increment, then update with the observations.

        Returns the ``(observation, landmark)`` pairs used, as ``update`` does.
        """
        self.predict(increment, increment_cov)
        return self.update(observations, stamp)

    def _propagate_bias(self, stamp: float) -> None:
        """Grow the bias variance by its random walk up to ``stamp`` (time never goes back)."""
        if self._bias_stamp is not None and stamp > self._bias_stamp:
            self._filter.P[3, 3] += self.params.range_bias_walk**2 * (stamp - self._bias_stamp)
        if self._bias_stamp is None or stamp > self._bias_stamp:
            self._bias_stamp = stamp

    # ------------------------------------------------------------------ re-localisation
    def relocalize(
        self, observations: Sequence[LandmarkObservation], stamp: float
    ) -> list[tuple[int, int]]:
        """Re-initialise the pose by triangulation, ignoring the current estimate's gate.

        Observations are matched to the map by their post-to-post distances (pose
        invariant) and a verification of every hypothesis against all observations; the
        best hypothesis is triangulated from its bearings. When hypotheses tie (a
        symmetric layout), the one nearest the current estimate wins. A range-bias
        estimate is subtracted from the ranges for the matching and kept, with its
        variance, in the new state (bearings say nothing about it).

        Returns
        -------
        list of (int, int)
            The pairs used, or ``[]`` when no unambiguous, reliable fix was found (the
            state is then left untouched).
        """
        hypothesis = self._best_hypothesis(observations)
        if hypothesis is None or len(hypothesis.pairs) < _MIN_TRIANGULATION_POSTS:
            return []
        obs_index = [k for k, _ in hypothesis.pairs]
        landmark_index = [m for _, m in hypothesis.pairs]
        bearings = [observations[k].bearing for k in obs_index]
        sigmas = [math.sqrt(observations[k].covariance[1, 1]) for k in obs_index]
        try:
            sensor_pose, sensor_cov = triangulate(
                bearings,
                self.landmarks[landmark_index],
                sigmas,
                min_reliability=self.params.min_reliability,
            )
        except TriangulationError:
            return []
        pose, cov = self._robot_from_sensor(sensor_pose, sensor_cov)
        if _largest_sigma(cov) > self.params.max_position_sigma:
            return []
        prior = self.pose if self.initialized else pose
        self.initialize(pose, cov, stamp=stamp)
        if self.params.record_history:
            self._record(stamp, prior, landmark_index, [], True)
        return list(hypothesis.pairs)

    def _robot_from_sensor(
        self, sensor_pose: np.ndarray, sensor_cov: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Return the robot pose ``sensor ⊕ mount⁻¹`` and its propagated covariance."""
        mount_x, mount_y, mount_yaw = self._mount
        cm, sm = math.cos(mount_yaw), math.sin(mount_yaw)
        # The base seen from the sensor: the inverse of the mount.
        bx, by = -cm * mount_x - sm * mount_y, sm * mount_x - cm * mount_y
        theta = sensor_pose[2]
        c, s = math.cos(theta), math.sin(theta)
        pose = np.array(
            [
                sensor_pose[0] + c * bx - s * by,
                sensor_pose[1] + s * bx + c * by,
                wrap_angle(theta - mount_yaw),
            ]
        )
        jacobian = np.array(
            [[1.0, 0.0, -s * bx - c * by], [0.0, 1.0, c * bx - s * by], [0.0, 0.0, 1.0]]
        )
        return pose, self._repair_covariance(jacobian @ sensor_cov @ jacobian.T)

    def best_matches(
        self, observations: Sequence[LandmarkObservation]
    ) -> list[tuple[tuple[int, int], ...]]:
        """Return every best match of ``observations`` to the map, by geometry alone.

        A match is the ``(observation, landmark)`` pairs of one hypothesis (three
        observations placed on three landmarks with the same pairwise distances, then
        verified against all observations); the best are those with the most pairs.
        :meth:`relocalize` uses the only one, or, when several tie, the one nearest the
        current estimate; a filter that has no estimate yet (lap 1) cannot choose. So
        more than one match means the layout is ambiguous from where the posts were
        seen, and none means fewer than three posts could be matched.

        Examples
        --------
        >>> posts = [[0.0, 2.0], [2.0, 2.0], [4.0, 2.0], [1.0, -2.0], [3.0, -2.0]]  # even
        >>> seen = [LandmarkObservation(math.hypot(x - 1.0, y), math.atan2(y, x - 1.0),
        ...                             np.diag([1e-4, 1e-6]), [])
        ...         for x, y in (posts[0], posts[1], posts[3])]   # seen from (1, 0), ahead
        >>> len(EKFLocalizer(posts).best_matches(seen))   # shifted by 2 m, or turned round
        3
        >>> uneven = [[0.0, 2.0], [2.0, 2.0], [4.0, 2.0], [1.0, -2.0], [3.6, -2.0]]
        >>> EKFLocalizer(uneven).best_matches(seen)
        [((0, 0), (1, 1), (2, 3))]
        """
        return [tuple((int(k), int(m)) for k, m in hypothesis.pairs)
                for hypothesis in self._tied_hypotheses(observations)]

    def _best_hypothesis(self, observations: Sequence[LandmarkObservation]) -> _Hypothesis | None:
        """Match observations to landmarks by geometry alone; return the best match."""
        best = self._tied_hypotheses(observations)
        if len(best) > 1 and self.initialized:
            robot = self.pose[:2]
            best.sort(key=lambda h: float(np.linalg.norm(h.sensor_pose[:2] - robot)))
        elif len(best) > 1:
            return None
        return best[0] if best else None

    def _tied_hypotheses(self, observations: Sequence[LandmarkObservation]) -> list[_Hypothesis]:
        """Return the hypotheses with the most verified pairs (none: no match)."""
        if len(observations) < _MIN_TRIANGULATION_POSTS or self.landmarks.shape[0] < 3:
            return []
        points = np.array([obs.point() for obs in observations])
        if self._has_bias:
            # Remove the estimated range bias: post-to-post distances come out truer.
            ranges = np.array([obs.range for obs in observations])
            points *= ((ranges - self.range_bias) / ranges)[:, None]
        tolerance = self.params.relocalization_tolerance
        nearest = np.argsort([obs.range for obs in observations])[:_MAX_HYPOTHESIS_OBSERVATIONS]
        hypotheses: list[_Hypothesis] = []
        seen: set[tuple[int, ...]] = set()
        for triple in itertools.combinations(sorted(nearest.tolist()), 3):
            for landmark_triple in self._landmark_triples(points[list(triple)], tolerance):
                sensor_pose = _rigid_transform(
                    points[list(triple)], self.landmarks[list(landmark_triple)]
                )
                pairs = self._inliers(points, sensor_pose, tolerance)
                key = tuple(m for _, m in pairs)
                if len(pairs) >= _MIN_TRIANGULATION_POSTS and key not in seen:
                    seen.add(key)
                    hypotheses.append(_Hypothesis(sensor_pose, pairs))
        if not hypotheses:
            return []
        most = max(len(h.pairs) for h in hypotheses)
        return [h for h in hypotheses if len(h.pairs) == most]

    def _landmark_triples(self, points: np.ndarray, tolerance: float) -> list[tuple[int, ...]]:
        """Return landmark triples congruent (same orientation) to three observed points."""
        d01 = float(np.linalg.norm(points[1] - points[0]))
        d02 = float(np.linalg.norm(points[2] - points[0]))
        d12 = float(np.linalg.norm(points[2] - points[1]))
        distances = self._landmark_distances
        first_pairs = np.argwhere(np.abs(distances - d01) < tolerance)
        observed_turn = _cross(points[1] - points[0], points[2] - points[0])
        triples = []
        for a, b in first_pairs:
            if a == b:
                continue
            candidates = np.flatnonzero(
                (np.abs(distances[a] - d02) < tolerance) & (np.abs(distances[b] - d12) < tolerance)
            )
            for c in candidates:
                if c in (a, b):
                    continue
                turn = _cross(
                    self.landmarks[b] - self.landmarks[a], self.landmarks[c] - self.landmarks[a]
                )
                if turn * observed_turn > 0.0:
                    triples.append((int(a), int(b), int(c)))
        return triples

    def _inliers(
        self, points: np.ndarray, sensor_pose: np.ndarray, tolerance: float
    ) -> list[tuple[int, int]]:
        """Return the unambiguous observation-landmark pairs closer than ``tolerance``."""
        c, s = math.cos(sensor_pose[2]), math.sin(sensor_pose[2])
        world = points @ np.array([[c, s], [-s, c]]) + sensor_pose[:2]
        gaps = np.linalg.norm(world[:, None, :] - self.landmarks[None, :, :], axis=-1)
        return pairs_inside_gate(gaps, tolerance)

    # ------------------------------------------------------------------ bookkeeping
    @staticmethod
    def _repair_covariance(cov: np.ndarray) -> np.ndarray:
        """Return ``cov`` symmetrised, eigenvalue-floored if it is not positive definite."""
        cov = 0.5 * (cov + cov.T)
        if not _positive_definite(cov):
            values, vectors = np.linalg.eigh(cov)
            values = np.maximum(values, _MIN_COVARIANCE_EIGENVALUE)
            cov = (vectors * values) @ vectors.T
            cov = 0.5 * (cov + cov.T)
        return cov

    def _record(
        self,
        stamp: float,
        prior: np.ndarray,
        landmarks: list[int],
        nis: list[float],
        reinitialized: bool,
    ) -> None:
        """Append the correction just applied to ``history``."""
        state, covariance = self._filter.x, self._filter.P
        posterior = state[:3, 0].copy()
        correction = posterior - prior
        correction[2] = wrap_angle(float(correction[2]))
        self.history.append(
            EKFRecord(
                stamp,
                prior,
                posterior,
                correction,
                np.sqrt(covariance.diagonal()[:3]),
                tuple(landmarks),
                tuple(map(float, nis)),
                reinitialized,
                float(state[3, 0]) if self._has_bias else 0.0,
                math.sqrt(covariance[3, 3]) if self._has_bias else 0.0,
            )
        )

    def history_arrays(self) -> dict[str, np.ndarray]:
        """Return the update history as arrays: stamp, correction, sigma, reinitialized, bias.

        ``correction`` and ``sigma`` are ``(N, 3)``: exactly what the paper's Figure 5
        plots (corrections of x, y, theta inside their sigma bounds). ``range_bias`` and
        ``range_bias_sigma`` are ``(N,)`` (zeros without a bias state).

        Examples
        --------
        >>> EKFLocalizer([[1.0, 0.0]]).history_arrays()["correction"].shape
        (0, 3)
        """
        records = self.history
        return {
            "stamp": np.array([r.stamp for r in records], dtype=float),
            "correction": np.array([r.correction for r in records], dtype=float).reshape(-1, 3),
            "sigma": np.array([r.sigma for r in records], dtype=float).reshape(-1, 3),
            "reinitialized": np.array([r.reinitialized for r in records], dtype=bool),
            "range_bias": np.array([r.range_bias for r in records], dtype=float),
            "range_bias_sigma": np.array([r.range_bias_sigma for r in records], dtype=float),
        }


@numba.njit(cache=True)
def _stacked_pairs(
    measured_all, noise_all, predicted, jacobians, observations, landmarks
):  # pragma: no cover - compiled
    """Return the stacked measurement, prediction, Jacobian and noise of matched pairs.

    Pair ``i`` is observation ``observations[i]`` (row of ``measured_all`` and
    ``noise_all``) with landmark ``landmarks[i]`` (row of ``predicted`` and
    ``jacobians``): rows ``2i, 2i + 1`` of the ``(2n, 1)`` measurement and prediction and
    of the ``(2n, D)`` Jacobian; the ``(2n, 2n)`` noise is block diagonal.

    Examples
    --------
    >>> measured, expected, jacobian, noise = _stacked_pairs(
    ...     np.array([[2.0, 0.1], [3.0, 0.2]]), np.array([np.eye(2), 2 * np.eye(2)]),
    ...     np.array([[2.1, 0.1]]), np.ones((1, 2, 3)), np.array([1]), np.array([0]))
    >>> measured.ravel().tolist(), expected.ravel().tolist(), jacobian.shape
    ([3.0, 0.2], [2.1, 0.1], (2, 3))
    >>> noise.tolist()
    [[2.0, 0.0], [0.0, 2.0]]
    """
    count, columns = observations.size, jacobians.shape[2]
    measured, expected = np.empty((2 * count, 1)), np.empty((2 * count, 1))
    jacobian = np.empty((2 * count, columns))
    noise = np.empty((2 * count, 2 * count))  # (np.zeros in 2-d compiles code of its own)
    for row in range(2 * count):
        for column in range(2 * count):
            noise[row, column] = 0.0
    for i in range(count):
        k, m = observations[i], landmarks[i]
        for row in range(2):
            measured[2 * i + row, 0] = measured_all[k, row]
            expected[2 * i + row, 0] = predicted[m, row]
            for column in range(columns):
                jacobian[2 * i + row, column] = jacobians[m, row, column]
            for column in range(2):
                noise[2 * i + row, 2 * i + column] = noise_all[k, row, column]
    return measured, expected, jacobian, noise


def _largest_sigma(cov: np.ndarray) -> float:
    """Return the 1-sigma of the position block of ``cov`` along its worst direction."""
    a, b, c = float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])
    largest = 0.5 * (a + c) + math.hypot(0.5 * (a - c), b)
    return math.sqrt(max(largest, 0.0))


def _positive_definite(cov: np.ndarray) -> bool:
    """Return whether a symmetric 3x3 or 4x4 matrix is positive definite.

    Closed form (Sylvester's criterion) rather than a Cholesky call: this runs after
    every update. A 4x4 matrix is positive definite iff its leading 3x3 block is and the
    Schur complement of that block is positive.

    Examples
    --------
    >>> _positive_definite(np.diag([1.0, 2.0, 3.0, 4.0])), _positive_definite(-np.eye(3))
    (True, False)
    """
    (a, b, c), (_, d, e), (_, _, f) = cov[:3, :3].tolist()
    minor2 = a * d - b * b
    determinant = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c)
    if not (a > 0.0 and minor2 > 0.0 and determinant > 0.0):
        return False
    if cov.shape[0] == 3:
        return True
    # Schur complement cov[3, 3] - v^T A^-1 v, A^-1 from the adjugate of the 3x3 block.
    v0, v1, v2 = cov[:3, 3].tolist()
    adjugate_quadratic = (
        (d * f - e * e) * v0 * v0
        + (a * f - c * c) * v1 * v1
        + (a * d - b * b) * v2 * v2
        + 2.0 * (c * e - b * f) * v0 * v1
        + 2.0 * (b * e - c * d) * v0 * v2
        + 2.0 * (b * c - a * e) * v1 * v2
    )
    return float(cov[3, 3]) - adjugate_quadratic / determinant > 0.0


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    """Return the z component of the cross product of two 2D vectors."""
    return float(a[0] * b[1] - a[1] * b[0])


def _rigid_transform(local: np.ndarray, world: np.ndarray) -> np.ndarray:
    """Return the pose mapping ``local`` points onto ``world`` points (least squares).

    Examples
    --------
    >>> local = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    >>> _rigid_transform(local, local + [2.0, 0.0]).round(9)
    array([2., 0., 0.])
    """
    local_mean = local.mean(axis=0)
    world_mean = world.mean(axis=0)
    a = local - local_mean
    b = world - world_mean
    # 2D Kabsch: the rotation angle that best aligns the centred point sets.
    theta = math.atan2(
        float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])),
        float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])),
    )
    c, s = math.cos(theta), math.sin(theta)
    translation = world_mean - np.array(
        [c * local_mean[0] - s * local_mean[1], s * local_mean[0] + c * local_mean[1]]
    )
    return np.array([translation[0], translation[1], theta])
