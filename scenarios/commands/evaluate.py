"""``semistatic evaluate LOG``: extraction accuracy on a real log with PLE's ray-wise metric.

Scores the paper's pipeline, the default extraction and the split-and-merge baseline
(:data:`semistatic.evaluation.EXTRACTORS`) on one scan in ``--every`` of a CARMEN log or
bag, with replay's thresholds (:data:`scenarios.logs.real_log.REPLAY_PARAMS`) and the
Douglas-Peucker tolerance fitted to the log's measured range noise, as replay does.
The paper's pipeline is also scored at the default's vertex count (its tolerance bisected,
:func:`semistatic.evaluation.at_vertex_count`). ``--sweep`` adds a curve of RMSE against
vertices per scan over several tolerances, written to ``DIR/evaluation.json`` and
``DIR/figures/rmse_vertices.png``. On the logs PLE was evaluated on, its published figures
(:mod:`semistatic.published`) are printed at our vertex count and drawn beside our curves.

Examples
--------
>>> parser = argparse.ArgumentParser(prog="semistatic")
>>> _ = add_parser(parser.add_subparsers(dest="command"))
>>> args = parser.parse_args(["evaluate", "intel.log.gz", "--sweep", "0.01,0.02"])
>>> args.every, args.sweep
(5, '0.01,0.02')
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

from scenarios.logs.real_log import NOISE_SCANS, REPLAY_PARAMS, open_log
from scenarios.process.output_paths import check_output_paths
from scenarios.process.staging import check_output_dir, stage_and_publish
from semistatic.errors import SpecError
from semistatic.evaluation import EXTRACTORS, RayScore, at_vertex_count, tolerance_sweep
from semistatic.noise import estimate_range_noise, noise_params
from semistatic.published import (
    PLE_PUBLISHED,
    PLE_VERTEX_COUNTS,
    published_log,
    published_rmse,
)

__all__ = ["add_parser", "main_evaluate", "score_row"]


COMMAND_LINE = "<command line>"


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``semistatic evaluate`` on the subparsers ``commands``; return its parser.

    Examples
    --------
    >>> parser = argparse.ArgumentParser(prog="semistatic")
    >>> evaluate = add_parser(parser.add_subparsers(dest="command"))
    >>> parser.parse_args(["evaluate", "aces.log.gz", "--every", "2"]).every
    2
    """
    evaluate = commands.add_parser(
        "evaluate", help="score polyline extraction on a real log (PLE's ray-wise RMSE)"
    )
    evaluate.add_argument("log", type=Path, help="CARMEN log (.log, .gz) or ROS 1/2 bag")
    evaluate.add_argument("--every", type=int, default=5, help="score one scan in N (default 5)")
    evaluate.add_argument(
        "--sweep", metavar="EPS,...",
        help="also trace RMSE against vertices per scan at these tolerances (m)",
    )
    evaluate.add_argument(
        "--out", type=Path,
        help="where --sweep writes its curve (default results/evaluate-LOG); the scores "
             "alone are printed, not written",
    )
    return evaluate


def score_row(method: str, epsilon: float, score: RayScore) -> str:
    """Return one printed row: method, tolerance, RMSE, coverage, vertices per scan.

    Examples
    --------
    >>> score_row("default", 0.015, RayScore(2, 100, 98, 0.0098, 40, 10))
    'default           1.50 cm   RMSE 1.00 cm   f 0.980   20.0 vertices/scan'
    """
    return (
        f"{method:<16} {100 * epsilon:5.2f} cm   RMSE {100 * score.rmse:.2f} cm   "
        f"f {score.coverage:.3f}   {score.vertices_per_scan:.1f} vertices/scan"
    )


def _tolerances(text: str | None) -> list[float]:
    if text is None:
        return []
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        raise SpecError(COMMAND_LINE, "--sweep",
                        f"{text!r}: give tolerances in metres, e.g. 0.01,0.02,0.03") from None
    if not all(value > 0.0 for value in values):
        raise SpecError(COMMAND_LINE, "--sweep", f"{text!r}: every tolerance must be > 0 m")
    return values


