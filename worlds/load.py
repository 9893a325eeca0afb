"""Load a world from TOML: a bundled name (``"pal1"``) or a path to a ``.toml`` file.

The file mirrors :class:`~worlds.spec.WorldSpec`: top-level ``name`` (defaults to the file
name), ``description``, arrays of tables ``walls``, ``posts``, ``boxes``, ``people``,
``test_pieces`` (optional) and a ``path`` table with ``knots`` and an array of
``segments``. Every key is checked (type, range, unknown keys with a "did you mean"), then
the dataclasses check the geometry.
Any problem raises :class:`~semistatic.errors.SpecError` naming the file and the key.

Examples
--------
>>> world = load_world("pal1")
>>> world.name, len(world.path.segments) >= 2
('pal1', True)
>>> load_world("sim_1")
Traceback (most recent call last):
...
semistatic.errors.SpecError: sim_1: <file>: not a bundled world (did you mean 'sim1'?) \
and no such file; bundled worlds: fault_hall, fault_hall_pallet, fault_hall_short, occlusion_hall, \
pal1, pal3, sim1, sim2, warehouse
"""

from __future__ import annotations

from pathlib import Path

from semistatic.errors import SpecError
from semistatic.validation import FILE_KEY, as_table, did_you_mean, from_table, read_toml
from worlds.spec import WorldSpec

__all__ = ["DATA_DIR", "bundled_worlds", "load_world", "world_from_toml", "world_path"]

DATA_DIR = Path(__file__).resolve().parent / "data"
"""Directory of the bundled world files."""


def bundled_worlds() -> tuple[str, ...]:
    """Return the names of the bundled worlds, sorted.

    Examples
    --------
    >>> bundled_worlds()  # doctest: +NORMALIZE_WHITESPACE
    ('fault_hall', 'fault_hall_pallet', 'fault_hall_short', 'occlusion_hall', 'pal1', 'pal3',
     'sim1', 'sim2', 'warehouse')
    """
    return tuple(sorted(path.stem for path in DATA_DIR.glob("*.toml")))


def world_path(name_or_path: str | Path) -> Path:
    """Return the file of a bundled world name, or ``name_or_path`` itself as a path.

    Raises :class:`SpecError` when it is neither a bundled name nor an existing file.

    Examples
    --------
    >>> world_path("sim1").name
    'sim1.toml'
    """
    text = str(name_or_path)
    if isinstance(name_or_path, str) and text in bundled_worlds():
        return DATA_DIR / f"{text}.toml"
    path = Path(name_or_path)
    if path.exists():
        return path
    names = bundled_worlds()
    looks_like_name = isinstance(name_or_path, str) and path.suffix == "" and "/" not in text
    if looks_like_name:
        raise SpecError(
            text,
            FILE_KEY,
            f"not a bundled world{did_you_mean(text, names)} and no such file; "
            f"bundled worlds: {', '.join(names)}",
        )
    raise SpecError(text, FILE_KEY, f"no such file (bundled worlds: {', '.join(names)})")


def world_from_toml(table: dict, *, file: str) -> WorldSpec:
    """Build a :class:`WorldSpec` from a parsed TOML table, naming ``file`` in errors.

    ``name`` defaults to the file's stem; ``source`` is set to ``file``.

    Examples
    --------
    >>> table = {"path": {"knots": [[0, 0]], "segments": []}, "walls": [], "posts": [],
    ...          "boxes": [], "people": []}
    >>> world_from_toml(table, file="w.toml")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: w.toml: path.knots: needs at least 2 knots, got 1
    """
    table = dict(as_table(table, file=file, key=""))
    table.setdefault("name", Path(file).stem)
    for kind in ("walls", "posts", "boxes", "people"):
        table.setdefault(kind, [])
    return from_table(WorldSpec, table, file=file, key="", fixed={"source": file})


def load_world(name_or_path: str | Path) -> WorldSpec:
    """Load a world: a bundled name (see :func:`bundled_worlds`) or a path to a TOML file.

    Examples
    --------
    >>> world = load_world("sim1")
    >>> world.source.endswith("sim1.toml")
    True
    """
    path = world_path(name_or_path)
    return world_from_toml(read_toml(path), file=str(path))
