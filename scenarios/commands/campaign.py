"""``semistatic campaign``: many seeds, policies and sampled variations, with statistics.

``semistatic campaign pal1,sim1 --policy conservative,adaptive --seeds 0:9 --vary
'world.boxes.crate_corridor.pose[1]=uniform(0.8, 1.0)' --samples 4 --out DIR`` runs every
combination of the scenarios, policies, variation samples and seeds (the work is split
by job in :mod:`scenarios.campaign`) and writes::

    DIR/manifest.json    the command, the project version, every run's scenario digest
    DIR/runs.jsonl       the journal: one line per finished run (what a resume reads)
    DIR/runs.parquet     one row per run: axes, status, drawn values, flattened metrics
    DIR/runs.csv         the same table as CSV
    DIR/summary.json     per scenario and policy: mean, std, 95 % CI, worst of each metric
    DIR/figures/*.png    metric distributions; Table 1 with error bars beside the paper's
    DIR/worlds/*.toml    the varied worlds of samples that move boxes or people

Everything is checked before the first run (bad input: exit 2, nothing written).
Re-running the same command after an interruption keeps every finished run and runs
only the rest; ``DIR`` holding another campaign is refused.

Examples
--------
>>> parser = argparse.ArgumentParser(prog="semistatic")
>>> _ = add_parser(parser.add_subparsers(dest="command"))
>>> args = parser.parse_args(["campaign", "pal1,sim1", "--seeds", "0:4", "--jobs", "2"])
>>> args.scenario, parse_seed_range(args.seeds), args.backend
('pal1,sim1', (0, 1, 2, 3, 4), 'pool')
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import json
from pathlib import Path

from scenarios.process.staging import (
    check_resumable_dir,
    read_result_marker,
    write_atomic,
    write_result_marker,
)
from scenarios.spec.load import scenario_help
from scenarios.tuning.run import BACKENDS, check_backend
from semistatic.errors import SpecError

__all__ = ["DEFAULT_SEEDS", "add_parser", "main_campaign", "parse_seed_range", "split_policies"]

DEFAULT_SEEDS = "0:9"
MAX_RUNS = 100_000
"""More runs than this is a typo (a seed range of millions), not a campaign."""


def parse_seed_range(text: str) -> tuple[int, ...]:
    """Parse ``--seeds A:B`` (A to B, both included) or ``S1,S2,...``.

    Examples
    --------
    >>> parse_seed_range("3:5"), parse_seed_range("7,2")
    ((3, 4, 5), (7, 2))
    >>> parse_seed_range("5:3")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --seeds: seed: reversed range 5:3; write FIRST:LAST, e.g. 0:9
    """
    from scenarios.tuning.points import parse_seeds

    if ":" not in text:
        return parse_seeds(text)
    first, _, last = (part.strip() for part in text.partition(":"))
    if not (first.isdigit() and last.isdigit()):
        raise SpecError("--seeds", "seed", f"expected FIRST:LAST of integers >= 0, like 0:9, "
                        f"got {text!r}")
    if int(first) > int(last):
        raise SpecError("--seeds", "seed",
                        f"reversed range {text}; write FIRST:LAST, e.g. 0:9")
    if int(last) - int(first) >= MAX_RUNS:
        raise SpecError("--seeds", "seed", f"{text} is more than {MAX_RUNS} seeds")
    return tuple(range(int(first), int(last) + 1))


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``semistatic campaign`` on the subparsers ``commands``; return its parser."""
    campaign = commands.add_parser(
        "campaign",
        help="run scenarios over many seeds, policies and sampled variations; statistics",
        description="Run every combination of SCENARIO(s), --policy, --samples draws of the "
                    "--vary distributions and --seeds; write a table with one row per run "
                    "(DIR/runs.parquet, DIR/runs.csv) and per scenario and policy the mean, "
                    "95 % confidence interval and worst case of every metric "
                    "(DIR/summary.json, DIR/figures/). Re-run the same command to resume.",
    )
    campaign.add_argument("scenario", help=f"{scenario_help()}; several comma-separated")
    campaign.add_argument("--policy", metavar="P1,P2,...",
                          help="field policies to run each scenario with (default: the "
                               "scenario's own)")
    campaign.add_argument("--seeds", default=DEFAULT_SEEDS, metavar="A:B | S1,S2,...",
                          help=f"seeds, both ends included (default {DEFAULT_SEEDS})")
    campaign.add_argument(
        "--vary", action="append", default=[], metavar="KEY=DIST",
        help="a sampled variation: DIST is uniform(LOW, HIGH), normal(MEAN, SIGMA) or "
             "choice(V1, V2, ...); KEY a --set key (mapper.epsilon, noise.range) or a world "
             "object, world.boxes.NAME.FIELD or world.people.NAME.FIELD (pose[0] is x)",
    )
    campaign.add_argument("--samples", type=int, default=1,
                          help="draws of the --vary values (default 1); each runs every "
                               "policy and seed")
    campaign.add_argument("--variation-seed", type=int, default=0,
                          help="seed of the variation draws (default 0)")
    campaign.add_argument("--laps", type=int, help="laps of every run (overrides the files)")
    campaign.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="fixed override for every run, e.g. --set mapper.epsilon=0.05",
    )
    campaign.add_argument("--backend", default="pool", choices=BACKENDS,
                          help="where runs go: worker processes (default) or Ray tasks")
    campaign.add_argument("--address", metavar="ADDR",
                          help="Ray cluster address (with --backend ray)")
    campaign.add_argument("--jobs", type=int, default=1, help="runs in parallel (default 1)")
    campaign.add_argument("--out", type=Path, help="output directory (default "
                                                   "results/campaign-SCENARIOS)")
    campaign.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    return campaign


