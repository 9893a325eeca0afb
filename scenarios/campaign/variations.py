"""Sampled variations of ``semistatic campaign --vary KEY=DIST``: parsed, checked, drawn.

``KEY`` is a scenario key as ``--set`` takes it (``mapper.epsilon``, ``noise.range``,
``safety.slowdown``, ...) or an object of the scenario's world,
``world.boxes.NAME.FIELD`` / ``world.people.NAME.FIELD``, where ``FIELD`` may pick one
element of a list (``pose[1]``: the box's y). ``DIST`` is one of

- ``uniform(LOW, HIGH)``: a float drawn evenly from ``[LOW, HIGH)``;
- ``normal(MEAN, SIGMA)``: a float from a normal distribution (values outside the key's
  range make the sample rejected, not the campaign fail);
- ``choice(V1, V2, ...)``: one of TOML-typed values, each equally likely.

Every draw comes from one generator seeded by the campaign's variation seed, in the
order the ``--vary`` options are given, so a campaign is reproducible from its command
line.

Examples
--------
>>> import numpy as np
>>> variation = parse_variation("mapper.epsilon=uniform(0.02, 0.04)")
>>> variation.key, variation.distribution
('mapper.epsilon', 'uniform')
>>> samples = draw_samples([variation], 3, seed=0)
>>> len(samples), all(0.02 <= s["mapper.epsilon"] < 0.04 for s in samples)
(3, True)
>>> draw_samples([variation], 3, seed=0) == samples
True
>>> parse_variation("world.boxes.crate.pose[1]=normal(1.0, 0.05)").world_path
('boxes', 'crate', 'pose', 1)
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from scenarios.spec.load import parse_override
from semistatic.errors import SpecError

__all__ = [
    "DISTRIBUTIONS",
    "MAX_SAMPLES",
    "VARY_OPTION",
    "Variation",
    "draw_samples",
    "parse_variation",
    "parse_variations",
]

VARY_OPTION = "--vary"
"""The ``file`` named in errors about variations."""

DISTRIBUTIONS = ("uniform", "normal", "choice")
"""The distributions ``--vary`` draws from."""

MAX_SAMPLES = 10_000
"""More variation draws than this is a typo, not a campaign."""

WORLD_PREFIX = "world."
WORLD_LISTS = ("boxes", "people")
"""The lists of a world file whose named entries a variation may change."""

_CALL = re.compile(r"^\s*(?P<name>[a-z_]+)\s*\((?P<args>.*)\)\s*$", re.DOTALL)
_FIELD = re.compile(r"^(?P<field>[a-z_][a-z0-9_]*)(\[(?P<index>\d+)\])?$")


@dataclass(frozen=True)
class Variation:
    """One varied key and the distribution its values are drawn from.

    ``arguments`` are ``(LOW, HIGH)`` of ``uniform``, ``(MEAN, SIGMA)`` of ``normal``
    and the values of ``choice``.

    Examples
    --------
    >>> Variation("mapper.gate", "uniform", (0.2, 0.1))
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --vary: mapper.gate: reversed range uniform(0.2, 0.1); \
write uniform(LOW, HIGH)
    """

    key: str
    distribution: str
    arguments: tuple[Any, ...]

    def __post_init__(self) -> None:
        if self.distribution not in DISTRIBUTIONS:
            raise SpecError(VARY_OPTION, self.key, f"unknown distribution "
                            f"{self.distribution!r}; one of {', '.join(DISTRIBUTIONS)}")
        if self.distribution == "choice":
            if not self.arguments:
                raise SpecError(VARY_OPTION, self.key, "choice() is empty; give choice(V1, V2)")
            if len(set(map(repr, self.arguments))) != len(self.arguments):
                raise SpecError(VARY_OPTION, self.key, "a choice is given twice")
            return
        if len(self.arguments) != 2 or not all(_is_number(a) for a in self.arguments):
            raise SpecError(VARY_OPTION, self.key, f"{self.distribution}() takes two numbers")
        first, second = (float(a) for a in self.arguments)
        if not (np.isfinite(first) and np.isfinite(second)):
            raise SpecError(VARY_OPTION, self.key, f"{self.text}: give finite numbers")
        if self.distribution == "uniform":
            if first > second:
                raise SpecError(VARY_OPTION, self.key,
                                f"reversed range {self.text}; write uniform(LOW, HIGH)")
            if first == second:
                raise SpecError(VARY_OPTION, self.key,
                                f"empty range {self.text}; give LOW < HIGH or --set it")
        elif second <= 0:
            raise SpecError(VARY_OPTION, self.key,
                            f"{self.text}: the standard deviation must be > 0")

    @property
    def text(self) -> str:
        """Return the distribution as written: ``uniform(0.1, 0.2)``."""
        from scenarios.tuning.points import toml_value

        return f"{self.distribution}({', '.join(map(toml_value, self.arguments))})"

    @property
    def world_path(self) -> tuple[str, str, str, int | None] | None:
        """Return ``(list, name, field, index)`` of a world key, ``None`` for a scenario key."""
        if not self.key.startswith(WORLD_PREFIX):
            return None
        parts = self.key[len(WORLD_PREFIX):].split(".")
        if len(parts) != 3 or parts[0] not in WORLD_LISTS or not parts[1]:
            raise SpecError(VARY_OPTION, self.key, "write world.boxes.NAME.FIELD or "
                            "world.people.NAME.FIELD (e.g. world.boxes.crate.pose[0])")
        match = _FIELD.fullmatch(parts[2])
        if match is None:
            raise SpecError(VARY_OPTION, self.key, f"{parts[2]!r} is no field; write FIELD "
                            "or FIELD[INDEX], e.g. pose[0]")
        index = match["index"]
        return parts[0], parts[1], match["field"], None if index is None else int(index)

    def checked_values(self) -> tuple[Any, ...]:
        """Return the values to validate against each scenario: both ends, or every choice.

        A normal distribution has no ends: its mean stands for it, and draws outside the
        key's range make their sample rejected.
        """
        if self.distribution == "choice":
            return self.arguments
        if self.distribution == "normal":
            return (float(self.arguments[0]),)
        return tuple(float(a) for a in self.arguments)

    def draw(self, rng: np.random.Generator) -> Any:
        """Return one value drawn with ``rng``."""
        if self.distribution == "uniform":
            return float(rng.uniform(*self.arguments))
        if self.distribution == "normal":
            return float(rng.normal(*self.arguments))
        return self.arguments[int(rng.integers(len(self.arguments)))]


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def parse_variation(text: str) -> Variation:
    """Read ``KEY=uniform(a,b)``, ``KEY=normal(mean,sigma)`` or ``KEY=choice(v1,...)``.

    Examples
    --------
    >>> parse_variation("policy=choice(adaptive, guarded)").arguments
    ('adaptive', 'guarded')
    >>> parse_variation("mapper.gate=0.1")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --vary: mapper.gate: write KEY=uniform(LOW, HIGH), \
