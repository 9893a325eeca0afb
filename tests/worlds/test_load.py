"""Loading worlds: a good file round-trips, every kind of bad file is one clear SpecError."""

from __future__ import annotations

import pickle
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from semistatic.errors import MEMORY
from semistatic.validation import FILE_KEY, bounds, from_table
from worlds import (
    BoxSpec,
    PathSpec,
    PersonSpec,
    PostSpec,
    SegmentSpec,
    SpecError,
    WallSpec,
    WorldSpec,
    bundled_worlds,
    load_world,
)

GOOD = """\
name = "tiny"
description = "a 6 m corridor"

walls = [
    { start = [0.0, -1.2], end = [6.0, -1.2] },
    { start = [0.0, 1.2], end = [6.0, 1.2], thickness = 0.2 },
]
posts = [
    { x = 1.0, y = -1.1 },
    { x = 3.0, y = 1.0, radius = 0.05 },
]

[[boxes]]
name = "carton"
size = [0.4, 0.4, 0.5]
pose = [3.0, -0.7, 0.0]

[[boxes]]
name = "crate"
size = [0.6, 0.4, 0.8]
pose = [4.5, 0.7, 0.3]

[[people]]
name = "walker"
waypoints = [[2.0, -1.0], [2.0, 1.0]]
enabled = false

[path]
speed = 0.5
knots = [[0.5, 0.0], [3.0, 0.0], [5.5, 0.0]]

[[path.segments]]
name = "first"
start_knot = 0
end_knot = 1
warning = [[0.25, -0.5], [1.4, -0.5], [1.4, 0.5], [0.25, 0.5]]
protective = [[0.25, -0.3], [0.6, -0.3], [0.6, 0.3], [0.25, 0.3]]

[[path.segments]]
name = "second"
start_knot = 1
end_knot = 2
warning = [[0.25, -0.4], [1.0, -0.4], [1.0, 0.4], [0.25, 0.4]]
protective = [[0.25, -0.25], [0.5, -0.25], [0.5, 0.25], [0.25, 0.25]]
"""


