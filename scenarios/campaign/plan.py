"""The runs of a campaign: every scenario x policy x variation sample x seed, validated.

Bad input (an unknown key, a range a key cannot take, an unknown policy) raises
:class:`~semistatic.errors.SpecError` from :func:`check_campaign` before anything is
written. A drawn sample that breaks a scenario (a box pushed into a wall, a threshold
out of range from a normal draw) is no bad input: :func:`plan_campaign` records its runs
as *rejected*, with the reason the scenario check gave, and the campaign goes on.

A sample that changes world objects gets its own world file, ``WORLDS/NAME-DIGEST.toml``
(the bundled world with the drawn values), which its runs name as their ``world``: a
run of a campaign is a plain scenario that ``semistatic run`` can repeat.

Examples
--------
>>> runs = plan_campaign(["pal1"], ["conservative", "adaptive"], [0, 1], (), [{}],
...                      laps=1, worlds_dir=None)
>>> [run.run for run in runs]  # doctest: +NORMALIZE_WHITESPACE
['pal1 conservative sample=0 seed=0', 'pal1 conservative sample=0 seed=1',
 'pal1 adaptive sample=0 seed=0', 'pal1 adaptive sample=0 seed=1']
>>> runs[3].spec.policy, runs[3].spec.seed, runs[3].status
('adaptive', 1, 'ok')
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scenarios.campaign.variations import VARY_OPTION, Variation
from scenarios.spec.layout import with_loaded_world
from scenarios.spec.load import OVERRIDE_FILE, scenario_from_toml, scenario_path
from scenarios.spec.scenario import LOADER_FIELDS, ScenarioSpec
from scenarios.tuning.points import toml_value
from semistatic.errors import SpecError
from semistatic.params import MapperParams
from semistatic.validation import did_you_mean, read_toml
from worlds.load import world_from_toml, world_path
from worlds.spec import BoxSpec, PersonSpec

__all__ = ["CampaignRun", "check_campaign", "plan_campaign", "scenario_digest", "world_document"]

_ENTRY_SPECS = {"boxes": BoxSpec, "people": PersonSpec}
_SINGULAR = {"boxes": "box", "people": "person"}


@dataclass(frozen=True)
class CampaignRun:
    """One run of a campaign: its axes, the drawn values, and its scenario or why not.

    Examples
    --------
    >>> CampaignRun("r", "pal1", "adaptive", 0, 0, (), None, "boxes[1]: in a wall").status
    'rejected'
    """

    run: str
    scenario: str
    policy: str
    seed: int
    sample: int
    values: tuple[tuple[str, Any], ...]
    spec: ScenarioSpec | None
    reason: str | None = None
    overrides: tuple[str, ...] = ()
    """The ``--set`` overrides that make the run of its scenario file (the seed aside)."""

    @property
    def status(self) -> str:
        """Return ``"ok"`` for a run to simulate, ``"rejected"`` for a broken sample."""
        return "ok" if self.spec is not None else "rejected"


def _scenario_table(scenario: str) -> tuple[Path, dict[str, Any]]:
    path = scenario_path(scenario)
    return path, read_toml(path)


def _as_vary(error: SpecError, key: str) -> SpecError:
    """Return ``error`` of a ``--set``-applied variation as an error of ``--vary``."""
    if error.file == OVERRIDE_FILE:
        return SpecError(VARY_OPTION, error.key, error.message)
    return SpecError(VARY_OPTION, key, f"{error.file}: {error.key}: {error.message}")


def _entry(table: Mapping[str, Any], variation: Variation, world: str) -> dict[str, Any]:
    """Return the named box or person of a world table that ``variation`` changes."""
    kind, name, field, index = variation.world_path
    entries = [e for e in table.get(kind, []) if isinstance(e, dict) and e.get("name") == name]
    if not entries:
        names = [e.get("name") for e in table.get(kind, []) if isinstance(e, dict)]
        raise SpecError(VARY_OPTION, variation.key,
                        f"world {world} has no {_SINGULAR[kind]} "
                        f"{name!r}{did_you_mean(name, names)}; {kind}: {', '.join(names)}")
    known = [f.name for f in dataclasses.fields(_ENTRY_SPECS[kind]) if f.init]
    if field not in known or field == "name":
        raise SpecError(VARY_OPTION, variation.key,
                        f"{kind} have no field {field!r}{did_you_mean(field, known)}")
    if index is not None and not (isinstance(entries[0].get(field), list)
                                  and index < len(entries[0][field])):
        raise SpecError(VARY_OPTION, variation.key,
                        f"{name}.{field} in world {world} has no element [{index}]")
    return entries[0]


def _varied_world(table: Mapping[str, Any], values: Mapping[str, Any],
                  variations: Mapping[str, Variation], world: str) -> dict[str, Any]:
    """Return a copy of world ``table`` with the drawn world values set."""
    table = copy.deepcopy(dict(table))
    table.setdefault("name", world)
    for key, value in values.items():
        variation = variations[key]
        if variation.world_path is None:
            continue
        entry = _entry(table, variation, world)
        _, _, field, index = variation.world_path
        if index is None:
            entry[field] = value
        else:
            entry[field] = [*entry[field][:index], value, *entry[field][index + 1:]]
    return table


def world_document(table: Mapping[str, Any]) -> str:
    """Return a world table as TOML text (top-level keys, inline tables and arrays).

    Examples
    --------
    >>> print(world_document({"name": "w", "boxes": [{"name": "b", "pose": [1.0, 2.0, 0.0]}]}))
    name = "w"
    boxes = [{name = "b", pose = [1.0, 2.0, 0.0]}]
    <BLANKLINE>
    """
    return "".join(f"{key} = {toml_value(value)}\n" for key, value in table.items())


def scenario_digest(spec: ScenarioSpec) -> str:
    """Return a SHA-256 of everything that defines a run of ``spec`` (not where it lies).

    The world counts by its file's content, so a moved checkout gives the same digest.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> a, b = load_scenario("pal1"), load_scenario("pal1", overrides=["seed=1"])
    >>> scenario_digest(a) == scenario_digest(a), scenario_digest(a) == scenario_digest(b)
    (True, False)
    """
    fields = dataclasses.asdict(spec)
    for name in LOADER_FIELDS:  # where it came from: no part of what runs
        fields.pop(name)
    if not spec.faults.active():
        # Fault-free runs keep the digests they had before faults existed.
        fields.pop("faults")
    fields["world"] = hashlib.sha256(world_path(spec.world).read_bytes()).hexdigest()
    text = json.dumps(fields, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


def _base_overrides(laps: int | None, overrides: Sequence[str]) -> list[str]:
    return [*overrides, *([f"laps={laps}"] if laps is not None else [])]


def check_campaign(
    scenarios: Sequence[str],
    policies: Sequence[str],
    variations: Sequence[Variation],
    *,
    seeds: Sequence[int] = (),
    laps: int | None = None,
    overrides: Sequence[str] = (),
) -> None:
    """Raise :class:`SpecError` unless every scenario takes every policy, seed and variation.

    Each scenario key is set to both ends of its range (or every choice, or a normal's
    mean) and checked like ``--set``; each world key must name a box or person of the
    scenario's world and a field it has, and each value must be one the field can take.
    Layouts are not checked here: a drawn value that breaks one rejects its sample.

    Examples
    --------
    >>> from scenarios.campaign.variations import parse_variation
    >>> check_campaign(["pal1"], ["adaptive"], [parse_variation("mapper.gte=uniform(0.1, 0.2)")])
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --vary: mapper.gte: unknown key (did you mean 'gate'?)
    >>> check_campaign(["pal1"], ["fast"], [])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --policy: policy: ...
    """
    base = _base_overrides(laps, overrides)
    for scenario in scenarios:
        path, table = _scenario_table(scenario)
        spec = scenario_from_toml(table, file=str(path), overrides=base, check_layout=False)
        for option, key, values in (("--policy", "policy", policies),
                                    ("--seeds", "seed", [max(seeds)] if seeds else [])):
            for value in values:
                try:
                    scenario_from_toml(table, file=str(path), check_layout=False,
                                       overrides=[*base, f"{key}={toml_value(value)}"])
                except SpecError as error:
                    raise SpecError(option, key, error.message) from None
        world_file = world_path(spec.world)
        world_table = read_toml(world_file)
        by_key = {variation.key: variation for variation in variations}
        for variation in variations:
            for value in variation.checked_values():
                try:
                    if variation.world_path is None:
                        setting = f"{variation.key}={toml_value(value)}"
                        scenario_from_toml(table, file=str(path), check_layout=False,
                                           overrides=[*base, setting])
                    else:
                        varied = _varied_world(world_table, {variation.key: value}, by_key,
                                               world_file.stem)
                        world_from_toml(varied, file=str(world_file))
                except SpecError as error:
                    if error.file == VARY_OPTION:
                        raise
                    raise _as_vary(error, variation.key) from None


def _layout_key(spec: ScenarioSpec) -> ScenarioSpec:
    # What the layout and field checks read: not the seed or the mapper's thresholds.
    return dataclasses.replace(spec, seed=0, mapper=MapperParams())


def plan_campaign(
    scenarios: Sequence[str],
    policies: Sequence[str],
    seeds: Sequence[int],
    variations: Sequence[Variation],
    samples: Sequence[Mapping[str, Any]],
    *,
    laps: int | None = None,
    overrides: Sequence[str] = (),
    worlds_dir: Path | None,
    read_files: dict[tuple[str, ...], tuple] | None = None,
) -> list[CampaignRun]:
    """Return every run, scenario by scenario, then policy, sample and seed.

    Writes the varied world of each sample that changes world objects into
    ``worlds_dir`` (which only such campaigns need); every run's scenario is checked in
    full (every lap's layout and the protective fields), once per distinct layout.
    ``read_files``, a dictionary the caller keeps, holds each scenario's and world's
    tables as first read: a caller that plans again (a falsification, once per sample)
    plans every time from the files as they were at the start.
    """
    base = _base_overrides(laps, overrides)
    by_key = {variation.key: variation for variation in variations}
    checked: dict[ScenarioSpec, str | None] = {}
    runs: list[CampaignRun] = []
    read = {} if read_files is None else read_files
    for scenario in scenarios:
        if (scenario, *base) not in read:
            path, table = _scenario_table(scenario)
            name = scenario_from_toml(table, file=str(path), overrides=base,
                                      check_layout=False)
            world_file = world_path(name.world)
            read[(scenario, *base)] = (path, table, name, world_file, read_toml(world_file))
        path, table, name, world_file, world_table = read[(scenario, *base)]
        # The world read once here is carried by every run's spec (to the workers too).
        worlds = {name.world: world_from_toml(world_table, file=str(world_file))}
        for policy in policies:
            for index, values in enumerate(samples):
                texts = [f"{key}={toml_value(value)}" for key, value in values.items()
                         if by_key[key].world_path is None]
                if any(by_key[key].world_path is not None for key in values):
                    varied_table = _varied_world(world_table, values, by_key, world_file.stem)
                    document = world_document(varied_table)
                    digest = hashlib.sha256(document.encode()).hexdigest()[:12]
                    varied = worlds_dir / f"{world_file.stem}-{digest}.toml"
                    if not varied.exists():
                        worlds_dir.mkdir(parents=True, exist_ok=True)
                        varied.write_text(document)
                    texts.append(f"world={toml_value(str(varied.absolute()))}")
                    with contextlib.suppress(SpecError):  # the check below names it
                        worlds[str(varied.absolute())] = world_from_toml(
                            varied_table, file=str(varied.absolute()))
                point = [*base, *texts, f"policy={policy}"]
                reason = None
                try:
                    spec = scenario_from_toml(table, file=str(path), overrides=point,
                                              check_layout=False)
                    spec = with_loaded_world(spec, worlds.get(spec.world))
                    layout = _layout_key(spec)
                    if layout not in checked:
                        try:
                            scenario_from_toml(table, file=str(path), overrides=point,
                                               worlds=worlds)
                            checked[layout] = None
                        except SpecError as error:
                            checked[layout] = str(error)
                    reason = checked[layout]
                except SpecError as error:
                    reason = str(_as_vary(error, error.key) if error.file == OVERRIDE_FILE
                                 else error)
                if reason is not None and worlds_dir is not None:
                    # Name a varied world as the campaign's folder holds it, wherever it is.
                    reason = reason.replace(f"{worlds_dir.absolute()}/", "worlds/")
                for seed in seeds:
                    run = (f"{name.name} {policy} sample={index} seed={seed}")
                    seeded = None
                    if reason is None:
                        seeded = dataclasses.replace(spec, seed=int(seed))
                    runs.append(CampaignRun(run, name.name, policy, int(seed), index,
                                            tuple(values.items()), seeded, reason,
                                            tuple(point)))
    return runs
