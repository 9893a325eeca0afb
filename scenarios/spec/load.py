"""Load scenario files (TOML) into :class:`ScenarioSpec`, with ``--set`` overrides.

Examples
--------
>>> spec = load_scenario("sim1", overrides=["laps=2", "mapper.gate=0.15"])
>>> spec.laps, spec.mapper.gate
(2, 0.15)
>>> load_scenario("sim1", overrides=["mapper.gte=0.15"])
Traceback (most recent call last):
...
semistatic.errors.SpecError: --set: mapper.gte: unknown key (did you mean 'gate'?)
"""

from __future__ import annotations

import contextlib
import dataclasses
import tomllib
import typing
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from robots.presets import PRESETS
from scenarios.spec.layout import with_loaded_world
from scenarios.spec.preflight import check_scenario
from scenarios.spec.scenario import LOADER_FIELDS, ScenarioSpec
from semistatic.errors import SpecError, join_key
from semistatic.noise import spec_noise_params
from semistatic.params import MapperParams
from semistatic.validation import (
    FILE_KEY,
    as_table,
    check_nesting,
    convert,
    did_you_mean,
    from_table,
    read_toml,
    reject_unknown_keys,
)
from worlds.spec import WorldSpec

__all__ = [
    "DATA_DIR",
    "OVERRIDE_FILE",
    "PAPER_SCENARIOS",
    "bundled_scenarios",
    "laser_mapper_params",
    "load_scenario",
    "mapper_from_table",
    "paper_scenarios",
    "parse_override",
    "scenario_from_toml",
    "scenario_help",
    "scenario_path",
    "scenario_table",
]

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
"""Directory of the bundled scenario files."""

OVERRIDE_FILE = "--set"
"""The ``file`` named in errors about command-line overrides."""


MAPPER_RANGES = {
    field.name: field.metadata["range"]
    for field in dataclasses.fields(MapperParams)
    if "range" in field.metadata
}
"""The bounds of the mapper thresholds, from :class:`MapperParams`'s own fields."""


def bundled_scenarios() -> tuple[str, ...]:
    """Return the names of the bundled scenarios, sorted.

    Examples
    --------
    >>> bundled_scenarios()  # doctest: +NORMALIZE_WHITESPACE
    ('fault_blind_policy', 'fault_short_field', 'fault_slow_scanner', 'occlusion_hall', 'pal1',
     'pal3a', 'pal3b', 'sim1', 'sim2', 'warehouse', 'warehouse_fleet', 'warehouse_occlusion')
    """
    return tuple(sorted(path.stem for path in DATA_DIR.glob("*.toml")))


PAPER_SCENARIOS = ("pal1", "pal3a", "pal3b", "sim1", "sim2")
"""The bundled scenarios that are rows of the paper's Table 1 (``semistatic table``)."""


def scenario_help() -> str:
    """Return the help of a SCENARIO argument, naming the bundled scenarios (one registry).

    Examples
    --------
    >>> scenario_help()  # doctest: +ELLIPSIS
    'bundled name (fault_blind_policy, fault_short_field, ..., warehouse_occlusion) or a .toml'
    """
    return f"bundled name ({', '.join(bundled_scenarios())}) or a .toml"


def paper_scenarios() -> tuple[str, ...]:
    """Return the bundled scenarios that reproduce the paper's Table 1 rows, sorted.

    The others (the warehouse) go beyond the paper's experiments.

    Examples
    --------
    >>> paper_scenarios()
    ('pal1', 'pal3a', 'pal3b', 'sim1', 'sim2')
    """
    return tuple(name for name in bundled_scenarios() if name in PAPER_SCENARIOS)


