"""The metric columns of a sweep: where each sits in ``metrics.json`` and which way is better.

Examples
--------
>>> METRICS["f1"].path, METRICS["f1"].better
(('detection', 'f1'), 'high')
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "DEFAULT_SORT",
    "METRICS",
    "NEES_TARGET",
    "TIMING_COLUMNS",
    "SweepMetric",
    "metric_value",
]

NEES_TARGET = 3.0
"""Mean NEES of a consistent 3-state (x, y, theta) filter: the best NEES is the closest."""


@dataclass(frozen=True)
class SweepMetric:
    """One column of the sweep: where it sits in ``metrics.json`` and which way is better.

    Parameters
    ----------
    path
        Keys leading to the value in the metrics of a run.
    better
        ``"low"``, ``"high"`` or ``"nees"`` (closest to :data:`NEES_TARGET`).
    label
        Short heading for tables and figure axes.

    Examples
    --------
    >>> SweepMetric(("detection", "f1"), "high", "F1").better
    'high'
    >>> SweepMetric(("detection", "f1"), "up", "F1")
    Traceback (most recent call last):
    ...
    ValueError: SweepMetric.better must be 'low', 'high' or 'nees' (got 'up')
    """

    path: tuple[str, ...]
    better: str
    label: str

    def __post_init__(self) -> None:
        if self.better not in ("low", "high", "nees"):
            raise ValueError(
                f"SweepMetric.better must be 'low', 'high' or 'nees' (got {self.better!r})"
            )

    def score(self, value: float) -> float:
        """Return ``value`` as a score where lower is better (for sorting).

        Examples
        --------
        >>> METRICS["f1"].score(0.9), METRICS["nees_mean"].score(2.5)
        (-0.9, 0.5)
        """
        if self.better == "high":
            return -value
        if self.better == "nees":
            return abs(value - NEES_TARGET)
        return value


METRICS: dict[str, SweepMetric] = {
    "table1_mean_avg_cm": SweepMetric(("table1_cm", "mean", "avg"), "low", "Table 1 mean avg (cm)"),
    "table1_mean_max_cm": SweepMetric(("table1_cm", "mean", "max"), "low", "Table 1 mean max (cm)"),
    # How many polylines Table 1 compared: a wider gate accepts more (and worse) pairs, so
    # read the Table 1 means of a gate sweep together with this count.
    "table1_polylines": SweepMetric(("table1_cm", "polylines"), "high", "Table 1 polylines"),
    "f1": SweepMetric(("detection", "f1"), "high", "F1"),
    "precision": SweepMetric(("detection", "precision"), "high", "precision"),
    "recall": SweepMetric(("detection", "recall"), "high", "recall"),
    "collisions": SweepMetric(("safety", "collisions"), "low", "collisions"),
    "stops": SweepMetric(("safety", "stops"), "low", "stops"),
    "total_lap_time_s": SweepMetric(("safety", "total_time_s"), "low", "lap time (s)"),
    "laps_completed": SweepMetric(("safety", "laps_completed"), "high", "laps done"),
    "rmse_xy_m": SweepMetric(("localization", "rmse_xy_m"), "low", "RMSE xy (m)"),
    "nees_mean": SweepMetric(("localization", "nees_mean"), "nees", "NEES"),
    "wall_time_s": SweepMetric(("performance", "wall_time_s"), "low", "wall (s)"),
}
"""The metric columns of ``sweep.csv``, in order; any of them can be ``--sort``."""

TIMING_COLUMNS = ("wall_time_s",)
"""Columns that measure the machine, not the run: they differ between identical runs."""

DEFAULT_SORT = "table1_mean_avg_cm"


def _lookup(metrics: Mapping[str, Any] | None, path: Sequence[str]) -> Any:
    value: Any = metrics
    for key in path:
        if not isinstance(value, Mapping):
            return None
        value = value.get(key)
    return value


def metric_value(metrics: Mapping[str, Any] | None, name: str) -> Any:
    """Return metric column ``name`` (a key of :data:`METRICS`) of a run's metrics, or None.

    Examples
    --------
    >>> metric_value({"detection": {"f1": 0.5}}, "f1"), metric_value(None, "f1")
    (0.5, None)
    """
    return _lookup(metrics, METRICS[name].path)


