"""Descriptive statistics of a campaign: per scenario and policy, each metric's spread.

A campaign's rows (one per run, metrics flattened with dots) are grouped by
``(scenario, policy)``; only runs whose ``status`` is ``"ok"`` count. Every figure is a
plain float or ``None`` (never NaN), ready for JSON; confidence intervals of the mean are
bootstrapped (BCa) from the ``numpy.random.Generator`` passed in, nothing else is random.

Examples
--------
>>> rows = [{"run": f"r{seed}", "scenario": "sim1", "policy": "adaptive", "seed": seed,
...          "status": "ok", "detection.f1": value}
...         for seed, value in enumerate([0.9, 1.0, 0.8])]
>>> metric_columns(rows)
['detection.f1']
>>> stats = group_statistics(rows, np.random.default_rng(0))
>>> f1 = stats["groups"][0]["metrics"]["detection.f1"]
>>> f1["mean"], f1["std"], f1["worst"]
(0.9, 0.1, 0.8)
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from numbers import Real
from typing import Any

import numpy as np
from scipy.stats import DegenerateDataWarning, bootstrap

from scenarios.campaign.table import IDENTITY_COLUMNS
from scenarios.campaign.tolerances import Tolerances, default_tolerances

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "CONFIDENCE",
    "STATUSES",
    "VARY_PREFIX",
    "bootstrap_ci",
    "bootstrap_difference_ci",
    "finite_values",
    "group_rows",
    "group_statistics",
    "metric_columns",
    "status_counts",
]

VARY_PREFIX = "vary."
"""Prefix of the columns holding a run's sampled variation values."""

STATUSES = ("ok", "rejected", "error")
"""Run statuses; only ``"ok"`` runs have metrics."""

CONFIDENCE = 0.95
"""Confidence level of every interval."""

BOOTSTRAP_RESAMPLES = 9999
"""Bootstrap resamples per interval (scipy's default): from one generator to another the
ends of a 12-run interval move by about 1 % of its width."""

Interval = tuple[float, float]


def _is_number(value: Any) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool | np.bool_)


def _finite(values: Iterable[Any]) -> np.ndarray:
    array = np.array([float(value) for value in values if _is_number(value)], dtype=float)
    return array[np.isfinite(array)]


