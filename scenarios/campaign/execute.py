"""Running a campaign's runs on a tuning backend, each finished run journalled at once.

The backends are the tuning's (:func:`scenarios.tuning.run.open_backend`): worker
processes of this machine (``pool``) or Ray tasks (``ray``). Runs are submitted longest
first, so that the last ones to finish are short and the workers stay busy to the end.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from scenarios.campaign.plan import CampaignRun
>>> from scenarios.tuning.run import PoolBackend
>>> folder = Path(tempfile.mkdtemp())
>>> rejected = CampaignRun("r", "pal1", "adaptive", 0, 0, (), None, "in a wall")
>>> with PoolBackend(1) as backend, Journal(folder / "runs.jsonl") as journal:
...     run_pending([rejected], {}, backend, journal)
0
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

from scenarios.campaign.journal import Journal, JournalEntry
from scenarios.campaign.plan import CampaignRun
from scenarios.spec.layout import estimated_sim_time
from scenarios.tuning.run import PoolBackend, RayBackend

__all__ = ["POLL_S", "pending_runs", "run_pending"]

POLL_S = 0.5
"""How long (s) to wait for a finished run before checking again."""


def pending_runs(runs: Sequence[CampaignRun], finished: Mapping[str, JournalEntry],
                 ) -> list[CampaignRun]:
    """Return the runs still to simulate: not rejected, not in the journal; longest first.

    Examples
    --------
    >>> from scenarios.campaign.plan import plan_campaign
    >>> runs = plan_campaign(["sim2", "pal1"], ["adaptive"], [0], (), [{}], laps=1,
    ...                      worlds_dir=None)
    >>> [run.scenario for run in pending_runs(runs, {})]  # pal1's path is the longer
    ['pal1', 'sim2']
    >>> [run.scenario for run in pending_runs(runs, {runs[1].run: ({}, None)})]
    ['sim2']
    """
    todo = [run for run in runs if run.spec is not None and run.run not in finished]
    durations: dict[tuple[str, str], float] = {}
    for run in todo:
        key = (run.spec.world, run.spec.name)
        if key not in durations:
            durations[key] = estimated_sim_time(run.spec)
    # Python's sort is stable: equal durations keep the plan's order.
    return sorted(todo, key=lambda run: -durations[(run.spec.world, run.spec.name)])


def run_pending(
    pending: Sequence[CampaignRun],
    finished: Mapping[str, JournalEntry],
    backend: PoolBackend | RayBackend,
    journal: Journal,
    on_result: Callable[[CampaignRun, JournalEntry], None] | None = None,
) -> int:
    """Run every run of ``pending`` on ``backend``; journal each; return how many ran.

    Runs already in ``finished`` or rejected are skipped (so a resumed campaign never
    runs one twice). ``on_result`` is called as each run finishes.
    """
    todo = {run.run: run for run in pending if run.spec is not None and run.run not in finished}
    for key, run in todo.items():
        backend.submit(key, [run.spec], None)
    done = 0
    while done < len(todo):
        for key, outcomes in backend.finished(timeout=POLL_S):
            metrics, error = outcomes[0]
            journal.append(key, metrics, error)
            done += 1
            if on_result is not None:
                on_result(todo[key], (metrics, error))
    return done