KEY=normal(MEAN, SIGMA) or KEY=choice(V1, V2, ...), got '0.1'
    """
    from scenarios.tuning.points import parse_grid  # the grid's TOML-typed value lists

    key, sep, raw = text.partition("=")
    key = key.strip()
    usage = "write KEY=uniform(LOW, HIGH), KEY=normal(MEAN, SIGMA) or KEY=choice(V1, V2, ...)"
    if not sep or not key:
        raise SpecError(VARY_OPTION, key or text, usage)
    if key == "seed":
        raise SpecError(VARY_OPTION, key, "seeds are a campaign axis: use --seeds A:B")
    call = _CALL.fullmatch(raw)
    if call is None:
        raise SpecError(VARY_OPTION, key, f"{usage}, got {raw.strip()!r}")
    name, arguments = call["name"], call["args"]
    if name not in DISTRIBUTIONS:
        from semistatic.validation import did_you_mean

        raise SpecError(VARY_OPTION, key, f"unknown distribution {name!r}"
                        f"{did_you_mean(name, DISTRIBUTIONS)}; one of {', '.join(DISTRIBUTIONS)}")
    if not arguments.strip():
        values: tuple[Any, ...] = ()
    elif name == "choice":
        try:
            values = parse_grid(f"{key}={arguments}")[1]
        except SpecError as error:
            raise SpecError(VARY_OPTION, key, error.message) from None
    else:
        values = tuple(parse_override(f"{key}={part.strip()}", option=VARY_OPTION)[1]
                       for part in arguments.split(","))
        bad = [value for value in values if not _is_number(value)]
        if bad:
            raise SpecError(VARY_OPTION, key, f"{name}() takes numbers, got {bad[0]!r}")
    variation = Variation(key, name, values)
    variation.world_path  # noqa: B018 -- a malformed world key fails here, at parse time
    return variation


def parse_variations(texts: Sequence[str]) -> tuple[Variation, ...]:
    """Parse every ``--vary``; refuse a key given twice.

    Examples
    --------
    >>> texts = ["mapper.gate=uniform(0.1, 0.2)", "noise.range=normal(1, 0.1)"]
    >>> [variation.key for variation in parse_variations(texts)]
    ['mapper.gate', 'noise.range']
    >>> parse_variations(["mapper.gate=uniform(0.1, 0.2)", "mapper.gate=normal(0.1, 0.01)"])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --vary: mapper.gate: given twice; keep one --vary per key
    """
    from scenarios.tuning.points import once_per_key

    return once_per_key(map(parse_variation, texts), VARY_OPTION)


def draw_samples(variations: Sequence[Variation], samples: int, *, seed: int,
                 ) -> list[dict[str, Any]]:
    """Return ``samples`` draws of every variation, from one generator seeded by ``seed``.

    Without variations there is one sample: the scenarios as they are.

    Examples
    --------
    >>> draw_samples([], 5, seed=0)
    [{}]
    >>> draw_samples([parse_variation("policy=choice(adaptive)")], 2, seed=1)
    [{'policy': 'adaptive'}, {'policy': 'adaptive'}]
    """
    if not variations:
        return [{}]
    if not 1 <= samples <= MAX_SAMPLES:
        raise SpecError("--samples", "samples", f"must be >= 1 and <= {MAX_SAMPLES}, got {samples}")
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    return [{variation.key: variation.draw(rng) for variation in variations}
            for _ in range(samples)]
