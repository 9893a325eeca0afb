"""A sweep's results as a person reads them: rows, means over seeds, ranking, files.

``write_sweep`` writes ``DIR/sweep.csv`` (one row per run), ``DIR/sweep.json`` (the same,
the full metrics of every run, the ranking) and ``DIR/figures/sweep.png`` atomically;
``format_ranking`` prints the ranking.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from scenarios.tuning.metrics import DEFAULT_SORT, METRICS, TIMING_COLUMNS, metric_value
from scenarios.tuning.points import display_value, settings_text, toml_value
from scenarios.tuning.run import PointResult
from semistatic.validation import did_you_mean

__all__ = [
    "combine_seeds",
    "format_ranking",
    "rank",
    "sweep_row",
    "write_sweep",
]

MEAN_DIGITS = 4
"""Decimals kept in the means over seeds."""

RANKING_ROWS = 20
"""Rows of the ranked table printed by the CLI; the rest is in sweep.csv."""


def sweep_row(result: PointResult) -> dict[str, Any]:
    """Return the flat ``sweep.csv`` row of one point (``None`` where a metric is missing).

    Examples
    --------
    >>> from scenarios.tuning.points import sweep_points
    >>> point = sweep_points("sim1", {"mapper.gate": [0.1]}, seeds=[2])[0]
    >>> row = sweep_row(PointResult(point, {"detection": {"f1": 0.8}}))
    >>> row["point"], row["mapper.gate"], row["seed"], row["f1"], row["stops"], row["error"]
    (0, 0.1, 2, 0.8, None, '')
    """
    point = result.point
    row: dict[str, Any] = {"point": point.index, **dict(point.settings),
                           "scenario": point.spec.name, "seed": point.seed}
    for name in METRICS:
        row[name] = metric_value(result.metrics, name)
    row["error"] = result.error or ""
    return row


def _mean(values: Sequence[Any]) -> float | None:
    numbers = [float(v) for v in values if isinstance(v, int | float) and math.isfinite(v)]
    return round(math.fsum(numbers) / len(numbers), MEAN_DIGITS) if numbers else None


def _worst_and_spread(values: Sequence[Any], name: str) -> tuple[Any, Any]:
    numbers = [float(v) for v in values if isinstance(v, int | float) and math.isfinite(v)]
    if not numbers:
        return None, None
    worst = max(numbers, key=METRICS[name].score)
    return worst, round(max(numbers) - min(numbers), MEAN_DIGITS)


def combine_seeds(results: Sequence[PointResult]) -> list[dict[str, Any]]:
    """Return one row per grid combination: each metric's mean over its seeds.

    A row has ``settings`` (the grid values), ``seeds``, ``failed`` (runs that raised),
    one entry per :data:`METRICS` column (``None`` where no seed has a value), and
    ``worst`` and ``spread``: each metric's worst seed and its range over the seeds.

    Examples
    --------
    >>> from scenarios.tuning.points import sweep_points
    >>> points = sweep_points("sim1", {"mapper.gate": [0.1]}, seeds=[0, 1])
    >>> rows = combine_seeds([PointResult(points[0], {"detection": {"f1": 0.8}}),
    ...                       PointResult(points[1], {"detection": {"f1": 0.9}})])
    >>> rows[0]["settings"], rows[0]["seeds"], rows[0]["f1"], rows[0]["failed"]
    ({'mapper.gate': 0.1}, [0, 1], 0.85, 0)
    """
    groups: dict[tuple, list[PointResult]] = {}
    for result in results:
        key = tuple((name, toml_value(value)) for name, value in result.point.settings)
        groups.setdefault(key, []).append(result)
    rows = []
    for members in groups.values():
        point_rows = [sweep_row(result) for result in members]
        row: dict[str, Any] = {
            "settings": dict(members[0].point.settings),
            "seeds": [result.point.seed for result in members],
            "points": [result.point.index for result in members],
            "failed": sum(result.failed for result in members),
        }
        row["worst"], row["spread"] = {}, {}
        for name in METRICS:
            values = [point_row[name] for point_row in point_rows]
            row[name] = _mean(values)
            row["worst"][name], row["spread"][name] = _worst_and_spread(values, name)
        rows.append(row)
    return rows


def rank(rows: Sequence[Mapping[str, Any]], metric: str = DEFAULT_SORT) -> list[Mapping[str, Any]]:
    """Return ``rows`` best first by ``metric``; failed runs and missing values go last.

    Ties keep the grid order. "Best" is the lowest value, the highest for F1, precision,
    recall and laps completed, and the closest to 3 for the NEES.

    Examples
    --------
    >>> rows = [{"f1": 0.7}, {"f1": None}, {"f1": 0.9}, {"f1": 1.0, "error": "x"}]
    >>> rank(rows, "f1")
    [{'f1': 0.9}, {'f1': 0.7}, {'f1': None}, {'f1': 1.0, 'error': 'x'}]
    >>> rank(rows, "recal")
    Traceback (most recent call last):
    ...
    ValueError: rank: unknown metric 'recal' (did you mean 'recall'?)
    """
    if metric not in METRICS:
        raise ValueError(f"rank: unknown metric {metric!r}{did_you_mean(metric, METRICS)}")

    def order(row: Mapping[str, Any]) -> tuple[bool, bool, float]:
        failed = bool(row.get("error")) or bool(row.get("failed"))
        value = row.get(metric)
        if value is None:
            return failed, True, 0.0
        return failed, False, METRICS[metric].score(float(value))

    return sorted(rows, key=order)


def _sweep_summary(results: Sequence[PointResult], sort: str) -> dict[str, Any]:
    first = results[0].point
    grid: dict[str, list[Any]] = {key: [] for key, _ in first.settings}
    seeds: list[int] = []
    for result in results:
        for key, value in result.point.settings:
            if value not in grid[key]:
                grid[key].append(value)
        if result.point.seed not in seeds:
            seeds.append(result.point.seed)
    ranking = rank(combine_seeds(results), sort)
    best = ranking[0] if ranking and ranking[0][sort] is not None else None
    if best is not None and best["failed"]:
        best = None
    # Robust choice: the combination whose worst seed is best (rank on the worst values).
    by_worst = rank([{sort: row["worst"][sort], "failed": row["failed"], "row": row}
                     for row in ranking], sort)
    best_worst = by_worst[0]["row"] if by_worst and by_worst[0][sort] is not None else None
    if best_worst is not None and best_worst["failed"]:
        best_worst = None
    return {
        "scenario": first.spec.name,
        "source": first.spec.source,
        "laps": first.spec.laps,
        "grid": grid,
        "seeds": seeds,
        "sort": sort,
        "columns": list(sweep_row(results[0])),
        "timing_columns": list(TIMING_COLUMNS),
        "points": [
            {**sweep_row(result), "settings": dict(result.point.settings),
             "metrics": result.metrics}
            for result in results
        ],
        "ranking": ranking,
        "best": best,
        "best_worst_case": best_worst,
    }


def write_sweep(
    results: Sequence[PointResult],
    out: str | Path,
    *,
    sort: str = DEFAULT_SORT,
    figures: bool = True,
    extra: Callable[[dict[str, Any], Path], None] | None = None,
) -> dict[str, Any]:
    """Write ``sweep.csv``, ``sweep.json`` and ``figures/sweep.png`` into ``out`` atomically.

    ``extra(summary, staging)``, when given, adds to the summary and writes more files
    into the staging directory before it is published (a search's study report).

    Returns the content of ``sweep.json``: the scenario, the grid, the seeds, every
    point (its row and full metrics), the grid combinations ranked by ``sort`` (means
    over seeds) and the best one (``None`` if no combination has a value).

    Examples
    --------
    >>> import tempfile
    >>> from scenarios.tuning.points import sweep_points
    >>> points = sweep_points("sim1", {"mapper.gate": [0.08, 0.12]}, laps=1)
    >>> results = [PointResult(points[0], {"table1_cm": {"mean": {"avg": 3.1, "max": 5.0}}}),
    ...            PointResult(points[1], {"table1_cm": {"mean": {"avg": 2.4, "max": 4.2}}})]
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     summary = write_sweep(results, Path(tmp) / "sweep", figures=False)
    ...     sorted(path.name for path in (Path(tmp) / "sweep").iterdir())
    ['.semistatic-result', 'sweep.csv', 'sweep.json']
    >>> summary["best"]["settings"], summary["best"]["table1_mean_avg_cm"]
    ({'mapper.gate': 0.12}, 2.4)
    """
    from scenarios.results.outputs import csv_text, json_text, stage_and_publish

    if not results:
        raise ValueError("write_sweep: no results to write (the sweep has no points)")
    if sort not in METRICS:
        raise ValueError(f"write_sweep: unknown sort metric {sort!r}{did_you_mean(sort, METRICS)}")
    summary = _sweep_summary(results, sort)
    columns = summary["columns"]
    rows = [columns] + [[_display_cell(point[column]) for column in columns]
                        for point in summary["points"]]

    def fill(staging: Path) -> None:
        if figures:
            (staging / "figures").mkdir()
            from scenarios.tuning.plot import plot_sweep  # matplotlib only when drawing

            plot_sweep(summary, staging / "figures" / "sweep.png")
        if extra is not None:
            extra(summary, staging)
        (staging / "sweep.csv").write_text(csv_text(rows))
        (staging / "sweep.json").write_text(json_text(summary))

    stage_and_publish(Path(out), fill, command="tune")
    return summary


def _display_cell(value: Any) -> Any:
    return toml_value(value) if isinstance(value, list | tuple | dict | bool) else value


TABLE_COLUMNS = {
    "table1_mean_avg_cm": "T1 avg cm",
    "table1_mean_max_cm": "T1 max cm",
    "table1_polylines": "T1 lines",
    "f1": "F1",
    "precision": "prec",
    "recall": "recall",
    "collisions": "coll",
    "stops": "stops",
    "total_lap_time_s": "laps s",
    "nees_mean": "NEES",
    "wall_time_s": "wall s",
}
"""The columns of the printed ranking and their (terminal-width) headings."""


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def format_ranking(summary: Mapping[str, Any], out: str | Path, *,
                   limit: int = RANKING_ROWS, figures: bool = True) -> str:
    """Return the ranked table of a sweep (means over seeds) and its best point, as text.

    Examples
    --------
    >>> from scenarios.tuning.points import sweep_points
    >>> points = sweep_points("sim1", {"mapper.gate": [0.08, 0.12]})
    >>> summary = _sweep_summary([PointResult(points[0], {"detection": {"f1": 0.5}}),
    ...                           PointResult(points[1], {"detection": {"f1": 0.75}})], "f1")
    >>> print(format_ranking(summary, "out", figures=False).splitlines()[-1])
    results in out/ (sweep.csv, sweep.json)
    >>> print(format_ranking(summary, "out").splitlines()[-2])
    best by F1: mapper.gate=0.12 (0.75, 1 seed)
    """
    sort = summary["sort"]
    ranking = summary["ranking"]
    keys = list(summary["grid"])
    several = len(summary["seeds"]) > 1  # then the worst seed and the spread of --sort
    header = ["rank", *keys, "seeds", *TABLE_COLUMNS.values(),
              *(["worst", "spread"] if several else [])]
    lines = [[str(rank_number), *(display_value(row["settings"][key]) for key in keys),
              str(len(row["seeds"])) + (f" ({row['failed']} failed)" if row["failed"] else ""),
              *(_cell(row[name]) for name in TABLE_COLUMNS),
              *([_cell(row["worst"][sort]), _cell(row["spread"][sort])] if several else [])]
             for rank_number, row in enumerate(ranking[:limit], start=1)]
    widths = [max(len(cell) for cell in column) for column in zip(header, *lines, strict=True)]
    text = [
        f"{summary['scenario']}: {len(summary['points'])} runs of {summary['laps']} laps, "
        f"ranked by {METRICS[sort].label} (means over seeds"
        + (f"; worst and spread: of {METRICS[sort].label} over the seeds)" if several else ")"),
        "  ".join(cell.rjust(width) for cell, width in zip(header, widths, strict=True)),
    ]
    text += ["  ".join(cell.rjust(width) for cell, width in zip(line, widths, strict=True))
             for line in lines]
    if len(ranking) > limit:
        text.append(f"... {len(ranking) - limit} more combinations in sweep.csv")
    failed = [point for point in summary["points"] if point["error"]]
    for point in failed:
        text.append(f"point {point['point']} failed: {point['error']}")
    best = summary["best"]
    if best is None:
        text.append(f"best: none, no run has a value for {METRICS[sort].label}")
    else:
        settings = settings_text(best["settings"])
        seeds = len(best["seeds"])
        text.append(
            f"best by {METRICS[sort].label}: {settings or 'the scenario as is'} "
            f"({_cell(best[sort])}, {'mean of ' * (seeds > 1)}{seeds} seed{'s' * (seeds > 1)})"
        )
    robust = summary.get("best_worst_case")
    if several and robust is not None:
        text.append(f"best worst case: {settings_text(robust['settings']) or 'the scenario as is'}"
                    f" ({_cell(robust['worst'][sort])} at worst, mean {_cell(robust[sort])})")
    written = ["sweep.csv", "sweep.json"] + (["figures/sweep.png"] if figures else [])
    text.append(f"results in {out}/ ({', '.join(written)})")
    return "\n".join(text)


