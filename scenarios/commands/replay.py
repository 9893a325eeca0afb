"""The ``replay`` command: the mapper on a real laser log (CARMEN or ROS bag).

Examples
--------
>>> parser = argparse.ArgumentParser(prog="semistatic")
>>> add_parser(parser.add_subparsers(dest="command"))
>>> args = parser.parse_args(["replay", "intel.log.gz", "--every", "2", "--no-align"])
>>> args.every, args.align
(2, False)
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from scenarios.logs.rrd_options import DEFAULT_VIEWER_URL, open_timeline
from scenarios.process.errors import InputError
from scenarios.process.output_paths import check_output_paths
from scenarios.process.progress import scan_progress
from scenarios.process.staging import check_output_dir
from semistatic.errors import SpecError
from semistatic.validation import Range, as_float, as_int

__all__ = ["add_parser", "main_replay"]


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``replay`` on the subparsers ``commands``."""
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
    replay.add_argument(
        "--rrd", type=Path, metavar="FILE",
        help="also record the replay for the Rerun viewer (FILE.rrd must not exist): scans, "
             "poses and each place's map coloured by status, on the log's clock",
    )
    replay.add_argument(
        "--viewer", nargs="?", const=DEFAULT_VIEWER_URL, metavar="URL",
        help=f"stream the replay live to a Rerun viewer (default {DEFAULT_VIEWER_URL})",
    )


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


def main_replay(args: argparse.Namespace) -> int:
    """Run ``semistatic replay``: replay a log and write its results; return the status."""
    from scenarios.logs.real_log import ReplayOptions, open_log, replay_log, write_replay_outputs
    from semistatic.logs import LogFormatError

    params = _replay_params(args.overrides, args.max_range)
    every = as_int(args.every, file="--every", key="every", valid=Range(ge=1, le=100_000))
    tile = as_float(args.tile, file="--tile", key="tile", valid=Range(ge=1.0, le=1000.0))
    options = ReplayOptions(params=params, every=every, tile_size=tile,
                            align=args.align, auto_noise=args.auto_noise)
    if not args.log.exists():
        raise InputError(f"{args.log}: <file>: no such file or directory")
    name = args.log.name.split(".")[0]
    out = args.out if args.out is not None else Path("results") / f"replay-{name}"
    check_output_paths({"--out": out, "--rrd": args.rrd}, into_result=["--rrd"],
                       inputs={"LOG": args.log})
    out = check_output_dir(out)
    timeline = open_timeline(args.rrd, args.viewer, out, f"replay-{name}")
    try:
        with scan_progress(f"replay {name}") as advance:
            result = replay_log(open_log(args.log, lenient=args.lenient), options,
                                progress=advance,
                                on_scan=None if timeline is None else timeline.replayed_scan)
    except (LogFormatError, ValueError) as error:
        if timeline is not None:
            timeline.close(finish=False)
        raise InputError(str(error)) from None
    except BaseException:
        if timeline is not None:
            timeline.close(finish=False)  # no half recording at --rrd
        raise
    if result.quality is not None and result.quality.vertices_per_scan == 0.0:
        raise InputError(
            f"{args.log}: <file>: no polyline in any of its {result.scans} scans (are all "
            "ranges NaN, inf or beyond --max-range?); nothing to map"
        )
    metrics = write_replay_outputs(result, out, log_name=name, figures=not args.no_figures)
    recorded = ""
    if timeline is not None:
        timeline.close()  # after the outputs: a recording inside --out lands in them
        recorded = "".join(
            [f"\nRerun recording in {args.rrd} (open it with: rerun {args.rrd})"
             if args.rrd is not None else "",
             f"\nstreamed to the Rerun viewer at {args.viewer}" if args.viewer else ""])
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
        f"{recorded}"
    )
    return 0
