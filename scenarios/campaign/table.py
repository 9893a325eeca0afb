"""The results table of a campaign: one row per run, as Parquet and CSV, and its reader.

A row holds the run's axes (``run``, ``scenario``, ``policy``, ``seed``, ``sample``), its
``status`` (``ok``, ``rejected``: the drawn sample broke the scenario, ``error``: the run
raised) with the ``reason``, the scenario ``digest``, the drawn values (``vary.KEY``) and
every metric of its ``metrics.json`` flattened with dots (``table1_cm.mean.avg``). Lists
of numbers (per-lap figures) stay in the journal; a list of records becomes its count
(``safety.protective_stops.count``) and the infractions a count per kind
(``safety.infractions.contact``). A fleet's vehicles are columns too
(``vehicles.NAME.detection.f1``).

The files are readable without this project: ``pandas.read_parquet``, DuckDB's
``read_parquet`` or any CSV reader.

Examples
--------
>>> flat = flatten_metrics({"table1_cm": {"mean": {"avg": 1.5}},
...                         "safety": {"infractions": [{"kind": "contact"}], "lap_time_s": [9.0]}})
>>> flat["table1_cm.mean.avg"], flat["safety.infractions.contact"], "safety.lap_time_s" in flat
(1.5, 1, False)
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.csv
import pyarrow.parquet

from scenarios.bench.safety_record import INFRACTION_KINDS
from scenarios.process.staging import write_atomic
from semistatic.errors import SpecError
from semistatic.validation import loads_json

__all__ = [
    "CSV_FILE",
    "FORMAT",
    "IDENTITY_COLUMNS",
    "KIND",
    "MANIFEST_FILE",
    "PARQUET_FILE",
    "CampaignResult",
    "flatten_metrics",
    "read_campaign",
    "runs_table",
    "write_runs",
]

FORMAT = 1
"""Version of the campaign's result format; ``compare`` refuses two different ones."""

KIND = "semistatic-campaign"
MANIFEST_FILE = "manifest.json"
PARQUET_FILE = "runs.parquet"
CSV_FILE = "runs.csv"

IDENTITY_COLUMNS = ("run", "scenario", "policy", "seed", "sample", "status", "reason", "digest")
"""The columns that say which run a row is, before the drawn values and the metrics."""

# Keys of metrics.json that repeat a row's identity or describe the run, not measure it.
_DESCRIPTIVE = ("scenario", "seed", "policy", "laps", "world", "robot")


def flatten_metrics(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Return the scalars of a ``metrics.json`` as ``{"a.b.c": value}`` (see the module)."""
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if not prefix and key in _DESCRIPTIVE:
            continue
        if isinstance(value, Mapping):
            flat.update(flatten_metrics(value, f"{name}."))
        elif name.endswith("safety.infractions") and isinstance(value, list):
            kinds = [item.get("kind") for item in value if isinstance(item, Mapping)]
            flat.update({f"{name}.{kind}": kinds.count(kind) for kind in INFRACTION_KINDS})
        elif isinstance(value, list):
            if all(isinstance(item, Mapping) for item in value):
                flat[f"{name}.count"] = len(value)
        elif value is None or isinstance(value, bool | int | float | str):
            flat[name] = value
    return flat


def _column(values: list[Any]) -> pa.Array:
    """Return one column, typed by its values: bool, int64, float64 or string."""
    present = [value for value in values if value is not None]
    if present and all(isinstance(value, bool) for value in present):
        return pa.array(values, type=pa.bool_())
    if present and all(isinstance(value, int) and not isinstance(value, bool)
                       for value in present):
        return pa.array(values, type=pa.int64())
    if all(isinstance(value, int | float) and not isinstance(value, bool) for value in present):
        return pa.array([None if value is None else float(value) for value in values],
                        type=pa.float64())
    return pa.array([None if value is None else str(value) for value in values],
                    type=pa.string())


def runs_table(rows: Sequence[Mapping[str, Any]]) -> pa.Table:
    """Return the rows as a table: identity columns, then ``vary.*``, then metrics.

    Columns are in first-seen order; a key a row lacks is null there.

    Examples
    --------
    >>> table = runs_table([{"run": "a", "seed": 0, "x": 1}, {"run": "b", "seed": 1, "x": 2.5}])
    >>> table.column_names, table.schema.field("x").type
    (['run', 'seed', 'x'], DataType(double))
    """
    names = list(dict.fromkeys(key for row in rows for key in row))
    ordered = ([n for n in IDENTITY_COLUMNS if n in names]
               + [n for n in names if n.startswith("vary.")]
               + [n for n in names if n not in IDENTITY_COLUMNS and not n.startswith("vary.")])
    return pa.table({name: _column([row.get(name) for row in rows]) for name in ordered})


def write_runs(rows: Sequence[Mapping[str, Any]], out: Path) -> pa.Table:
    """Write ``runs.parquet`` and ``runs.csv`` into ``out`` (each atomically); return the table."""
    table = runs_table(rows)
    sink = pa.BufferOutputStream()
    pa.parquet.write_table(table, sink)
    write_atomic(out / PARQUET_FILE, sink.getvalue().to_pybytes())
    sink = pa.BufferOutputStream()
    pa.csv.write_csv(table, sink)
    write_atomic(out / CSV_FILE, sink.getvalue().to_pybytes())
    return table


@dataclass(frozen=True)
class CampaignResult:
    """A finished campaign as read back: its directory, manifest and rows."""

    path: Path
    manifest: dict[str, Any]
    rows: list[dict[str, Any]]


def read_campaign(path: str | Path, *, option: str = "campaign") -> CampaignResult:
    """Read the campaign in directory ``path``; a missing or damaged one is a SpecError.

    ``option`` names the argument in errors (``BASELINE``, ``CANDIDATE``).

    Examples
    --------
    >>> read_campaign("/no/such/campaign", option="BASELINE")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: BASELINE: /no/such/campaign: no such directory; give the \
--out of a finished `semistatic campaign`
    """
    path = Path(path)
    if not path.is_dir():
        raise SpecError(option, str(path), "no such directory; give the --out of a finished "
                        "`semistatic campaign`")
    manifest_file, parquet_file = path / MANIFEST_FILE, path / PARQUET_FILE
    for required in (manifest_file, parquet_file):
        if not required.is_file():
            raise SpecError(option, str(required), "missing: not a finished campaign (run the "
                            "same `semistatic campaign` command again to finish it)")
    try:
        manifest = loads_json(manifest_file.read_text(), file=option, key=str(manifest_file))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise SpecError(option, str(manifest_file), f"unreadable: {error}") from None
    if not isinstance(manifest, dict) or manifest.get("kind") != KIND:
        raise SpecError(option, str(manifest_file), f"not the manifest of a campaign "
                        f"(kind {KIND!r} expected)")
    try:
        rows = pa.parquet.read_table(parquet_file).to_pylist()
    except (OSError, pa.ArrowException) as error:
        raise SpecError(option, str(parquet_file), f"unreadable: {error}") from None
    missing = [name for name in IDENTITY_COLUMNS[:6] if rows and name not in rows[0]]
    if missing:
        raise SpecError(option, str(parquet_file), f"lacks the column(s) {', '.join(missing)}")
    return CampaignResult(path, manifest, rows)
