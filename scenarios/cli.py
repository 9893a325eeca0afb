"""The ``semistatic`` command line (a contract: DESIGN.md "Command line").

Bad input (a missing or malformed file, an unknown key, an out-of-range value) ends with
exit status 2 and one line ``error: <file>: <key>: <what is wrong>``, before anything is
written.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import dataclasses
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from tqdm import tqdm

from scenarios.evaluate import add_parser as add_evaluate_parser
from scenarios.evaluate import main_evaluate
from scenarios.tune import add_parser as add_tune_parser
from scenarios.tune import main_tune
from worlds.errors import SpecError

__all__ = ["main"]

EXIT_BAD_INPUT = 2

# scenarios.bag.BAG_STORAGES, spelled out so that --help does not import rosbags.
BAG_STORAGE_CHOICES = ("sqlite3", "mcap")


class InputError(Exception):
    """Bad input the user can fix; printed as one ``error:`` line, exit status 2."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="semistatic",
        description="Semi-static object detection with polygonal maps: a PyBullet testbench.",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

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


@contextlib.contextmanager
def _progress(total: float, label: str) -> Iterator[Callable[[float], None] | None]:
    """Yield a callback advancing a progress bar in simulated seconds (terminal only)."""
    if not sys.stderr.isatty():
        yield None
        return
    with tqdm(total=round(total, 1), desc=label, unit="sim s", leave=False,
              bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} sim s "
                         "[{elapsed}<{remaining}]") as bar:
        pending = [0.0]

        def advance(seconds: float) -> None:
            pending[0] += seconds
            if pending[0] >= 0.5:
                bar.update(min(pending[0], bar.total - bar.n))
                pending[0] = 0.0

        yield advance


def _load(scenario: str, overrides: Sequence[str]):
    """Load and validate a scenario (every lap's layout included) before anything runs."""
    from scenarios.layout import scenario_world
    from scenarios.load import load_scenario

    spec = load_scenario(scenario, overrides=overrides)
    return spec, scenario_world(spec)


def _estimated_sim_time(spec, world) -> float:
    from robots.path import SplinePath

    return spec.laps * SplinePath(world.path.knots).length / world.path.speed


def _run(args: argparse.Namespace) -> int:
    from scenarios.bag import BAG_TOPICS, BagRecorder, check_new_bag_path, write_run_bag
    from scenarios.outputs import summarize, write_outputs
    from scenarios.runner import run_scenario

    overrides = list(args.overrides)
    if args.laps is not None:
        overrides.append(f"laps={args.laps}")
    if args.seed is not None:
        overrides.append(f"seed={args.seed}")
    spec, world = _load(args.scenario, overrides)
    out = args.out if args.out is not None else Path("results") / spec.name
    recorder = None
    if args.bag is not None:
        try:
            check_new_bag_path(args.bag, out=out)
        except ValueError as error:
            raise InputError(str(error)) from None
        recorder = BagRecorder()
    with _progress(_estimated_sim_time(spec, world), f"{spec.name} ({spec.policy})") as bar:
        log = run_scenario(spec, gui=args.gui, progress=bar, on_scan=recorder)
    comparison = None
    if args.compare:
        other = "adaptive" if spec.policy == "conservative" else "conservative"
        other_spec = dataclasses.replace(spec, policy=other)
        with _progress(_estimated_sim_time(spec, world), f"{spec.name} ({other})") as bar:
            other_log = run_scenario(other_spec, progress=bar)
        comparison = summarize(other_log)
    metrics = write_outputs(log, out, figures=not args.no_figures, comparison=comparison)
    summary = _run_summary(metrics, out)
    if recorder is not None:
        # After the outputs, so that a bag inside --out finds its parent directory.
        write_run_bag(args.bag, recorder.frames, log.robot, storage=args.bag_storage)
        summary += (
            f"\nROS 2 bag in {args.bag}/ ({args.bag_storage}, {len(recorder.frames)} scans; "
            f"topics {', '.join(BAG_TOPICS)})"
        )
    print(summary)
    return 0


def _run_summary(metrics: dict, out: Path) -> str:
    table = metrics["table1_cm"]["mean"]
    detection = metrics["detection"]
    safety = metrics["safety"]
    perf = metrics["performance"]
    lines = [
        f"{metrics['scenario']}: {metrics['laps']} laps, policy {metrics['policy']}, "
        f"seed {metrics['seed']}",
        f"  Table 1 mean restricted Hausdorff (cm): avg {table['avg']} min {table['min']} "
        f"max {table['max']}",
        f"  detection: precision {detection['precision']:.3f} recall {detection['recall']:.3f} "
        f"F1 {detection['f1']:.3f}, objects from people {detection['false_objects_from_people']}",
        f"  localization RMSE {metrics['localization']['rmse_xy_m']} m, "
        f"NEES {metrics['localization']['nees_mean']}",
        f"  safety: {safety['collisions']} collisions, {safety['stops']} stops, "
        f"{safety['slowdowns']} slowdowns, {safety['total_time_s']:.1f} s over all laps",
    ]
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


