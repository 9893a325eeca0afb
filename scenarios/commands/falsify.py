"""``semistatic falsify``: search scenario variations for where a field policy fails.

``semistatic falsify occlusion_hall --policy adaptive,guarded --vary
'world.people.worker.trigger_distance=uniform(0.3, 3.0)' --vary
'world.people.worker.speed=uniform(0.3, 1.6)' --budget 60 --jobs 2`` lets a sampler
(:mod:`scenarios.falsify.search`) propose values of the varied keys, runs each sample,
and drives the objective (default: the least separation between the vehicle and a person)
toward a violation (default: contact). Every policy gets its own study and the same
budget. It writes::

    DIR/study.db               the Optuna studies, one per policy (what a resume reads)
    DIR/falsify.json           the command and what defines the search
    DIR/runs.parquet, runs.csv one row per sample: policy, drawn values, objectives,
                               violation, the run's metrics flattened
    DIR/summary.json           per policy: violations, rate, worst sample, best so far,
                               key importance, coverage of the bins
    DIR/counterexamples/       every violation and the --k-worst worst other samples:
                               POLICY-NNNN.toml and its world, for ``semistatic run``
                               (with --rrd also POLICY-NNNN.rrd, its Rerun recording)
    DIR/figures/*.png          best so far against simulations; failure-region maps
    DIR/worlds/*.toml          the varied worlds of world-object keys

Everything is checked before a study is opened (bad input: exit 2, nothing touched).
The same command resumes an interrupted search: finished samples are kept, a sample left
running by a killed process is run again, none twice.

Examples
--------
>>> parser = argparse.ArgumentParser(prog="semistatic")
>>> _ = add_parser(parser.add_subparsers(dest="command"))
>>> args = parser.parse_args(["falsify", "occlusion_hall", "--vary",
...                           "world.people.worker.speed=uniform(0.5, 1.5)"])
>>> args.budget, args.sampler, args.objectives
(50, 'tpe', [])
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import json
from pathlib import Path

from scenarios.process.errors import InputError
from scenarios.process.output_paths import check_output_paths, sqlite_path
from scenarios.process.staging import (
    check_resumable_dir,
    read_result_marker,
    write_atomic,
    write_result_marker,
)
from scenarios.spec.load import scenario_help
from scenarios.tuning.run import BACKENDS, check_backend
from semistatic.errors import SpecError

__all__ = ["DEFAULT_BUDGET", "KIND", "MANIFEST_FILE", "add_parser", "main_falsify"]

DEFAULT_BUDGET = 50
KIND = "falsify"
MANIFEST_FILE = "falsify.json"


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``semistatic falsify`` on the subparsers ``commands``; return its parser."""
    from scenarios.falsify.objectives import DEFAULT_OBJECTIVE
    from scenarios.falsify.search import DEFAULT_SAMPLER, SAMPLERS

    falsify = commands.add_parser(
        "falsify", help="search scenario variations for where a field policy fails",
        description="Search the --vary box for samples where the --objective reaches its "
                    "--threshold (default: a person touched), per --policy on the same "
                    "--budget; write every violation as a scenario file semistatic run "
                    "repeats. Re-run the same command to resume.",
    )
    falsify.add_argument("scenario", help=scenario_help())
    falsify.add_argument(
        "--vary", action="append", default=[], metavar="KEY=uniform(LOW, HIGH)",
        help="a searched key and its range (or choice(V1, V2, ...)): a --set key "
             "(safety.slowdown, faults.braking_factor) or a world object, "
             "world.people.NAME.FIELD or world.boxes.NAME.FIELD (pose[1] is y)",
    )
    falsify.add_argument(
        "--objective", dest="objectives", action="append", default=[], metavar="METRIC",
        help=f"metric driven the worse way (default {DEFAULT_OBJECTIVE}); a metrics.json "
             "column as runs.csv names it; several make a Pareto search")
    falsify.add_argument(
        "--threshold", dest="thresholds", action="append", default=[], type=float,
        metavar="VALUE", help="a violation, one per --objective (default: contact, 0 m of "
                              "separation or 1 collision)")
    falsify.add_argument("--budget", type=int, default=DEFAULT_BUDGET,
                         help=f"simulations per policy (default {DEFAULT_BUDGET})")
    falsify.add_argument("--stop-at-first", action="store_true",
                         help="stop a policy's search at its first violation")
    falsify.add_argument("--sampler", default=DEFAULT_SAMPLER,
                         help=f"{', '.join(SAMPLERS)} (default {DEFAULT_SAMPLER})")
    falsify.add_argument("--sampler-seed", type=int, default=0,
                         help="seed of the sampler (default 0)")
    falsify.add_argument("--policy", metavar="P1,P2,...",
                         help="field policies to search, each on the whole budget "
                              "(default: the scenario's own)")
    falsify.add_argument("--seed", type=int, help="scenario seed of every run (default: the "
                                                  "file's)")
    falsify.add_argument("--laps", type=int, help="laps of every run (overrides the file)")
    falsify.add_argument("--set", dest="overrides", action="append", default=[],
                         metavar="KEY=VALUE", help="fixed override for every run")
    falsify.add_argument("--k-worst", type=int, default=5,
                         help="worst samples written as counterexamples besides the "
                              "violations (default 5)")
    falsify.add_argument("--bins", type=int, default=5,
                         help="coverage bins per range (default 5; a choice: one per value)")
    falsify.add_argument("--backend", default="pool", choices=BACKENDS,
                         help="where runs go: worker processes (default) or Ray tasks")
    falsify.add_argument("--address", metavar="ADDR",
                         help="Ray cluster address (with --backend ray)")
    falsify.add_argument("--jobs", type=int, default=1, help="runs in parallel (default 1)")
    falsify.add_argument("--storage", metavar="URL",
                         help="Optuna storage URL (default sqlite:///DIR/study.db)")
    falsify.add_argument("--out", type=Path,
                         help="output directory (default results/falsify-SCENARIO)")
    falsify.add_argument("--no-warm-start", action="store_true",
                         help="run every sample in full, even when the varied people act "
                              "only in the last laps (the metrics are the same)")
    falsify.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    falsify.add_argument("--rrd", action="store_true",
                         help="also record every counterexample for the Rerun viewer: one more "
                              "run each, counterexamples/POLICY-NNNN.rrd beside its file")
    return falsify


