"""Write ``docs/scenario-format.md`` from the specs themselves, so it cannot drift.

Every key of a scenario or world file is a field of a spec dataclass: its type, default
and bounds come from the field, its meaning (and the unit, written in parentheses) from
the class docstring's ``Parameters`` entry. A field without an entry is an error, so a
new key cannot go undocumented; a test checks that the file is current.

Regenerate with ``python -m scenarios.spec.format docs/scenario-format.md``.

Examples
--------
>>> print(render().splitlines()[0])
# Scenario and world files
>>> "| `laps` | integer | 5 |  | >= 1 and <= 1000 |" in render()
True
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
import sys
import types
import typing
from pathlib import Path
from typing import Any

from robots.presets import PRESETS
from scenarios.spec.scenario import (
    BOX_ACTIONS,
    LOADER_FIELDS,
    MINIMUM_FIELDS,
    POLICIES,
    BoxMove,
    Faults,
    Noise,
    Rates,
    SafetySettings,
    ScenarioSpec,
    VehicleSpec,
)
from semistatic.params import MapperParams
from semistatic.validation import SAFE_NAME
from worlds.spec import (
    TEST_PIECE_KINDS,
    TEST_PIECE_SIZES,
    TRIGGERS,
    BoxSpec,
    PathSpec,
    PersonSpec,
    PostSpec,
    SegmentSpec,
    TestPieceSpec,
    WallSpec,
    WorldSpec,
)

__all__ = ["SECTIONS", "field_rows", "render"]

SECTIONS = (
    ("Scenario file: top level", ScenarioSpec),
    ("Scenario `[rates]`", Rates),
    ("Scenario `[noise]`", Noise),
    ("Scenario `[safety]`", SafetySettings),
    ("Scenario `[faults]`", Faults),
    ("Scenario `[mapper]`", MapperParams),
    ("Scenario `[[moves]]`", BoxMove),
    ("Scenario `[[vehicles]]`", VehicleSpec),
    ("World file: top level", WorldSpec),
    ("World `walls = [...]` items", WallSpec),
    ("World `posts = [...]` items", PostSpec),
    ("World `[[boxes]]`", BoxSpec),
    ("World `[[people]]`", PersonSpec),
    ("World `[[test_pieces]]`", TestPieceSpec),
    ("World `[path]`", PathSpec),
    ("World `[[path.segments]]`", SegmentSpec),
)
"""The tables of the two file kinds, in the order the page lists them."""

NOT_IN_FILES = LOADER_FIELDS
"""Fields the loaders set themselves (never keys of a file)."""

CHOICES = {
    (ScenarioSpec, "policy"): POLICIES,
    (ScenarioSpec, "robot"): tuple(sorted(PRESETS)),
    (BoxMove, "action"): BOX_ACTIONS,
    (SafetySettings, "minimum_field"): MINIMUM_FIELDS,
    (PersonSpec, "trigger"): TRIGGERS,
    (TestPieceSpec, "kind"): TEST_PIECE_KINDS,
    (VehicleSpec, "robot"): tuple(sorted(PRESETS)),
}
"""Fields whose value is one of a few words (the rest come from ``Literal`` types)."""

FILE_DEFAULTS = {
    (ScenarioSpec, "name"): "the file's stem",
    (WorldSpec, "name"): "the file's stem",
    **{(WorldSpec, kind): "[]" for kind in ("walls", "posts", "boxes", "people")},
    # A test piece's size defaults by its kind (the standard's two pieces).
    **{(TestPieceSpec, name): ", ".join(f"{sizes[index]:g} {kind}"
                                        for kind, sizes in TEST_PIECE_SIZES.items())
       for index, name in enumerate(("diameter", "length"))},
}
"""Defaults the loaders supply where the dataclass has none."""

_UNIT = re.compile(r"\((m|s|Hz|rad|m/s|m2|m, m, rad)\)")
_ENTRY = re.compile(r"^(\w+)\n((?:    .*\n?)+)", re.M)

INTRO = """\
# Scenario and world files

Generated from the spec dataclasses by `python -m scenarios.spec.format
docs/scenario-format.md`; a test fails when this page is not current. Units are SI,
frames REP-103 (x forward, y left, z up, angles counter-clockwise in radians); world
coordinates are metres in the world frame, field polygons metres in the robot frame.

- A **scenario** (`semistatic run FILE.toml`, or a bundled name: `sim1`, `sim2`, `pal1`,
  `pal3a`, `pal3b`) names a world and says how to drive it. `world` is a bundled world
  name (`pal1`, `pal3`, `sim1`, `sim2`) or a `.toml` path; a relative path is resolved
  against the folder of the scenario file, not the working directory. `name` defaults to
  the file's stem.
