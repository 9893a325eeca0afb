"""Threshold sweeps: run a scenario over a grid of ``--set`` values and rank the results.

``semistatic tune SCENARIO --grid mapper.gate=0.08,0.12,0.16 --seeds 0,1 --jobs 2`` runs
every point of the Cartesian product of the grids (times the seeds) as an independent
closed-loop run (:func:`scenarios.runner.run_scenario`), in a process pool, and writes::

    DIR/sweep.csv           one row per point: grid values, seed, Table 1, detection,
                            safety, NEES, wall time (and the error of a failed run)
    DIR/sweep.json          the same, the full metrics of every point, and the grid
                            combinations (mean over seeds) ranked by --sort
    DIR/figures/sweep.png   metrics against the value (one grid key), heatmaps (two
                            keys) or ranked bars (more)

Every point's overrides are validated before anything runs, and a point's result does
not depend on how many workers run the sweep (same seed, same metrics).

Examples
--------
>>> grid = parse_grids(["mapper.gate=0.08,0.12", "policy=conservative,adaptive"])
>>> grid
{'mapper.gate': (0.08, 0.12), 'policy': ('conservative', 'adaptive')}
>>> for point in sweep_points("sim1", grid, laps=1):
...     print(point.label)
mapper.gate=0.08 policy=conservative seed=0
mapper.gate=0.08 policy=adaptive seed=0
mapper.gate=0.12 policy=conservative seed=0
mapper.gate=0.12 policy=adaptive seed=0
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import itertools
import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scenarios.load import OVERRIDE_FILE, parse_override, scenario_from_toml, scenario_path
from scenarios.output_dir import check_output_dir
from scenarios.progress import count_progress
from scenarios.spec import ScenarioSpec
from scenarios.tune_run import PointResult, RecordingSet, run_sweep
from worlds.errors import SpecError
from worlds.validation import did_you_mean, read_toml

__all__ = [
    "DEFAULT_SORT",
    "MAX_POINTS",
    "METRICS",
    "PointResult",
    "SweepMetric",
    "SweepPoint",
    "add_parser",
    "combine_seeds",
    "display_value",
    "format_ranking",
    "main_tune",
    "metric_value",
    "parse_grid",
    "parse_grids",
    "parse_seeds",
    "rank",
    "run_sweep",
    "settings_text",
    "sweep_points",
    "sweep_row",
    "toml_value",
    "write_sweep",
]

MAX_POINTS = 256
"""Most runs one sweep may ask for: beyond this a typo (an extra value list) is likelier
than intent, and a few hundred closed-loop runs already take hours on a laptop."""

GRID_OPTION = "--grid"
SEEDS_OPTION = "--seeds"
LAPS_OPTION = "--laps"
"""The ``file`` named in errors about these options (errors read ``error: --grid: key: ...``)."""

NEES_TARGET = 3.0
"""Mean NEES of a consistent 3-state (x, y, theta) filter: the best NEES is the closest."""

MEAN_DIGITS = 4
"""Decimals kept in the means over seeds."""

RANKING_ROWS = 20
"""Rows of the ranked table printed by the CLI; the rest is in sweep.csv."""


@dataclass(frozen=True)
class SweepMetric:
    """One column of the sweep: where it sits in ``metrics.json`` and which way is better.

    Parameters
    ----------
    path
        Keys leading to the value in the metrics of a run.
    better
        ``"low"``, ``"high"`` or ``"nees"`` (closest to :data:`NEES_TARGET`).
    label
        Short heading for tables and figure axes.

    Examples
    --------
    >>> SweepMetric(("detection", "f1"), "high", "F1").better
    'high'
    >>> SweepMetric(("detection", "f1"), "up", "F1")
    Traceback (most recent call last):
    ...
    ValueError: SweepMetric.better must be 'low', 'high' or 'nees' (got 'up')
    """

    path: tuple[str, ...]
    better: str
    label: str

    def __post_init__(self) -> None:
        if self.better not in ("low", "high", "nees"):
            raise ValueError(
                f"SweepMetric.better must be 'low', 'high' or 'nees' (got {self.better!r})"
            )

    def score(self, value: float) -> float:
        """Return ``value`` as a score where lower is better (for sorting).

        Examples
        --------
        >>> METRICS["f1"].score(0.9), METRICS["nees_mean"].score(2.5)
        (-0.9, 0.5)
        """
        if self.better == "high":
            return -value
        if self.better == "nees":
            return abs(value - NEES_TARGET)
        return value


METRICS: dict[str, SweepMetric] = {
    "table1_mean_avg_cm": SweepMetric(("table1_cm", "mean", "avg"), "low", "Table 1 mean avg (cm)"),
    "table1_mean_max_cm": SweepMetric(("table1_cm", "mean", "max"), "low", "Table 1 mean max (cm)"),
    # How many polylines Table 1 compared: a wider gate accepts more (and worse) pairs, so
    # read the Table 1 means of a gate sweep together with this count.
    "table1_polylines": SweepMetric(("table1_cm", "polylines"), "high", "Table 1 polylines"),
    "f1": SweepMetric(("detection", "f1"), "high", "F1"),
    "precision": SweepMetric(("detection", "precision"), "high", "precision"),
    "recall": SweepMetric(("detection", "recall"), "high", "recall"),
    "collisions": SweepMetric(("safety", "collisions"), "low", "collisions"),
    "stops": SweepMetric(("safety", "stops"), "low", "stops"),
    "total_lap_time_s": SweepMetric(("safety", "total_time_s"), "low", "lap time (s)"),
    "laps_completed": SweepMetric(("safety", "laps_completed"), "high", "laps done"),
    "rmse_xy_m": SweepMetric(("localization", "rmse_xy_m"), "low", "RMSE xy (m)"),
    "nees_mean": SweepMetric(("localization", "nees_mean"), "nees", "NEES"),
    "wall_time_s": SweepMetric(("performance", "wall_time_s"), "low", "wall (s)"),
}
"""The metric columns of ``sweep.csv``, in order; any of them can be ``--sort``."""

TIMING_COLUMNS = ("wall_time_s",)
"""Columns that measure the machine, not the run: they differ between identical runs."""

DEFAULT_SORT = "table1_mean_avg_cm"


# --------------------------------------------------------------------------------------
# The grid


def _split_values(raw: str) -> list[str]:
    """Split ``raw`` at top-level commas (not inside ``[...]``, ``{...}`` or quotes)."""
    parts, depth, quote, start = [], 0, "", 0
    for position, char in enumerate(raw):
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(raw[start:position])
            start = position + 1
    parts.append(raw[start:])
    return [part.strip() for part in parts]


def parse_grid(text: str) -> tuple[str, tuple[Any, ...]]:
    """Split ``"section.key=V1,V2,..."`` into the key and its TOML-typed values.

    Values are read like ``--set`` values (:func:`scenarios.load.parse_override`); commas
    inside ``[...]`` or quotes do not split.

    Examples
    --------
    >>> parse_grid("mapper.gate=0.08, 0.12")
    ('mapper.gate', (0.08, 0.12))
    >>> parse_grid("rates.safety_hz=12.5,25")
    ('rates.safety_hz', (12.5, 25))
    >>> parse_grid("mapper.gate=0.1,0.10")
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: --grid: mapper.gate: value 0.1 appears twice; list each once
    """
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise SpecError(GRID_OPTION, text, "expected KEY=V1,V2,..., e.g. mapper.gate=0.08,0.12")
    if key == "seed":
        raise SpecError(GRID_OPTION, key, "sweep seeds with --seeds S1,S2,... instead")
    items = _split_values(raw)
    if items == [""]:
        raise SpecError(GRID_OPTION, key, "empty grid: give values, e.g. mapper.gate=0.08,0.12")
    if "" in items:
        raise SpecError(GRID_OPTION, key, f"empty value in {raw.strip()!r}: drop the extra comma")
    values = tuple(parse_override(f"{key}={item}")[1] for item in items)
    for position, value in enumerate(values):
        if value in values[:position]:
            raise SpecError(
                GRID_OPTION, key, f"value {display_value(value)} appears twice; list each once"
            )
    return key, values


def parse_grids(texts: Iterable[str]) -> dict[str, tuple[Any, ...]]:
    """Parse every ``--grid`` option into ``{key: values}``, refusing a key given twice.

    Examples
    --------
    >>> parse_grids(["mapper.gate=0.1,0.2", "mapper.epsilon=0.03"])
    {'mapper.gate': (0.1, 0.2), 'mapper.epsilon': (0.03,)}
    >>> parse_grids(["mapper.gate=0.1", "mapper.gate=0.2"])
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: --grid: mapper.gate: given twice; put all values in one \
--grid mapper.gate=V1,V2,...
    """
    grids: dict[str, tuple[Any, ...]] = {}
    for text in texts:
        key, values = parse_grid(text)
        if key in grids:
            raise SpecError(
                GRID_OPTION, key, f"given twice; put all values in one --grid {key}=V1,V2,..."
            )
        grids[key] = values
    return grids


def parse_seeds(text: str) -> tuple[int, ...]:
    """Parse ``--seeds S1,S2,...`` (non-negative integers, each once).

    Examples
    --------
    >>> parse_seeds("0, 1,2")
    (0, 1, 2)
    >>> parse_seeds("0,x")
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: --seeds: seed: expected integers >= 0 like --seeds 0,1,2, got 'x'
    """
    seeds = []
    for item in text.split(","):
        item = item.strip()
        if not item.isdigit():
            raise SpecError(
                SEEDS_OPTION, "seed", f"expected integers >= 0 like --seeds 0,1,2, got {item!r}"
            )
        if int(item) in seeds:
            raise SpecError(SEEDS_OPTION, "seed", f"seed {int(item)} appears twice; list each once")
        seeds.append(int(item))
    return tuple(seeds)


def toml_value(value: Any) -> str:
    """Write ``value`` back as TOML text for an override (the inverse of parse_override).

    Examples
    --------
    >>> toml_value(0.1), toml_value("adaptive"), toml_value(True)
    ('0.1', '"adaptive"', 'true')
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)  # also TOML for inf and nan
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    return str(value)