def _configs(args: argparse.Namespace, out: Path):
    """Return one validated search configuration per policy."""
    from scenarios.campaign.variations import parse_variations
    from scenarios.commands.campaign import split_policies
    from scenarios.falsify.objectives import parse_objectives
    from scenarios.falsify.search import FalsifyConfig
    from scenarios.spec.load import load_scenario

    variations = parse_variations(args.vary)
    kpis = parse_objectives(args.objectives, args.thresholds)
    for option, value, low in (("--k-worst", args.k_worst, 0), ("--bins", args.bins, 1)):
        if not low <= value <= 1000:
            raise SpecError(option, option[2:], f"must be >= {low} and <= 1000, got {value}")
    base = load_scenario(args.scenario, overrides=[
        *args.overrides, *([f"laps={args.laps}"] if args.laps is not None else [])])
    policies = split_policies(args.policy) or [base.policy]
    seed = base.seed if args.seed is None else args.seed
    configs = [FalsifyConfig(args.scenario, policy, variations, kpis, budget=args.budget,
                             seed=seed, sampler=args.sampler, sampler_seed=args.sampler_seed,
                             laps=args.laps, overrides=tuple(args.overrides),
                             worlds_dir=out.absolute() / "worlds")
               for policy in policies]
    for config in configs:
        config.check()
    return base.name, configs


