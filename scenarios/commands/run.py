"""The ``check``, ``run`` and ``table`` commands: a scenario validated, run, tabulated.

``semistatic check SCENARIO`` validates everything a run reads (files, every lap's layout,
options, the output location) and stops; ``run`` runs one scenario headless and writes
its output directory (:mod:`scenarios.results.outputs`); ``table`` runs the five paper
scenarios and prints Table 1 beside the paper's. Bad input raises before any work
(:mod:`scenarios.process.errors`).

Examples
--------
>>> parser = argparse.ArgumentParser(prog="semistatic")
>>> add_parsers(parser.add_subparsers(dest="command"))
>>> args = parser.parse_args(["run", "pal1", "--laps", "2", "--compare"])
>>> args.scenario, args.laps, args.compare, args.out
('pal1', 2, True, None)
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path

from scenarios.logs.rrd_options import DEFAULT_VIEWER_URL, open_timeline
from scenarios.process.errors import (
    EXIT_RUN_FAILED,
    InputError,
    check_display,
    check_jobs,
)
from scenarios.process.output_paths import check_output_paths
from scenarios.process.progress import count_progress, sim_progress
from scenarios.process.staging import check_output_dir, stage_and_publish
from scenarios.spec.load import scenario_help
from scenarios.spec.scenario import POLICIES
from semistatic.errors import SpecError

__all__ = ["BAG_STORAGE_CHOICES", "add_parsers", "main_check", "main_run", "main_table"]

# scenarios.logs.bag.BAG_STORAGES, spelled out so that --help does not import rosbags.
BAG_STORAGE_CHOICES = ("sqlite3", "mcap")


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Register ``check``, ``run`` and ``table`` on the subparsers ``commands``."""
    check = commands.add_parser(
        "check", help="validate a scenario (files, every lap's layout, options) and stop",
    )
    check.add_argument("scenario", help=scenario_help())
    check.add_argument("--laps", type=int, help="number of laps (overrides the file)")
    check.add_argument("--seed", type=int, help="random seed (overrides the file)")
    check.add_argument("--out", type=Path, help="also check this output directory")
    check.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a scenario value, e.g. --set mapper.gate=0.15",
    )

    run = commands.add_parser("run", help="run one scenario headless and write its results")
    run.add_argument("scenario", help=scenario_help())
    run.add_argument("--laps", type=int, help="number of laps (overrides the file)")
    run.add_argument("--seed", type=int, help="random seed (overrides the file)")
    run.add_argument("--out", type=Path, help="output directory (default results/SCENARIO)")
    run.add_argument("--gui", action="store_true", help="watch the run in the PyBullet GUI")
    run.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a scenario value, e.g. --set mapper.gate=0.15 --set policy=adaptive",
    )
    run.add_argument(
        "--compare", action="store_true",
        help="also run the other bundled field policies (conservative, adaptive, guarded) on "
             "the same seed and compare lap times and safety figures",
    )
    run.add_argument(
        "--compare-sharing", action="store_true",
        help="also run with sharing off on the same seed and compare every vehicle's lap "
             "times (metrics.json sharing_comparison, figures/lap_times_sharing.png)",
    )
    run.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    run.add_argument(
        "--bag", type=Path, metavar="DIR",
        help="also write the run as a ROS 2 bag directory DIR (must not exist): clock, "
             "scans, odometry, EKF pose, tf (map, odom, base_link, laser), the map "
             "polylines coloured by status, the safety fields, people and boxes, for "
             "RViz 2 (fixed frame map) or Foxglove",
    )
    run.add_argument(
        "--bag-storage", choices=BAG_STORAGE_CHOICES, default="sqlite3",
        help="storage of the --bag (default sqlite3, ROS 2 Humble's; mcap for Foxglove)",
    )

    run.add_argument(
        "--rrd", type=Path, metavar="FILE",
        help="also record the run on a timeline for the Rerun viewer (FILE.rrd must not "
             "exist): the map top-down with fields, scans, maps and people, time series and "
             "events (needs the rerun extra: pip install 'semistatic[rerun]')",
    )
    run.add_argument(
        "--viewer", nargs="?", const=DEFAULT_VIEWER_URL, metavar="URL",
        help="stream the run live to a Rerun viewer (start `rerun` first; default "
             f"{DEFAULT_VIEWER_URL})",
    )
    run.add_argument(
        "--record", type=Path, metavar="DIR",
        help="also record what the mapper and the scoring saw (DIR must not exist), for "
             "`semistatic tune --recording DIR`",
    )

    table = commands.add_parser("table", help="run every bundled scenario: the paper's Table 1")
    table.add_argument("--out", type=Path, default=Path("results/table"), help="output directory")
    table.add_argument("--laps", type=int, help="laps per scenario (overrides the files)")
    table.add_argument("--jobs", type=int, default=1, help="scenarios run in parallel")
    table.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    table.add_argument(
        "--compare", action="store_true",
        help="also run each scenario with the other bundled field policies (adaptive, "
             "guarded) and compare lap times and safety figures",
    )


