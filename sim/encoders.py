"""Wheel encoders: quantised, noisy wheel travel turned into odometry increments.

The model, per wheel, between two readings:

1. Quantisation. An incremental encoder counts ``floor(angle * N / 2 pi)`` ticks for
   ``N = spec.encoder_ticks_per_rev`` counts per wheel revolution; the travel is
   ``d = delta_ticks * 2 pi r / N``.
2. Slip noise. The measured travel is ``d + e`` with ``e ~ N(0, sigma**2 * |d| * 1 m)``
   and ``sigma = spec.encoder_slip_sigma``, drawn independently for each wheel and each
   increment from the caller's ``numpy.random.Generator``. It is multiplicative in the
   sense that it scales with the distance rolled (zero when standing still), and its
   variance grows linearly with distance - Siegwart & Nourbakhsh's ``k |Δs|`` model
   ("Introduction to Autonomous Mobile Robots", Sec. 5.2.4) with ``k = sigma**2 * 1 m``
   - so summing many small increments gives the same error statistics as one big one,
   whatever the odometry rate.

The two wheel travels give the body's displacement along an arc of constant curvature
(exact for a differential drive turning at a constant rate): with ``d = (d_l + d_r)/2``
and ``dtheta = (d_r - d_l) / b`` (track ``b``), the increment in the frame of the
previous pose is ``dx = c cos(dtheta/2)``, ``dy = c sin(dtheta/2)`` with the chord
``c = d sinc(dtheta/2)``. That is the frame transformation ``u`` with
``x_k = x_{k-1} ⊕ u`` the EKF compounds.

``increment_covariance`` propagates the per-wheel variances - the slip term above plus
the quantisation of a tick difference, ``(2 pi r / N)**2 / 6`` (each reading's rounding
error is uniform over one tick) - through the Jacobian of that arc model.

Examples
--------
>>> from robots.presets import PIONEER3DX
>>> encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0), noise_free=True)
>>> encoders.reset([0.0, 0.0])
>>> u = encoders.odometry_increment([10.0, 10.0])  # both wheels 10 rad forward
>>> u.round(4)
array([0.975, 0.   , 0.   ])
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from robots.presets import UGVSpec

__all__ = ["WheelEncoders", "arc_increment", "arc_increment_jacobian"]

# Below this half heading change the chord and its derivative use their Taylor series:
# sin(a)/a and its derivative lose precision to cancellation near a = 0.
_SMALL_HALF_TURN = 1e-4


def _sinc_and_derivative(a: float) -> tuple[float, float]:
    """Return ``sin(a)/a`` and its derivative, accurate near 0."""
    a = float(a)
    if abs(a) < _SMALL_HALF_TURN:
        a2 = a * a
        return 1.0 - a2 / 6.0 + a2 * a2 / 120.0, -a / 3.0 + a * a2 / 30.0
    # math's sin and cos are numpy's to the last bit (both call the C library).
    s, c = math.sin(a), math.cos(a)
    return s / a, (a * c - s) / (a * a)


def arc_increment(left: float, right: float, track: float) -> np.ndarray:
    """Return the pose increment ``(dx, dy, dtheta)`` of a differential drive.

    Parameters
    ----------
    left, right
        Distances (m) rolled by the left and right wheels.
    track
        Distance between the wheels' contact points (m).

    Returns
    -------
    numpy.ndarray
        The new pose in the frame of the old one, for motion along a circular arc
        (a straight line when both distances are equal).

    Examples
    --------
    >>> arc_increment(1.0, 1.0, 0.5)
    array([1., 0., 0.])
    >>> arc_increment(-np.pi / 4, np.pi / 4, 1.0).round(6)  # a quarter turn on the spot
    array([0.      , 0.      , 1.570796])
    >>> arc_increment(np.pi / 4, 3 * np.pi / 4, 1.0).round(6)  # quarter circle of radius 1
    array([1.      , 1.      , 1.570796])
    """
    return np.array(_arc_increment(float(left), float(right), float(track)))


def _arc_increment(left: float, right: float, track: float) -> tuple[float, float, float]:
    """Return ``arc_increment`` as a tuple of floats (the encoders' per-tick path)."""
    distance = 0.5 * (left + right)
    dtheta = (right - left) / track
    half = 0.5 * dtheta
    sinc, _ = _sinc_and_derivative(half)
    chord = distance * sinc
    return chord * math.cos(half), chord * math.sin(half), dtheta


def arc_increment_jacobian(left: float, right: float, track: float) -> np.ndarray:
    """Return the ``3 x 2`` Jacobian of ``arc_increment`` wrt ``(left, right)``.

    Examples
    --------
    >>> arc_increment_jacobian(1.0, 1.0, 0.5).round(3)  # straight: dy depends on the difference
    array([[ 0.5,  0.5],
           [-1. ,  1. ],
           [-2. ,  2. ]])
    """
    left, right, track = float(left), float(right), float(track)
    distance = 0.5 * (left + right)
    half = 0.5 * (right - left) / track
    sinc, dsinc = _sinc_and_derivative(half)
    cos_h, sin_h = math.cos(half), math.sin(half)
    # Derivatives wrt the mean distance d and the half angle a = dtheta / 2.
    wrt_mean = (sinc * cos_h, sinc * sin_h, 0.0)
    wrt_half = (  # dtheta = 2a
        distance * (dsinc * cos_h - sinc * sin_h),
        distance * (dsinc * sin_h + sinc * cos_h),
        2.0,
    )
    # Chain rule: d/dl = 1/2 d/dd - 1/(2b) d/da, d/dr = 1/2 d/dd + 1/(2b) d/da. Rows
    # written out (no comprehension): this runs at every odometry reading.
    half_rate = 0.5 / track
    (mean_x, mean_y, mean_theta), (turn_x, turn_y, turn_theta) = wrt_mean, wrt_half
    return np.array([
        [0.5 * mean_x - half_rate * turn_x, 0.5 * mean_x + half_rate * turn_x],
        [0.5 * mean_y - half_rate * turn_y, 0.5 * mean_y + half_rate * turn_y],
        [0.5 * mean_theta - half_rate * turn_theta, 0.5 * mean_theta + half_rate * turn_theta],
    ])


class WheelEncoders:
    """Incremental wheel encoders of a differential-drive UGV, with slip noise.

    Parameters
    ----------
    spec
        The vehicle: wheel radius, track, ticks per wheel revolution, slip sigma.
    rng
        Source of the slip noise; the same seed gives the same odometry.
    noise_free
        Quantise only (no slip noise), for tests and as a reference.

    Attributes
    ----------
    last_tick_deltas
        ``(2,)`` int tick counts ``(left, right)`` of the last increment.

    Examples
    --------
    >>> from robots.presets import PIONEER3DX
    >>> encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(1))
    >>> encoders.reset([0.0, 0.0])
    >>> u = encoders.odometry_increment([1.0, 1.2])
    >>> encoders.last_tick_deltas
    array([3047, 3657])
    >>> cov = encoders.increment_covariance(encoders.last_tick_deltas)
    >>> cov.shape, int(np.linalg.matrix_rank(cov))  # two wheels drive three coordinates
    ((3, 3), 2)
    """

    def __init__(self, spec: UGVSpec, rng: np.random.Generator, *, noise_free: bool = False):
        if not isinstance(rng, np.random.Generator):
            raise TypeError(
                "WheelEncoders: rng must be a numpy.random.Generator "
                "(np.random.default_rng(seed)), not the legacy global state"
            )
        self.spec = spec
        self.rng = rng
        self.noise_free = bool(noise_free)
        self._ticks_per_radian = spec.encoder_ticks_per_rev / (2.0 * np.pi)
        self._metres_per_tick = spec.metres_per_tick
        self._quantisation_variance = self._metres_per_tick**2 / 6.0
        # Counts as Python ints: the per-tick path does its arithmetic on floats and ints.
        self._ticks: tuple[int, int] | None = None
        self._last_deltas = (0, 0)
        self.last_tick_deltas = np.zeros(2, dtype=np.int64)

    @property
    def slip_sigma(self) -> float:
        """Return the relative slip sigma in use (0 when ``noise_free``)."""
        return 0.0 if self.noise_free else self.spec.encoder_slip_sigma

    def ticks(self, wheel_angles: ArrayLike) -> np.ndarray:
        """Return the encoder counts ``floor(angle * N / 2 pi)`` for wheel angles in rad.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> WheelEncoders(PIONEER3DX, np.random.default_rng(0)).ticks([2 * np.pi, -1e-9])
        array([19150,    -1])
        """
        return np.array(self._count(wheel_angles), dtype=np.int64)

    def _count(self, wheel_angles: ArrayLike) -> tuple[int, int]:
        """Return ``ticks`` as two Python ints (math.floor rounds exactly as numpy.floor)."""
        angles = np.asarray(wheel_angles, dtype=float).reshape(-1)
        left, right = angles.tolist() if angles.shape == (2,) else (math.nan, math.nan)
        if not (math.isfinite(left) and math.isfinite(right)):
            raise ValueError(
                f"WheelEncoders: wheel_angles must be finite (left, right) in rad, got {angles}"
            )
        per_radian = self._ticks_per_radian
        return math.floor(left * per_radian), math.floor(right * per_radian)

    def reset(self, wheel_angles: ArrayLike) -> None:
        """Start counting from the current wheel angles (call once before driving).

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0))
        >>> encoders.reset([12.0, -3.0])  # e.g. after a lap, wherever the wheels stand
        >>> encoders.odometry_increment([12.0, -3.0])
        array([0., 0., 0.])
        """
        self._ticks = self._count(wheel_angles)
        self._last_deltas = (0, 0)
        self.last_tick_deltas = np.zeros(2, dtype=np.int64)

    def odometry_increment(self, wheel_angles: ArrayLike) -> np.ndarray:
        """Read the encoders and return the increment ``(dx, dy, dtheta)`` since the last read.

        The increment is expressed in the robot frame at the previous reading: the
        pose update is ``pose_k = compose(pose_{k-1}, increment)``.

        Parameters
        ----------
        wheel_angles
            Current ``(left, right)`` wheel joint angles in rad (``SimUGV.wheel_angles()``).

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0))
        >>> encoders.reset([0.0, 0.0])
        >>> dx, dy, dtheta = encoders.odometry_increment([-1.0, 1.0])  # turn on the spot
        >>> round(float(dtheta), 3), abs(round(float(dx), 6))
        (0.591, 0.0)
        """
        ticks = self._count(wheel_angles)
        if self._ticks is None:
            raise RuntimeError(
                "WheelEncoders: call reset(wheel_angles) before the first odometry_increment"
            )
        left_ticks, right_ticks = ticks[0] - self._ticks[0], ticks[1] - self._ticks[1]
        self._ticks = ticks
        self._last_deltas = (left_ticks, right_ticks)
        self.last_tick_deltas = np.array(self._last_deltas, dtype=np.int64)
        left = left_ticks * self._metres_per_tick
        right = right_ticks * self._metres_per_tick
        sigma = self.slip_sigma
        if sigma > 0.0:
            # Always draw two normals so the random stream does not depend on motion.
            left_noise, right_noise = self.rng.standard_normal(2).tolist()
            left = left + sigma * math.sqrt(abs(left)) * left_noise
            right = right + sigma * math.sqrt(abs(right)) * right_noise
        return np.array(_arc_increment(left, right, self.spec.wheel_separation))

    def increment_covariance(self, tick_deltas: ArrayLike) -> np.ndarray:
        """Return the ``3 x 3`` covariance of the increment measured from ``tick_deltas``.

        This is the EKF's process noise for one prediction with that increment,
        consistent with the noise ``odometry_increment`` draws. It is symmetric positive
        semi-definite of rank 2 (two independent wheel errors drive three coordinates);
        the EKF's prior keeps its own covariance positive definite.

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0))
        >>> cov = encoders.increment_covariance([31260, 31260])  # about 1 m straight
        >>> float(np.sqrt(cov[0, 0])).__round__(6)  # ~ sigma * sqrt(1 m) / sqrt(2)
        0.000354
        """
        left_ticks, right_ticks = np.asarray(tick_deltas).tolist()
        return self._covariance(left_ticks, right_ticks)

    def read(self, wheel_angles: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Return :meth:`odometry_increment` and the :meth:`increment_covariance` of its ticks.

        What the EKF's prediction takes, in one call (the closed loop's per-tick path).

        Examples
        --------
        >>> from robots.presets import PIONEER3DX
        >>> encoders = WheelEncoders(PIONEER3DX, np.random.default_rng(0), noise_free=True)
        >>> encoders.reset([0.0, 0.0])
        >>> increment, covariance = encoders.read([1.0, 1.0])
        >>> increment.round(4), covariance.shape
        (array([0.0975, 0.    , 0.    ]), (3, 3))
        """
        increment = self.odometry_increment(wheel_angles)
        return increment, self._covariance(*self._last_deltas)

    def _covariance(self, left_ticks: int, right_ticks: int) -> np.ndarray:
        """Return :meth:`increment_covariance` for tick counts given as two numbers."""
        left = left_ticks * self._metres_per_tick
        right = right_ticks * self._metres_per_tick
        jacobian = arc_increment_jacobian(left, right, self.spec.wheel_separation)
        # Per wheel: slip * |travel| + quantisation (the module docstring's model).
        slip = self.slip_sigma**2
        quantisation = self._quantisation_variance
        variances = np.array([slip * abs(left) + quantisation, slip * abs(right) + quantisation])
        # numpy's (BLAS) product, not a Python sum of products: they round differently.
        return (jacobian * variances) @ jacobian.T
