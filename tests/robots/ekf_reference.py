"""The EKF's predict and update as first written: the reference for the streamlined ones.

``robots.ekf.EKFLocalizer`` predicts and corrects on Python floats, with the landmark
coordinates split once and every observation stacked once per update. ``ReferenceEKF``
keeps the original code (numpy scalars, the public ``range_bearing_model`` and
``mahalanobis_matrix``, a block loop for the noise), which is easier to read against the
module docstring. Tests require the two to give the same state, covariance and history
bit for bit; ``benchmarks/test_bench_localization.py`` times both.
"""

from __future__ import annotations

import math

import numpy as np

from robots.ekf import EKFLocalizer, EKFRecord, _residual
from robots.landmarks import mahalanobis_matrix, pairs_inside_gate, range_bearing_model
from semistatic.frames import wrap_angle

# Jacobian of one (range, bearing) observation with respect to the range bias.
_BIAS_JACOBIAN = np.array([1.0, 0.0])


def _reference_pairs(distances: np.ndarray, gate: float) -> list[tuple[int, int]]:
    """Return ``pairs_inside_gate`` as first written (five numpy reductions)."""
    inside = distances < gate
    if inside.size == 0:
        return []
    columns = inside.argmax(axis=1)
    unique = (inside.sum(axis=1) == 1) & (inside.sum(axis=0)[columns] == 1)
    rows = np.flatnonzero(unique)
    return list(zip(rows.tolist(), columns[rows].tolist(), strict=True))


class ReferenceEKF(EKFLocalizer):
    """An ``EKFLocalizer`` whose predict, update and records run the original code."""

    def predict(self, increment, increment_cov=None) -> None:
        """Compound an odometry increment: ``EKFLocalizer.predict`` as first written."""
        if not self.initialized:
            return
        u = np.asarray(increment, dtype=float).reshape(3)
        sigma_u = (
            self.params.increment_covariance(u)
            if increment_cov is None
            else np.asarray(increment_cov, dtype=float)
        )
        theta = self._filter.x[2, 0]
        c, s = math.cos(theta), math.sin(theta)
        state_jacobian = np.eye(self._dim)
        state_jacobian[0, 2] = -s * u[0] - c * u[1]
        state_jacobian[1, 2] = c * u[0] - s * u[1]
        self._filter.F = state_jacobian
        increment_jacobian = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        pose_noise = increment_jacobian @ sigma_u @ increment_jacobian.T
        if self._has_bias:
            self._filter.Q = np.zeros((4, 4))
            self._filter.Q[:3, :3] = pose_noise
        else:
            self._filter.Q = pose_noise
        self._filter.predict(u)

    def update(self, observations, stamp) -> list[tuple[int, int]]:
        """Correct with landmark observations: ``EKFLocalizer.update`` as first written."""
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
        if lost and len(observations) >= 3:
            pairs = self.relocalize(observations, stamp)
            if pairs:
                return pairs
        if not self.initialized or not observations:
            return []
        prior = self._filter.x[:3, 0].copy()
        predicted, jacobians = range_bearing_model(prior, self.landmarks, self._mount)
        if self._has_bias:
            predicted[:, 0] += self._filter.x[3, 0]
            pose_jacobians = jacobians
            jacobians = np.empty((pose_jacobians.shape[0], 2, 4))
            jacobians[:, :, :3] = pose_jacobians
            jacobians[:, :, 3] = _BIAS_JACOBIAN
        nis = mahalanobis_matrix(observations, predicted, jacobians, self._filter.P)
        pairs = _reference_pairs(nis, self.params.nis_gate)
        assert pairs == pairs_inside_gate(nis, self.params.nis_gate)
        if not pairs:
            return []
        obs_index = [k for k, _ in pairs]
        landmark_index = [m for _, m in pairs]
        measured = np.array(
            [(observations[k].range, observations[k].bearing) for k in obs_index]
        ).reshape(-1, 1)
        expected = predicted[landmark_index].reshape(-1, 1)
        jacobian = jacobians[landmark_index].reshape(-1, self._dim)
        noise = np.zeros((2 * len(pairs), 2 * len(pairs)))
        for row, k in enumerate(obs_index):
            noise[2 * row : 2 * row + 2, 2 * row : 2 * row + 2] = observations[k].covariance
        self._filter.update(
            measured, lambda _x: jacobian, lambda _x: expected, R=noise, residual=_residual
        )
        self._filter.x[2, 0] = wrap_angle(self._filter.x[2, 0])
        self._filter.P = self._repair_covariance(self._filter.P)
        self.last_update_stamp = stamp
        if self.params.record_history:
            self._record(stamp, prior, landmark_index, [nis[k, m] for k, m in pairs], False)
        return pairs

    def _record(self, stamp, prior, landmarks, nis, reinitialized) -> None:
        """Append the correction just applied: ``EKFLocalizer._record`` as first written."""
        posterior = self._filter.x[:3, 0].copy()
        correction = posterior - prior
        correction[2] = wrap_angle(correction[2])
        self.history.append(
            EKFRecord(
                stamp=stamp,
                prior=prior,
                posterior=posterior,
                correction=correction,
                sigma=np.sqrt(np.diag(self._filter.P)[:3]),
                landmarks=tuple(landmarks),
                nis=tuple(float(v) for v in nis),
                reinitialized=reinitialized,
                range_bias=self.range_bias,
                range_bias_sigma=self.range_bias_sigma,
            )
        )
