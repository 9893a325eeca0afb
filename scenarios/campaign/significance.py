"""The tests of a comparison: Wilcoxon signed-rank for pairs, Mann-Whitney U otherwise.

Both give two-sided p-values of candidate against baseline, with a bootstrap interval of
the difference of means (:mod:`scenarios.campaign.stats`).

Examples
--------
>>> signed_rank_p(np.ones(10))  # ten pairs, all better: 2 / 2**10
0.001953125
>>> difference, interval, p = difference_test(np.zeros(3), np.zeros(3), False,
...                                           np.random.default_rng(0), 999)
>>> difference, interval, p
(0.0, (0.0, 0.0), 1.0)
"""

from __future__ import annotations

import numpy as np
from scipy.stats import mannwhitneyu, permutation_test, rankdata, wilcoxon

from scenarios.campaign.stats import bootstrap_ci, bootstrap_difference_ci

__all__ = ["EXACT_SIGN_FLIPS", "difference_test", "signed_rank_p"]

EXACT_SIGN_FLIPS = 13
"""Pairs up to which ``scipy.stats.wilcoxon`` enumerates all 2^n sign flips on ties or zeros."""


def signed_rank_p(differences: np.ndarray) -> float:
    """Return the two-sided p of the Wilcoxon signed-rank test, as ``scipy.stats.wilcoxon``."""
    nonzero = differences != 0
    if not np.any(nonzero):
        return 1.0
    magnitudes = np.abs(differences[nonzero])
    tied = np.unique(magnitudes).size < magnitudes.size
    if differences.size > EXACT_SIGN_FLIPS or not (tied or magnitudes.size < differences.size):
        return float(wilcoxon(differences).pvalue)
    # With ties or zeros in a small sample scipy enumerates every sign flip, one at a time
    # (seconds for 12 pairs). Flips leave the ranks of |d| as they are, so the statistic
    # (sum of the ranks of the positive differences) of all 2^n flips is one array sum.
    ranks = np.zeros(differences.size)
    ranks[nonzero] = rankdata(magnitudes)
    return float(permutation_test(
        (differences,), lambda flipped, axis: np.sum((flipped > 0) * ranks, axis=axis),
        permutation_type="samples", vectorized=True, n_resamples=np.inf,
    ).pvalue)


def difference_test(
    before: np.ndarray, after: np.ndarray, paired: bool, rng: np.random.Generator,
    n_resamples: int,
) -> tuple[float, tuple[float, float] | None, float]:
    """Return (difference of means, its interval, two-sided p) of candidate - baseline."""
    if paired:
        differences = after - before
        return (float(np.mean(differences)),
                bootstrap_ci(differences, rng, n_resamples=n_resamples),
                signed_rank_p(differences))
    values = np.concatenate([before, after])
    p = 1.0 if np.all(values == values[0]) else float(mannwhitneyu(after, before).pvalue)
    return (float(np.mean(after) - np.mean(before)),
            bootstrap_difference_ci(before, after, rng, n_resamples=n_resamples), p)