def _load(scenario: str, overrides: Sequence[str], laps: int | None = None,
          seed: int | None = None):
    """Load and validate a scenario (every lap's layout included) before anything runs.

    ``--laps`` and ``--seed`` are applied as overrides; an error in them names the option.
    """
    from scenarios.spec.layout import scenario_world
    from scenarios.spec.load import OVERRIDE_FILE, load_scenario

    options = [(option, key, value) for option, key, value in
               (("--laps", "laps", laps), ("--seed", "seed", seed)) if value is not None]
    texts = [*overrides, *(f"{key}={value}" for _, key, value in options)]
    try:
        spec = load_scenario(scenario, overrides=texts)
    except SpecError as error:
        for option, key, _ in options:
            if error.file == OVERRIDE_FILE and error.key == key:
                raise SpecError(option, key, error.message) from None
        raise
    return spec, scenario_world(spec)


def _inputs(spec, world) -> dict[str, str]:
    """Return the files a run reads (a result replacing them would delete them)."""
    return {"scenario file": spec.source, "world file": getattr(world, "source", None)}


def _other_policies(spec) -> list[str]:
    """Return the bundled field policies other than the scenario's, in their order.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> _other_policies(SimpleNamespace(policy="adaptive"))
    ['conservative', 'guarded']
    """
    return [policy for policy in POLICIES if policy != spec.policy]


def _pieces(world) -> str:
    """Return ``"N test pieces, "`` for a world that has any, else ``""``."""
    count = len(world.test_pieces)
    return f"{count} test piece{'s' if count > 1 else ''}, " if count else ""


def main_check(args: argparse.Namespace) -> int:
    """Run ``semistatic check``: validate and print a summary; return the exit status."""
    from scenarios.spec.field_sizing import field_checks
    from scenarios.spec.layout import lap_worlds, robot_preset
    from worlds.checks import build_spline

    spec, world = _load(args.scenario, args.overrides, args.laps, args.seed)
    if args.out is not None:
        check_output_paths({"--out": args.out}, inputs=_inputs(spec, world))
        check_output_dir(args.out)
    boxes = [len(lap.boxes) for lap in lap_worlds(spec)]
    length = build_spline(world.path).length
    print(
        f"{spec.name}: valid ({spec.source})\n"
        f"  world {world.name}: {len(world.walls)} walls, {len(world.posts)} posts, "
        f"{_pieces(world)}"
        f"path {length:.2f} m in {len(world.path.segments)} segments at "
        f"{world.path.speed:g} m/s\n"
        f"  robot {spec.robot}, {spec.laps} laps, seed {spec.seed}, policy {spec.policy}, "
        f"{len(spec.moves)} box moves; boxes per lap: {boxes}\n"
        f"  every lap's layout passes the checks (posts in view, boxes clear of walls, "
        f"the path and the protective fields)\n"
        f"  protective fields against the formula (m; margin = actual - required):"
    )
    print(f"    {'segment':<16} {'speed':>5} {'length':>8} {'needs':>6} {'width':>6} "
          f"{'needs':>6} {'margin':>7}")
    for check in field_checks(spec, world, robot_preset(spec.robot, file=spec.source)):
        margin = min(check.length_margin, check.width_margin)
        flag = "  undersized (studied)" if check.undersized else ""
        print(f"    {check.segment:<16} {check.speed:>5.2f} {check.actual_length:>8.3f} "
              f"{check.required_length:>6.3f} {check.actual_width:>6.3f} "
              f"{check.required_width:>6.3f} {margin:>+7.3f}{flag}")
    _print_piece_sightings(spec, world)
    return 0


