"""Turn TOML tables into frozen dataclasses, or say exactly which key is wrong and why.

This layer is generic: nothing here knows about worlds. It reads a TOML file with
``tomllib`` (never ``eval``), and :func:`from_table` builds any frozen dataclass from a
table, driven by the dataclass's own field types:

- ``float``, ``int``, ``str``, ``bool``: checked strictly (``true`` is not a number,
  ``1.5`` is not an int, an int is accepted for a float; ``nan``/``inf`` are rejected);
- ``tuple[float, float, float]``: a list of exactly 3 numbers;
- ``tuple[X, ...]``: a list whose items are converted as ``X``;
- a nested dataclass: a (inline) table, converted recursively;
- ``Range`` in a field's metadata (``field(metadata=bounds(gt=0.0))``) range-checks
  the value, or every number in it.

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
worlds.errors.SpecError: w.toml: boxes[0].sise: unknown key (did you mean 'size'?); \
allowed keys: name, size
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
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

from worlds.errors import MEMORY, SpecError, join_key

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
    "convert",
    "did_you_mean",
    "from_table",
    "read_toml",
    "reject_unknown_keys",
    "safe_name",
]

FILE_KEY = "<file>"
"""The key reported for problems with the file as a whole (missing, unreadable)."""

SUGGESTION_CUTOFF = 0.6
"""difflib similarity above which a known name is offered as "did you mean"."""

SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
"""Names that may become file or folder names: no separators, no leading dot, <= 64 chars."""

_TOML_POSITION = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")


@dataclass(frozen=True)
class Range:
    """Bounds a number must satisfy; ``None`` means unbounded on that side.

    Examples
    --------
    >>> Range(gt=0.0).describe()
    '> 0.0'
    >>> Range(ge=0.0, le=1.0).contains(1.5)
    False
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None

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


def bounds(
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
) -> dict[str, Range]:
    """Return dataclass field metadata that range-checks the field on load.

    Examples
    --------
    >>> bounds(gt=0.0)
    {'range': Range(gt=0.0, ge=None, lt=None, le=None)}
    """
    return {"range": Range(gt=gt, ge=ge, lt=lt, le=le)}


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
    worlds.errors.SpecError: f: posts[0].radus: unknown key (did you mean 'radius'?); \
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
        raise SpecError(file, key, f"must be {valid.describe()}, got {value}")


def as_float(value: Any, *, file: str, key: str, valid: Range | None = None) -> float:
    """Return ``value`` as a finite float (ints accepted, booleans not), range-checked.

    Examples
    --------
    >>> as_float(2, file="f", key="speed", valid=Range(gt=0.0))
    2.0
    >>> as_float(-1.0, file="f", key="speed", valid=Range(gt=0.0))
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: f: speed: must be > 0.0, got -1.0
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
    worlds.errors.SpecError: f: end_knot: expected an integer, got a float 3.0
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
    worlds.errors.SpecError: f: start: expected a list of 2 numbers, got 1 value(s)
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
            raise SpecError(
                file, key, f"every value must be {valid.describe()}, got {list(numbers)}"
            )
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
    worlds.errors.SpecError: f: posts[0].x: missing required key
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
def _checked_fields(cls: type) -> tuple[tuple[str, Any, Range | None, bool, bool], ...]:
    """Return ``(name, hint, range, safe name, or object)`` of the fields to convert."""
    hints = typing.get_type_hints(cls)
    return tuple(
        (field.name, hints[field.name], field.metadata.get("range"),
         field.metadata.get("safe_name", False), field.metadata.get("or_object", False))
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
    name); a field with :func:`safe_name` metadata must match ``SAFE_NAME``. Nested
    dataclasses validate themselves. Call it first in ``__post_init__``.

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
    worlds.errors.SpecError: <memory>: radius: must be > 0.0 and <= 1.0, got 2.0
    >>> Wheel(radius=np.float32(0.5)).radius
    0.5
    """
    for name, hint, valid, path_like, or_object_ in _checked_fields(type(obj)):
        if getattr(obj, name) is None and type(None) in typing.get_args(hint):
            continue
        if or_object_ and not isinstance(getattr(obj, name), str | int | float | bool):
            continue
        value = convert(hint, _as_toml(getattr(obj, name)), file=MEMORY, key=name, valid=valid)
        if path_like and not SAFE_NAME.fullmatch(value):
            raise SpecError(
                MEMORY, name,
                f"{value!r} is not a usable name: use 1-64 letters, digits, '_', '-' or '.', "
                "starting with a letter or digit (it may become a file name)",
            )
        object.__setattr__(obj, name, value)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file, reporting a missing file or a syntax error as :class:`SpecError`.

    A syntax error is reported at key ``"line L, column C"`` with tomllib's message.

    Examples
    --------
    >>> read_toml("/no/such/world.toml")
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: /no/such/world.toml: <file>: no such file
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise SpecError(str(path), FILE_KEY, "no such file") from None
    except IsADirectoryError:
        raise SpecError(str(path), FILE_KEY, "is a directory, expected a .toml file") from None
    except OSError as error:
        raise SpecError(str(path), FILE_KEY, f"cannot read: {error.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SpecError(
            str(path), FILE_KEY, f"not a TOML file: not UTF-8 text (byte {error.start})"
        ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        message = str(error)
        position = _TOML_POSITION.search(message)
        where = f"line {position[1]}, column {position[2]}" if position else FILE_KEY
        reason = _TOML_POSITION.sub("", message) if position else message
        raise SpecError(str(path), where, f"not valid TOML: {reason}") from None
