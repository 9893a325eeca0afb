"""Which process drives a search trial, and whether it is gone: a prompt resume.

A trial's driver records :func:`driver_identity` on it (a trial system attribute,
``DRIVER_ATTR``). A new driver on the same host fails and queues again, at once, every
running trial whose driver ended (:func:`fail_orphaned_trials`): it need not wait the
heartbeat's grace period (``scenarios.tuning.storage.GRACE_S``), which still covers the
drivers of other hosts. A process is told from a later one with the same id by its start
time (Linux ``/proc/PID/stat``); where that is unknown only the heartbeats decide.

Examples
--------
>>> driver_gone(driver_identity())
False
"""

from __future__ import annotations

import os
import socket
from collections.abc import Collection
from typing import Any

import optuna

from scenarios.process.reaper import start_time

__all__ = ["DRIVER_ATTR", "driver_gone", "driver_identity", "fail_orphaned_trials"]

DRIVER_ATTR = "semistatic_driver"
"""Trial system attribute naming the driver that runs it (:func:`driver_identity`)."""
RUNNING = optuna.trial.TrialState.RUNNING


def driver_identity() -> dict[str, Any]:
    """Return this process's identity: host, process id and start time (``None`` off Linux).

    The start time tells this process from a later one that got the same id.

    Examples
    --------
    >>> identity = driver_identity()
    >>> identity["pid"] == os.getpid(), driver_gone(identity)
    (True, False)
    """
    return {"host": socket.gethostname(), "pid": os.getpid(), "started": start_time(os.getpid())}


def driver_gone(identity: Any) -> bool:
    """Return whether the driver ``identity`` is known to be gone (ran on this host, ended).

    A driver on another host, or one whose start time is unknown, is not known to be gone:
    its trials wait for their heartbeats to go stale.

    Examples
    --------
    >>> driver_gone({"host": socket.gethostname(), "pid": os.getpid(), "started": -1})
    True
    >>> driver_gone({"host": "elsewhere", "pid": 1, "started": 0}), driver_gone(None)
    (False, False)
    """
    if not isinstance(identity, dict) or identity.get("host") != socket.gethostname():
        return False
    if not isinstance(identity.get("pid"), int) or not isinstance(identity.get("started"), int):
        return False
    return start_time(identity["pid"]) != identity["started"]


def fail_orphaned_trials(study: optuna.Study, storage: optuna.storages.RDBStorage,
                         own: Collection[int] = ()) -> int:
    """Fail and queue again the running trials whose driver is gone; return how many.

    ``own`` are the numbers of this driver's trials (left alone). Each failed trial is
    queued again by the storage's stale-trial callback (Optuna's
    ``RetryHeartbeatStaleTrialCallback``: the same values, its history in
    ``retry_history``), as a trial whose heartbeat went stale would be.

    Examples
    --------
    >>> storage = optuna.storages.RDBStorage(
    ...     "sqlite://", heartbeat_interval=2,
    ...     heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback())
    >>> study = optuna.create_study(storage=storage)
    >>> trial = study.ask({"x": optuna.distributions.FloatDistribution(0.0, 1.0)})
    >>> dead = {**driver_identity(), "started": -1}  # this pid, but an earlier process
    >>> storage.set_trial_system_attr(trial._trial_id, DRIVER_ATTR, dead)
    >>> fail_orphaned_trials(study, storage), fail_orphaned_trials(study, storage)
    (1, 0)
    >>> [(t.state.name, t.params == trial.params) for t in study.get_trials()]
    [('FAIL', True), ('WAITING', True)]
    """
    running = [trial for trial in study.get_trials(deepcopy=False, states=(RUNNING,))
               if trial.number not in own]
    retry = storage.get_heartbeat_stale_trial_callback()
    failed = 0
    for trial in running:
        if not driver_gone(trial.system_attrs.get(DRIVER_ATTR)):
            continue
        try:
            # As fail_stale_trials does: of two drivers doing this, one wins and retries.
            if not storage.set_trial_state_values(trial._trial_id,
                                                  state=optuna.trial.TrialState.FAIL):
                continue
        except optuna.exceptions.UpdateFinishedTrialError:
            continue
        if retry is not None:
            retry(study, storage.get_trial(trial._trial_id))
        failed += 1
    return failed