def _print_piece_sightings(spec, world) -> None:
    """Print whether each vehicle's safety laser scans through each test piece."""
    from scenarios.spec.pieces import piece_sightings

    sightings = piece_sightings(spec, world)
    if not sightings:
        return
    print("  test pieces against the safety lasers' scan planes (m above the floor):")
    print(f"    {'piece':<16} {'kind':<8} {'top':>5}  {'vehicle':<12} {'robot':<12} "
          f"{'scan':>5}  seen")
    for sighting in sightings:
        # Only a scenario that studies unseen pieces gets here with one (else: an error).
        seen = "yes" if sighting.seen else "NO: scans over it (studied)"
        print(f"    {sighting.piece:<16} {sighting.kind:<8} {sighting.top:>5.3f}  "
              f"{sighting.vehicle:<12} {sighting.robot:<12} {sighting.scan_height:>5.3f}  {seen}")


def main_run(args: argparse.Namespace) -> int:
    """Run ``semistatic run``: the scenario, its outputs, bag and recording; return the status."""
    from scenarios.bench.runner import run_scenario
    from scenarios.logs.bag import BAG_TOPICS, BagRecorder, check_new_bag_path, write_run_bag
    from scenarios.logs.recording import ScanRecorder, check_new_recording_path
    from scenarios.results.outputs import summarize, write_outputs
    from scenarios.spec.layout import estimated_sim_time, lap_worlds

    spec, world = _load(args.scenario, args.overrides, args.laps, args.seed)
    out = args.out if args.out is not None else Path("results") / spec.name
    # The bag and the Rerun recording may go into the new result (written after it).
    check_output_paths({"--out": out, "--bag": args.bag, "--record": args.record,
                        "--rrd": args.rrd}, into_result=["--bag", "--rrd"],
                       inputs=_inputs(spec, world))
    out = check_output_dir(out)
    check_display(args.gui)
    recorder = None
    if args.bag is not None:
        try:
            check_new_bag_path(args.bag, out=out)
        except ValueError as error:
            raise InputError(str(error)) from None
        recorder = BagRecorder()
    scan_recorder = None
    if args.record is not None:
        check_new_recording_path(args.record)
        scan_recorder = ScanRecorder()
    timeline = open_timeline(args.rrd, args.viewer, out, f"{spec.name}-seed{spec.seed}")
    observers = [observer for observer in (recorder, scan_recorder, timeline)
                 if observer is not None]
    total = estimated_sim_time(spec, world)
    try:
        with sim_progress(total, f"{spec.name} ({spec.policy})", spec.laps) as bar:
            log = run_scenario(spec, gui=args.gui, progress=bar, observers=observers,
                               world=world)
    except BaseException:
        if timeline is not None:
            timeline.close(finish=False)  # no half recording at --rrd
        raise
    comparison = None
    if args.compare:
        comparison = {}
        for other in _other_policies(spec):
            # The world as loaded at the start, never its file again (it may have changed).
            with sim_progress(total, f"{spec.name} ({other})", spec.laps) as bar:
                other_log = run_scenario(dataclasses.replace(spec, policy=other), progress=bar,
                                         world=world)
            comparison[other] = summarize(other_log)
    sharing_off = None
    if args.compare_sharing:
        if not spec.sharing:
            raise InputError(f"--compare-sharing: {spec.name} does not share segment maps "
                             "(sharing = false); add --set sharing=true")
        off_spec = dataclasses.replace(spec, sharing=False)
        with sim_progress(total, f"{spec.name} (sharing off)", spec.laps) as bar:
            sharing_off = summarize(run_scenario(off_spec, progress=bar, world=world))
    metrics = write_outputs(log, out, figures=not args.no_figures, comparison=comparison,
                            sharing_off=sharing_off)
    summary = _run_summary(metrics, out)
    if scan_recorder is not None:
        # Fingerprinted with the world the runs drove, not the file as it is now.
        scan_recorder.write(args.record, spec, metrics, worlds=lap_worlds(spec, world=world))
        summary += f"\nrecording in {args.record}/ ({scan_recorder.scans} scans)"
    if timeline is not None:
        # After the outputs too: a recording inside --out lands in the published directory.
        timeline.close()
        scans = sum(timeline.scans.values())
        if args.rrd is not None:
            summary += (f"\nRerun recording in {args.rrd} ({scans} scans; open it with: "
                        f"rerun {args.rrd})")
        if args.viewer is not None:
            summary += f"\nstreamed {scans} scans to the Rerun viewer at {args.viewer}"
    if recorder is not None:
        # After the outputs, so that a bag inside --out finds its parent directory.
        write_run_bag(args.bag, recorder.frames, log.robot, storage=args.bag_storage)
        summary += (
            f"\nROS 2 bag in {args.bag}/ ({args.bag_storage}, {len(recorder.frames)} scans; "
            f"topics {', '.join(BAG_TOPICS)}; RViz 2 fixed frame map, play with --clock)"
        )
    print(summary)
    failures = metrics["safety"]["failed_laps"]
    if failures:
        first = failures[0]
        more = f" (and {len(failures) - 1} more lap(s))" if len(failures) > 1 else ""
        print(f"run failed: lap {first['lap']}: {first['reason']}{more}; results in {out}/ "
              "record it (metrics.json safety.failed_laps)", file=sys.stderr)
        return EXIT_RUN_FAILED
    return 0


