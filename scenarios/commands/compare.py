"""``semistatic compare``: judge a candidate campaign against a baseline, for people and CI.

``semistatic compare BASELINE CANDIDATE`` reads two finished campaign directories
(``semistatic campaign --out``), compares every metric of the tolerance file per
scenario and policy (:mod:`scenarios.campaign.compare`), prints a Markdown report and
exits with 1 when a metric got worse, 0 otherwise (2 for bad input, before anything is
written). ``--junit FILE`` and ``--markdown FILE`` also write the report as JUnit XML (a
failing test case per regression) and as Markdown, each atomically.

The bootstrap intervals draw from a fixed seed: the same two campaigns always give the
same report.

Examples
--------
>>> parser = argparse.ArgumentParser(prog="semistatic")
>>> _ = add_parser(parser.add_subparsers(dest="command"))
>>> args = parser.parse_args(["compare", "runs/main", "runs/branch", "--junit", "j.xml"])
>>> args.baseline, args.candidate, args.junit, args.tolerance
(PosixPath('runs/main'), PosixPath('runs/branch'), PosixPath('j.xml'), None)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from scenarios.campaign.compare import compare_campaigns
from scenarios.campaign.table import read_campaign
from scenarios.campaign.tolerances import DEFAULT_TOLERANCES, default_tolerances, read_tolerances
from scenarios.process.output_paths import check_output_paths
from scenarios.process.staging import check_writable_parent, write_atomic
from semistatic.errors import SpecError

__all__ = ["COMPARE_SEED", "add_parser", "main_compare"]

COMPARE_SEED = 0
"""Seed of the bootstrap resamples, so a comparison is reproducible."""


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``semistatic compare`` on the subparsers ``commands``; return its parser.

    Examples
    --------
    >>> parser = argparse.ArgumentParser(prog="semistatic")
    >>> _ = add_parser(parser.add_subparsers(dest="command"))
    >>> parser.parse_args(["compare", "a", "b", "--tolerance", "t.toml"]).tolerance
    PosixPath('t.toml')
    """
    compare = commands.add_parser(
        "compare", help="judge a candidate campaign against a baseline (exit 1 on a regression)",
        description="Compare the metrics of two finished campaigns per scenario and policy "
                    "(paired runs: Wilcoxon signed-rank, else Mann-Whitney U; p-values "
                    "adjusted with Benjamini-Hochberg), print a Markdown report and exit "
                    "with 1 when a metric got significantly worse by at least its min_change.",
    )
    compare.add_argument("baseline", type=Path, metavar="BASELINE",
                         help="campaign directory of the reference (its --out)")
    compare.add_argument("candidate", type=Path, metavar="CANDIDATE",
                         help="campaign directory to judge against BASELINE")
    compare.add_argument("--tolerance", type=Path, metavar="FILE",
                         help="tolerance file: the judged metrics, which way each is better "
                              f"and its min_change (default {DEFAULT_TOLERANCES.name}, bundled)")
    compare.add_argument("--junit", type=Path, metavar="FILE",
                         help="also write the verdicts as JUnit XML (one test per metric)")
    compare.add_argument("--markdown", type=Path, metavar="FILE",
                         help="also write the printed report to FILE")
    return compare


def _check_target(path: Path, option: str) -> None:
    if path.is_dir():
        raise SpecError(option, str(path), "is a directory; name a file")
    check_writable_parent(path, option=option)


def main_compare(args: argparse.Namespace) -> int:
    """Run ``semistatic compare``; return 1 when a metric got worse, else 0.

    Bad input (a missing campaign, a bad tolerance file, an output that cannot be
    written, campaigns of different formats or groups) raises
    :class:`~semistatic.errors.SpecError` before anything is written.

    Examples
    --------
    >>> parser = argparse.ArgumentParser()
    >>> _ = add_parser(parser.add_subparsers())
    >>> main_compare(parser.parse_args(["compare", "/no/such/a", "/no/such/b"]))
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: BASELINE: /no/such/a: no such directory; give the --out \
of a finished `semistatic campaign`
    """
    tolerances = (read_tolerances(args.tolerance) if args.tolerance is not None
                  else default_tolerances())
    targets = {option: path for option, path in (("--junit", args.junit),
                                                 ("--markdown", args.markdown)) if path}
    for option, path in targets.items():
        _check_target(path, option)
    check_output_paths(targets, replaced=None,
                       inputs={"BASELINE": args.baseline, "CANDIDATE": args.candidate})
    baseline = read_campaign(args.baseline, option="BASELINE")
    candidate = read_campaign(args.candidate, option="CANDIDATE")
    comparison = compare_campaigns(
        baseline.rows, candidate.rows, tolerances,
        rng=np.random.default_rng(np.random.SeedSequence(COMPARE_SEED)),
        baseline_manifest=baseline.manifest, candidate_manifest=candidate.manifest,
        baseline_name=str(baseline.path), candidate_name=str(candidate.path),
    )
    report = comparison.markdown()
    for option, path in targets.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, comparison.junit_xml() if option == "--junit" else report)
    print(report, end="")
    return comparison.exit_status
