"""Turn TOML tables into frozen dataclasses, or say exactly which key is wrong and why.

This layer is generic: nothing here knows about worlds, robots or scenarios, which all
use it. It reads a TOML file with ``tomllib`` (never ``eval``), :func:`from_table` builds
any frozen dataclass from a table and :func:`check_fields` validates one built in code,
both driven by the dataclass's own field types:

- ``float``, ``int``, ``str``, ``bool``: checked strictly (``true`` is not a number,
  ``1.5`` is not an int, an int is accepted for a float; ``nan``/``inf`` are rejected);
- ``tuple[float, float, float]``: a list of exactly 3 numbers;
- ``tuple[X, ...]``: a list whose items are converted as ``X``;
- a nested dataclass: a (inline) table, converted recursively;
- ``Range`` in a field's metadata (``field(metadata=bounds(gt=0.0))``) range-checks
  the value, or every number in it; :func:`unlimited` also lets code pass ``math.inf``.

Unknown keys are rejected at every level with a difflib "did you mean" suggestion.
Errors raised by a dataclass's ``__post_init__`` as :class:`SpecError` with a key
relative to the object are re-anchored at the object's place in the file.

Examples
--------
>>> from dataclasses import dataclass, field
>>> @dataclass(frozen=True)
... class Box:
...     name: str
...     size: tuple[float, float, float] = field(metadata=bounds(gt=0.0))
>>> from_table(Box, {"name": "a", "size": [0.4, 0.4, 0.5]}, file="w.toml", key="boxes[0]")
Box(name='a', size=(0.4, 0.4, 0.5))
>>> from_table(Box, {"name": "a", "sise": [1, 1, 1]}, file="w.toml", key="boxes[0]")
Traceback (most recent call last):
...
semistatic.errors.SpecError: w.toml: boxes[0].sise: unknown key (did you mean 'size'?); \
allowed keys: name, size
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import json
import math
import re
import tomllib
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from semistatic.errors import MEMORY, SpecError, join_key
from semistatic.inputs import FILE_KEY, MAX_SPEC_BYTES, read_bounded

__all__ = [
    "FILE_KEY",
    "Range",
    "as_bool",
    "as_float",
    "as_floats",
    "as_int",
    "as_str",
    "as_table",
    "bounds",
    "check_fields",
    "check_nesting",
    "check_printable",
    "convert",
    "did_you_mean",
    "from_table",
    "loads_json",
    "or_object",
    "printable",
    "read_toml",
    "reject_unknown_keys",
    "safe_name",
    "unlimited",
]


SUGGESTION_CUTOFF = 0.6
"""difflib similarity above which a known name is offered as "did you mean"."""

SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
"""Names that may become file or folder names: no separators, no leading dot, <= 64 chars."""

_TOML_POSITION = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")

MAX_NESTING = 64
"""Deepest nesting of arrays and tables a TOML or JSON input may have.

Real files nest fewer than 10 levels; the parsers recurse once per level and die of a
``RecursionError`` (tomllib near 500 levels, json near 1000), and so would the code that
walks what they return.
"""

# The tokens that decide the nesting: strings and comments (whose brackets do not count),
# then the brackets. The leftmost match wins, so a quote or a ``#`` inside a string never
# starts a token of its own.
_NESTING_TOKENS = {
    "toml": re.compile("|".join([
        r'"""(?:[^\\]|\\.)*?"{3,5}',  # multi-line basic string (may end in 1-2 quotes)
        r"'''.*?'{3,5}",  # multi-line literal string
        r'"(?:[^"\\\n]|\\[^\n])*"',  # basic string
        r"'[^'\n]*'",  # literal string
        r"#[^\n]*",  # comment
        r"[\[\]{}]",
    ]), re.DOTALL),
    "json": re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', re.DOTALL),
}