def record_counterexamples(out: Path) -> str:
    """Record each counterexample of ``out`` once for Rerun; return a summary line.

    Each ``counterexamples/STEM.toml`` is run again (its metrics are the sample's) with a
    :class:`~scenarios.logs.rrd.RerunRecorder` writing ``STEM.rrd`` beside it; one that
    has its recording already (a resumed search) is skipped.
    """
    from scenarios.bench.runner import run_scenario
    from scenarios.falsify.report import COUNTEREXAMPLES_DIR
    from scenarios.logs.rrd import RerunRecorder
    from scenarios.process.progress import count_progress
    from scenarios.spec.load import load_scenario

    folder = out / COUNTEREXAMPLES_DIR
    files = sorted(path for path in folder.glob("*.toml")
                   if not path.name.endswith(".world.toml")) if folder.is_dir() else []
    todo = [path for path in files if not path.with_suffix(".rrd").exists()]
    with count_progress(len(todo), "record counterexamples", "run") as advance:
        for path in todo:
            spec = load_scenario(str(path))
            recorder = RerunRecorder(path.with_suffix(".rrd"), recording_id=path.stem)
            try:
                run_scenario(spec, observers=(recorder,))
            except BaseException:
                recorder.close(finish=False)
                raise
            recorder.close()
            advance(path.stem)
    return (f"{len(files)} counterexample recordings in {folder}/ (open one with: rerun "
            f"{folder}/NAME.rrd)")


def main_falsify(args: argparse.Namespace) -> int:
    """Run ``semistatic falsify``; return 0, or 1 when some sample's run raised."""
    check_backend(args.backend, args.jobs, args.address)
    if args.rrd:
        from scenarios.logs.rrd_options import rerun_missing

        if rerun_missing() is not None:
            raise InputError(f"--rrd: {rerun_missing()}")
    out = args.out
    if out is None:
        out = Path("results") / f"falsify-{Path(args.scenario).stem}"
    check_output_paths({"--out": out, "--storage": sqlite_path(args.storage)}, replaced=None,
                       storages=["--storage"])
    name, configs = _configs(args, out)
    definition = {"version": importlib.metadata.version("semistatic"),
                  "searches": [config.fingerprint() for config in configs]}
    resume = check_resumable_dir(out, manifest=MANIFEST_FILE, kind=KIND, definition=definition,
                                 noun="falsification search")
    from scenarios.falsify.report import PolicySearch, trial_status, write_falsification
    from scenarios.process.progress import count_progress
    from scenarios.tuning.run import open_backend
    from scenarios.tuning.search import finished_trials, open_study, run_study
    from scenarios.tuning.study import default_storage
    from scenarios.tuning.warm import WarmStarts

    out.mkdir(parents=True, exist_ok=True)
    if read_result_marker(out) is None:  # a resumed falsify keeps its marker and id
        write_result_marker(out, "falsify")
    command = ["semistatic", *getattr(args, "argv", ["falsify"])]
    if not resume:
        write_atomic(out / MANIFEST_FILE, json.dumps(
            {"kind": KIND, "definition": definition, "command": command}, indent=2) + "\n")
    url = args.storage or default_storage(out)
    searches = []
    with open_backend(args.backend, args.jobs, args.address) as backend:
        for config in configs:
            study, storage = open_study(config, url, f"falsify-{name}-{config.policy}")
            done = len(finished_trials(study))
            if done:
                print(f"{out}: {config.policy}: {done} samples finished earlier")

            def found(study, config=config) -> bool:
                return args.stop_at_first and any(
                    config.violated(trial) for trial in finished_trials(study))

            remaining = 0 if found(study) else max(0, config.budget - done)
            warm = None if args.no_warm_start else config.warm_lap()
            if warm is not None and remaining:
                print(f"{config.policy}: the varied people act from lap {warm} on: laps "
                      f"1-{warm - 1}, and lap {warm} up to where they step out, are "
                      "simulated once per worker (warm start)")
            source = None if warm is None else WarmStarts(config.base_spec(), warm)
            with count_progress(remaining, f"falsify {name} {config.policy}", "sample") as advance:
                run_study(study, storage, config, backend, source,
                          on_trial=lambda number, values: advance(f"sample {number}: {values}"),
                          until=found)
            searches.append(PolicySearch(config, study))
    print(write_falsification(out, searches, bins=args.bins, k_worst=args.k_worst,
                              command=command, figures=not args.no_figures))
    if args.rrd:
        print(record_counterexamples(out))
    raised = [trial for search in searches for trial in finished_trials(search.study)
              if trial_status(trial)[0] == "error"]
    return 1 if raised else 0