def display_value(value: Any) -> str:
    """Return ``value`` as a person writes it on the command line.

    Examples
    --------
    >>> display_value("adaptive"), display_value(0.25)
    ('adaptive', '0.25')
    """
    return value if isinstance(value, str) else toml_value(value)


@dataclass(frozen=True)
class SweepPoint:
    """One run of a sweep: its grid values and the validated scenario it runs.

    Examples
    --------
    >>> point = sweep_points("sim1", {"mapper.gate": [0.1]}, seeds=[4])[0]
    >>> point.index, dict(point.settings), point.seed, point.spec.mapper.gate
    (0, {'mapper.gate': 0.1}, 4, 0.1)
    """

    index: int
    settings: tuple[tuple[str, Any], ...]
    spec: ScenarioSpec

    @property
    def seed(self) -> int:
        """Return the run's seed."""
        return self.spec.seed

    @property
    def label(self) -> str:
        """Return ``key=value ... seed=S``: the grid values and the seed.

        Examples
        --------
        >>> sweep_points("sim1", {"policy": ["adaptive"]}, seeds=[1, 2])[1].label
        'policy=adaptive seed=2'
        """
        values = [f"{key}={display_value(value)}" for key, value in self.settings]
        return " ".join([*values, f"seed={self.seed}"])


