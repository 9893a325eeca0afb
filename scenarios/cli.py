"""The ``semistatic`` command line (a contract: DESIGN.md "Command line").

Bad input (a missing or malformed file, an unknown key, an out-of-range value, an option
out of range, an output directory that cannot be created) ends with exit status 2 and one
line ``error: <file or option>: <key>: <what is wrong>``, before any work starts and
before anything is written. ``semistatic check`` runs that validation alone. A run whose
lap cannot complete exits with status 1; Ctrl-C exits with status 130 and one line.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from scenarios.logs.evaluate import add_parser as add_evaluate_parser
from scenarios.logs.evaluate import main_evaluate
from scenarios.process.progress import count_progress, scan_progress, sim_progress
from scenarios.process.staging import check_output_dir, stage_and_publish
from scenarios.tuning.command import add_parser as add_tune_parser
from scenarios.tuning.command import main_tune
from semistatic.errors import SpecError
from semistatic.validation import Range, as_float, as_int

__all__ = ["main"]

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 1
EXIT_INTERRUPTED = 130

MAX_JOBS = 256
"""More worker processes than this is a typo, not a machine."""

# scenarios.logs.bag.BAG_STORAGES, spelled out so that --help does not import rosbags.
BAG_STORAGE_CHOICES = ("sqlite3", "mcap")


class InputError(Exception):
    """Bad input the user can fix; printed as one ``error:`` line, exit status 2."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="semistatic",
        description="Semi-static object detection with polygonal maps: a PyBullet testbench.",
    )
    parser.add_argument("--version", action="version",
                        version=f"%(prog)s {importlib.metadata.version('semistatic')}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    check = commands.add_parser(
        "check", help="validate a scenario (files, every lap's layout, options) and stop",
    )
    check.add_argument("scenario", help="bundled name (sim1, sim2, pal1, pal3a, pal3b) or a .toml")
    check.add_argument("--laps", type=int, help="number of laps (overrides the file)")
    check.add_argument("--seed", type=int, help="random seed (overrides the file)")
    check.add_argument("--out", type=Path, help="also check this output directory")
    check.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a scenario value, e.g. --set mapper.gate=0.15",
    )

    run = commands.add_parser("run", help="run one scenario headless and write its results")
    run.add_argument("scenario", help="bundled name (sim1, sim2, pal1, pal3a, pal3b) or a .toml")
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
        help="also run the other field policy on the same seed and compare lap times",
    )
    run.add_argument(
        "--compare-sharing", action="store_true",
        help="also run with sharing off on the same seed and compare every vehicle's lap "
             "times (metrics.json sharing_comparison, figures/lap_times_sharing.png)",
    )
    run.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    run.add_argument(
        "--bag", type=Path, metavar="DIR",
        help="also write the run as a ROS 2 bag directory DIR (must not exist): scans, "
             "odometry, EKF pose, tf and the map polylines, for RViz 2 or Foxglove",
    )
    run.add_argument(
        "--bag-storage", choices=BAG_STORAGE_CHOICES, default="sqlite3",
        help="storage of the --bag (default sqlite3, ROS 2 Humble's; mcap for Foxglove)",
    )

    run.add_argument(
        "--record", type=Path, metavar="DIR",
        help="also record what the mapper and the scoring saw (DIR must not exist), for "
             "`semistatic tune --recording DIR`",
    )

    replay = commands.add_parser("replay", help="replay the mapper on a real laser log")
    replay.add_argument("log", type=Path, help="CARMEN log (.log, .gz) or ROS 1/2 bag")
    replay.add_argument("--out", type=Path, help="output directory (default results/replay-LOG)")
    replay.add_argument("--every", type=int, default=1, help="use one scan in N")
    replay.add_argument("--max-range", type=float, help="ignore readings beyond this (m)")
    replay.add_argument("--tile", type=float, default=8.0, help="side of a place (m)")
    replay.add_argument(
        "--align", action=argparse.BooleanOptionalAction, default=True,
        help="align each revisit scan to its place's reference map before association, as a "
             "robot localised on its map (default); --no-align keeps the logged poses",
    )
    replay.add_argument("--lenient", action="store_true", help="skip and count malformed lines")
    replay.add_argument(
        "--auto-noise", action=argparse.BooleanOptionalAction, default=True,
        help="set epsilon to 3 sigma and the breakpoint noise to >= sigma of the range noise "
             "measured on the first 50 scans (default); --no-auto-noise keeps the fixed ones",
    )
    replay.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="mapper.KEY=VALUE",
        help="override a mapper threshold, e.g. --set mapper.gate=0.15",
    )
    replay.add_argument("--no-figures", action="store_true", help="skip the PNG figure")

    table = commands.add_parser("table", help="run every bundled scenario: the paper's Table 1")
    table.add_argument("--out", type=Path, default=Path("results/table"), help="output directory")
    table.add_argument("--laps", type=int, help="laps per scenario (overrides the files)")
    table.add_argument("--jobs", type=int, default=1, help="scenarios run in parallel")
    table.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    table.add_argument(
        "--compare", action="store_true",
        help="also run each scenario with adaptive fields and compare lap times",
    )
    add_tune_parser(commands)
    add_evaluate_parser(commands)
    return parser


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