def _table_job(name: str, laps: int | None, out: Path, figures: bool, compare: bool) -> dict:
    from scenarios.outputs import summarize, write_outputs
    from scenarios.runner import run_scenario

    overrides = [f"laps={laps}"] if laps is not None else []
    spec, _ = _load(name, overrides)
    comparison = None
    if compare:
        other = "adaptive" if spec.policy == "conservative" else "conservative"
        comparison = summarize(run_scenario(dataclasses.replace(spec, policy=other)))
    return write_outputs(run_scenario(spec), out / name, figures=figures, comparison=comparison)


def _table(args: argparse.Namespace) -> int:
    from scenarios.load import bundled_scenarios
    from scenarios.table import render_table, write_table

    names = bundled_scenarios()
    overrides = [f"laps={args.laps}"] if args.laps is not None else []
    for name in names:
        _load(name, overrides)  # fail fast on bad input, before any run
    if args.jobs < 1:
        raise InputError(f"--jobs: must be >= 1, got {args.jobs}")
    results: dict[str, dict] = {}
    with concurrent.futures.ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = {
            pool.submit(
                _table_job, name, args.laps, args.out, not args.no_figures, args.compare
            ): name
            for name in names
        }
        done = concurrent.futures.as_completed(futures)
        for future in tqdm(done, total=len(futures), desc="scenarios",
                           disable=not sys.stderr.isatty()):
            results[futures[future]] = future.result()
    ordered = {name: results[name] for name in names}
    write_table(ordered, args.out)
    print(render_table(ordered))
    print(f"results in {args.out}/ (table1.csv, table1.md, one folder per scenario)")
    return 0


def _replay_params(overrides: Sequence[str], max_range: float | None):
    from scenarios.load import OVERRIDE_FILE, parse_override
    from scenarios.replay import REPLAY_PARAMS
    from worlds.validation import did_you_mean

    params = REPLAY_PARAMS
    fields = set(dataclasses.asdict(params))
    changes: dict[str, object] = {}
    for text in overrides:
        path, value = parse_override(text)
        dotted = ".".join(path)
        if len(path) != 2 or path[0] != "mapper" or path[1] not in fields:
            hint = did_you_mean(path[-1], fields) if len(path) == 2 else ""
            raise SpecError(OVERRIDE_FILE, dotted, f"replay takes mapper.KEY=VALUE{hint}")
        changes[path[1]] = value
    if max_range is not None:
        changes["max_range"] = max_range
    try:
        return params.replace(**changes)
    except (ValueError, TypeError) as error:
        raise InputError(f"{OVERRIDE_FILE}: {error}") from None


def _replay(args: argparse.Namespace) -> int:
    from scenarios.replay import ReplayOptions, open_log, replay, write_replay_outputs
    from semistatic.logs import LogFormatError

    params = _replay_params(args.overrides, args.max_range)
    try:
        options = ReplayOptions(params=params, every=args.every, tile_size=args.tile,
                                align=args.align, auto_noise=args.auto_noise)
    except ValueError as error:
        raise InputError(str(error)) from None
    if not args.log.exists():
        raise InputError(f"{args.log}: <file>: no such file or directory")
    name = args.log.name.split(".")[0]
    out = args.out if args.out is not None else Path("results") / f"replay-{name}"
    try:
        with tqdm(desc=name, unit="scan", disable=not sys.stderr.isatty(), leave=False) as bar:
            result = replay(open_log(args.log, lenient=args.lenient), options,
                            progress=bar.update)
    except (LogFormatError, ValueError) as error:
        raise InputError(str(error)) from None
    metrics = write_replay_outputs(result, out, log_name=name, figures=not args.no_figures)
    table, quality = metrics["table1_cm"], metrics["extraction"]
    alignment = metrics["alignment"]
    aligned = ""
    if alignment is not None and alignment["attempted"]:
        raw = alignment["table1_cm_log_pose"]["mean"]["avg"]
        aligned = (
            f"  aligned {alignment['accepted']}/{alignment['attempted']} revisit scans to the "
            f"reference (median correction {alignment['translation_cm']['median']} cm, "
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
    """Run the ``semistatic`` command line; return the exit status."""
    args = _parser().parse_args(argv)
    handlers = {"run": _run, "table": _table, "replay": _replay, "tune": main_tune,
                "evaluate": main_evaluate}
    try:
        return handlers[args.command](args)
    except (SpecError, InputError) as error:
        print(f"error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