@dataclass(frozen=True)
class Range:
    """Bounds a number must satisfy; ``None`` means unbounded on that side.

    ``fix`` tells the user what a valid value looks like (units, a typical figure); it
    ends every out-of-range message.

    Examples
    --------
    >>> Range(gt=0.0).describe()
    '> 0.0'
    >>> Range(ge=0.0, le=1.0).contains(1.5)
    False
    >>> Range(gt=0.0, fix="metres, e.g. 0.1").complaint(-1.0)
    'must be > 0.0, got -1.0 (metres, e.g. 0.1)'
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    fix: str = ""

    def contains(self, value: float) -> bool:
        """Return whether ``value`` satisfies every bound."""
        return not (
            (self.gt is not None and not value > self.gt)
            or (self.ge is not None and not value >= self.ge)
            or (self.lt is not None and not value < self.lt)
            or (self.le is not None and not value <= self.le)
        )

    def describe(self) -> str:
        """Return the bounds as text, e.g. ``'>= 0.0 and <= 1.0'``."""
        parts = [
            f"{symbol} {bound}"
            for symbol, bound in ((">", self.gt), (">=", self.ge), ("<", self.lt), ("<=", self.le))
            if bound is not None
        ]
        return " and ".join(parts) if parts else "any value"

    def complaint(self, got: Any, *, every: bool = False) -> str:
        """Return the message for a value ``got`` outside the bounds (``every`` for lists)."""
        subject = "every value must be" if every else "must be"
        fix = f" ({self.fix})" if self.fix else ""
        return f"{subject} {self.describe()}, got {got}{fix}"


def bounds(
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    fix: str = "",
) -> dict[str, Range]:
    """Return dataclass field metadata that range-checks the field on load.

    ``fix`` (units, a typical value) is appended to the message of a value out of range.

    Examples
    --------
    >>> bounds(gt=0.0)
    {'range': Range(gt=0.0, ge=None, lt=None, le=None, fix='')}
    """
    return {"range": Range(gt=gt, ge=ge, lt=lt, le=le, fix=fix)}


def unlimited() -> dict[str, bool]:
    """Return field metadata for a limit that code may switch off with ``math.inf``.

    Combine it with :func:`bounds`: ``metadata={**bounds(gt=0.0, le=20.0), **unlimited()}``.
    Only ``+inf`` passes unchecked, and only in :func:`check_fields` (a file's ``inf``
    is still rejected); any finite value must satisfy the bounds.

    Examples
    --------
    >>> unlimited()
    {'unlimited': True}
    """
    return {"unlimited": True}


def safe_name() -> dict[str, bool]:
    """Return field metadata for a name that may become a path (see ``SAFE_NAME``).

    Examples
    --------
    >>> safe_name()
    {'safe_name': True}
    """
    return {"safe_name": True}


def or_object() -> dict[str, bool]:
    """Return field metadata for a plain field that code may also set to an object.

    A file only holds the plain value (a policy's name, say); a spec built in Python may
    pass an object instead (the policy itself), which :func:`check_fields` leaves to the
    code that uses it.

    Examples
    --------
    >>> or_object()
    {'or_object': True}
    """
    return {"or_object": True}


def printable() -> dict[str, bool]:
    """Return field metadata for a name that is printed: see :func:`check_printable`.

    Examples
    --------
    >>> printable()
    {'printable': True}
    """
    return {"printable": True}


def check_printable(value: str, *, file: str, key: str) -> str:
    r"""Return ``value`` unless it holds a character that is not printable.

    Names are printed as they are; an escape sequence in one would recolour or rewrite
    the terminal, a line break would split a one-line message. ``" "`` passes; tabs, line
    breaks, ESC, the other control and format characters and the other spaces do not
    (:meth:`str.isprintable`). The message shows the name escaped (``repr``), never raw.

    Examples
    --------
    >>> check_printable("tiny hall", file="w.toml", key="name")
    'tiny hall'
    >>> check_printable("\x1b[31mred", file="w.toml", key="name")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: w.toml: name: '\x1b[31mred' holds the unprintable character ...
    """
    for position, char in enumerate(value):
        if not char.isprintable():
            raise SpecError(file, key, f"{value!r} holds the unprintable character {char!r} at "
                            f"position {position}; use printable characters only")
    return value


def check_nesting(text: str, *, file: str, key: str = FILE_KEY, syntax: str = "toml") -> None:
    """Raise :class:`SpecError` if arrays and tables in ``text`` nest deeper than allowed.

    The limit is ``MAX_NESTING`` (64) levels.

    Call it before parsing user TOML (``syntax="toml"``) or JSON (``"json"``): the
    parsers recurse once per level, so a file of 100000 ``[`` would end them in a
    ``RecursionError`` instead of one error line. Brackets inside strings and comments
    do not count; the scan is a regular expression over the text, and skipped entirely
    when the text opens too few brackets to nest that deep.

    Examples
    --------
    >>> check_nesting('knots = [[0, 0], [1, 2]]  # "[[[" in a comment', file="w.toml")
    >>> check_nesting("[" * 65 + "]" * 65, file="m.json", syntax="json")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: m.json: <file>: arrays and tables nest deeper than 64 \
levels (at line 1); no input needs more than a few
    """
    if text.count("[") + text.count("{") <= MAX_NESTING:
        return  # it cannot nest deeper than it opens: most files end here
    depth = 0
    for token in _NESTING_TOKENS[syntax].finditer(text):
        bracket = token.group()
        if bracket in ("[", "{"):
            depth += 1
            if depth > MAX_NESTING:
                line = text.count("\n", 0, token.start()) + 1
                raise SpecError(file, key, f"arrays and tables nest deeper than {MAX_NESTING} "
                                f"levels (at line {line}); no input needs more than a few")
        elif bracket in ("]", "}"):
            # A stray closer (a broken file) must not hide the nesting that follows it.
            depth = max(depth - 1, 0)


def loads_json(text: str, *, file: str, key: str = FILE_KEY) -> Any:
    """Parse user JSON ``text``, refusing deep nesting first (:func:`check_nesting`).

    Malformed JSON raises ``json.JSONDecodeError`` as :func:`json.loads` does.

    Examples
    --------
    >>> loads_json('{"kind": "campaign", "seeds": [0, 1]}', file="manifest.json")
    {'kind': 'campaign', 'seeds': [0, 1]}
    >>> loads_json('{"a": ' + "[" * 100000, file="manifest.json")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: manifest.json: <file>: arrays and tables nest deeper than 64 ...
    """
    check_nesting(text, file=file, key=key, syntax="json")
    return json.loads(text)


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the closest candidate, or ``""``.

    Examples
    --------
    >>> did_you_mean("thicknes", ["thickness", "height"])
    " (did you mean 'thickness'?)"
    >>> did_you_mean("zzz", ["thickness"])
    ''
    """
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=SUGGESTION_CUTOFF)
    return f" (did you mean '{close[0]}'?)" if close else ""


def _describe(value: Any) -> str:
    kind = {
        bool: "a boolean",
        int: "an integer",
        float: "a float",
        str: "a string",
        list: "a list",
        dict: "a table",
    }.get(type(value), type(value).__name__)
    text = repr(value)
    return f"{kind} {text}" if len(text) <= 40 else kind


def reject_unknown_keys(
    table: Mapping[str, Any], allowed: Iterable[str], *, file: str, key: str
) -> None:
    """Raise :class:`SpecError` for the first key of ``table`` not in ``allowed``.

    Examples
    --------
    >>> reject_unknown_keys({"radius": 1.0}, ["radius", "height"], file="f", key="posts[0]")
    >>> reject_unknown_keys({"radus": 1.0}, ["radius", "height"], file="f", key="posts[0]")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: f: posts[0].radus: unknown key (did you mean 'radius'?); \
allowed keys: height, radius
    """
    allowed = sorted(allowed)
    for name in table:
        if name not in allowed:
            raise SpecError(
                file,
                join_key(key, name),
                f"unknown key{did_you_mean(name, allowed)}; allowed keys: {', '.join(allowed)}",
            )


def as_table(value: Any, *, file: str, key: str) -> dict[str, Any]:
    """Return ``value`` if it is a TOML table, else raise :class:`SpecError`.

    Examples
    --------
    >>> as_table({"a": 1}, file="f", key="path")
    {'a': 1}
    """
    if not isinstance(value, dict):
        raise SpecError(file, key, f"expected a table, got {_describe(value)}")
    return value


def _check_range(value: float, valid: Range | None, *, file: str, key: str) -> None:
    if valid is not None and not valid.contains(value):
        raise SpecError(file, key, valid.complaint(value))


def as_float(value: Any, *, file: str, key: str, valid: Range | None = None) -> float:
    """Return ``value`` as a finite float (ints accepted, booleans not), range-checked.

    Examples
    --------
    >>> as_float(2, file="f", key="speed", valid=Range(gt=0.0))
    2.0
    >>> as_float(-1.0, file="f", key="speed", valid=Range(gt=0.0))
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: f: speed: must be > 0.0, got -1.0
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SpecError(file, key, f"expected a number, got {_describe(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise SpecError(file, key, f"must be a finite number, got {number}")
    _check_range(number, valid, file=file, key=key)
    return number


def as_int(value: Any, *, file: str, key: str, valid: Range | None = None) -> int:
    """Return ``value`` if it is an integer (not a boolean, not a float), range-checked.

    Examples
    --------
    >>> as_int(3, file="f", key="end_knot")
    3
    >>> as_int(3.0, file="f", key="end_knot")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: f: end_knot: expected an integer, got a float 3.0
    """
    if isinstance(value, bool) or not isinstance(value, int):
        raise SpecError(file, key, f"expected an integer, got {_describe(value)}")
    _check_range(value, valid, file=file, key=key)
    return value


def as_str(value: Any, *, file: str, key: str) -> str:
    """Return ``value`` if it is a string.

    Examples
    --------
    >>> as_str("box_a", file="f", key="name")
    'box_a'
    """
    if not isinstance(value, str):
        raise SpecError(file, key, f"expected a string, got {_describe(value)}")
    return value


def as_bool(value: Any, *, file: str, key: str) -> bool:
    """Return ``value`` if it is a boolean (``true``/``false``, not 0/1).

    Examples
    --------
    >>> as_bool(True, file="f", key="loop")
    True
    """
    if not isinstance(value, bool):
        raise SpecError(file, key, f"expected true or false, got {_describe(value)}")
    return value


def as_floats(
    value: Any, n: int, *, file: str, key: str, valid: Range | None = None
) -> tuple[float, ...]:
    """Return ``value`` as a tuple of exactly ``n`` finite floats, each range-checked.

    Examples
    --------
    >>> as_floats([1, 2.5], 2, file="f", key="start")
    (1.0, 2.5)
    >>> as_floats([1.0], 2, file="f", key="start")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: f: start: expected a list of 2 numbers, got 1 value(s)
    """
    if not isinstance(value, list):
        raise SpecError(file, key, f"expected a list of {n} numbers, got {_describe(value)}")
    if len(value) != n:
        raise SpecError(file, key, f"expected a list of {n} numbers, got {len(value)} value(s)")
    numbers = tuple(
        as_float(item, file=file, key=join_key(key, f"[{index}]"))
        for index, item in enumerate(value)
    )
    for number in numbers:
        if valid is not None and not valid.contains(number):
            raise SpecError(file, key, valid.complaint(list(numbers), every=True))
    return numbers


def convert(hint: Any, value: Any, *, file: str, key: str, valid: Range | None = None) -> Any:
    """Convert a TOML ``value`` to the Python type ``hint`` or raise :class:`SpecError`.

    Supports ``float``, ``int``, ``str``, ``bool``, ``X | None``, fixed-length tuples of
    floats, ``tuple[X, ...]`` and dataclasses (via :func:`from_table`).

    Examples
    --------
    >>> convert(tuple[tuple[float, float], ...], [[0, 0], [1, 2]], file="f", key="knots")
    ((0.0, 0.0), (1.0, 2.0))
    """
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = [arg for arg in typing.get_args(hint) if arg is not type(None)]
        if len(options) != 1:
            raise TypeError(f"convert: unsupported union {hint}")
        return convert(options[0], value, file=file, key=key, valid=valid)
    if hint is float:
        return as_float(value, file=file, key=key, valid=valid)
    if hint is int:
        return as_int(value, file=file, key=key, valid=valid)
    if hint is str:
        return as_str(value, file=file, key=key)
    if hint is bool:
        return as_bool(value, file=file, key=key)
    if dataclasses.is_dataclass(hint):
        return from_table(hint, value, file=file, key=key)
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            if not isinstance(value, list):
                raise SpecError(file, key, f"expected a list, got {_describe(value)}")
            return tuple(
                convert(args[0], item, file=file, key=join_key(key, f"[{index}]"), valid=valid)
                for index, item in enumerate(value)
            )
        if all(arg is float for arg in args):
            return as_floats(value, len(args), file=file, key=key, valid=valid)
    raise TypeError(f"convert: unsupported field type {hint} at {key!r}")


def from_table(
    cls: type,
    table: Any,
    *,
    file: str,
    key: str = "",
    fixed: Mapping[str, Any] | None = None,
) -> Any:
    """Build the dataclass ``cls`` from a TOML table, validating every key.

    Parameters
    ----------
    cls
        A dataclass; its field types drive the conversion (see :func:`convert`).
    table
        The parsed TOML value (must be a table).
    file, key
        Where the table comes from, for error messages (``key=""`` for the root).
    fixed
        Field values supplied by the caller, not read from the file (such keys in the
        table are rejected as unknown).

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class Post:
    ...     x: float
    ...     radius: float = 0.04
    >>> from_table(Post, {"x": 1}, file="f", key="posts[0]")
    Post(x=1.0, radius=0.04)
    >>> from_table(Post, {}, file="f", key="posts[0]")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: f: posts[0].x: missing required key
    """
    fixed = dict(fixed or {})
    table = as_table(table, file=file, key=key)
    hints = typing.get_type_hints(cls)
    fields = [field for field in dataclasses.fields(cls) if field.init]
    readable = [field for field in fields if field.name not in fixed]
    reject_unknown_keys(table, (field.name for field in readable), file=file, key=key)
    kwargs = dict(fixed)
    for field in readable:
        field_key = join_key(key, field.name)
        if field.name in table:
            kwargs[field.name] = convert(
                hints[field.name],
                table[field.name],
                file=file,
                key=field_key,
                valid=field.metadata.get("range"),
            )
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise SpecError(file, field_key, "missing required key")
    try:
        return cls(**kwargs)
    except SpecError as error:
        raise error.located(file, key) from None


@functools.cache
def _checked_fields(cls: type) -> tuple[tuple[str, Any, Mapping[str, Any]], ...]:
    """Return ``(name, type hint, metadata)`` of the fields :func:`check_fields` converts."""
    hints = typing.get_type_hints(cls)
    return tuple(
        (field.name, hints[field.name], field.metadata)
        for field in dataclasses.fields(cls)
        if field.init and _is_plain(hints[field.name])
    )


def _is_plain(hint: Any) -> bool:
    """Whether ``hint`` is a number, string or boolean, a tuple of them, or optional."""
    if hint in (float, int, str, bool):
        return True
    origin = typing.get_origin(hint)
    args = [arg for arg in typing.get_args(hint) if arg is not type(None) and arg is not Ellipsis]
    if origin in (typing.Union, types.UnionType, tuple):
        return bool(args) and all(_is_plain(arg) for arg in args)
    return False


def _as_toml(value: Any) -> Any:
    """Return a Python-built value as the TOML parser would give it (lists, plain numbers)."""
    if isinstance(value, np.ndarray | tuple | list):
        return [_as_toml(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def check_fields(obj: Any) -> None:
    """Validate a dataclass's plain fields exactly as the loader does, in place.

    Numbers, strings, booleans and tuples of them are converted with :func:`convert`
    against the field's type and range metadata, so a spec built in Python fails with
    the same message as a file (its file reads ``<memory>``, its key is the field's
    name); a field with :func:`safe_name` metadata must match ``SAFE_NAME``, one with
    :func:`printable` metadata must pass :func:`check_printable`, one with
    :func:`unlimited` metadata may also be ``math.inf``. Nested dataclasses validate
    themselves. Call it first in ``__post_init__``.

    Examples
    --------
    >>> from dataclasses import dataclass, field
    >>> @dataclass(frozen=True)
    ... class Wheel:
    ...     radius: float = field(default=0.1, metadata=bounds(gt=0.0, le=1.0))
    ...     def __post_init__(self):
    ...         check_fields(self)
    >>> Wheel(radius=2).radius
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: radius: must be > 0.0 and <= 1.0, got 2.0
    >>> Wheel(radius=np.float32(0.5)).radius
    0.5
    """
    for name, hint, metadata in _checked_fields(type(obj)):
        given = getattr(obj, name)
        if given is None and type(None) in typing.get_args(hint):
            continue
        if metadata.get("or_object") and not isinstance(given, str | int | float | bool):
            continue
        if metadata.get("unlimited") and isinstance(given, float) and given == math.inf:
            object.__setattr__(obj, name, math.inf)
            continue
        value = convert(hint, _as_toml(given), file=MEMORY, key=name, valid=metadata.get("range"))
        if metadata.get("printable"):
            check_printable(value, file=MEMORY, key=name)
        if metadata.get("safe_name") and not SAFE_NAME.fullmatch(value):
            raise SpecError(
                MEMORY, name,
                f"{value!r} is not a usable name: use 1-64 letters, digits, '_', '-' or '.', "
                "starting with a letter or digit (it may become a file name)",
            )
        object.__setattr__(obj, name, value)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file, reporting a missing file or a syntax error as :class:`SpecError`.

    A syntax error is reported at key ``"line L, column C"`` with tomllib's message;
    arrays and tables nested too deep for the parser, before it starts
    (:func:`check_nesting`).

    Examples
    --------
    >>> read_toml("/no/such/world.toml")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: /no/such/world.toml: <file>: no such file
    """
    path = Path(path)
    # A regular file of at most MAX_SPEC_BYTES, checked before it is opened (a FIFO).
    raw = read_bounded(path, limit=MAX_SPEC_BYTES, what=".toml file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SpecError(
            str(path), FILE_KEY, f"not a TOML file: not UTF-8 text (byte {error.start})"
        ) from None
    check_nesting(text, file=str(path))
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        message = str(error)
        position = _TOML_POSITION.search(message)
        where = f"line {position[1]}, column {position[2]}" if position else FILE_KEY
        reason = _TOML_POSITION.sub("", message) if position else message
        raise SpecError(str(path), where, f"not valid TOML: {reason}") from None
