"""Tolerance files of ``semistatic compare``: which way each metric is better, and by how much.

A tolerance file names the metrics a comparison judges; a metric it leaves out is not
judged (machine timings, say, which differ between identical runs)::

    format = 1
    alpha = 0.05            # optional: significance level of the whole comparison
    [metrics."table1_cm.mean.avg"]
    better = "lower"        # "lower" | "higher"
    min_change = 0.2        # smallest difference that matters, in the metric's unit

Examples
--------
>>> tolerances = default_tolerances()
>>> tolerances.alpha, tolerances.metrics["detection.f1"].better
(0.05, 'higher')
>>> Tolerance("detection.f1", "up", 0.02)
Traceback (most recent call last):
...
semistatic.errors.SpecError: <memory>: better: must be 'lower' or 'higher', got 'up'
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from semistatic.errors import MEMORY, SpecError, join_key
from semistatic.validation import (
    Range,
    as_float,
    as_int,
    as_table,
    bounds,
    check_fields,
    from_table,
    read_toml,
    reject_unknown_keys,
)

__all__ = [
    "DEFAULT_ALPHA",
    "DEFAULT_TOLERANCES",
    "TOLERANCE_FORMAT",
    "Tolerance",
    "Tolerances",
    "default_tolerances",
    "read_tolerances",
]

TOLERANCE_FORMAT = 1
"""The ``format`` a tolerance file must declare (the version of this layout)."""

DEFAULT_ALPHA = 0.05
"""Significance level of a whole comparison when the file gives no ``alpha``."""

ALPHA_RANGE = Range(gt=0.0, le=0.5, fix="a probability, e.g. 0.05")
"""An ``alpha`` above 0.5 would call a coin toss significant."""

DEFAULT_TOLERANCES = Path(__file__).with_name("tolerances.toml")
"""The bundled tolerance file, used when ``--tolerance`` is not given."""

BETTER = ("lower", "higher")


@dataclass(frozen=True)
class Tolerance:
    """How one metric is judged: which way is better, and the smallest change that matters.

    Parameters
    ----------
    metric
        The metric column, e.g. ``"table1_cm.mean.avg"``.
    better
        ``"lower"`` or ``"higher"``.
    min_change
        Smallest difference of means that matters, in the metric's unit (>= 0); a
        significant difference smaller than this is no change.

    Examples
    --------
    >>> Tolerance("safety.min_ttc_s", "higher", 0.2).is_worse(-0.5)
    True
    >>> Tolerance("safety.min_ttc_s", "higher", -1.0)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: min_change: must be >= 0.0, got -1.0 \
(in the metric's unit, e.g. 0.5)
    """

    metric: str
    better: str
    min_change: float = field(metadata=bounds(ge=0.0, fix="in the metric's unit, e.g. 0.5"))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.better not in BETTER:
            raise SpecError(MEMORY, "better",
                            f"must be 'lower' or 'higher', got {self.better!r}")

    def is_worse(self, difference: float) -> bool:
        """Return whether ``difference`` (candidate minus baseline) points the bad way.

        Examples
        --------
        >>> Tolerance("safety.collisions", "lower", 0.0).is_worse(1.0)
        True
        """
        return difference > 0 if self.better == "lower" else difference < 0

    def is_better(self, difference: float) -> bool:
        """Return whether ``difference`` (candidate minus baseline) points the good way.

        Examples
        --------
        >>> Tolerance("safety.collisions", "lower", 0.0).is_better(0.0)
        False
        """
        return difference < 0 if self.better == "lower" else difference > 0

    def worst(self, values: Iterable[float]) -> float:
        """Return the worst of ``values``: the largest when lower is better, else the smallest.

        Examples
        --------
        >>> Tolerance("detection.f1", "higher", 0.02).worst([0.9, 0.7, 1.0])
        0.7
        """
        return max(values) if self.better == "lower" else min(values)


@dataclass(frozen=True)
class Tolerances:
    """The judged metrics of a comparison and its significance level.

    Examples
    --------
    >>> Tolerances(0.05, {"detection.f1": Tolerance("detection.f1", "higher", 0.02)}).alpha
    0.05
    >>> Tolerances(0.7, {})
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: alpha: must be > 0.0 and <= 0.5, got 0.7 \
(a probability, e.g. 0.05)
    """

    alpha: float
    metrics: dict[str, Tolerance]

    def __post_init__(self) -> None:
        as_float(self.alpha, file=MEMORY, key="alpha", valid=ALPHA_RANGE)
        for name, tolerance in self.metrics.items():
            if tolerance.metric != name:
                raise SpecError(MEMORY, join_key("metrics", name),
                                f"holds the tolerance of {tolerance.metric!r}")


def _quoted(name: str) -> str:
    # Metric names hold dots, so a file writes them as quoted keys: metrics."a.b".
    return f'metrics."{name}"'


def read_tolerances(path: str | Path) -> Tolerances:
    """Read a tolerance file; every problem is a :class:`SpecError` naming the file and key.

    Examples
    --------
    >>> import tempfile
    >>> folder = tempfile.TemporaryDirectory()
    >>> path = Path(folder.name) / "tolerances.toml"
    >>> _ = path.write_text('''format = 1
    ... [metrics."detection.f1"]
    ... better = "higher"
    ... min_chang = 0.02
    ... ''')
    >>> read_tolerances(path)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: .../tolerances.toml: metrics."detection.f1".min_chang: \
unknown key (did you mean 'min_change'?); allowed keys: better, min_change
    >>> folder.cleanup()
    """
    file = str(path)
    table = read_toml(path)
    reject_unknown_keys(table, ("format", "alpha", "metrics"), file=file, key="")
    if "format" not in table:
        raise SpecError(file, "format", f"missing required key; add `format = {TOLERANCE_FORMAT}`")
    version = as_int(table["format"], file=file, key="format")
    if version != TOLERANCE_FORMAT:
        raise SpecError(file, "format", f"unsupported format {version}; this semistatic "
                                        f"reads format {TOLERANCE_FORMAT}")
    alpha = as_float(table.get("alpha", DEFAULT_ALPHA), file=file, key="alpha",
                     valid=ALPHA_RANGE)
    metrics = as_table(table.get("metrics", {}), file=file, key="metrics")
    if not metrics:
        raise SpecError(file, "metrics", 'no metric to judge; add [metrics."NAME"] tables '
                                         "with better and min_change")
    tolerances = {
        name: from_table(Tolerance, entry, file=file, key=_quoted(name), fixed={"metric": name})
        for name, entry in metrics.items()
    }
    return Tolerances(alpha, tolerances)


def default_tolerances() -> Tolerances:
    """Read the bundled tolerance file (:data:`DEFAULT_TOLERANCES`).

    Examples
    --------
    >>> default_tolerances().metrics["localization.rmse_xy_m"].min_change
    0.005
    """
    return read_tolerances(DEFAULT_TOLERANCES)
