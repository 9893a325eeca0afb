"""The one error type of spec files: it names the file, the key and what is wrong.

Examples
--------
>>> error = SpecError("pal1.toml", "boxes[2].size", "every value must be > 0, got -0.4")
>>> str(error)
'pal1.toml: boxes[2].size: every value must be > 0, got -0.4'
>>> isinstance(error, ValueError)
True
"""

from __future__ import annotations

__all__ = ["MEMORY", "SpecError", "caused_by_interrupt", "join_key"]

MEMORY = "<memory>"
"""The ``file`` of a spec built in Python rather than loaded from a file."""


def join_key(prefix: str, key: str) -> str:
    """Return the dotted key of ``key`` inside the table at ``prefix``.

    List indices (``"[2]"``) attach without a dot; an empty side is dropped.

    Examples
    --------
    >>> join_key("boxes[2]", "size")
    'boxes[2].size'
    >>> join_key("boxes", "[2]")
    'boxes[2]'
    >>> join_key("", "path")
    'path'
    """
    if not prefix:
        return key
    if not key:
        return prefix
    return prefix + key if key.startswith("[") else f"{prefix}.{key}"


class SpecError(ValueError):
    """A spec file (or a spec built in Python) is wrong at one key.

    Parameters
    ----------
    file
        The file the value came from (``"<memory>"`` when built in Python).
    key
        Dotted path of the offending key, e.g. ``"path.segments[1].end_knot"``.
    message
        What is wrong and, where possible, how to fix it.

    Examples
    --------
    >>> error = SpecError(MEMORY, "size", "must be > 0")
    >>> str(error.located("w.toml", "boxes[0]"))
    'w.toml: boxes[0].size: must be > 0'
    """

    def __init__(self, file: str, key: str, message: str) -> None:
        super().__init__(file, key, message)
        self.file = str(file)
        self.key = key
        self.message = message

    def __str__(self) -> str:
        return f"{self.file}: {self.key}: {self.message}"

    def located(self, file: str, prefix: str) -> SpecError:
        """Return this error re-anchored in ``file`` with its key nested under ``prefix``.

        Dataclass validation raises keys relative to the object; the loader that built
        the object knows the file and where in it the object lives.

        Examples
        --------
        >>> SpecError(MEMORY, "", "bad").located("a.toml", "walls[1]").key
        'walls[1]'
        """
        return SpecError(file, join_key(prefix, self.key), self.message)


def caused_by_interrupt(error: BaseException) -> bool:
    """Return whether a KeyboardInterrupt is among the causes of ``error``.

    Ctrl-C inside compiled or C code (numba's unpickling, PyBullet) reaches Python as
    another exception (e.g. ``SystemError``) caused by the interrupt, which must go on.

    Examples
    --------
    >>> try:
    ...     try:
    ...         raise KeyboardInterrupt
    ...     except KeyboardInterrupt as interrupt:
    ...         raise SystemError("returned a result with an exception set") from interrupt
    ... except SystemError as wrapped:
    ...     caused_by_interrupt(wrapped), caused_by_interrupt(SystemError("other"))
    (True, False)
    """
    seen: set[int] = set()
    cause: BaseException | None = error
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False
