"""The points of a sweep: grid and seed options parsed, every point's scenario validated.

Examples
--------
>>> grid = parse_grids(["mapper.gate=0.08,0.12", "policy=conservative,adaptive"])
>>> grid
{'mapper.gate': (0.08, 0.12), 'policy': ('conservative', 'adaptive')}
>>> for point in sweep_points("sim1", grid, laps=1):
...     print(point.label)
mapper.gate=0.08 policy=conservative seed=0
mapper.gate=0.08 policy=adaptive seed=0
mapper.gate=0.12 policy=conservative seed=0
mapper.gate=0.12 policy=adaptive seed=0
"""

from __future__ import annotations

import contextlib
import copy
import itertools
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scenarios.spec.layout import with_loaded_world
from scenarios.spec.load import OVERRIDE_FILE, parse_override, scenario_from_toml, scenario_path
from scenarios.spec.scenario import ScenarioSpec
from semistatic.errors import SpecError
from semistatic.validation import read_toml
from worlds.spec import WorldSpec

__all__ = [
    "GRID_OPTION",
    "LAPS_OPTION",
    "MAX_POINTS",
    "SEEDS_OPTION",
    "ScenarioSource",
    "ScenarioSources",
    "SweepPoint",
    "display_value",
    "once_per_key",
    "parse_grid",
    "parse_grids",
    "parse_seeds",
    "settings_text",
    "sweep_points",
    "toml_value",
]

MAX_POINTS = 256
"""Most runs one sweep may ask for: beyond this a typo (an extra value list) is likelier
than intent, and a few hundred closed-loop runs already take hours on a laptop."""

GRID_OPTION = "--grid"
SEEDS_OPTION = "--seeds"
LAPS_OPTION = "--laps"
"""The ``file`` named in errors about these options (errors read ``error: --grid: key: ...``)."""


# --------------------------------------------------------------------------------------
# The grid


def _split_values(raw: str) -> list[str]:
    """Split ``raw`` at top-level commas (not inside ``[...]``, ``{...}`` or quotes)."""
    parts, depth, quote, start = [], 0, "", 0
    for position, char in enumerate(raw):
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(raw[start:position])
            start = position + 1
    parts.append(raw[start:])
    return [part.strip() for part in parts]


def parse_grid(text: str) -> tuple[str, tuple[Any, ...]]:
    """Split ``"section.key=V1,V2,..."`` into the key and its TOML-typed values.

    Values are read like ``--set`` values (:func:`scenarios.spec.load.parse_override`); commas
    inside ``[...]`` or quotes do not split.

    Examples
    --------
    >>> parse_grid("mapper.gate=0.08, 0.12")
    ('mapper.gate', (0.08, 0.12))
    >>> parse_grid("rates.safety_hz=12.5,25")
    ('rates.safety_hz', (12.5, 25))
    >>> parse_grid("mapper.gate=0.1,0.10")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --grid: mapper.gate: value 0.1 appears twice; list each once
    """
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise SpecError(GRID_OPTION, text, "expected KEY=V1,V2,..., e.g. mapper.gate=0.08,0.12")
    if key == "seed":
        raise SpecError(GRID_OPTION, key, "sweep seeds with --seeds S1,S2,... instead")
    items = _split_values(raw)
    if items == [""]:
        raise SpecError(GRID_OPTION, key, "empty grid: give values, e.g. mapper.gate=0.08,0.12")
    if "" in items:
        raise SpecError(GRID_OPTION, key, f"empty value in {raw.strip()!r}: drop the extra comma")
    values = tuple(parse_override(f"{key}={item}", option=GRID_OPTION)[1] for item in items)
    for position, value in enumerate(values):
        if value in values[:position]:
            raise SpecError(
                GRID_OPTION, key, f"value {display_value(value)} appears twice; list each once"
            )
    return key, values