def scenario_path(name_or_path: str | Path) -> Path:
    """Return the file of a bundled scenario name, or ``name_or_path`` as an existing path.

    Examples
    --------
    >>> scenario_path("pal3b").name
    'pal3b.toml'
    >>> scenario_path("sim3")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: sim3: <file>: not a bundled scenario (did you mean 'sim2'?) \
and no such file; bundled: fault_blind_policy, fault_short_field, fault_slow_scanner, \
occlusion_hall, pal1, pal3a, pal3b, sim1, sim2, warehouse, warehouse_fleet, warehouse_occlusion
    """
    text = str(name_or_path)
    names = bundled_scenarios()
    if isinstance(name_or_path, str) and text in names:
        return DATA_DIR / f"{text}.toml"
    path = Path(name_or_path)
    if path.is_dir():
        raise SpecError(text, FILE_KEY, "is a directory, expected a scenario .toml file")
    if path.exists():  # read_toml refuses what is not a regular file (a FIFO, a device)
        return path
    if path.suffix == "" and "/" not in text:
        raise SpecError(
            text,
            FILE_KEY,
            f"not a bundled scenario{did_you_mean(text, names)} and no such file; "
            f"bundled: {', '.join(names)}",
        )
    raise SpecError(text, FILE_KEY, f"no such file (bundled scenarios: {', '.join(names)})")


def parse_override(text: str, *, option: str = OVERRIDE_FILE) -> tuple[list[str], Any]:
    r"""Split ``"section.key=value"`` into its key path and a TOML-typed value.

    The value is read as a TOML value (``0.15``, ``true``, ``[1, 2, 0]``, ``"adaptive"``);
    a bare word that is not TOML is taken as a string, so ``policy=adaptive`` works. One
    text sets one key: a line break (after which TOML would read another ``key = value``)
    or another unprintable character is refused, and so is a value nested deeper than
    the files may be (:func:`semistatic.validation.check_nesting`). ``option`` names the
    command-line option in errors (``--set``; ``--grid`` and ``--vary`` read their values
    here too).

    Examples
    --------
    >>> parse_override("mapper.gate=0.15")
    (['mapper', 'gate'], 0.15)
    >>> parse_override("policy=adaptive")
    (['policy'], 'adaptive')
    >>> parse_override("seed=3\nlaps=7")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --set: 'seed=3\nlaps=7': holds a line break ('\n'); ...
    """
    for char in text:
        # A tab is TOML whitespace; anything else unprintable has no place in one value.
        if char != "\t" and not char.isprintable():
            what = "a line break" if char in "\n\r" else "an unprintable character"
            raise SpecError(option, repr(text), f"holds {what} ({char!r}); one {option} sets "
                            f"one KEY=VALUE on one line: give each key its own {option}")
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise SpecError(option, text, "expected KEY=VALUE, e.g. mapper.gate=0.15")
    check_nesting(raw, file=option, key=key)
    try:
        parsed = tomllib.loads(f"value = {raw.strip()}")
    except tomllib.TOMLDecodeError:
        return key.split("."), raw.strip()
    if list(parsed) != ["value"]:  # one line cannot hold two keys; kept as the invariant
        raise SpecError(option, key, f"{raw.strip()!r} sets more than one key; give each "
                        f"KEY=VALUE its own {option}")
    return key.split("."), parsed["value"]


def _known_keys(cls: type) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {field.name: hints[field.name] for field in dataclasses.fields(cls) if field.init}


def _apply_overrides(
    table: dict[str, Any], overrides: Iterable[str]
) -> tuple[dict[str, Any], list[str]]:
    """Return ``table`` with each override set and the dotted keys set.

    Each key is checked against the spec first: an unknown one is an error naming ``--set``.
    """
    table = {key: dict(value) if isinstance(value, dict) else value for key, value in table.items()}
    settable = {name: hint for name, hint in _known_keys(ScenarioSpec).items()}
    for name in LOADER_FIELDS:
        settable.pop(name)
    settable.pop("moves")
    settable.pop("vehicles")
    keys = []
    for text in overrides:
        path, value = parse_override(text)
        dotted = ".".join(path)
        head = path[0]
        if head not in settable:
            raise SpecError(OVERRIDE_FILE, dotted, f"unknown key{did_you_mean(head, settable)}")
        hint = settable[head]
        if dataclasses.is_dataclass(hint):
            if len(path) != 2:
                raise SpecError(OVERRIDE_FILE, dotted, f"expected {head}.KEY=VALUE")
            known = _known_keys(hint)
            if path[1] not in known:
                raise SpecError(OVERRIDE_FILE, dotted, f"unknown key{did_you_mean(path[1], known)}")
            section = table.setdefault(head, {})
            if not isinstance(section, dict):
                raise SpecError(OVERRIDE_FILE, dotted, f"'{head}' in the file is not a table")
            section[path[1]] = value
        else:
            if len(path) != 1:
                raise SpecError(OVERRIDE_FILE, dotted, f"'{head}' has no sub-keys")
            table[head] = value
        keys.append(dotted)
    return table, keys


