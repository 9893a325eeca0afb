"""Search parameters of ``semistatic tune --param``: ranges, log scales, integers, choices.

``--param KEY=LOW:HIGH`` is a range (floats, or integers when both ends are integers),
``--param KEY=LOW:HIGH:log`` the same on a log scale, ``--param KEY=V1,V2,...`` a choice
among TOML-typed values. Each becomes an Optuna distribution; the grid sampler takes
``grid_points`` values of a range (evenly, or evenly in log).

Examples
--------
>>> parse_param("mapper.gate=0.05:0.20")
SearchParam(key='mapper.gate', low=0.05, high=0.2, log=False, integer=False, choices=None)
>>> parse_param("mapper.outlier_k=2,3,4").choices
(2, 3, 4)
>>> parse_param("mapper.min_points=2:6").grid_values(5)
(2, 3, 4, 5, 6)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import optuna

from scenarios.spec.load import parse_override
from semistatic.errors import SpecError

__all__ = [
    "MAX_GRID_POINTS", "MAX_GRID_TRIALS", "PARAM_OPTION", "SearchParam", "parse_param",
    "parse_params",
]

PARAM_OPTION = "--param"
"""The ``file`` named in errors about search parameters."""

GRID_DIGITS = 10
"""Decimals kept of a float grid value (so ``0.15`` is not written ``0.15000000000000002``)."""

GRID_POINTS_OPTION = "--grid-points"

MAX_GRID_POINTS = 1000
"""Most values ``--grid-points`` takes of a range: the bundled studies use 5; a thousand
values of one threshold are finer than any run's noise tells apart, and each is a trial."""

MAX_GRID_TRIALS = 100_000
"""Most combinations a grid may have: each is a trial (a replay or a run); a hundred
thousand replays of a recording take days on a workstation."""


@dataclass(frozen=True)
class SearchParam:
    """One scenario key to search: a range (``low``..``high``) or ``choices``.

    Examples
    --------
    >>> SearchParam("mapper.gate", 0.2, 0.1)
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --param: mapper.gate: reversed range 0.2:0.1; write LOW:HIGH
    """

    key: str
    low: float | None = None
    high: float | None = None
    log: bool = False
    integer: bool = False
    choices: tuple[Any, ...] | None = None

    def __post_init__(self) -> None:
        if self.choices is not None:
            if not self.choices:
                raise SpecError(PARAM_OPTION, self.key, "no choices; give V1,V2,...")
            if len(set(map(repr, self.choices))) != len(self.choices):
                raise SpecError(PARAM_OPTION, self.key, "a choice is given twice")
            return
        if self.low is None or self.high is None:
            raise SpecError(PARAM_OPTION, self.key, "give a range LOW:HIGH or choices V1,V2")
        if self.low > self.high:
            raise SpecError(PARAM_OPTION, self.key,
                            f"reversed range {self.low}:{self.high}; write LOW:HIGH")
        if self.low == self.high:
            raise SpecError(PARAM_OPTION, self.key,
                            f"empty range {self.low}:{self.high}; give LOW < HIGH or --set it")
        if self.log and self.low <= 0:
            raise SpecError(PARAM_OPTION, self.key,
                            f"a log range needs LOW > 0, got {self.low}")

    def distribution(self) -> optuna.distributions.BaseDistribution:
        """Return the Optuna distribution of this parameter.

        Examples
        --------
        >>> parse_param("mapper.gate=0.01:0.1:log").distribution()
        FloatDistribution(high=0.1, log=True, low=0.01, step=None)
        """
        if self.choices is not None:
            return optuna.distributions.CategoricalDistribution(self.choices)
        if self.integer:
            return optuna.distributions.IntDistribution(int(self.low), int(self.high),
                                                        log=self.log)
        return optuna.distributions.FloatDistribution(self.low, self.high, log=self.log)

    def grid_values(self, points: int) -> tuple[Any, ...]:
        """Return the values the grid sampler tries: the choices, or ``points`` of the range.

        Examples
        --------
        >>> parse_param("mapper.gate=0.05:0.2").grid_values(4)
        (0.05, 0.1, 0.15, 0.2)
        >>> parse_param("mapper.gate=0.01:1:log").grid_values(3)
        (0.01, 0.1, 1.0)
        """
        if self.choices is not None:
            return self.choices
        if points > MAX_GRID_POINTS:  # before linspace allocates them
            raise SpecError(GRID_POINTS_OPTION, "grid_points", f"must be <= {MAX_GRID_POINTS} "
                            f"(values of one range), got {points}")
        if self.integer:
            values = np.unique(np.round(
                np.geomspace(self.low, self.high, points) if self.log
                else np.linspace(self.low, self.high, points)
            ).astype(int))
            return tuple(int(value) for value in values)
        values = (np.geomspace if self.log else np.linspace)(self.low, self.high, points)
        return tuple(round(float(value), GRID_DIGITS) for value in values)

    def endpoints(self) -> tuple[Any, ...]:
        """Return the values to validate against the scenario: both ends, or every choice."""
        return self.choices if self.choices is not None else (self.low, self.high)


