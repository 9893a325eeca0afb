"""The shared spec validation layer: a bound's fix, unlimited limits, file/code parity."""

import json
import math
import tomllib
from dataclasses import dataclass, field

import pytest

from semistatic.errors import MEMORY, SpecError
from semistatic.validation import (
    FILE_KEY,
    bounds,
    check_fields,
    check_nesting,
    check_printable,
    from_table,
    loads_json,
    unlimited,
)


@dataclass(frozen=True)
class Drive:
    """A toy spec: one bounded number with a fix and one limit that may be switched off."""

    radius: float = field(default=0.1, metadata=bounds(gt=0.0, le=2.0, fix="metres, e.g. 0.1"))
    top_speed: float = field(default=1.0, metadata={**bounds(gt=0.0, le=20.0), **unlimited()})

    def __post_init__(self):
        check_fields(self)


@pytest.mark.parametrize(
    ("changes", "key", "message"),
    [
        ({"radius": 3.0}, "radius", "must be > 0.0 and <= 2.0, got 3.0 (metres, e.g. 0.1)"),
        ({"top_speed": 25.0}, "top_speed", "must be > 0.0 and <= 20.0, got 25.0"),
        ({"top_speed": -math.inf}, "top_speed", "must be a finite number, got -inf"),
        ({"top_speed": math.nan}, "top_speed", "must be a finite number, got nan"),
    ],
)
def test_code_and_file_give_the_same_message(changes, key, message):
    with pytest.raises(SpecError) as in_code:
        Drive(**changes)
    assert (in_code.value.file, in_code.value.key, in_code.value.message) == (MEMORY, key, message)
    with pytest.raises(SpecError) as from_file:
        from_table(Drive, changes, file="drive.toml", key="drive")
    assert str(from_file.value) == f"drive.toml: drive.{key}: {message}"


def test_an_unlimited_field_takes_plus_inf_only_in_code():
    assert Drive(top_speed=math.inf).top_speed == math.inf
    assert type(Drive(top_speed=2).top_speed) is float
    # A file never switches a limit off: inf in TOML stays an error there.
    with pytest.raises(SpecError, match="finite"):
        from_table(Drive, {"top_speed": math.inf}, file="drive.toml")


# --- nesting: bounded before a parser recurses --------------------------------------------

DEEP = "arrays and tables nest deeper than 64 levels"


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


def test_64_levels_pass_and_parse_65_are_refused():
    check_nesting("a = " + _nested(64), file="f.toml")
    check_nesting(_nested(64), file="f.json", syntax="json")
    # The limit is one the parsers and the code after them handle with room to spare.
    assert tomllib.loads("a = " + _nested(64))["a"] != []
    assert json.loads(_nested(64)) != []
    for syntax in ("toml", "json"):
        with pytest.raises(SpecError) as info:
            check_nesting("a = " + _nested(65) if syntax == "toml" else _nested(65),
                          file="f", syntax=syntax)
        assert (info.value.file, info.value.key) == ("f", FILE_KEY)
        assert info.value.message.startswith(f"{DEEP} (at line 1)")


def test_inline_tables_count_as_levels():
    with pytest.raises(SpecError, match=DEEP):
        check_nesting("a = " + "{b = " * 65 + "}" * 65, file="f.toml")
    with pytest.raises(SpecError, match=DEEP):
        check_nesting('{"a": ' * 65 + "1" + "}" * 65, file="f.json", syntax="json")


@pytest.mark.parametrize(
    "text",
    [
        'a = "' + "[" * 100 + '"',  # basic string
        'a = "\\\"' + "[" * 100 + '"',  # escaped quote and backslash inside it
        "a = '" + "[" * 100 + "'",  # literal string
        'a = """\n' + "[" * 100 + '\n"""',  # multi-line basic string
        'a = """x""""\nb = "' + "[" * 100 + '"',  # ends in one extra quote
        "a = '''\n" + "{" * 100 + "\n'''",  # multi-line literal string
        "# " + "[" * 100,  # comment
        '"[[" = 1\n' + "[[t]]\n" * 100,  # quoted key, headers of arrays of tables
    ],
    ids=["basic", "escapes", "literal", "multi-line", "extra-quote", "multi-literal",
         "comment", "headers"],
)
def test_brackets_in_toml_strings_and_comments_do_not_count(text):
    check_nesting(text, file="f.toml")
    tomllib.loads(text)  # and each is TOML the parser reads


def test_brackets_in_json_strings_do_not_count():
    text = json.dumps({"a": "[" * 100, "b": '\\"{' * 100, "c": [[1]]})
    assert loads_json(text, file="m.json") == json.loads(text)


def test_stray_closers_do_not_hide_the_nesting_after_them():
    with pytest.raises(SpecError, match=r"\(at line 2\)"):
        check_nesting("]" * 100 + "\n" + "[" * 65, file="f.json", syntax="json")


def test_deep_json_is_refused_before_json_recurses():
    with pytest.raises(SpecError) as info:
        loads_json('{"a": ' + _nested(100_000) + "}", file="--recording", key="manifest.json")
    assert str(info.value).startswith(f"--recording: manifest.json: {DEEP} (at line 1)")


# --- printable names ------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["pal1", "Halle Süd 2", "Zone (B)", "α-β"])
def test_printable_names_pass(name):
    assert check_printable(name, file="f", key="name") == name


@pytest.mark.parametrize(
    ("name", "bad", "position"),
    [("\x1b[31mred", "\x1b", 0), ("a\nb", "\n", 1), ("a\rb", "\r", 1), ("ab\x7f", "\x7f", 2),
     ("a\u200bb", "\u200b", 1), ("a\u00a0b", "\xa0", 1)],
    ids=["escape", "newline", "cr", "delete", "zero-width-space", "no-break-space"],
)
def test_unprintable_names_are_shown_escaped(name, bad, position):
    with pytest.raises(SpecError) as info:
        check_printable(name, file="w.toml", key="boxes[0].name")
    assert str(info.value) == (f"w.toml: boxes[0].name: {name!r} holds the unprintable "
                               f"character {bad!r} at position {position}; use printable "
                               "characters only")
    assert bad not in str(info.value)
