"""``semistatic tune --param ...``: validate, open (or resume) the study, run it, report.

Everything is checked before the study is touched: the parameters against the scenario
(both ends of every range, every choice), the recordings, the objectives, the backend,
then the storage (a study of another search in it is refused and left as it is). The
output directory holds the SQLite study while the search runs and is replaced as a whole
by the results (with a copy of the study) when it ends.

Examples
--------
>>> default_storage(Path("/tmp/out"))
'sqlite:////tmp/out/study.db'
"""

from __future__ import annotations

import argparse
import sqlite3
from pathlib import Path

from scenarios.process.output_paths import check_output_paths, sqlite_path
from scenarios.process.progress import count_progress
from scenarios.process.staging import check_output_dir, read_result_marker, write_result_marker
from scenarios.results.outputs import json_text
from scenarios.tuning.params import grid_size, parse_params
from scenarios.tuning.points import GRID_OPTION, parse_seeds
from scenarios.tuning.report import format_study, plot_study, study_report
from scenarios.tuning.run import RecordingSet, check_backend, open_backend
from scenarios.tuning.search import (
    SearchConfig,
    finished_trials,
    open_study,
    run_study,
    trial_results,
)
from scenarios.tuning.table import write_sweep
from semistatic.errors import SpecError

__all__ = ["DEFAULT_TRIALS", "STUDY_FILE", "default_storage", "main_search", "split_scenarios"]

DEFAULT_TRIALS = 20
STUDY_FILE = "study.db"


def split_scenarios(text: str) -> list[str]:
    """Return the scenarios of ``SCENARIO[,SCENARIO...]``: every trial runs each of them.

    Examples
    --------
    >>> split_scenarios("pal1,sim1"), split_scenarios("my.toml")
    (['pal1', 'sim1'], ['my.toml'])
    >>> split_scenarios("pal1,")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: scenario: pal1,: an empty name; give SCENARIO[,SCENARIO...]
    """
    names = [name.strip() for name in text.split(",")]
    if not all(names):
        raise SpecError("scenario", text, "an empty name; give SCENARIO[,SCENARIO...]")
    return names


def default_storage(out: Path) -> str:
    """Return the SQLite URL of the study kept in output directory ``out``."""
    return f"sqlite:///{(out / STUDY_FILE).absolute()}"


def _config(args: argparse.Namespace, recordings: RecordingSet | None) -> SearchConfig:
    params = parse_params(args.params)
    seeds = parse_seeds(args.seeds) if args.seeds is not None else None
    laps = args.laps
    if recordings is not None:
        laps, seeds = recordings.defaults(laps, seeds)
    trials = args.trials
    if trials is None:
        trials = grid_size(params, args.grid_points) if args.sampler == "grid" else DEFAULT_TRIALS
    first, *also = split_scenarios(args.scenario)
    config = SearchConfig(
        first, params, objectives=tuple(args.objectives or [args.sort]),
        seeds=seeds, laps=laps, overrides=tuple(args.overrides), sampler=args.sampler,
        trials=trials, grid_points=args.grid_points, also=tuple(also),
    )
    config.validate(recordings)
    return config


def main_search(args: argparse.Namespace) -> int:
    """Run ``semistatic tune --param ...``; return 0, or 1 when some trial's runs raised."""
    if args.grids:
        raise SpecError(GRID_OPTION, args.grids[0], "search with --param or sweep with "
                        "--grid, not both (--sampler grid makes a grid of --param ranges)")
    check_backend(args.backend, args.jobs, args.address)
    recordings = RecordingSet.read(args.recordings) if args.recordings else None
    config = _config(args, recordings)
    name = args.study or "tune-" + "+".join(
        dict.fromkeys(point.spec.name for point in config.points({})))
    out = args.out if args.out is not None else Path("results") / name
    own_storage = out / STUDY_FILE  # carried over into the results when they replace out
    check_output_paths({"--out": out, "--storage": sqlite_path(args.storage)},
                       storages=["--storage"], managed=[own_storage],
                       inputs={"--recording": args.recordings})
    check_output_dir(out)
    given = sqlite_path(args.storage)
    keep_study = args.storage is None or (given is not None
                                          and given.resolve() == own_storage.resolve())
    url = None if keep_study else args.storage
    if url is None:
        out.mkdir(parents=True, exist_ok=True)
        if read_result_marker(out) is None:  # the study inside makes it a result being written
            write_result_marker(out, "tune")
        url = default_storage(out)
    study, storage = open_study(config, url, name)
    remaining = max(0, config.trials - len(finished_trials(study)))
    with count_progress(remaining, f"tune {name}", "trial") as advance, \
            open_backend(args.backend, args.jobs, args.address) as backend:
        run_study(study, storage, config, backend, recordings,
                  on_trial=lambda number, values: advance(f"trial {number}: {values}"))
    report = study_report(study, config)

    def extra(summary: dict, staging: Path) -> None:
        summary["study"] = {"name": name, "storage": url, **report}
        (staging / "study.json").write_text(json_text(summary["study"]))
        if keep_study:  # keep the study with the results (optuna-dashboard)
            with sqlite3.connect(own_storage) as source, \
                    sqlite3.connect(staging / STUDY_FILE) as copy:
                source.backup(copy)
        if not args.no_figures:
            plot_study(report, staging / "figures")

    # sweep.png draws a full grid; a search draws its curve and Pareto front instead.
    write_sweep(trial_results(study, config), out, sort=config.objectives[0],
                figures=False, extra=extra)
    print(format_study(report, out))
    return 1 if any(row["error"] for row in report["trials"]) else 0