def _number(text: str, key: str) -> float | int:
    value = parse_override(f"{key}={text.strip()}")[1]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SpecError(PARAM_OPTION, key, f"range end {text.strip()!r} is not a number")
    return value


def parse_param(text: str) -> SearchParam:
    """Read ``KEY=LOW:HIGH[:log]`` or ``KEY=V1,V2,...`` into a :class:`SearchParam`.

    Examples
    --------
    >>> parse_param("mapper.gate=0.2:0.1")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --param: mapper.gate: reversed range 0.2:0.1; write LOW:HIGH
    >>> parse_param("mapper.gate")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --param: mapper.gate: write KEY=LOW:HIGH[:log] or KEY=V1,V2,...
    """
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or not raw.strip():
        raise SpecError(PARAM_OPTION, key or text,
                        "write KEY=LOW:HIGH[:log] or KEY=V1,V2,...")
    if ":" in raw and "," not in raw and not raw.strip().startswith(("[", "{", '"', "'")):
        parts = raw.split(":")
        scale = parts[2].strip() if len(parts) == 3 else None
        if len(parts) not in (2, 3) or scale not in (None, "log"):
            raise SpecError(PARAM_OPTION, key, f"{raw!r}: write LOW:HIGH or LOW:HIGH:log")
        low, high = _number(parts[0], key), _number(parts[1], key)
        integer = isinstance(low, int) and isinstance(high, int)
        return SearchParam(key, low, high, log=scale == "log", integer=integer)
    from scenarios.tuning.points import parse_grid  # the grid's value syntax, TOML-typed

    try:
        return SearchParam(key, choices=parse_grid(f"{key}={raw}")[1])
    except SpecError as error:
        if error.file == PARAM_OPTION:
            raise
        raise SpecError(PARAM_OPTION, error.key, error.message) from None


def parse_params(texts: Iterable[str]) -> tuple[SearchParam, ...]:
    """Parse every ``--param``; refuse a key given twice.

    Examples
    --------
    >>> [p.key for p in parse_params(["mapper.gate=0.1:0.2", "policy=conservative,adaptive"])]
    ['mapper.gate', 'policy']
    """
    from scenarios.tuning.points import once_per_key

    return once_per_key(map(parse_param, texts), PARAM_OPTION)


def grid_size(params: Sequence[SearchParam], points: int) -> int:
    """Return how many combinations the grid sampler has.

    Examples
    --------
    >>> grid_size(parse_params(["mapper.gate=0.1:0.2", "mapper.outlier_k=2,3"]), 3)
    6
    """
    size = math.prod(len(param.grid_values(points)) for param in params)
    if size > MAX_GRID_TRIALS:
        raise SpecError(GRID_POINTS_OPTION, "grid_points", f"the grid has {size} points, more "
                        f"than the limit of {MAX_GRID_TRIALS} trials; use fewer --grid-points "
                        "or fewer --param, or a sampler (--sampler tpe)")
    return size