@contextlib.contextmanager
def _blame_options(grid_keys: Iterable[str]) -> Iterator[None]:
    """Re-anchor a ``--set`` error at a grid key, the seed or the laps to their option."""
    owners = {"seed": SEEDS_OPTION, "laps": LAPS_OPTION} | {key: GRID_OPTION for key in grid_keys}
    try:
        yield
    except SpecError as error:
        if error.file == OVERRIDE_FILE:
            for key, option in owners.items():
                if error.key == key or error.key.startswith((f"{key}.", f"{key}[")):
                    raise SpecError(option, error.key, error.message) from None
        raise


def sweep_points(
    scenario: str | Path,
    grids: Mapping[str, Sequence[Any]],
    *,
    seeds: Sequence[int] | None = None,
    laps: int | None = None,
    overrides: Sequence[str] = (),
    max_points: int = MAX_POINTS,
) -> list[SweepPoint]:
    """Expand the grids (times the seeds) into validated points, in grid order.

    Parameters
    ----------
    scenario
        A bundled scenario name or a scenario file.
    grids
        ``{"section.key": values}``: the Cartesian product of all values is swept, the
        last key varying fastest.
    seeds
        Seeds to run each combination with (innermost loop); ``None`` keeps the file's.
    laps
        Laps of every run (``None`` keeps the file's).
    overrides
        Fixed ``--set`` overrides applied to every point.
    max_points
        Refuse sweeps with more points than this.

    Returns
    -------
    list of SweepPoint
        Every point's scenario is loaded and validated (world and box layouts included)
        before this returns, so a bad value fails before anything runs.

    Raises
    ------
    worlds.errors.SpecError
        An empty grid, a key given both in ``grids`` and ``overrides``, too many points,
        or any point's scenario not valid (unknown key with a suggestion, value out of
        range); the error names the option (``--grid``, ``--seeds``, ``--laps``, ``--set``).

    Examples
    --------
    >>> [p.label for p in sweep_points("pal1", {"mapper.gate": [0.08, 0.12]}, seeds=[0, 1])]
    ['mapper.gate=0.08 seed=0', 'mapper.gate=0.08 seed=1', 'mapper.gate=0.12 seed=0', \
'mapper.gate=0.12 seed=1']
    >>> sweep_points("pal1", {"mapper.gte": [0.1]})
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: --grid: mapper.gte: unknown key (did you mean 'gate'?)
    >>> sweep_points("pal1", {"mapper.gate": [0.1, -0.1]})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: --grid: mapper.gate: must be > 0.0 and <= 5.0, got -0.1
    """
    grids = {key: tuple(values) for key, values in grids.items()}
    for key, values in grids.items():
        if key == "seed":
            raise SpecError(GRID_OPTION, key, "sweep seeds with --seeds S1,S2,... instead")
        if not values:
            raise SpecError(GRID_OPTION, key, "empty grid: give values, e.g. mapper.gate=0.08,0.12")
    fixed = {".".join(parse_override(text)[0]): text for text in overrides}
    for key in grids:
        if key in fixed:
            raise SpecError(
                GRID_OPTION, key, f"also given as --set {fixed[key]}; keep one of the two"
            )
    if laps is not None and "laps" in grids:
        raise SpecError(GRID_OPTION, "laps", "also given as --laps; keep one of the two")
    if seeds is not None:
        if not seeds:
            raise SpecError(SEEDS_OPTION, "seed", "empty: give seeds, e.g. --seeds 0,1")
        if "seed" in fixed:
            raise SpecError(SEEDS_OPTION, "seed", f"also given as --set {fixed['seed']}")
    seed_axis: Sequence[int | None] = tuple(seeds) if seeds is not None else (None,)
    count = math.prod(len(values) for values in grids.values()) * len(seed_axis)
    if count > max_points:
        sizes = [str(len(values)) for values in grids.values()]
        if seeds is not None:
            sizes.append(f"{len(seed_axis)} seeds")
        raise SpecError(
            GRID_OPTION, ", ".join(grids) or "seed",
            f"{count} points ({' x '.join(sizes)}) exceed the limit of {max_points}; "
            "use fewer values or split the sweep",
        )
    base = list(overrides) + ([f"laps={laps}"] if laps is not None else [])
    path = scenario_path(scenario)
    table = read_toml(path)
    # The layout check (world, robot footprint, people, every lap's boxes) is most of a
    # load's time and reads only these fields: run it once per distinct layout, exactly
    # as load_scenario does, and build the other points' specs without it.
    checked_layouts = set()
    points = []
    for combination in itertools.product(*grids.values()):
        settings = tuple(zip(grids, combination, strict=True))
        for seed in seed_axis:
            point_overrides = base + [f"{key}={toml_value(value)}" for key, value in settings]
            if seed is not None:
                point_overrides.append(f"seed={seed}")
            with _blame_options(grids):
                spec = scenario_from_toml(copy.deepcopy(table), file=str(path),
                                          overrides=point_overrides, check_layout=False)
                layout = (spec.world, spec.robot, spec.people)
                if layout not in checked_layouts:
                    spec = scenario_from_toml(copy.deepcopy(table), file=str(path),
                                              overrides=point_overrides)
                    checked_layouts.add(layout)
            points.append(SweepPoint(len(points), settings, spec))
    return points