def main_evaluate(args: argparse.Namespace) -> int:
    """Run ``semistatic evaluate``; print the scores and write the sweep (if any).

    Bad input raises :class:`~semistatic.errors.SpecError` (the CLI prints it, exit 2).

    Examples
    --------
    >>> main_evaluate(argparse.Namespace(log=Path("missing.log"), every=5, sweep=None,
    ...                                  out=None))
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: missing.log: <file>: no such file or directory
    """
    if args.every < 1:
        raise SpecError(COMMAND_LINE, "--every", f"{args.every}: must be an integer >= 1")
    sweep = _tolerances(args.sweep)
    if not args.log.exists():
        raise SpecError(str(args.log), "<file>", "no such file or directory")
    name = args.log.name.split(".")[0]
    # Checked before the work, as every command does: a bad --out costs no scoring.
    out = args.out if args.out is not None else Path("results") / f"evaluate-{name}"
    check_output_paths({"--out": out}, inputs={"LOG": args.log})
    out = check_output_dir(out)
    try:
        scans = list(itertools.islice(open_log(args.log), 0, None, args.every))
    except ValueError as error:  # LogFormatError, BagError
        raise SpecError(str(args.log), "<file>", str(error)) from None
    if not any(scan.valid_mask().any() for scan in scans):  # before any score is printed
        raise SpecError(str(args.log), "<file>", f"no valid range in any of its {len(scans)} "
                        "scans (all NaN, inf or beyond the maximum range); nothing to evaluate")
    sigma = estimate_range_noise(scans[:NOISE_SCANS], REPLAY_PARAMS.max_range)
    params = noise_params(REPLAY_PARAMS, sigma)
    print(f"{name}: {len(scans)} scans (one in {args.every}), range noise "
          f"{100 * sigma:.2f} cm, tolerance {100 * params.epsilon:.2f} cm")
    at_default = tolerance_sweep(scans, params, [params.epsilon])
    for method, points in at_default.items():
        print("  " + score_row(method, *points[0]))
    ours = at_default["default"][0][1]
    vertices = ours.vertices_per_scan
    if vertices == 0.0:  # as replay says it: nothing to compare the pipelines on
        raise SpecError(str(args.log), "<file>", f"no polyline in any of its {len(scans)} "
                        "scans (are all ranges NaN, inf or beyond the maximum range?); "
                        "nothing to evaluate")
    paper_epsilon, paper = at_vertex_count(scans, params, vertices, method="paper")
    print(f"  paper's pipeline at equal vertex count ({paper.vertices_per_scan:.1f}/scan, "
          f"tolerance {100 * paper_epsilon:.2f} cm): RMSE {100 * paper.rmse:.2f} cm; the "
          f"default is {100 * (1.0 - ours.rmse / paper.rmse):.1f} % below")
    reference = published_log(name)
    if reference is not None:
        print(f"  published (Schaefer et al. 2018) at {vertices:.1f} vertices/scan: "
              f"PLE+ {100 * published_rmse(reference, vertices):.2f} cm, "
              f"PLE {100 * published_rmse(reference, vertices, 'PLE'):.2f} cm")
    if not sweep:
        return 0
    curves = tolerance_sweep(scans, params, sweep)
    for method, points in curves.items():
        for epsilon, score in points:
            print("  " + score_row(method, epsilon, score))
    table = {
        method: [
            {"epsilon_m": epsilon, "rmse_m": score.rmse, "coverage": score.coverage,
             "vertices_per_scan": score.vertices_per_scan}
            for epsilon, score in points
        ]
        for method, points in curves.items()
    }

    def fill(staging: Path) -> None:
        (staging / "evaluation.json").write_text(json.dumps(
            {"log": name, "every": args.every, "noise_sigma_m": sigma,
             "default_epsilon_m": params.epsilon, "curves": table,
             "published": _published(reference)}, indent=2))
        _plot(staging / "figures" / "rmse_vertices.png", name, table, reference)

    stage_and_publish(out, fill, command="evaluate")
    print(f"results in {out}/ (evaluation.json, figures/rmse_vertices.png)")
    return 0


def _published(reference: str | None) -> dict | None:
    """Return PLE's published curves for the log ``reference`` as JSON, or None."""
    if reference is None:
        return None
    curve = PLE_PUBLISHED[reference]
    return {"source": "Schaefer et al., IROS 2018, Fig. 4a data (acschaefer/ple eval.mat)",
            "log": reference, "vertices_per_scan": list(PLE_VERTEX_COUNTS),
            "ple_plus_rmse_m": list(curve.ple_plus), "ple_rmse_m": list(curve.ple),
            "coverage": list(curve.coverage)}


def _plot(path: Path, name: str, table: dict, reference: str | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    figure, axes = plt.subplots(figsize=(5.5, 4.0))
    for method in EXTRACTORS:
        points = table.get(method, [])
        axes.plot([p["vertices_per_scan"] for p in points],
                  [100 * p["rmse_m"] for p in points], marker="o", label=method)
    if reference is not None:
        curve = PLE_PUBLISHED[reference]
        for label, values in (("PLE+ (published)", curve.ple_plus),
                              ("PLE (published)", curve.ple)):
            axes.plot(PLE_VERTEX_COUNTS, [100 * value for value in values],
                      linestyle="--", marker="s", label=label)
    axes.set_xlabel("vertices per scan")
    axes.set_ylabel("ray-wise RMSE (cm)")
    axes.set_title(f"{name}: RMSE against vertices per scan")
    axes.grid(alpha=0.3)
    axes.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