@contextlib.contextmanager
def _blame_overrides(file: str, keys: Iterable[str]) -> Iterator[None]:
    """Re-anchor an error in ``file`` at an overridden key (or inside it) to ``--set``.

    The value at fault came from the command line, not from the file.
    """
    keys = list(keys)
    try:
        yield
    except SpecError as error:
        inside = any(
            error.key == key or error.key.startswith((f"{key}.", f"{key}[")) for key in keys
        )
        if error.file == file and inside:
            raise SpecError(OVERRIDE_FILE, error.key, error.message) from None
        raise


def mapper_from_table(
    value: Any, *, file: str, key: str = "mapper", base: MapperParams | None = None
) -> MapperParams:
    """Return ``base`` (default :class:`MapperParams`) with the table's thresholds set.

    Every key is checked (unknown keys with a suggestion, types) and then the mapper's
    own rules; errors name ``file`` and the key inside the table at ``key``.

    Examples
    --------
    >>> mapper_from_table({"gate": 0.2}, file="--set").gate
    0.2
    >>> mapper_from_table({"gate": "abc"}, file="--set")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --set: mapper.gate: expected a number, got a string 'abc'
    >>> mapper_from_table({"max_range": -1.0}, file="--max-range", key="")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --max-range: max_range: must be > 0.0 and <= 100.0, got -1.0 (m)
    """
    table = as_table(value, file=file, key=key)
    keys = _known_keys(MapperParams)
    reject_unknown_keys(table, keys, file=file, key=key)
    kwargs = {}
    for name, raw in table.items():
        hint = keys[name]
        if typing.get_origin(hint) is typing.Literal:
            hint = str
        kwargs[name] = convert(hint, raw, file=file, key=join_key(key, name),
                               valid=MAPPER_RANGES.get(name))
    try:
        return (base or MapperParams()).replace(**kwargs)
    except SpecError as error:
        raise error.located(file, key) from None


def scenario_from_toml(
    table: Mapping[str, Any],
    *,
    file: str,
    overrides: Iterable[str] = (),
    check_layout: bool = True,
    worlds: Mapping[str, WorldSpec] | None = None,
) -> ScenarioSpec:
    """Build a :class:`ScenarioSpec` from a parsed TOML table plus ``--set`` overrides.

    ``name`` defaults to the file's stem; a relative ``world`` path is resolved against
    the scenario file's folder. The file is validated on its own first, then with the
    overrides (an error in an overridden value names ``--set``). ``--set laps=N`` below
    the file's laps drops the moves of the laps that never run. With ``check_layout``
    the world, robot, people and every lap's box layout are checked too
    (:func:`scenarios.spec.layout.check_scenario_layout`), which loads the world, and
    every segment's protective field against the standard's formula
    (:func:`scenarios.spec.field_sizing.check_field_sizes`) and every test piece against
    every vehicle's safety laser (:func:`scenarios.spec.pieces.check_piece_sightings`)
    and every vehicle's start (:func:`scenarios.spec.starts.check_starts`): the one pass
    of :func:`scenarios.spec.preflight.check_scenario`. The world it loads then (or finds
    in ``worlds``, the worlds read already by ``world`` value) is attached to the spec
    (:func:`scenarios.spec.layout.with_loaded_world`): the runs use that one read.

    Examples
    --------
    >>> scenario_from_toml({"world": "sim1", "laps": 0}, file="s.toml")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: s.toml: laps: must be >= 1 and <= 1000, got 0
    """
    table = dict(as_table(table, file=file, key=""))
    table.setdefault("name", Path(file).stem)
    world = table.get("world")
    if isinstance(world, str) and world.endswith(".toml") and not Path(world).is_absolute():
        table["world"] = str(Path(file).resolve().parent / world)
    # The file alone must be valid (its moves within its laps) before overrides apply.
    file_spec = _spec_from_table(table, file=file)
    spec, keys = file_spec, []
    overrides = list(overrides)
    if overrides:
        merged, keys = _apply_overrides(table, overrides)
        merged.pop("moves", None)
        with _blame_overrides(file, keys):
            spec = _spec_from_table(merged, file=file)
            # ``--set laps=N`` runs fewer laps: the moves of the laps that never run go.
            kept = tuple(move for move in file_spec.moves if move.lap <= spec.laps)
            spec = dataclasses.replace(spec, moves=kept)
    if check_layout:
        with _blame_overrides(file, keys):
            # The world is read here once: the checks and every run then use this read.
            spec = with_loaded_world(spec, (worlds or {}).get(spec.world))
            check_scenario(spec, moves=file_spec.moves)
    return spec


