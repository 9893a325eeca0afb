"""What a falsification minimises and what counts as a violation.

An objective is a metric column of a run (``metrics.json`` flattened with dots, as a
campaign's ``runs.csv`` names it: ``safety.min_separation_m.person``) that the bundled
tolerance file judges, so its better direction is known; the search drives it the *worse*
way. A run violates an objective when its value reaches the threshold: at or below it
where higher is better (a separation of 0 m is contact), at or above it where lower is
better (one collision). Separations, times and counts are never negative, so a negative
threshold can never be reached and is refused.

Examples
--------
>>> objective = parse_objectives(["safety.min_separation_m.person"], [])[0]
>>> objective.direction, objective.threshold, objective.violated(0.0), objective.violated(0.3)
('minimize', 0.0, True, False)
>>> parse_objectives(["safety.collisions"], [])[0].violated(1)
True
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from scenarios.campaign.table import flatten_metrics
from scenarios.campaign.tolerances import default_tolerances
from semistatic.errors import SpecError
from semistatic.validation import did_you_mean

__all__ = [
    "CONTACT_THRESHOLDS",
    "DEFAULT_OBJECTIVE",
    "OBJECTIVE_OPTION",
    "THRESHOLD_OPTION",
    "Objective",
    "objective_metrics",
    "parse_objectives",
]

OBJECTIVE_OPTION = "--objective"
THRESHOLD_OPTION = "--threshold"
DEFAULT_OBJECTIVE = "safety.min_separation_m.person"
"""The separation between a vehicle's footprint and a person's: 0 m is contact."""

CONTACT_THRESHOLDS = {
    "safety.min_separation_m.person": 0.0,
    "safety.min_separation_m.box": 0.0,
    "safety.collisions": 1.0,
}
"""Default thresholds (``--threshold`` unset): contact."""


@dataclass(frozen=True)
class Objective:
    """One searched metric: its column, the worse direction and the violation threshold.

    Examples
    --------
    >>> Objective("safety.min_ttc_s", "higher", 0.5).violated(0.4)
    True
    >>> Objective("safety.min_ttc_s", "higher", -1.0)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --threshold: safety.min_ttc_s: -1.0 can never be reached: \
the metric is >= 0; give a threshold >= 0
    """

    metric: str
    better: str
    threshold: float

    def __post_init__(self) -> None:
        if not math.isfinite(self.threshold):
            raise SpecError(THRESHOLD_OPTION, self.metric, f"{self.threshold} is not a number")
        if self.threshold < 0.0:
            raise SpecError(THRESHOLD_OPTION, self.metric,
                            f"{self.threshold} can never be reached: the metric is >= 0; "
                            "give a threshold >= 0")

    @property
    def direction(self) -> str:
        """Return Optuna's direction: toward the worse values."""
        return "minimize" if self.better == "higher" else "maximize"

    def violated(self, value: float | None) -> bool:
        """Return whether ``value`` reaches the threshold (``None``: no value, no violation)."""
        if value is None:
            return False
        return value <= self.threshold if self.better == "higher" else value >= self.threshold

    def value(self, metrics: Mapping[str, Any] | None) -> float | None:
        """Return the objective's value in a run's metrics (``None`` when absent).

        Examples
        --------
        >>> Objective("safety.collisions", "lower", 1.0).value({"safety": {"collisions": 2}})
        2.0
        """
        if metrics is None:
            return None
        value = flatten_metrics(metrics).get(self.metric)
        return None if value is None or isinstance(value, str) else float(value)


def objective_metrics() -> dict[str, str]:
    """Return the metrics a falsification can search, each with its better direction.

    They are the metrics the bundled tolerance file judges (``semistatic compare``).

    Examples
    --------
    >>> objective_metrics()["safety.min_separation_m.person"]
    'higher'
    """
    return {name: tolerance.better for name, tolerance in default_tolerances().metrics.items()}


def parse_objectives(names: Sequence[str], thresholds: Sequence[float]) -> tuple[Objective, ...]:
    """Return the objectives of ``--objective`` (default the person separation).

    ``thresholds`` are given in the objectives' order, one each; none takes the contact
    thresholds of :data:`CONTACT_THRESHOLDS` (another metric then needs its own).

    Examples
    --------
    >>> parse_objectives(["safety.min_separation_m.persn"], [])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --objective: safety.min_separation_m.persn: not a metric a \
search can judge (did you mean 'safety.min_separation_m.person'?)
    >>> parse_objectives(["safety.min_ttc_s"], [])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --threshold: safety.min_ttc_s: no default threshold: give \
--threshold VALUE (what counts as a violation)
    """
    names = list(names) or [DEFAULT_OBJECTIVE]
    known = objective_metrics()
    for name in names:
        if name not in known:
            raise SpecError(OBJECTIVE_OPTION, name, "not a metric a search can judge"
                            f"{did_you_mean(name, known) or '; one of ' + ', '.join(known)}")
    if len(set(names)) != len(names):
        raise SpecError(OBJECTIVE_OPTION, ",".join(names), "an objective twice")
    if thresholds and len(thresholds) != len(names):
        raise SpecError(THRESHOLD_OPTION, "threshold", f"{len(thresholds)} thresholds for "
                        f"{len(names)} objectives: give one per --objective, in order")
    objectives = []
    for index, name in enumerate(names):
        if thresholds:
            threshold = float(thresholds[index])
        elif name in CONTACT_THRESHOLDS:
            threshold = CONTACT_THRESHOLDS[name]
        else:
            raise SpecError(THRESHOLD_OPTION, name, "no default threshold: give --threshold "
                            "VALUE (what counts as a violation)")
        objectives.append(Objective(name, known[name], threshold))
    return tuple(objectives)