def _estimated_sim_time(spec, world) -> float:
    from worlds.checks import build_spline

    return spec.laps * build_spline(world.path).length / world.path.speed


def _check_jobs(jobs: int) -> None:
    as_int(jobs, file="--jobs", key="jobs", valid=Range(ge=1, le=MAX_JOBS))


def _check_display(gui: bool) -> None:
    """Refuse ``--gui`` without a display before PyBullet tries (and dies silently)."""
    if gui and sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        raise SpecError("--gui", "DISPLAY", "no display to open the PyBullet GUI on (DISPLAY "
                        "is not set); run without --gui or set DISPLAY")


def _check(args: argparse.Namespace) -> int:
    from scenarios.spec.layout import lap_worlds
    from worlds.checks import build_spline

    spec, world = _load(args.scenario, args.overrides, args.laps, args.seed)
    if args.out is not None:
        check_output_dir(args.out)
    boxes = [len(lap.boxes) for lap in lap_worlds(spec)]
    length = build_spline(world.path).length
    print(
        f"{spec.name}: valid ({spec.source})\n"
        f"  world {world.name}: {len(world.walls)} walls, {len(world.posts)} posts, "
        f"path {length:.2f} m in {len(world.path.segments)} segments at "
        f"{world.path.speed:g} m/s\n"
        f"  robot {spec.robot}, {spec.laps} laps, seed {spec.seed}, policy {spec.policy}, "
        f"{len(spec.moves)} box moves; boxes per lap: {boxes}\n"
        f"  every lap's layout passes the checks (posts in view, boxes clear of walls, "
        f"the path and the protective fields)"
    )
    return 0