def _spec_from_table(table: Mapping[str, Any], *, file: str) -> ScenarioSpec:
    """Build the spec from a table whose ``name`` and ``world`` are already resolved.

    The mapper's noise thresholds default to the robot's safety laser (the mapper's input)
    at the scenario's noise scale (:func:`laser_mapper_params`); ``[mapper]`` keys win.
    """
    table = dict(table)
    mapper_table = table.pop("mapper", {})
    fixed = {"source": file, "loaded_world": None, "mapper": MapperParams()}
    spec = from_table(ScenarioSpec, table, file=file, key="", fixed=fixed)
    # An unknown robot keeps the plain defaults: the layout check names it.
    base = laser_mapper_params(spec) if spec.robot in PRESETS else MapperParams()
    return dataclasses.replace(spec, mapper=mapper_from_table(mapper_table, file=file, base=base))


def laser_mapper_params(spec: ScenarioSpec) -> MapperParams:
    """Return the default mapper thresholds for the range noise of ``spec``'s safety laser.

    The mapper reads the safety laser's scans, whose range noise is the data sheet's sigma
    times ``spec.noise.range``; :func:`semistatic.noise.spec_noise_params` sets the
    Douglas-Peucker tolerance and the breakpoint noise from it.

    Examples
    --------
    >>> from scenarios.spec.scenario import ScenarioSpec
    >>> laser_mapper_params(ScenarioSpec("s", world="sim1")) == MapperParams()  # LMS100 1.2 cm
    True
    >>> lgv = laser_mapper_params(ScenarioSpec("w", world="warehouse", robot="lgv"))  # S300
    >>> round(lgv.epsilon, 3), lgv.breakpoint_sigma_r
    (0.075, 0.03)
    """
    laser = PRESETS[spec.robot].safety_laser.laser
    return spec_noise_params(MapperParams(), laser.range_sigma * spec.noise.range)


def scenario_table(name_or_path: str | Path, *, overrides: Iterable[str] = ()) -> dict[str, Any]:
    """Return a scenario file's table with ``overrides`` set, as :func:`load_scenario` reads it.

    The table is what a file that needs no ``--set`` would hold (``semistatic falsify``
    writes its counterexamples so); nothing is validated but the keys.

    Examples
    --------
    >>> table = scenario_table("pal1", overrides=["seed=4", "mapper.gate=0.1"])
    >>> table["seed"], table["mapper"]["gate"], table["world"]
    (4, 0.1, 'pal1')
    """
    return _apply_overrides(read_toml(scenario_path(name_or_path)), overrides)[0]


def load_scenario(name_or_path: str | Path, *, overrides: Iterable[str] = ()) -> ScenarioSpec:
    """Load a scenario: a bundled name (see :func:`bundled_scenarios`) or a TOML path.

    ``overrides`` are ``"section.key=value"`` strings (the CLI's ``--set``), validated
    against the scenario schema before anything runs; so are the world, the robot, the
    people and the box layout of every lap.

    Examples
    --------
    >>> load_scenario("pal3b").people
    ('walker',)
    >>> load_scenario("pal3b", overrides=["laps=0"])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --set: laps: must be >= 1 and <= 1000, got 0
    """
    path = scenario_path(name_or_path)
    return scenario_from_toml(read_toml(path), file=str(path), overrides=list(overrides))