def parse_grids(texts: Iterable[str]) -> dict[str, tuple[Any, ...]]:
    """Parse every ``--grid`` option into ``{key: values}``, refusing a key given twice.

    Examples
    --------
    >>> parse_grids(["mapper.gate=0.1,0.2", "mapper.epsilon=0.03"])
    {'mapper.gate': (0.1, 0.2), 'mapper.epsilon': (0.03,)}
    >>> parse_grids(["mapper.gate=0.1", "mapper.gate=0.2"])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --grid: mapper.gate: given twice; put all values in one \
--grid mapper.gate=V1,V2,...
    """
    grids: dict[str, tuple[Any, ...]] = {}
    for text in texts:
        key, values = parse_grid(text)
        if key in grids:
            raise SpecError(
                GRID_OPTION, key, f"given twice; put all values in one --grid {key}=V1,V2,..."
            )
        grids[key] = values
    return grids


def once_per_key(items: Iterable[Any], option: str) -> tuple[Any, ...]:
    """Return ``items`` (each with a ``key``), refusing a key given twice to ``option``.

    Examples
    --------
    >>> from types import SimpleNamespace as Item
    >>> once_per_key([Item(key="a"), Item(key="a")], "--param")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --param: a: given twice; keep one --param per key
    """
    by_key: dict[str, Any] = {}
    for item in items:
        if item.key in by_key:
            raise SpecError(option, item.key, f"given twice; keep one {option} per key")
        by_key[item.key] = item
    return tuple(by_key.values())


def parse_seeds(text: str) -> tuple[int, ...]:
    """Parse ``--seeds S1,S2,...`` (non-negative integers, each once).

    Examples
    --------
    >>> parse_seeds("0, 1,2")
    (0, 1, 2)
    >>> parse_seeds("0,x")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --seeds: seed: expected integers >= 0 like --seeds 0,1,2, got 'x'
    """
    seeds = []
    for item in text.split(","):
        item = item.strip()
        if not item.isdigit():
            raise SpecError(
                SEEDS_OPTION, "seed", f"expected integers >= 0 like --seeds 0,1,2, got {item!r}"
            )
        if int(item) in seeds:
            raise SpecError(SEEDS_OPTION, "seed", f"seed {int(item)} appears twice; list each once")
        seeds.append(int(item))
    return tuple(seeds)


def toml_value(value: Any) -> str:
    """Write ``value`` back as TOML text for an override (the inverse of parse_override).

    Examples
    --------
    >>> toml_value(0.1), toml_value("adaptive"), toml_value(True)
    ('0.1', '"adaptive"', 'true')
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)  # also TOML for inf and nan
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    return str(value)


def display_value(value: Any) -> str:
    """Return ``value`` as a person writes it on the command line.

    Examples
    --------
    >>> display_value("adaptive"), display_value(0.25)
    ('adaptive', '0.25')
    """
    return value if isinstance(value, str) else toml_value(value)


@dataclass(frozen=True)
class SweepPoint:
    """One run of a sweep: its grid values and the validated scenario it runs.

    Examples
    --------
    >>> point = sweep_points("sim1", {"mapper.gate": [0.1]}, seeds=[4])[0]
    >>> point.index, dict(point.settings), point.seed, point.spec.mapper.gate
    (0, {'mapper.gate': 0.1}, 4, 0.1)
    """

    index: int
    settings: tuple[tuple[str, Any], ...]
    spec: ScenarioSpec

    @property
    def seed(self) -> int:
        """Return the run's seed."""
        return self.spec.seed

    @property
    def run(self) -> str:
        """Return ``SCENARIO seed=S``: which recorded or simulated run the point is.

        Examples
        --------
        >>> sweep_points("sim1", {"policy": ["adaptive"]}, seeds=[2])[0].run
        'sim1 seed=2'
        """
        return f"{self.spec.name} seed={self.seed}"

    @property
    def label(self) -> str:
        """Return ``key=value ... seed=S``: the grid values and the seed.

        Examples
        --------
        >>> sweep_points("sim1", {"policy": ["adaptive"]}, seeds=[1, 2])[1].label
        'policy=adaptive seed=2'
        """
        values = [f"{key}={display_value(value)}" for key, value in self.settings]
        return " ".join([*values, f"seed={self.seed}"])


