"""Numbers from a run: Table 1, localization and EKF corrections.

Detection against ground truth is scored during the run (:mod:`scenarios.bench.ground_truth`).

Pure functions on arrays and small dicts, so each one is tested on hand-made input.

Examples
--------
>>> table1_cm({"a/0": [0.02, 0.04], "a/1": [0.01, 0.01, 0.01]}, min_samples=2)
{'mean': {'avg': 2.0, 'min': 1.0, 'max': 3.0}, 'std': {'avg': 0.5, 'min': 0.0, 'max': 1.0}, \
'polylines': 2}
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import wrap_angle

__all__ = [
    "MIN_TABLE1_SAMPLES",
    "ekf_correction_metrics",
    "localization_metrics",
    "table1_cm",
]

MIN_TABLE1_SAMPLES = 5
"""Reference polylines associated fewer times than this are left out of Table 1."""

def table1_cm(
    distances: Mapping[str, Sequence[float]], min_samples: int = MIN_TABLE1_SAMPLES
) -> dict:
    """Return the paper's Table 1 (cm) from each reference polyline's distances (m).

    For each reference polyline with at least ``min_samples`` associations: the mean and
    standard deviation of its restricted Hausdorff distances; then the average, minimum
    and maximum of those means and of those deviations.
    """
    means, stds = [], []
    for values in distances.values():
        values = np.asarray(values, dtype=float)
        if len(values) >= min_samples:
            means.append(values.mean() * 100.0)
            stds.append(values.std() * 100.0)

    def summary(numbers: list[float]) -> dict:
        if not numbers:
            return {"avg": None, "min": None, "max": None}
        return {
            "avg": round(float(np.mean(numbers)), 4),
            "min": round(float(np.min(numbers)), 4),
            "max": round(float(np.max(numbers)), 4),
        }

    return {"mean": summary(means), "std": summary(stds), "polylines": len(means)}


def localization_metrics(
    true_poses: ArrayLike, estimated_poses: ArrayLike, covariances: ArrayLike
) -> dict:
    """Return RMSE of position and heading, the largest position sigma and the mean NEES.

    Examples
    --------
    >>> truth = np.zeros((2, 3))
    >>> estimate = np.array([[0.03, 0.04, 0.0], [0.0, 0.0, 0.01]])
    >>> cov = np.array([np.diag([1e-3, 1e-3, 1e-4])] * 2)
    >>> localization_metrics(truth, estimate, cov)
    {'rmse_xy_m': 0.035355, 'rmse_theta_rad': 0.007071, 'max_sigma_xy_m': 0.031623, \
'nees_mean': 1.75}
    """
    truth = np.asarray(true_poses, dtype=float).reshape(-1, 3)
    estimate = np.asarray(estimated_poses, dtype=float).reshape(-1, 3)
    cov = np.asarray(covariances, dtype=float).reshape(-1, 3, 3)
    if len(truth) == 0:
        return {"rmse_xy_m": None, "rmse_theta_rad": None, "max_sigma_xy_m": None,
                "nees_mean": None}
    error = estimate - truth
    error[:, 2] = wrap_angle(error[:, 2])
    nees = np.einsum("ni,nij,nj->n", error, np.linalg.inv(cov), error)
    sigma_xy = np.sqrt(np.linalg.eigvalsh(cov[:, :2, :2]).max(axis=1))
    return {
        "rmse_xy_m": round(float(np.sqrt((error[:, :2] ** 2).sum(axis=1).mean())), 6),
        "rmse_theta_rad": round(float(np.sqrt((error[:, 2] ** 2).mean())), 6),
        "max_sigma_xy_m": round(float(sigma_xy.max()), 6),
        "nees_mean": round(float(nees.mean()), 4),
    }


def ekf_correction_metrics(
    corrections: ArrayLike, sigmas: ArrayLike, reinitialized: ArrayLike | None = None
) -> dict:
    """Return the EKF corrections' RMS and their shares within 1 and 3 sigma (paper Fig. 5).

    A re-localisation (the filter re-initialised from triangulation at a lap start, when
    the robot was carried back) is no correction: its jump of metres is left out
    (``reinitialized`` marks those updates). RMS in m, m, rad per state ``(x, y, theta)``.

    Examples
    --------
    >>> corrections = np.array([[0.001, 0.0, 0.0], [3.0, 1.0, 0.5], [-0.001, 0.002, 0.001]])
    >>> sigmas = np.full((3, 3), 0.0015)
    >>> stats = ekf_correction_metrics(corrections, sigmas, [False, True, False])
    >>> stats["updates"], stats["relocalizations"], stats["rms"]
    (2, 1, [0.001, 0.001414214, 0.000707107])
    >>> stats["within_1_sigma"], stats["within_3_sigma"]
    ([1.0, 0.5, 1.0], [1.0, 1.0, 1.0])
    """
    corrections = np.asarray(corrections, dtype=float).reshape(-1, 3)
    sigmas = np.asarray(sigmas, dtype=float).reshape(-1, 3)
    if reinitialized is None:
        restarts = np.zeros(len(corrections), dtype=bool)
    else:
        restarts = np.asarray(reinitialized, dtype=bool).reshape(-1)
    kept = ~restarts
    size = np.abs(corrections[kept])
    sigma = sigmas[kept]
    if len(size) == 0:
        empty = [None, None, None]
        return {"updates": 0, "relocalizations": int(restarts.sum()), "rms": empty,
                "within_1_sigma": empty, "within_3_sigma": empty}
    return {
        "updates": int(kept.sum()),
        "relocalizations": int(restarts.sum()),
        "rms": [round(float(v), 9) for v in np.sqrt(np.mean(size**2, axis=0))],
        "within_1_sigma": [round(float(v), 4) for v in np.mean(size <= sigma, axis=0)],
        "within_3_sigma": [round(float(v), 4) for v in np.mean(size <= 3.0 * sigma, axis=0)],
    }