def metric_columns(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """Return the numeric metric columns of ``rows`` in first-seen order.

    Identity columns and ``vary.*`` columns are not metrics; a column is numeric when
    every value is a number or missing (``None``, NaN) and at least one is a number.

    Examples
    --------
    >>> metric_columns([{"seed": 0, "vary.gate": 0.1, "safety.stops": None, "note": "x"},
    ...                 {"seed": 1, "safety.stops": 2, "detection.f1": 1.0}])
    ['safety.stops', 'detection.f1']
    """
    numeric: dict[str, bool | None] = {}  # None: only missing values so far
    for row in rows:
        for name, value in row.items():
            if name in IDENTITY_COLUMNS or name.startswith(VARY_PREFIX):
                continue
            if value is None:
                numeric.setdefault(name, None)
            elif numeric.get(name) is not False:
                numeric[name] = _is_number(value)
    return [name for name, is_numeric in numeric.items() if is_numeric]


def finite_values(rows: Iterable[Mapping[str, Any]], metric: str) -> np.ndarray:
    """Return the finite numbers of column ``metric`` in ``rows`` (missing, NaN, inf dropped).

    Examples
    --------
    >>> finite_values([{"a": 1}, {"a": None}, {"a": float("nan")}, {}, {"a": 2.5}], "a")
    array([1. , 2.5])
    """
    return _finite(row.get(metric) for row in rows)


def group_rows(rows: Iterable[Mapping[str, Any]]) -> dict[tuple[str, str], list[Mapping[str, Any]]]:
    """Return the rows (every status) by ``(scenario, policy)``, groups in first-seen order.

    Examples
    --------
    >>> list(group_rows([{"scenario": "a", "policy": "p"}, {"scenario": "b", "policy": "p"},
    ...                  {"scenario": "a", "policy": "p"}]))
    [('a', 'p'), ('b', 'p')]
    """
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault((str(row["scenario"]), str(row["policy"])), []).append(row)
    return groups


def status_counts(rows: Iterable[Mapping[str, Any]]) -> dict[str, int]:
    """Return how many of ``rows`` have each status (every one of :data:`STATUSES` listed).

    Examples
    --------
    >>> status_counts([{"status": "ok"}, {"status": "error"}, {"status": "ok"}])
    {'ok': 2, 'rejected': 0, 'error': 1}
    """
    counts = dict.fromkeys(STATUSES, 0)
    for row in rows:
        counts[str(row["status"])] = counts.get(str(row["status"]), 0) + 1
    return counts


def _interval(
    samples: tuple[np.ndarray, ...],
    statistic: Callable[..., Any],
    rng: np.random.Generator,
    confidence: float,
    n_resamples: int,
) -> Interval | None:
    options = {"vectorized": True, "confidence_level": confidence, "rng": rng}
    # BCa needs the jackknife's acceleration and the bias correction; skewed or huge
    # data make them infinite and scipy returns NaN with a warning: the percentile
    # interval of the same resamples is then the honest fallback.
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", DegenerateDataWarning)
        result = bootstrap(samples, statistic, n_resamples=n_resamples, method="BCa", **options)
        if not np.all(np.isfinite(result.confidence_interval)):
            result = bootstrap(samples, statistic, n_resamples=0, method="percentile",
                               bootstrap_result=result, **options)
    low, high = (float(end) for end in result.confidence_interval)
    return (low, high) if math.isfinite(low) and math.isfinite(high) else None


def bootstrap_ci(
    values: Iterable[float | None],
    rng: np.random.Generator,
    *,
    confidence: float = CONFIDENCE,
    n_resamples: int = BOOTSTRAP_RESAMPLES,
) -> Interval | None:
    """Return a bootstrap confidence interval of the mean of ``values`` (BCa), or None.

    Missing and non-finite values are dropped first; fewer than 2 left give ``None``,
    constant values ``(v, v)``. When BCa degenerates the percentile interval is returned.

    Examples
    --------
    >>> bootstrap_ci([2.0, 2.0, None], np.random.default_rng(0))
    (2.0, 2.0)
    >>> bootstrap_ci([1.0, float("nan")], np.random.default_rng(0)) is None
    True
    >>> low, high = bootstrap_ci([1.0, 2.0, 3.0, 4.0], np.random.default_rng(0))
    >>> 1.0 <= low < 2.5 < high <= 4.0
    True
    """
    sample = _finite(values)
    if sample.size < 2:
        return None
    if np.all(sample == sample[0]):
        return (float(sample[0]), float(sample[0]))
    return _interval((sample,), np.mean, rng, confidence, n_resamples)


def _difference_of_means(candidate: np.ndarray, baseline: np.ndarray, axis: int = -1) -> Any:
    return np.mean(candidate, axis=axis) - np.mean(baseline, axis=axis)


def bootstrap_difference_ci(
    baseline: Iterable[float | None],
    candidate: Iterable[float | None],
    rng: np.random.Generator,
    *,
    confidence: float = CONFIDENCE,
    n_resamples: int = BOOTSTRAP_RESAMPLES,
) -> Interval | None:
    """Return a bootstrap interval of ``mean(candidate) - mean(baseline)``, unpaired samples.

    Each side is resampled on its own (BCa, percentile when BCa degenerates). Missing
    and non-finite values are dropped; fewer than 2 on a side give ``None``.

    Examples
    --------
    >>> bootstrap_difference_ci([1.0, 1.0], [3.0, 3.0, 3.0], np.random.default_rng(0))
    (2.0, 2.0)
    >>> low, high = bootstrap_difference_ci([0.0, 1.0, 2.0], [10.0, 11.0, 12.0],
    ...                                     np.random.default_rng(0))
    >>> 8.0 <= low < 10.0 < high <= 12.0
    True
    """
    before, after = _finite(baseline), _finite(candidate)
    if before.size < 2 or after.size < 2:
        return None
    if np.all(before == before[0]) and np.all(after == after[0]):
        difference = float(after[0] - before[0])
        return (difference, difference)
    return _interval((after, before), _difference_of_means, rng, confidence, n_resamples)


def _summary(
    values: np.ndarray, rng: np.random.Generator, worst: Callable[[Iterable[float]], float] | None,
    n_resamples: int,
) -> dict[str, Any]:
    if values.size == 0:
        return {"n": 0, "mean": None, "std": None, "ci95": None, "min": None, "max": None,
                "worst": None}
    interval = bootstrap_ci(values, rng, n_resamples=n_resamples)
    return {
        "n": int(values.size),
        "mean": float(np.mean(values)),
        "std": float(np.std(values, ddof=1)) if values.size >= 2 else None,
        "ci95": list(interval) if interval is not None else None,
        "min": float(np.min(values)),
        "max": float(np.max(values)),
        "worst": float(worst(values.tolist())) if worst is not None else None,
    }


def group_statistics(
    rows: Sequence[Mapping[str, Any]],
    rng: np.random.Generator,
    metrics: Sequence[str] | None = None,
    *,
    tolerances: Tolerances | None = None,
    n_resamples: int = BOOTSTRAP_RESAMPLES,
) -> dict[str, Any]:
    """Return each metric's statistics per ``(scenario, policy)`` group, ready for JSON.

    Parameters
    ----------
    rows
        One mapping per run (``pyarrow.Table.to_pylist()`` of ``runs.parquet``).
    rng
        Source of the bootstrap resamples; each (group, metric) interval draws from its
        own generator spawned from it, so one interval's resampling leaves the others be.
    metrics
        Metric columns to describe (default :func:`metric_columns` of ``rows``).
    tolerances
        Which way each metric is better, for ``worst`` (default the bundled file); a
        metric it does not list has ``worst`` None.
    n_resamples
        Bootstrap resamples per interval.

    Returns
    -------
    dict
        ``{"metrics": [names], "groups": [{"scenario", "policy", "runs": {status:
        count}, "metrics": {name: {"n", "mean", "std", "ci95", "min", "max",
        "worst"}}}]}``; ``std`` (ddof 1) is None below 2 values, ``ci95`` is ``[low,
        high]`` or None, and a metric no ok run measured has ``n`` 0 and None elsewhere.

    Examples
    --------
    >>> rows = [{"scenario": "s", "policy": "p", "status": "ok", "safety.stops": 1},
    ...         {"scenario": "s", "policy": "p", "status": "error", "safety.stops": None}]
    >>> group = group_statistics(rows, np.random.default_rng(0))["groups"][0]
    >>> group["runs"], group["metrics"]["safety.stops"]["std"]
    ({'ok': 1, 'rejected': 0, 'error': 1}, None)
    """
    names = list(metrics) if metrics is not None else metric_columns(rows)
    judged = (tolerances if tolerances is not None else default_tolerances()).metrics
    groups = group_rows(rows)
    streams = iter(rng.spawn(len(groups) * len(names)))
    described = []
    for (scenario, policy), members in groups.items():
        ok = [row for row in members if row["status"] == "ok"]
        described.append({
            "scenario": scenario,
            "policy": policy,
            "runs": status_counts(members),
            "metrics": {
                name: _summary(finite_values(ok, name), next(streams),
                               judged[name].worst if name in judged else None, n_resamples)
                for name in names
            },
        })
    return {"metrics": names, "groups": described}