def write(tmp_path: Path, text: str, name: str = "world.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def edited(old: str, new: str) -> str:
    assert GOOD.count(old) == 1, f"test setup: {old!r} must occur once in GOOD"
    return GOOD.replace(old, new)


def load_error(path: Path | str) -> SpecError:
    with pytest.raises(SpecError) as info:
        load_world(path)
    error = info.value
    assert str(error) == f"{error.file}: {error.key}: {error.message}"
    assert str(path) in str(error)
    return error


def test_good_file_loads_every_field(tmp_path):
    world = load_world(write(tmp_path, GOOD))
    assert world.name == "tiny"
    assert world.source == str(tmp_path / "world.toml")
    assert world.walls[1] == WallSpec((0.0, 1.2), (6.0, 1.2), thickness=0.2)
    assert world.posts[1] == PostSpec(3.0, 1.0, radius=0.05)
    assert world.boxes[1] == BoxSpec("crate", (0.6, 0.4, 0.8), (4.5, 0.7, 0.3))
    assert world.people[0].waypoints == ((2.0, -1.0), (2.0, 1.0))
    assert world.active_people == ()
    assert world.path.speed == 0.5
    assert world.path.knots[2] == (5.5, 0.0)
    assert [segment.name for segment in world.path.segments] == ["first", "second"]
    assert world.path.segments[1].protective[1] == (0.5, -0.25)


def test_name_defaults_to_the_file_stem_and_lists_default_to_empty(tmp_path):
    text = GOOD.replace('name = "tiny"\n', "", 1)
    text = text[: text.index("[[boxes]]")] + text[text.index("[path]") :]
    world = load_world(write(tmp_path, text, "corridor.toml"))
    assert world.name == "corridor"
    assert world.boxes == ()
    assert world.people == ()


def test_bundled_name_and_path_load_the_same_world():
    name = bundled_worlds()[0]
    assert load_world(name) == load_world(load_world(name).source)


def test_specs_are_hashable_and_frozen():
    world = load_world("pal3")
    assert hash(world) == hash(load_world("pal3"))
    with pytest.raises(AttributeError):
        world.name = "other"  # type: ignore[misc]


@pytest.mark.parametrize(
    ("old", "new", "key", "fragment"),
    [
        pytest.param("walls = [", "wals = [", "wals", "did you mean 'walls'?", id="top-level"),
        pytest.param(
            'name = "crate"\nsize',
            'name = "crate"\nsise',
            "boxes[1].sise",
            "did you mean 'size'?",
            id="box",
        ),
        pytest.param(
            "{ x = 3.0, y = 1.0, radius",
            "{ x = 3.0, y = 1.0, raduis",
            "posts[1].raduis",
            "did you mean 'radius'?",
            id="inline-table",
        ),
        pytest.param(
            'name = "second"\nstart_knot',
            'name = "second"\nstrat_knot',
            "path.segments[1].strat_knot",
            "did you mean 'start_knot'?",
            id="segment",
        ),
        pytest.param("speed = 0.5", "sped = 0.5", "path.sped", "did you mean 'speed'?", id="path"),
    ],
)
def test_unknown_key_names_key_and_suggests(tmp_path, old, new, key, fragment):
    error = load_error(write(tmp_path, edited(old, new)))
    assert error.key == key
    assert fragment in error.message
    assert "unknown key" in error.message


def test_unknown_key_far_from_any_name_lists_the_allowed_keys(tmp_path):
    error = load_error(write(tmp_path, edited("speed = 0.5", "speed = 0.5\nzzz = 1")))
    assert error.key == "path.zzz"
    assert "did you mean" not in error.message
    assert "allowed keys: closed, knots, segments, speed" in error.message


@pytest.mark.parametrize(
    ("old", "new", "key", "fragment"),
    [
        pytest.param(
            "speed = 0.5",
            'speed = "fast"',
            "path.speed",
            "expected a number, got a string 'fast'",
            id="str-for-float",
        ),
        pytest.param(
            "{ x = 1.0, y = -1.1 }",
            "{ x = true, y = -1.1 }",
            "posts[0].x",
            "expected a number, got a boolean",
            id="bool-for-float",
        ),
        pytest.param(
            "start_knot = 1",
            "start_knot = 1.0",
            "path.segments[1].start_knot",
            "expected an integer, got a float",
            id="float-for-int",
        ),
        pytest.param(
            'name = "carton"', "name = 7", "boxes[0].name", "expected a string", id="int-for-str"
        ),
        pytest.param(
            "enabled = false",
            'enabled = "no"',
            "people[0].enabled",
            "expected true or false",
            id="str-for-bool",
        ),
        pytest.param(
            "size = [0.4, 0.4, 0.5]",
            "size = [0.4, 0.4]",
            "boxes[0].size",
            "expected a list of 3 numbers, got 2 value(s)",
            id="short-list",
        ),
        pytest.param(
            "size = [0.4, 0.4, 0.5]",
            "size = 0.4",
            "boxes[0].size",
            "expected a list of 3 numbers",
            id="scalar-for-list",
        ),
        pytest.param(
            "[0.5, 0.0], [3.0, 0.0]",
            '[0.5, 0.0], [3.0, "a"]',
            "path.knots[1][1]",
            "expected a number",
            id="knot-coordinate",
        ),
        pytest.param("x = 1.0, y = -1.1", "x = nan, y = -1.1", "posts[0].x", "finite", id="nan"),
    ],
)
def test_wrong_type_names_key(tmp_path, old, new, key, fragment):
    error = load_error(write(tmp_path, edited(old, new)))
    assert error.key == key
    assert fragment in error.message


@pytest.mark.parametrize(
    ("old", "new", "key", "fragment"),
    [
        pytest.param(
            "size = [0.4, 0.4, 0.5]",
            "size = [0.4, -0.4, 0.5]",
            "boxes[0].size",
            "every value must be > 0.0",
            id="negative-size",
        ),
        pytest.param(
            "size = [0.4, 0.4, 0.5]",
            "size = [0.4, 0.0, 0.5]",
            "boxes[0].size",
            "> 0.0",
            id="zero-size",
        ),
        pytest.param(
            "radius = 0.05",
            "radius = -0.05",
            "posts[1].radius",
            "must be > 0.0 and <= 2.0, got -0.05",
            id="negative-radius",
        ),
        pytest.param(
            "thickness = 0.2",
            "thickness = 0.2, remission = 1.5",
            "walls[1].remission",
            "must be >= 0.0 and <= 1.0",
            id="remission",
        ),
        pytest.param("speed = 0.5", "speed = 0.0", "path.speed", "must be > 0.0", id="zero-speed"),
        pytest.param(
            "start_knot = 1",
            "start_knot = -1",
            "path.segments[1].start_knot",
            ">= 0",
            id="negative-knot",
        ),
        pytest.param(
            "enabled = false",
            "enabled = false\nstart_time = -2.0",
            "people[0].start_time",
            ">= 0.0",
            id="negative-time",
        ),
    ],
)
def test_out_of_range_value_names_key(tmp_path, old, new, key, fragment):
    error = load_error(write(tmp_path, edited(old, new)))
    assert error.key == key
    assert fragment in error.message


def test_value_where_a_table_is_expected(tmp_path):
    text = edited('[[people]]\nname = "walker"\nwaypoints = [[2.0, -1.0], [2.0, 1.0]]\n', "")
    text = text.replace("enabled = false\n", "", 1).replace("walls = [", "people = [3]\nwalls = [")
    error = load_error(write(tmp_path, text))
    assert error.key == "people[0]"
    assert error.message == "expected a table, got an integer 3"


def test_missing_required_key(tmp_path):
    error = load_error(write(tmp_path, edited("pose = [4.5, 0.7, 0.3]\n", "")))
    assert (error.key, error.message) == ("boxes[1].pose", "missing required key")


def test_missing_file(tmp_path):
    error = load_error(tmp_path / "nowhere.toml")
    assert error.key == FILE_KEY
    assert "no such file" in error.message


def test_directory_is_not_a_world(tmp_path):
    error = load_error(tmp_path)
    assert error.key == FILE_KEY
    assert "directory" in error.message


def test_unknown_bundled_name_suggests_the_closest():
    error = load_error("pal11")
    assert error.key == FILE_KEY
    assert "did you mean 'pal1'?" in error.message
    assert "pal1, pal3, sim1, sim2" in error.message


def test_not_toml_reports_line_and_column(tmp_path):
    error = load_error(write(tmp_path, edited("speed = 0.5", "speed 0.5")))
    line = GOOD.splitlines().index("speed = 0.5") + 1
    assert error.key == f"line {line}, column 7"
    assert error.message.startswith("not valid TOML: ")


def test_binary_file_is_not_toml(tmp_path):
    path = tmp_path / "world.toml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe")
    error = load_error(path)
    assert error.key == FILE_KEY
    assert "not UTF-8" in error.message