def _run(args: argparse.Namespace) -> int:
    from scenarios.bench.runner import run_scenario
    from scenarios.logs.bag import BAG_TOPICS, BagRecorder, check_new_bag_path, write_run_bag
    from scenarios.logs.recording import ScanRecorder, check_new_recording_path
    from scenarios.results.outputs import summarize, write_outputs

    spec, world = _load(args.scenario, args.overrides, args.laps, args.seed)
    out = check_output_dir(args.out if args.out is not None else Path("results") / spec.name)
    _check_display(args.gui)
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
    total = _estimated_sim_time(spec, world)
    with sim_progress(total, f"{spec.name} ({spec.policy})", spec.laps) as bar:
        log = run_scenario(spec, gui=args.gui, progress=bar, on_scan=recorder,
                           observers=(scan_recorder,) if scan_recorder else ())
    comparison = None
    if args.compare:
        other = "adaptive" if spec.policy == "conservative" else "conservative"
        other_spec = dataclasses.replace(spec, policy=other)
        with sim_progress(total, f"{spec.name} ({other})", spec.laps) as bar:
            other_log = run_scenario(other_spec, progress=bar)
        comparison = summarize(other_log)
    sharing_off = None
    if args.compare_sharing:
        if not spec.sharing:
            raise InputError(f"--compare-sharing: {spec.name} does not share segment maps "
                             "(sharing = false); add --set sharing=true")
        off_spec = dataclasses.replace(spec, sharing=False)
        with sim_progress(total, f"{spec.name} (sharing off)", spec.laps) as bar:
            sharing_off = summarize(run_scenario(off_spec, progress=bar))
    metrics = write_outputs(log, out, figures=not args.no_figures, comparison=comparison,
                            sharing_off=sharing_off)
    summary = _run_summary(metrics, out)
    if scan_recorder is not None:
        scan_recorder.write(args.record, spec, metrics)
        summary += f"\nrecording in {args.record}/ ({scan_recorder.scans} scans)"
    if recorder is not None:
        # After the outputs, so that a bag inside --out finds its parent directory.
        write_run_bag(args.bag, recorder.frames, log.robot, storage=args.bag_storage)
        summary += (
            f"\nROS 2 bag in {args.bag}/ ({args.bag_storage}, {len(recorder.frames)} scans; "
            f"topics {', '.join(BAG_TOPICS)})"
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
    if "policy_comparison" in metrics:
        saved = metrics["policy_comparison"]
        lines.append(
            f"  adaptive fields save {saved['total_time_saved_s']:.1f} s "
            f"({saved['total_time_saved_percent']:.1f}%) against conservative"
        )
    lines.append(
        f"  performance: real-time x{perf['real_time_factor']}, wall/engine "
        f"{perf['wall_over_engine']}, mapper {perf['mapper_ms_median']} ms/scan, "
        f"raycast {perf['raycast_ms_median']} ms/scan"
    )
    lines.append(f"results in {out}/ (metrics.json, table1.csv, maps/, figures/)")
    return "\n".join(lines)


def _table_job(task: tuple[str, int | None, Path, bool, bool]) -> tuple[str, dict]:
    """Run one bundled scenario (in a worker) and write its folder into the staging dir."""
    from scenarios.bench.runner import run_scenario
    from scenarios.results.outputs import summarize, write_outputs

    name, laps, staging, figures, compare = task
    spec, _ = _load(name, [], laps)
    comparison = None
    if compare:
        other = "adaptive" if spec.policy == "conservative" else "conservative"
        comparison = summarize(run_scenario(dataclasses.replace(spec, policy=other)))
    metrics = write_outputs(run_scenario(spec), staging / name, figures=figures,
                            comparison=comparison)
    return name, metrics


def _table(args: argparse.Namespace) -> int:
    from scenarios.process.workers import worker_pool
    from scenarios.results.table import render_table, write_table
    from scenarios.spec.load import paper_scenarios

    names = paper_scenarios()
    _check_jobs(args.jobs)
    for name in names:
        _load(name, [], args.laps)  # fail fast on bad input, before any run
    out = check_output_dir(args.out)
    results: dict[str, dict] = {}

    def fill(staging: Path) -> None:
        # The whole table is staged: an interrupted table leaves the previous one intact.
        tasks = [(name, args.laps, staging, not args.no_figures, args.compare) for name in names]
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

    stage_and_publish(out, fill)
    ordered = {name: results[name] for name in names}
    print(render_table(ordered))
    print(f"results in {out}/ (table1.csv, table1.md, one folder per scenario)")
    failed = [name for name, metrics in ordered.items() if metrics["safety"]["failed_laps"]]
    if failed:
        print(f"run failed: some laps did not complete in {', '.join(failed)} "
              "(metrics.json safety.failed_laps)", file=sys.stderr)
        return EXIT_RUN_FAILED
    return 0


def _replay_params(overrides: Sequence[str], max_range: float | None):
    from scenarios.logs.real_log import REPLAY_PARAMS
    from scenarios.spec.load import OVERRIDE_FILE, mapper_from_table, parse_override

    table = {}
    for text in overrides:
        path, value = parse_override(text)
        if len(path) != 2 or path[0] != "mapper":
            raise SpecError(OVERRIDE_FILE, ".".join(path), "replay takes mapper.KEY=VALUE")
        table[path[1]] = value
    params = mapper_from_table(table, file=OVERRIDE_FILE, base=REPLAY_PARAMS)
    if max_range is not None:
        params = mapper_from_table({"max_range": max_range}, file="--max-range", key="",
                                   base=params)
    return params


def _replay(args: argparse.Namespace) -> int:
    from scenarios.logs.real_log import ReplayOptions, open_log, replay, write_replay_outputs
    from semistatic.logs import LogFormatError

    params = _replay_params(args.overrides, args.max_range)
    every = as_int(args.every, file="--every", key="every", valid=Range(ge=1, le=100_000))
    tile = as_float(args.tile, file="--tile", key="tile", valid=Range(ge=1.0, le=1000.0))
    options = ReplayOptions(params=params, every=every, tile_size=tile,
                            align=args.align, auto_noise=args.auto_noise)
    if not args.log.exists():
        raise InputError(f"{args.log}: <file>: no such file or directory")
    name = args.log.name.split(".")[0]
    out = check_output_dir(args.out if args.out is not None else Path("results") / f"replay-{name}")
    try:
        with scan_progress(f"replay {name}") as advance:
            result = replay(open_log(args.log, lenient=args.lenient), options,
                            progress=advance)
    except (LogFormatError, ValueError) as error:
        raise InputError(str(error)) from None
    if result.quality is not None and result.quality.vertices_per_scan == 0.0:
        raise InputError(
            f"{args.log}: <file>: no polyline in any of its {result.scans} scans (are all "
            "ranges NaN, inf or beyond --max-range?); nothing to map"
        )
    metrics = write_replay_outputs(result, out, log_name=name, figures=not args.no_figures)
    table, quality = metrics["table1_cm"], metrics["extraction"]
    alignment = metrics["alignment"]
    aligned = ""
    if alignment is not None and alignment["attempted"]:
        raw = alignment["table1_cm_log_pose"]["mean"]["avg"]
        aligned = (
            f"  aligned {alignment['accepted']}/{alignment['attempted']} revisit scans to the "
            f"reference ({alignment['partial']} only in the directions their walls constrain; "
            f"median correction {alignment['translation_cm']['median']} cm, "
            f"{alignment['rotation_deg']['median']} deg); at the logged poses: {raw} cm\n"
        )
    sigma_cm = metrics["noise"]["sigma_cm"]
    noise = "unmeasured" if sigma_cm is None else f"{sigma_cm} cm"
    print(
        f"{name}: {metrics['scans']} scans, {metrics['tiles']} places, "
        f"{metrics['revisit_scans']} revisit scans, {metrics['map_polylines']} map polylines\n"
        f"  revisit consistency (Table 1 mean of means): {table['mean']['avg']} cm over "
        f"{table['polylines']} polylines\n"
        f"{aligned}"
        f"  extraction: {100 * quality['coverage']:.1f}% of valid readings within epsilon "
        f"({100 * metrics['params']['epsilon_m']:.1f} cm), "
        f"{quality['vertices_per_scan']:.1f} vertices/scan; range noise {noise}\n"
        f"  {metrics['performance']['wall_time_s']:.1f} s, "
        f"mapper {metrics['performance']['mapper_ms_median']} ms/scan\n"
        f"results in {out}/ (metrics.json, table1.csv, map.geojson, figures/)"
    )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``semistatic`` command line; return the exit status.

    Examples
    --------
    >>> main(["check", "pal1"])  # doctest: +ELLIPSIS
    pal1: valid (...pal1.toml)
    ...
    0
    """
    args = _parser().parse_args(argv)
    handlers = {"check": _check, "run": _run, "table": _table, "replay": _replay,
                "tune": main_tune, "evaluate": main_evaluate}
    try:
        return handlers[args.command](args)
    except (SpecError, InputError) as error:
        # One line, whatever a library put into the message.
        print("error: " + " ".join(str(error).split()), file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted; earlier results are left as they were", file=sys.stderr)
        return EXIT_INTERRUPTED


def console_main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``semistatic`` command: :func:`main`, then exit with its status.

    After Ctrl-C the interpreter's own teardown is skipped (``os._exit``, once the output
    is flushed and every result staged or cleaned up by :func:`main`): an interrupt that
    lands while numba loads or compiles a kernel can leave a half-built llvmlite object
    whose destructor then frees memory twice at exit (seen as "free(): double free
    detected" after the one ``interrupted`` line).

    Examples
    --------
    >>> try:
    ...     console_main(["check", "pal1"])  # doctest: +ELLIPSIS
    ... except SystemExit as done:
    ...     print("exit status", done.code)
    pal1: valid (...pal1.toml)
    ...
    exit status 0
    """
    status = main(argv)
    if status == EXIT_INTERRUPTED:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    sys.exit(status)