def _definition(args: argparse.Namespace, scenarios, policies, seeds, variations) -> dict:
    """Return what makes two commands the same campaign (so the second may resume it)."""
    return {
        "version": importlib.metadata.version("semistatic"),
        "scenarios": list(scenarios),
        "policies": list(policies),
        "seeds": list(seeds),
        "laps": args.laps,
        "overrides": list(args.overrides),
        "vary": {variation.key: variation.text for variation in variations},
        "samples": args.samples if variations else 1,
        "variation_seed": args.variation_seed,
    }


def split_policies(text: str | None) -> list[str] | None:
    """Return the policies of ``--policy P1,P2,...`` (``None`` when not given).

    Examples
    --------
    >>> split_policies("adaptive,guarded"), split_policies(None)
    (['adaptive', 'guarded'], None)
    """
    if text is None:
        return None
    policies = [policy.strip() for policy in text.split(",")]
    if not all(policies) or len(set(policies)) != len(policies):
        raise SpecError("--policy", "policy", f"{text!r}: give P1,P2,... each once")
    return policies


def main_campaign(args: argparse.Namespace) -> int:
    """Run ``semistatic campaign``; return 0, or 1 when some run raised (its row says why)."""
    from scenarios.campaign.variations import draw_samples, parse_variations
    from scenarios.spec.load import load_scenario
    from scenarios.tuning.study import split_scenarios

    check_backend(args.backend, args.jobs, args.address)
    scenarios = split_scenarios(args.scenario)
    if len(set(scenarios)) != len(scenarios):
        raise SpecError("scenario", args.scenario, "a scenario is given twice")
    seeds = parse_seed_range(args.seeds)
    variations = parse_variations(args.vary)
    if args.samples != 1 and not variations:
        raise SpecError("--samples", "samples", "nothing to sample: add --vary KEY=DIST")
    samples = draw_samples(variations, args.samples, seed=args.variation_seed)
    policies = split_policies(args.policy)
    if policies is None:  # the scenarios' own, in order
        policies = list(dict.fromkeys(load_scenario(s, overrides=args.overrides).policy
                                      for s in scenarios))
    runs_asked = len(scenarios) * len(policies) * len(seeds) * len(samples)
    if runs_asked > MAX_RUNS:
        raise SpecError("--seeds", "seed", f"{runs_asked} runs exceed the limit of {MAX_RUNS}")

    from scenarios.campaign.plan import check_campaign

    check_campaign(scenarios, policies, variations, seeds=seeds, laps=args.laps,
                   overrides=args.overrides)
    definition = _definition(args, scenarios, policies, seeds, variations)
    out = args.out if args.out is not None else Path("results") / (
        "campaign-" + "+".join(scenarios) if len("+".join(scenarios)) < 60 else "campaign")
    from scenarios.campaign.table import KIND, MANIFEST_FILE

    resume = check_resumable_dir(out, manifest=MANIFEST_FILE, kind=KIND, definition=definition,
                                 noun="campaign")
    return _run(args, out, resume, definition, scenarios, policies, seeds, variations, samples)


def _run(args, out, resume, definition, scenarios, policies, seeds, variations,
         samples) -> int:
    """Plan, run what is missing, tabulate; the part after every check passed."""
    from scenarios.campaign.execute import pending_runs, run_pending
    from scenarios.campaign.journal import JOURNAL_FILE, Journal, read_journal
    from scenarios.campaign.plan import plan_campaign, scenario_digest
    from scenarios.campaign.report import write_report
    from scenarios.campaign.table import FORMAT, KIND, MANIFEST_FILE
    from scenarios.process.progress import count_progress
    from scenarios.tuning.run import open_backend

    out.mkdir(parents=True, exist_ok=True)
    if read_result_marker(out) is None:  # a resumed campaign keeps its marker and id
        write_result_marker(out, "campaign")
    runs = plan_campaign(scenarios, policies, seeds, variations, samples, laps=args.laps,
                         overrides=args.overrides, worlds_dir=out / "worlds")
    manifest = {
        "format": FORMAT, "kind": KIND, "definition": definition,
        "command": ["semistatic", *getattr(args, "argv", ["campaign"])],
        "version": definition["version"],
        "runs": {run.run: {"status": run.status,
                           "digest": scenario_digest(run.spec) if run.spec else None}
                 for run in runs},
    }
    if not resume:
        write_atomic(out / MANIFEST_FILE, json.dumps(manifest, indent=2) + "\n")
    finished = read_journal(out / JOURNAL_FILE)
    pending = pending_runs(runs, finished)
    rejected = sum(run.spec is None for run in runs)
    label = f"campaign {len(runs)} runs"
    if finished or rejected:
        print(f"{out}: {len(finished)} runs finished earlier, {rejected} rejected, "
              f"{len(pending)} to run")
    with count_progress(len(pending), label, "run") as advance, \
            Journal(out / JOURNAL_FILE) as journal:
        if pending:
            with open_backend(args.backend, args.jobs, args.address) as backend:
                run_pending(pending, finished, backend, journal,
                            on_result=lambda run, _: advance(run.run))
    finished = read_journal(out / JOURNAL_FILE)
    summary = write_report(out, runs, finished, manifest, figures=not args.no_figures)
    print(summary)
    return 1 if any(error is not None for _, error in finished.values()) else 0