@dataclass(frozen=True)
class ScenarioSource:
    """A scenario file as read once: its path, table and ``worlds`` (filled as points read them).

    Examples
    --------
    >>> source = ScenarioSource.read("pal1")
    >>> source.path.name, source.table["world"], source.worlds
    ('pal1.toml', 'pal1', {})
    >>> _ = sweep_points(source, {"mapper.gate": [0.1]})
    >>> [world.name for world in source.worlds.values()]
    ['pal1']
    """

    path: Path
    table: Mapping[str, Any]
    worlds: dict[str, WorldSpec] = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def read(cls, scenario: str | Path | ScenarioSource) -> ScenarioSource:
        """Return the source of ``scenario`` (a bundled name or a file), read now."""
        if isinstance(scenario, ScenarioSource):
            return scenario
        path = scenario_path(scenario)
        return cls(path, read_toml(path))


class ScenarioSources:
    """The scenario files of one command, each read the first time it is asked for.

    Examples
    --------
    >>> sources = ScenarioSources()
    >>> sources("pal1") is sources("pal1")
    True
    """

    def __init__(self) -> None:
        self._read: dict[str | Path, ScenarioSource] = {}

    def __call__(self, scenario: str | Path) -> ScenarioSource:
        """Return the source of ``scenario``, read on the first call only."""
        if scenario not in self._read:
            self._read[scenario] = ScenarioSource.read(scenario)
        return self._read[scenario]


@contextlib.contextmanager
def _blame_options(grid_keys: Iterable[str]) -> Iterator[None]:
    """Re-anchor a ``--set`` error at a grid key, the seed or the laps to their option."""
    owners = {"seed": SEEDS_OPTION, "laps": LAPS_OPTION} | {key: GRID_OPTION for key in grid_keys}
    try:
        yield
    except SpecError as error:
        if error.file == OVERRIDE_FILE:
            for key, option in owners.items():
                if error.key == key or error.key.startswith((f"{key}.", f"{key}[")):
                    raise SpecError(option, error.key, error.message) from None
        raise