def test_fewer_than_two_knots(tmp_path):
    text = edited("knots = [[0.5, 0.0], [3.0, 0.0], [5.5, 0.0]]", "knots = [[0.5, 0.0]]")
    error = load_error(write(tmp_path, text))
    assert (error.key, error.message) == ("path.knots", "needs at least 2 knots, got 1")


def test_repeated_knot(tmp_path):
    text = edited("[3.0, 0.0], [5.5, 0.0]]", "[3.0, 0.0], [3.0, 0.0]]")
    error = load_error(write(tmp_path, text))
    assert error.key == "path.knots[2]"
    assert "repeats the previous knot" in error.message


def test_overlapping_posts(tmp_path):
    error = load_error(write(tmp_path, edited("{ x = 3.0, y = 1.0,", "{ x = 1.05, y = -1.1,")))
    assert error.key == "posts[1]"
    assert "overlaps posts[0]" in error.message


def test_post_inside_a_wall(tmp_path):
    error = load_error(write(tmp_path, edited("{ x = 1.0, y = -1.1 }", "{ x = 1.0, y = -1.15 }")))
    assert error.key == "posts[0]"
    assert "overlaps walls[0]" in error.message


def test_segment_knot_index_out_of_range(tmp_path):
    error = load_error(write(tmp_path, edited("end_knot = 2", "end_knot = 5")))
    assert error.key == "path.segments[1].end_knot"
    assert "out of range: the path has 3 knots (indices 0..2)" in error.message


def test_segments_must_not_leave_gaps(tmp_path):
    error = load_error(write(tmp_path, edited("start_knot = 1", "start_knot = 0")))
    assert error.key == "path.segments[1].start_knot"
    assert "must be 1" in error.message


def test_segments_must_reach_the_last_knot(tmp_path):
    text = GOOD[: GOOD.index('[[path.segments]]\nname = "second"')].replace(
        "end_knot = 1", "end_knot = 1", 1
    )
    error = load_error(write(tmp_path, text))
    assert error.key == "path.segments[0].end_knot"
    assert "must end at the last knot (2)" in error.message


def test_segment_end_before_start(tmp_path):
    error = load_error(write(tmp_path, edited("end_knot = 2", "end_knot = 1")))
    assert error.key == "path.segments[1].end_knot"
    assert "greater than start_knot" in error.message


