"""Table 1 of the paper side by side with ours: text for the terminal, CSV and Markdown.

Examples
--------
>>> ours = {"sim1": {"table1_cm": {"mean": {"avg": 3.1, "min": 1.2, "max": 5.0},
...                                "std": {"avg": 1.0, "min": 0.5, "max": 2.0}}}}
>>> print(render_table(ours))  # doctest: +NORMALIZE_WHITESPACE
environment  source   mean avg  mean min  mean max  std avg  std min  std max
sim1         paper        4.71      2.19      6.62     1.89     1.25     2.69
sim1         ours         3.10      1.20      5.00     1.00     0.50     2.00
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from scenarios.process.staging import write_atomic
from scenarios.results.outputs import PAPER_TABLE1, TABLE1_COLUMNS
from scenarios.spec.scenario import POLICIES

__all__ = ["comparison_rows", "render_table", "table_rows", "write_table"]

HEADER = ("environment", "source", "mean avg", "mean min", "mean max", "std avg", "std min",
          "std max")


def _ours(metrics: Mapping[str, Any]) -> tuple[float | None, ...]:
    table = metrics["table1_cm"]
    return tuple(table[stat][key] for stat in ("mean", "std") for key in ("avg", "min", "max"))


def table_rows(results: Mapping[str, Mapping[str, Any]]) -> list[tuple[Any, ...]]:
    """Return rows ``(environment, source, 6 numbers)``: the paper's, then ours, per scenario."""
    rows = []
    for name, metrics in results.items():
        if name in PAPER_TABLE1:
            rows.append((name, "paper", *PAPER_TABLE1[name]))
        rows.append((name, "ours", *_ours(metrics)))
    return rows


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    return f"{value:.2f}" if isinstance(value, float) else str(value)


COMPARISON_HEADER = ("scenario", "policy", "total s", "saved %", "stops", "slowdowns",
                     "person m", "box m", "TTC s", "infractions")
"""The policy comparison's columns: lap times and the safety figures of each policy."""


def _aligned(header: tuple[str, ...], rows: list[tuple[Any, ...]], text_columns: int) -> list[str]:
    cells = [header, *[tuple(_cell(v) for v in row) for row in rows]]
    widths = [max(len(row[i]) for row in cells) for i in range(len(header))]
    return [
        "  ".join(
            cell.ljust(width) if i < text_columns else cell.rjust(width)
            for i, (cell, width) in enumerate(zip(row, widths, strict=True))
        ).rstrip()
        for row in cells
    ]


def render_table(results: Mapping[str, Mapping[str, Any]]) -> str:
    """Return the side-by-side table (and the policy comparison, if run) as aligned text."""
    lines = _aligned(HEADER, table_rows(results), text_columns=2)
    comparison = comparison_rows(results)
    if comparison:
        lines += ["", *_aligned(COMPARISON_HEADER, comparison, text_columns=2)]
    return "\n".join(lines)


def comparison_rows(results: Mapping[str, Mapping[str, Any]]) -> list[tuple[Any, ...]]:
    """Return one row per scenario and field policy compared (:data:`COMPARISON_HEADER`).

    The separations are the least from the vehicle's footprint to a person and to a box
    over the run (m), TTC the least time to collision (s); the infractions are counted.

    Examples
    --------
    >>> run = {"lap_time_s": [40.0, 30.0], "stops": 1, "slowdowns": 2, "saved_percent": 0.0,
    ...        "min_separation_m": {"person": 0.61, "box": 0.5}, "min_ttc_s": 1.5,
    ...        "infractions": {"near_miss": 1}}
    >>> comparison_rows({"pal3b": {"policy_comparison": {"conservative": run}}})
    [('pal3b', 'conservative', 70.0, 0.0, 1, 2, 0.61, 0.5, 1.5, 1)]
    """
    rows = []
    for name, metrics in results.items():
        compared = metrics.get("policy_comparison", {})
        for policy in POLICIES:
            if policy not in compared:
                continue
            run = compared[policy]
            rows.append((
                name, policy, round(sum(run["lap_time_s"]), 1), run["saved_percent"],
                run["stops"], run["slowdowns"], run["min_separation_m"]["person"],
                run["min_separation_m"]["box"], run["min_ttc_s"],
                sum(run["infractions"].values()),
            ))
    return rows


def _markdown(results: Mapping[str, Mapping[str, Any]]) -> str:
    lines = [
        "| " + " | ".join(HEADER) + " |",
        "|" + "|".join(["---"] * 2 + ["---:"] * 6) + "|",
    ]
    for row in table_rows(results):
        lines.append("| " + " | ".join(_cell(v) for v in row) + " |")
    comparison = comparison_rows(results)
    if comparison:
        lines += [
            "",
            "| scenario | policy | total (s) | saved (%) | stops | slowdowns "
            "| least separation, person (m) | least separation, box (m) | least TTC (s) "
            "| infractions |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        lines += ["| " + " | ".join(_cell(v) for v in row) + " |" for row in comparison]
    return "\n".join(lines) + "\n"


def write_table(results: Mapping[str, Mapping[str, Any]], out: str | os.PathLike[str]) -> None:
    """Write ``table1.csv`` (ours, the design page's columns) and ``table1.md`` (side by side)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    csv_lines = [",".join(TABLE1_COLUMNS)]
    for name, metrics in results.items():
        csv_lines.append(",".join([name, *("" if v is None else f"{v}" for v in _ours(metrics))]))
    write_atomic(out / "table1.csv", "\n".join(csv_lines) + "\n")
    write_atomic(out / "table1.md", _markdown(results))