def sweep_points(
    scenario: str | Path | ScenarioSource,
    grids: Mapping[str, Sequence[Any]],
    *,
    seeds: Sequence[int] | None = None,
    laps: int | None = None,
    overrides: Sequence[str] = (),
    max_points: int = MAX_POINTS,
) -> list[SweepPoint]:
    """Expand the grids (times the seeds) into validated points, in grid order.

    Parameters
    ----------
    scenario
        A bundled scenario name or a scenario file (read now), or its
        :class:`ScenarioSource` as read already (read no more).
    grids
        ``{"section.key": values}``: the Cartesian product of all values is swept, the
        last key varying fastest.
    seeds
        Seeds to run each combination with (innermost loop); ``None`` keeps the file's.
    laps
        Laps of every run (``None`` keeps the file's).
    overrides
        Fixed ``--set`` overrides applied to every point.
    max_points
        Refuse sweeps with more points than this.

    Returns
    -------
    list of SweepPoint
        Every point's scenario is loaded and validated (world and box layouts included)
        before this returns, so a bad value fails before anything runs. Each world is read
        once and carried by the specs: runs (in workers too) never read the files again.

    Raises
    ------
    semistatic.errors.SpecError
        An empty grid, a key given both in ``grids`` and ``overrides``, too many points,
        or any point's scenario not valid (unknown key with a suggestion, value out of
        range); the error names the option (``--grid``, ``--seeds``, ``--laps``, ``--set``).

    Examples
    --------
    >>> [p.label for p in sweep_points("pal1", {"mapper.gate": [0.08, 0.12]}, seeds=[0, 1])]
    ['mapper.gate=0.08 seed=0', 'mapper.gate=0.08 seed=1', 'mapper.gate=0.12 seed=0', \
'mapper.gate=0.12 seed=1']
    >>> sweep_points("pal1", {"mapper.gte": [0.1]})
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --grid: mapper.gte: unknown key (did you mean 'gate'?)
    >>> sweep_points("pal1", {"mapper.gate": [0.1, -0.1]})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --grid: mapper.gate: must be > 0.0 and <= 5.0, got -0.1 (m, ...)
    """
    grids = {key: tuple(values) for key, values in grids.items()}
    for key, values in grids.items():
        if key == "seed":
            raise SpecError(GRID_OPTION, key, "sweep seeds with --seeds S1,S2,... instead")
        if not values:
            raise SpecError(GRID_OPTION, key, "empty grid: give values, e.g. mapper.gate=0.08,0.12")
    fixed = {".".join(parse_override(text)[0]): text for text in overrides}
    for key in grids:
        if key in fixed:
            raise SpecError(
                GRID_OPTION, key, f"also given as --set {fixed[key]}; keep one of the two"
            )
    if laps is not None and "laps" in grids:
        raise SpecError(GRID_OPTION, "laps", "also given as --laps; keep one of the two")
    if seeds is not None:
        if not seeds:
            raise SpecError(SEEDS_OPTION, "seed", "empty: give seeds, e.g. --seeds 0,1")
        if "seed" in fixed:
            raise SpecError(SEEDS_OPTION, "seed", f"also given as --set {fixed['seed']}")
    seed_axis: Sequence[int | None] = tuple(seeds) if seeds is not None else (None,)
    count = math.prod(len(values) for values in grids.values()) * len(seed_axis)
    if count > max_points:
        sizes = [str(len(values)) for values in grids.values()]
        if seeds is not None:
            sizes.append(f"{len(seed_axis)} seeds")
        raise SpecError(
            GRID_OPTION, ", ".join(grids) or "seed",
            f"{count} points ({' x '.join(sizes)}) exceed the limit of {max_points}; "
            "use fewer values or split the sweep",
        )
    base = list(overrides) + ([f"laps={laps}"] if laps is not None else [])
    source = ScenarioSource.read(scenario)
    path, table = source.path, source.table
    # The layout check (world, robot footprint, people, every lap's boxes) is most of a
    # load's time and reads only these fields: run it once per distinct layout, exactly
    # as load_scenario does, and build the other points' specs without it.
    checked_layouts = set()
    points = []
    for combination in itertools.product(*grids.values()):
        settings = tuple(zip(grids, combination, strict=True))
        for seed in seed_axis:
            point_overrides = base + [f"{key}={toml_value(value)}" for key, value in settings]
            if seed is not None:
                point_overrides.append(f"seed={seed}")
            with _blame_options(grids):
                spec = scenario_from_toml(copy.deepcopy(table), file=str(path),
                                          overrides=point_overrides, check_layout=False)
                layout = (spec.world, spec.robot, spec.people)
                if layout not in checked_layouts:
                    spec = scenario_from_toml(copy.deepcopy(table), file=str(path),
                                              overrides=point_overrides, worlds=source.worlds)
                    checked_layouts.add(layout)
                    source.worlds.setdefault(spec.world, spec.loaded_world[1])
                else:
                    spec = with_loaded_world(spec, source.worlds[spec.world])
            points.append(SweepPoint(len(points), settings, spec))
    return points


def settings_text(settings: Mapping[str, Any]) -> str:
    """Return ``key=value ...`` of a point's settings, as on the command line.

    Examples
    --------
    >>> settings_text({"mapper.gate": 0.1, "policy": "adaptive"})
    'mapper.gate=0.1 policy=adaptive'
    """
    return " ".join(f"{key}={display_value(value)}" for key, value in settings.items())
