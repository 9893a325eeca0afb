"""Wheel odometry on numpy arrays, as first written: the reference for the float fast path.

``sim.encoders.WheelEncoders`` reads the encoders and propagates the increment covariance
on Python floats (it runs at the control rate). ``ReferenceEncoders`` keeps the original
array code (``numpy.floor`` counts, array travel and slip noise, ``numpy.column_stack``
Jacobian). Tests require both to return the same increments and covariances bit for bit
from the same random stream; ``benchmarks/test_bench_navigation.py`` times both.
"""

from __future__ import annotations

import numpy as np

from sim.encoders import WheelEncoders

_SMALL_HALF_TURN = 1e-4


def _sinc_and_derivative(a: float) -> tuple[float, float]:
    a = float(a)
    if abs(a) < _SMALL_HALF_TURN:
        a2 = a * a
        return 1.0 - a2 / 6.0 + a2 * a2 / 120.0, -a / 3.0 + a * a2 / 30.0
    s, c = np.sin(a), np.cos(a)
    return float(s / a), float((a * c - s) / (a * a))


def reference_arc_increment(left, right, track) -> np.ndarray:
    """Return ``arc_increment`` as first written (numpy scalars)."""
    distance = 0.5 * (left + right)
    dtheta = (right - left) / track
    half = 0.5 * dtheta
    sinc, _ = _sinc_and_derivative(half)
    chord = distance * sinc
    return np.array([chord * np.cos(half), chord * np.sin(half), dtheta])


def reference_arc_increment_jacobian(left, right, track) -> np.ndarray:
    """Return ``arc_increment_jacobian`` as first written (numpy arrays)."""
    distance = 0.5 * (left + right)
    half = 0.5 * (right - left) / track
    sinc, dsinc = _sinc_and_derivative(half)
    cos_h, sin_h = np.cos(half), np.sin(half)
    d_dx = np.array([sinc * cos_h, distance * (dsinc * cos_h - sinc * sin_h), 0.0])
    d_dy = np.array([sinc * sin_h, distance * (dsinc * sin_h + sinc * cos_h), 0.0])
    wrt_mean = np.array([d_dx[0], d_dy[0], 0.0])
    wrt_half = np.array([d_dx[1], d_dy[1], 2.0])
    half_rate = 0.5 / track
    return np.column_stack(
        [0.5 * wrt_mean - half_rate * wrt_half, 0.5 * wrt_mean + half_rate * wrt_half]
    )


class ReferenceEncoders(WheelEncoders):
    """``WheelEncoders`` whose readings and covariances run the original array code."""

    def _array_ticks(self, wheel_angles) -> np.ndarray:
        angles = np.asarray(wheel_angles, dtype=float).reshape(-1)
        return np.floor(angles * self._ticks_per_radian).astype(np.int64)

    def reset(self, wheel_angles) -> None:
        """Start counting from the current wheel angles."""
        self._ticks = self._array_ticks(wheel_angles)
        self.last_tick_deltas = np.zeros(2, dtype=np.int64)

    def odometry_increment(self, wheel_angles) -> np.ndarray:
        """Return the increment since the last read: the original array code."""
        ticks = self._array_ticks(wheel_angles)
        deltas = ticks - self._ticks
        self._ticks = ticks
        self.last_tick_deltas = deltas
        travel = self.wheel_travel(deltas)
        sigma = self.slip_sigma
        if sigma > 0.0:
            travel = travel + sigma * np.sqrt(np.abs(travel)) * self.rng.standard_normal(2)
        return reference_arc_increment(travel[0], travel[1], self.spec.wheel_separation)

    def increment_covariance(self, tick_deltas) -> np.ndarray:
        """Return the increment covariance: the original array code."""
        travel = self.wheel_travel(tick_deltas)
        jacobian = reference_arc_increment_jacobian(
            travel[0], travel[1], self.spec.wheel_separation
        )
        variances = self.wheel_variances(tick_deltas)
        return (jacobian * variances) @ jacobian.T