def test_duplicate_box_names(tmp_path):
    error = load_error(write(tmp_path, edited('name = "crate"', 'name = "carton"')))
    assert error.key == "boxes[1].name"
    assert "duplicate name 'carton'" in error.message


def test_non_simple_field_polygon(tmp_path):
    bow_tie = "warning = [[0.25, -0.4], [1.0, 0.4], [1.0, -0.4], [0.25, 0.4]]"
    error = load_error(
        write(
            tmp_path,
            edited("warning = [[0.25, -0.4], [1.0, -0.4], [1.0, 0.4], [0.25, 0.4]]", bow_tie),
        )
    )
    assert error.key == "path.segments[1].warning"
    assert "not simple" in error.message


@pytest.mark.parametrize(
    "polygon",
    [
        pytest.param("[]", id="no-vertices"),
        pytest.param("[[0.25, -0.3], [0.6, 0.3]]", id="two-vertices"),
        pytest.param("[[0.25, 0.0], [0.4, 0.0], [0.6, 0.0]]", id="collinear"),
    ],
)
def test_empty_field_polygon(tmp_path, polygon):
    text = edited(
        "protective = [[0.25, -0.3], [0.6, -0.3], [0.6, 0.3], [0.25, 0.3]]",
        f"protective = {polygon}",
    )
    error = load_error(write(tmp_path, text))
    assert error.key == "path.segments[0].protective"
    assert "at least 3 vertices" in error.message or "empty" in error.message


def test_protective_field_outside_warning_field(tmp_path):
    text = edited(
        "protective = [[0.25, -0.25], [0.5, -0.25], [0.5, 0.25], [0.25, 0.25]]",
        "protective = [[0.25, -0.25], [1.2, -0.25], [1.2, 0.25], [0.25, 0.25]]",
    )
    error = load_error(write(tmp_path, text))
    assert error.key == "path.segments[1].protective"
    assert "not inside the warning field" in error.message


def test_protective_field_sharing_the_warning_edge_is_inside():
    rectangle = [(0.25, -0.3), (0.6, -0.3), (0.6, 0.3), (0.25, 0.3)]
    segment = SegmentSpec("same", 0, 1, warning=rectangle, protective=rectangle)
    assert segment.protective == tuple(rectangle)


def test_spec_built_in_python_reports_memory_and_relative_key():
    with pytest.raises(SpecError) as info:
        BoxSpec("b", size=(0.4, -1.0, 0.4), pose=(0.0, 0.0, 0.0))
    assert (info.value.file, info.value.key) == (MEMORY, "size")


def test_spec_normalises_sequences_to_float_tuples():
    field = [[0.25, -0.3], [0.6, -0.3], [0.6, 0.3]]
    path = PathSpec(knots=[[0, 0], [2, 0]], segments=[SegmentSpec("s", 0, 1, field, field)])
    assert path.knots == ((0.0, 0.0), (2.0, 0.0))
    assert isinstance(path.segments, tuple)
    assert path.segments[0].warning[0] == (0.25, -0.3)


def test_enable_people_switches_on_only_the_named_and_rejects_typos():
    world = load_world("pal3")
    walker = world.people[0].name
    assert world.active_people == ()
    assert [p.name for p in world.enable_people(walker).active_people] == [walker]
    assert world.people[0].enabled is False  # the original is unchanged
    with pytest.raises(SpecError, match="did you mean"):
        world.enable_people(walker + "x")


def test_person_needs_a_waypoint():
    with pytest.raises(SpecError, match="waypoints: needs at least 1 waypoint"):
        PersonSpec("nobody", waypoints=[])


def test_world_rejects_duplicate_people():
    field = [(0.25, -0.3), (0.6, -0.3), (0.6, 0.3)]
    path = PathSpec([(0, 0), (2, 0)], [SegmentSpec("s", 0, 1, field, field)])
    person = PersonSpec("p", [(1.0, 1.0)])
    with pytest.raises(SpecError) as info:
        WorldSpec("w", [], [], [], [person, person], path)
    assert info.value.key == "people[1].name"


# The validation layer is generic (the scenario loader reuses it): exercise it directly.


@dataclass(frozen=True)
class Inner:
    count: int = field(default=1, metadata=bounds(ge=1))
    label: str | None = None


@dataclass(frozen=True)
class Outer:
    gains: tuple[float, float] = field(metadata=bounds(gt=0.0))
    inners: tuple[Inner, ...] = ()
    flag: bool = False