def _run_summary(metrics: dict, out: Path) -> str:
    table = metrics["table1_cm"]["mean"]
    detection = metrics["detection"]
    safety = metrics["safety"]
    perf = metrics["performance"]
    lines = [
        f"{metrics['scenario']}: {metrics['laps']} laps, policy {metrics['policy']}, "
        f"seed {metrics['seed']}",
    ]
    if metrics["laps"] < 2:
        lines.append("  Table 1 needs at least 2 laps (later laps against the lap-1 maps); "
                     "run with --laps 2 or more")
    elif table["avg"] is None:
        lines.append("  Table 1: no later-lap polyline was associated with a lap-1 map")
    else:
        lines.append(f"  Table 1 mean restricted Hausdorff (cm): avg {table['avg']} "
                     f"min {table['min']} max {table['max']}")
    if safety["failed_laps"]:
        lines.append(f"  detection: not scored, {len(safety['failed_laps'])} lap(s) did not "
                     "complete")
    else:
        lines.append(
            f"  detection: precision {detection['precision']:.3f} recall "
            f"{detection['recall']:.3f} F1 {detection['f1']:.3f}, objects from people "
            f"{detection['false_objects_from_people']}"
        )
    lines += [
        f"  localization RMSE {metrics['localization']['rmse_xy_m']} m, "
        f"NEES {metrics['localization']['nees_mean']}",
        f"  safety: {safety['collisions']} collisions, {safety['stops']} stops, "
        f"{safety['slowdowns']} slowdowns, {safety['total_time_s']:.1f} s over all laps",
    ]
    for name, vehicle in metrics.get("vehicles", {}).items():
        scores, laps = vehicle["detection"], vehicle["safety"]
        table = vehicle["table1_cm"]["mean"]["avg"]
        lines.append(
            f"  {name}: F1 {scores['f1']:.3f}, Table 1 mean {table} cm, "
            f"{laps['collisions']} collisions, {laps['stops']} stops, lap times "
            f"{', '.join(f'{t:.1f}' for t in laps['lap_time_s'])} s, objects from vehicles "
            f"{scores.get('false_objects_from_vehicles', 0)}"
        )
    for name, change in metrics.get("sharing_comparison", {}).items():
        lines.append(
            f"  {name}: sharing saves "
            f"{', '.join(f'{p:+.1f}%' for p in change['saved_percent'])} per lap"
        )
    for policy, compared in metrics.get("policy_comparison", {}).items():
        if policy in POLICIES and policy != "conservative":
            infractions = sum(compared["infractions"].values())
            lines.append(
                f"  {policy} fields save {compared['saved_percent']:.1f}% of the time against "
                f"conservative, {compared['stops']} stops, {infractions} infractions"
            )
    lines.append(
        f"  performance: real-time x{perf['real_time_factor']}, wall/engine "
        f"{perf['wall_over_engine']}, mapper {perf['mapper_ms_median']} ms/scan, "
        f"raycast {perf['raycast_ms_median']} ms/scan"
    )
    lines.append(f"results in {out}/ (metrics.json, table1.csv, maps/, figures/)")
    return "\n".join(lines)