# --------------------------------------------------------------------------------------
# Rows, ranking and outputs


def _lookup(metrics: Mapping[str, Any] | None, path: Sequence[str]) -> Any:
    value: Any = metrics
    for key in path:
        if not isinstance(value, Mapping):
            return None
        value = value.get(key)
    return value


def metric_value(metrics: Mapping[str, Any] | None, name: str) -> Any:
    """Return metric column ``name`` (a key of :data:`METRICS`) of a run's metrics, or None.

    Examples
    --------
    >>> metric_value({"detection": {"f1": 0.5}}, "f1"), metric_value(None, "f1")
    (0.5, None)
    """
    return _lookup(metrics, METRICS[name].path)


def sweep_row(result: PointResult) -> dict[str, Any]:
    """Return the flat ``sweep.csv`` row of one point (``None`` where a metric is missing).

    Examples
    --------
    >>> point = sweep_points("sim1", {"mapper.gate": [0.1]}, seeds=[2])[0]
    >>> row = sweep_row(PointResult(point, {"detection": {"f1": 0.8}}))
    >>> row["point"], row["mapper.gate"], row["seed"], row["f1"], row["stops"], row["error"]
    (0, 0.1, 2, 0.8, None, '')
    """
    point = result.point
    row: dict[str, Any] = {"point": point.index, **dict(point.settings), "seed": point.seed}
    for name, metric in METRICS.items():
        row[name] = _lookup(result.metrics, metric.path)
    row["error"] = result.error or ""
    return row