def test_from_table_builds_nested_dataclasses():
    table = {"gains": [1, 2.5], "inners": [{"count": 3, "label": "a"}, {}], "flag": True}
    assert from_table(Outer, table, file="s.toml", key="run") == Outer(
        (1.0, 2.5), (Inner(3, "a"), Inner()), True
    )


@pytest.mark.parametrize(
    ("table", "key", "fragment"),
    [
        pytest.param({"gains": [1, 1], "inners": [{"cont": 2}]}, "run.inners[0].cont", "'count'"),
        pytest.param({"gains": [1, 1], "inners": [{"count": 0}]}, "run.inners[0].count", ">= 1"),
        pytest.param(
            {"gains": [1, 1], "inners": [{"count": True}]}, "run.inners[0].count", "integer"
        ),
        pytest.param({"gains": [1, 1], "inners": [{"label": 5}]}, "run.inners[0].label", "string"),
        pytest.param({"gains": [1, -1]}, "run.gains", "every value must be > 0.0"),
        pytest.param({"gains": [1, float("inf")]}, "run.gains[1]", "finite"),
        pytest.param({"gains": [1, 1], "flag": 1}, "run.flag", "true or false"),
        pytest.param({"gains": [1, 1], "inners": {}}, "run.inners", "expected a list"),
        pytest.param({}, "run.gains", "missing required key"),
    ],
)
def test_from_table_names_the_bad_key(table, key, fragment):
    with pytest.raises(SpecError) as info:
        from_table(Outer, table, file="s.toml", key="run")
    assert (info.value.file, info.value.key) == ("s.toml", key)
    assert fragment in info.value.message


def test_from_table_fixed_fields_are_not_read_from_the_file():
    assert from_table(Outer, {}, file="s.toml", fixed={"gains": (1.0, 1.0)}).gains == (1.0, 1.0)
    with pytest.raises(SpecError, match="unknown key"):
        from_table(Outer, {"gains": [2, 2]}, file="s.toml", fixed={"gains": (1.0, 1.0)})


def test_spec_error_survives_pickling():
    error = SpecError("a.toml", "path.speed", "must be > 0.0, got -1.0")
    clone = pickle.loads(pickle.dumps(error))
    assert (clone.file, clone.key, clone.message, str(clone)) == (
        error.file,
        error.key,
        error.message,
        str(error),
    )


# --- names are printed: printable characters only; nesting is bounded ---------------------

@pytest.mark.parametrize(
    ("toml_name", "name", "bad"),
    [
        (r"\u001b[31mred", "\x1b[31mred", "\x1b"),  # a terminal colour sequence
        (r"two\nlines", "two\nlines", "\n"),
        (r"tab\there", "tab\there", "\t"),
        (r"nul\u0000", "nul\x00", "\x00"),
        (r"bidi\u202eevil", "bidi\u202eevil", "\u202e"),  # a format character (Cf)
    ],
    ids=["escape", "newline", "tab", "nul", "bidi-override"],
)
def test_world_name_with_an_unprintable_character_is_refused(tmp_path, toml_name, name, bad):
    error = load_error(write(tmp_path, edited('name = "tiny"', f'name = "{toml_name}"')))
    assert error.key == "name"
    position = name.index(bad)
    assert error.message == (f"{name!r} holds the unprintable character {bad!r} at position "
                             f"{position}; use printable characters only")
    assert bad not in str(error)  # shown escaped, never raw
    # A world built in code gets the same check.
    field = [(0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3)]
    path = PathSpec([(0, 0), (5, 0)], [SegmentSpec("a", 0, 1, field, field)])
    with pytest.raises(SpecError) as in_code:
        WorldSpec(name, walls=[], posts=[], boxes=[], people=[], path=path)
    assert (in_code.value.file, in_code.value.key, in_code.value.message) == (
        MEMORY, "name", error.message)


def test_world_name_may_be_any_printable_text(tmp_path):
    world = load_world(write(tmp_path, edited('name = "tiny"', 'name = "Halle Süd, Tor 2"')))
    assert world.name == "Halle Süd, Tor 2"


def test_a_world_nested_too_deep_is_refused_before_parsing(tmp_path):
    depth = 100_000
    text = GOOD + "deep = " + "[" * depth + "]" * depth + "\n"
    error = load_error(write(tmp_path, text))
    line = GOOD.count("\n") + 1  # the line after GOOD, where the nesting is
    assert (error.key, error.message) == (
        FILE_KEY, f"arrays and tables nest deeper than 64 levels (at line {line}); no input "
        "needs more than a few")