def _table_job(task: tuple) -> tuple[str, dict]:
    """Run one bundled scenario (in a worker) and write its folder into the staging dir.

    ``task`` holds the scenario and world the command loaded at the start: no run reads a
    file again.
    """
    from scenarios.bench.runner import run_scenario
    from scenarios.results.outputs import summarize, write_outputs

    name, spec, world, staging, figures, compare = task
    comparison = None
    if compare:
        comparison = {other: summarize(run_scenario(dataclasses.replace(spec, policy=other),
                                                    world=world))
                      for other in _other_policies(spec)}
    metrics = write_outputs(run_scenario(spec, world=world), staging / name, figures=figures,
                            comparison=comparison)
    return name, metrics


def main_table(args: argparse.Namespace) -> int:
    """Run ``semistatic table``: the paper scenarios in workers, Table 1; return the status."""
    from scenarios.process.workers import worker_pool
    from scenarios.results.table import render_table, write_table
    from scenarios.spec.load import paper_scenarios

    names = paper_scenarios()
    check_jobs(args.jobs)
    # Fail fast on bad input, before any run; the runs use what is loaded here.
    loaded = {name: _load(name, [], args.laps) for name in names}
    check_output_paths({"--out": args.out})
    out = check_output_dir(args.out)
    results: dict[str, dict] = {}

    def fill(staging: Path) -> None:
        # The whole table is staged: an interrupted table leaves the previous one intact.
        tasks = [(name, *loaded[name], staging, not args.no_figures, args.compare)
                 for name in names]
        with count_progress(len(names), "table", "scenario") as advance:
            if args.jobs == 1:
                outcomes = map(_table_job, tasks)
                for name, metrics in outcomes:
                    results[name] = metrics
                    advance(name)
            else:
                with worker_pool(min(args.jobs, len(names))) as pool:
                    for name, metrics in pool.imap_unordered(_table_job, tasks):
                        results[name] = metrics
                        advance(name)
        write_table({name: results[name] for name in names}, staging)

    stage_and_publish(out, fill, command="table")
    ordered = {name: results[name] for name in names}
    print(render_table(ordered))
    print(f"results in {out}/ (table1.csv, table1.md, one folder per scenario)")
    failed = [name for name, metrics in ordered.items() if metrics["safety"]["failed_laps"]]
    if failed:
        print(f"run failed: some laps did not complete in {', '.join(failed)} "
              "(metrics.json safety.failed_laps)", file=sys.stderr)
        return EXIT_RUN_FAILED
    return 0