def _mean(values: Sequence[Any]) -> float | None:
    numbers = [float(v) for v in values if isinstance(v, int | float) and math.isfinite(v)]
    return round(math.fsum(numbers) / len(numbers), MEAN_DIGITS) if numbers else None


def combine_seeds(results: Sequence[PointResult]) -> list[dict[str, Any]]:
    """Return one row per grid combination: each metric's mean over its seeds.

    A row has ``settings`` (the grid values), ``seeds``, ``failed`` (runs that raised) and
    one entry per :data:`METRICS` column (``None`` where no seed has a value).

    Examples
    --------
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
        for name in METRICS:
            row[name] = _mean([point_row[name] for point_row in point_rows])
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
    from scenarios.outputs import csv_text, json_text, stage_and_publish

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
            from scenarios.tune_plot import plot_sweep  # matplotlib only when drawing

            plot_sweep(summary, staging / "figures" / "sweep.png")
        if extra is not None:
            extra(summary, staging)
        (staging / "sweep.csv").write_text(csv_text(rows))
        (staging / "sweep.json").write_text(json_text(summary))

    stage_and_publish(Path(out), fill)
    return summary


def settings_text(settings: Mapping[str, Any]) -> str:
    """Return ``key=value ...`` of a point's settings, as on the command line.

    Examples
    --------
    >>> settings_text({"mapper.gate": 0.1, "policy": "adaptive"})
    'mapper.gate=0.1 policy=adaptive'
    """
    return " ".join(f"{key}={display_value(value)}" for key, value in settings.items())


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
                   limit: int = RANKING_ROWS) -> str:
    """Return the ranked table of a sweep (means over seeds) and its best point, as text.

    Examples
    --------
    >>> points = sweep_points("sim1", {"mapper.gate": [0.08, 0.12]})
    >>> summary = _sweep_summary([PointResult(points[0], {"detection": {"f1": 0.5}}),
    ...                           PointResult(points[1], {"detection": {"f1": 0.75}})], "f1")
    >>> print(format_ranking(summary, "out").splitlines()[-2])
    best by F1: mapper.gate=0.12 (0.75, 1 seed)
    """
    sort = summary["sort"]
    ranking = summary["ranking"]
    keys = list(summary["grid"])
    header = ["rank", *keys, "seeds", *TABLE_COLUMNS.values()]
    lines = [[str(rank_number), *(display_value(row["settings"][key]) for key in keys),
              str(len(row["seeds"])) + (f" ({row['failed']} failed)" if row["failed"] else ""),
              *(_cell(row[name]) for name in TABLE_COLUMNS)]
             for rank_number, row in enumerate(ranking[:limit], start=1)]
    widths = [max(len(cell) for cell in column) for column in zip(header, *lines, strict=True)]
    text = [
        f"{summary['scenario']}: {len(summary['points'])} runs of {summary['laps']} laps, "
        f"ranked by {METRICS[sort].label} (means over seeds)",
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
    text.append(f"results in {out}/ (sweep.csv, sweep.json, figures/sweep.png)")
    return "\n".join(text)


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``semistatic tune`` on the subparsers ``commands``; return its parser.

    Examples
    --------
    >>> parser = argparse.ArgumentParser(prog="semistatic")
    >>> tune = add_parser(parser.add_subparsers(dest="command"))
    >>> args = parser.parse_args(["tune", "sim1", "--grid", "mapper.gate=0.1,0.2"])
    >>> args.grids, args.jobs, args.sort
    (['mapper.gate=0.1,0.2'], 1, 'table1_mean_avg_cm')
    """
    tune = commands.add_parser(
        "tune", help="sweep thresholds over a grid (in parallel) and rank the results",
        description="Run SCENARIO for every combination of the --grid values (times the "
                    "--seeds), rank the results and write DIR/sweep.csv, DIR/sweep.json and "
                    "DIR/figures/sweep.png.",
    )
    tune.add_argument("scenario", help="bundled name (sim1, sim2, pal1, pal3a, pal3b) or a .toml")
    tune.add_argument(
        "--grid", dest="grids", action="append", default=[], metavar="KEY=V1,V2,...",
        help="values to sweep, e.g. --grid mapper.gate=0.08,0.12 --grid policy=conservative,"
             "adaptive (the Cartesian product is run)",
    )
    tune.add_argument("--laps", type=int, help="laps of every run (overrides the file)")
    tune.add_argument("--seeds", metavar="S1,S2,...",
                      help="run every combination with each seed (default: the file's seed)")
    tune.add_argument("--jobs", type=int, default=1, help="runs in parallel (default 1)")
    tune.add_argument("--out", type=Path, help="output directory (default results/tune-SCENARIO)")
    tune.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="fixed override for every run, e.g. --set policy=adaptive",
    )
    tune.add_argument(
        "--sort", default=DEFAULT_SORT, metavar="METRIC",
        help=f"rank by this column (default {DEFAULT_SORT}); one of {', '.join(METRICS)}",
    )
    tune.add_argument("--no-figures", action="store_true", help="skip figures/sweep.png")
    tune.add_argument(
        "--recording", dest="recordings", action="append", default=[], type=Path,
        metavar="DIR",
        help="replay the mapper on this recording (`semistatic run SCENARIO --record DIR`) "
             "instead of re-simulating; one per seed; only mapper thresholds under the "
             "conservative policy (they cannot change the motion)",
    )
    search = tune.add_argument_group(
        "search with Optuna (instead of --grid)",
        "the study lives in an Optuna storage (DIR/study.db by default): re-running the same "
        "command after an interruption continues it",
    )
    search.add_argument(
        "--param", dest="params", action="append", default=[],
        metavar="KEY=LOW:HIGH[:log] | KEY=V1,V2,...",
        help="a parameter to search: a range (integers when both ends are), on a log scale, "
             "or choices, e.g. --param mapper.gate=0.05:0.20 --param mapper.outlier_k=2,3,4",
    )
    search.add_argument("--trials", type=int, help="finished trials wanted (default 20; grid: "
                                                   "its size)")
    search.add_argument("--sampler", default="tpe", help="tpe (default), random or grid")
    search.add_argument("--grid-points", type=int, default=5,
                        help="values of each range for --sampler grid (default 5)")
    search.add_argument(
        "--objective", dest="objectives", action="append", default=[], metavar="METRIC",
        help="metric to optimise (mean over seeds; default the --sort metric); several make "
             "a multi-objective search with a Pareto front, e.g. --objective "
             "table1_mean_avg_cm --objective f1 --objective total_lap_time_s",
    )
    search.add_argument("--storage", metavar="URL",
                        help="Optuna storage URL (default sqlite:///DIR/study.db), e.g. a "
                             "shared postgresql:// database for a cluster")
    search.add_argument("--study", metavar="NAME", help="study name (default tune-SCENARIO)")
    search.add_argument("--backend", default="pool", choices=("pool", "ray"),
                        help="where trials run: worker processes (default) or Ray tasks")
    search.add_argument("--address", metavar="ADDR",
                        help="Ray cluster address (with --backend ray; default: a local "
                             "Ray instance with --jobs CPUs)")
    return tune


