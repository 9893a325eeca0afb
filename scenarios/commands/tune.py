"""``semistatic tune``: sweep a grid of ``--set`` values, or search them with Optuna.

The work is split by job: :mod:`scenarios.tuning.metrics` (the metric columns),
:mod:`scenarios.tuning.points` (grid options, validated points), :mod:`scenarios.tuning.run`
(running points: closed loop or replay, process pool or Ray),
:mod:`scenarios.tuning.table` (rows, ranking, sweep files), :mod:`scenarios.tuning.plot`
(sweep figure); the Optuna search (``--param``) is :mod:`scenarios.tuning.params`,
:mod:`scenarios.tuning.search`, :mod:`scenarios.tuning.report` and :mod:`scenarios.tuning.study`.

``semistatic tune SCENARIO --grid mapper.gate=0.08,0.12,0.16 --seeds 0,1 --jobs 2`` runs
every point of the Cartesian product of the grids (times the seeds) as an independent
closed-loop run (:func:`scenarios.bench.runner.run_scenario`), in a process pool, and writes::

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
>>> parser = argparse.ArgumentParser(prog="semistatic")
>>> _ = add_parser(parser.add_subparsers(dest="command"))
>>> args = parser.parse_args(["tune", "pal1", "--param", "mapper.gate=0.05:0.2"])
>>> args.params, args.sampler, args.backend
(['mapper.gate=0.05:0.2'], 'tpe', 'pool')
"""

from __future__ import annotations

import argparse
from pathlib import Path

from scenarios.process.errors import check_jobs
from scenarios.process.output_paths import check_output_paths
from scenarios.process.progress import count_progress
from scenarios.process.staging import check_output_dir
from scenarios.spec.load import scenario_help
from scenarios.tuning.metrics import DEFAULT_SORT, METRICS
from scenarios.tuning.points import GRID_OPTION, parse_grids, parse_seeds, sweep_points
from scenarios.tuning.run import RecordingSet, run_sweep
from scenarios.tuning.table import format_ranking, write_sweep
from semistatic.errors import SpecError
from semistatic.validation import did_you_mean

__all__ = ["add_parser", "main_tune"]


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
    tune.add_argument("scenario", help=f"{scenario_help()}; with --param several, "
                                       "comma-separated (pal1,sim1): every trial runs each")
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
             "instead of re-simulating; one per scenario and seed; only mapper thresholds "
             "under the conservative policy (they cannot change the motion)",
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
    input raises :class:`~semistatic.errors.SpecError` before anything runs or is written.

    Examples
    --------
    >>> parser = argparse.ArgumentParser()
    >>> _ = add_parser(parser.add_subparsers())
    >>> args = parser.parse_args(["tune", "sim1", "--grid", "mapper.gate=0.1", "--jobs", "0"])
    >>> main_tune(args)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --jobs: jobs: must be >= 1 and <= ..., got 0 (4 per CPU of ...
    """
    check_jobs(args.jobs)
    if getattr(args, "params", None):
        from scenarios.tuning.study import main_search  # Optuna only when searching

        return main_search(args)
    if "," in args.scenario:
        raise SpecError("scenario", args.scenario, "several scenarios are searched together "
                        "with --param (every trial runs each); --grid sweeps one")
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
    check_output_paths({"--out": out}, inputs={"--recording": args.recordings})
    check_output_dir(out)
    with count_progress(len(points), f"tune {points[0].spec.name}", "run") as advance:
        results = run_sweep(points, jobs=args.jobs, recordings=recordings,
                            on_result=lambda result: advance(result.point.label))
    summary = write_sweep(results, out, sort=args.sort, figures=not args.no_figures)
    print(format_ranking(summary, out, figures=not args.no_figures))
    return 1 if any(result.failed for result in results) else 0