- `--set KEY=VALUE` (e.g. `--set mapper.gate=0.15`, `--set policy=adaptive`) overrides a
  scenario key with the same checks as the file; `--laps` and `--seed` set `laps` and
  `seed`. An error names the option or the file and key: `error: FILE: KEY: what is wrong`.
- Every lap's layout is checked when the scenario loads (`semistatic check FILE`): at
  least 3 posts in view from every path pose, boxes clear of walls, of the swept robot
  footprint and of the protective fields but reaching into a warning field. A world's
  test pieces (the safety standard's personnel-detection pieces, meant to stand on the
  path) must be cut by every vehicle's safety-laser scan plane unless
  `safety.unseen_test_pieces = true`.
- Names that may become file names (`name`, box, person and segment names) are 1-64
  letters, digits, `_`, `-` or `.`, starting with a letter or digit.
- Numbers must be finite; `nan` and `inf` are refused everywhere. Unknown keys are refused
  with a "did you mean".
- Limits (each refused with one line naming the file, the key and the limit, before the
  file is parsed or the items are checked): a scenario or world file is a regular file
  (not a FIFO, a device or a directory) of at most 1 MiB; a world has at most 1000 walls,
  posts, boxes, people and test pieces each, and at most 10,000 path knots, segments,
  waypoints of a person or points of a field polygon; arrays and tables nest at most 64
  levels deep.
"""


def _type_name(hint: Any) -> str:
    options = [arg for arg in typing.get_args(hint) if arg is not type(None)]
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return _type_name(options[0])
    if typing.get_origin(hint) is typing.Literal:
        return "string"
    if dataclasses.is_dataclass(hint):
        return "table"
    names = {float: "float", int: "integer", str: "string", bool: "boolean"}
    if hint in names:
        return names[hint]
    args = typing.get_args(hint)
    if len(args) == 2 and args[1] is Ellipsis:
        item = args[0]
        if dataclasses.is_dataclass(item):
            return "array of tables"
        if typing.get_args(item) == (float, float):
            return "list of [x, y]"
        return f"list of {_type_name(item)}s"
    return f"list of {len(args)} floats"


def _default(cls: type, field: dataclasses.Field) -> str:
    if (cls, field.name) in FILE_DEFAULTS:
        return FILE_DEFAULTS[cls, field.name]
    if field.default is not dataclasses.MISSING:
        value = field.default
    elif field.default_factory is not dataclasses.MISSING:
        value = field.default_factory()
    else:
        return "required"
    if dataclasses.is_dataclass(value):
        return "see its table"
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return "[]" if not value else str(list(value))
    return "" if value is None else f"{value:g}" if isinstance(value, float) else str(value)


def _bounds(cls: type, field: dataclasses.Field, hint: Any) -> str:
    if (cls, field.name) in CHOICES:
        return "one of " + ", ".join(CHOICES[cls, field.name])
    if typing.get_origin(hint) is typing.Literal:
        return "one of " + ", ".join(typing.get_args(hint))
    parts = []
    valid = field.metadata.get("range")
    if valid is not None:
        parts.append(valid.describe())
    if field.metadata.get("safe_name"):
        parts.append(f"a name matching `{SAFE_NAME.pattern}`")
    return "; ".join(parts)


def _meanings(cls: type) -> dict[str, str]:
    doc = inspect.cleandoc(cls.__doc__ or "") + "\n"
    return {name: " ".join(text.split()) for name, text in _ENTRY.findall(doc)}


def field_rows(cls: type) -> list[tuple[str, str, str, str, str, str]]:
    """Return ``(key, type, default, unit, bounds, meaning)`` for each key of ``cls``.

    Raises ``ValueError`` for a field its class docstring does not describe.

    Examples
    --------
    >>> field_rows(Noise)[0][:5]
    ('odometry', 'float', '1', '', '>= 0.0 and <= 100.0')
    """
    hints = typing.get_type_hints(cls)
    meanings = _meanings(cls)
    rows = []
    for field in dataclasses.fields(cls):
        if field.name in NOT_IN_FILES or not field.init:
            continue
        if field.name not in meanings:
            raise ValueError(f"{cls.__name__}.{field.name} has no entry in the class docstring")
        meaning = meanings[field.name].replace("|", "\\|")
        unit = _UNIT.search(meaning)
        rows.append((field.name, _type_name(hints[field.name]), _default(cls, field),
                     unit[1] if unit else "", _bounds(cls, field, hints[field.name]), meaning))
    return rows


def render() -> str:
    """Return the Markdown of ``docs/scenario-format.md``."""
    lines = [INTRO]
    for title, cls in SECTIONS:
        lines += [f"## {title}", "", "| key | type | default | unit | bounds | meaning |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| `{key}` | {kind} | {default} | {unit} | {bounds} | {meaning} |"
                  for key, kind, default, unit, bounds, meaning in field_rows(cls)]
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/scenario-format.md")
    target.write_text(render())
    print(f"wrote {target}")