def main_tune(args: argparse.Namespace) -> int:
    """Run ``semistatic tune``: validate every point, run the sweep, write and rank.

    Returns 0 when every run finished, 1 when some raised (their rows say why). Bad
    input raises :class:`~worlds.errors.SpecError` before anything runs or is written.

    Examples
    --------
    >>> parser = argparse.ArgumentParser()
    >>> _ = add_parser(parser.add_subparsers())
    >>> main_tune(parser.parse_args(["tune", "sim1", "--grid", "mapper.gate=0.1", "--jobs", "0"]))
    Traceback (most recent call last):
    ...
    worlds.errors.SpecError: --jobs: jobs: must be >= 1, got 0
    """
    if args.jobs < 1:
        raise SpecError("--jobs", "jobs", f"must be >= 1, got {args.jobs}")
    if getattr(args, "params", None):
        from scenarios.tune_study import main_search  # Optuna only when searching

        return main_search(args)
    if args.sort not in METRICS:
        raise SpecError(
            "--sort", args.sort,
            f"unknown metric{did_you_mean(args.sort, METRICS)}; one of {', '.join(METRICS)}",
        )
    grids = parse_grids(args.grids)
    seeds = parse_seeds(args.seeds) if args.seeds is not None else None
    recordings = RecordingSet.read(args.recordings) if args.recordings else None
    laps = args.laps
    if recordings is not None:  # a replay runs the recorded laps and seeds by default
        laps, seeds = recordings.defaults(laps, seeds)
    if not grids and seeds is None:
        raise SpecError(
            GRID_OPTION, "KEY=V1,V2,...", "nothing to sweep: give at least one --grid or --seeds"
        )
    points = sweep_points(args.scenario, grids, seeds=seeds, laps=laps,
                          overrides=args.overrides)
    if recordings is not None:
        for point in points:  # refuse what a replay cannot honour before any work
            recordings.for_spec(point.spec)
    out = args.out if args.out is not None else Path("results") / f"tune-{points[0].spec.name}"
    check_output_dir(out)
    with count_progress(len(points), f"tune {points[0].spec.name}", "run") as advance:
        results = run_sweep(points, jobs=args.jobs, recordings=recordings,
                            on_result=lambda result: advance(result.point.label))
    summary = write_sweep(results, out, sort=args.sort, figures=not args.no_figures)
    print(format_ranking(summary, out))
    return 1 if any(result.failed for result in results) else 0
