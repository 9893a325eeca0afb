"""Recording a run for Rerun (``--rrd``) against the same run headless and unrecorded.

One sim1 lap is run plain and recorded (:class:`scenarios.logs.rrd.RerunRecorder` to a
file: every scan's poses, returns, fields, map, series and events), interleaved so that
the machine's load weighs on both alike. Goal: the recorded run's median wall time is
at most 1.15 times the plain run's. The recording's size and scans are printed beside,
with ``os.getloadavg()``. About 2 minutes.

Run: ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_recording.py``
"""

import os
import time

import numpy as np
import pytest

from scenarios.bench.runner import run_scenario
from scenarios.spec.load import load_scenario

pytestmark = pytest.mark.bench

ROUNDS = 4
GOAL = 1.15


def test_recording_costs_at_most_15_percent_of_a_headless_lap(tmp_path):
    pytest.importorskip("rerun", reason="the rerun extra is not installed")
    from scenarios.logs.rrd import RerunRecorder

    spec = load_scenario("sim1", overrides=["laps=1"])
    run_scenario(spec)  # warm up: compiled kernels, imports
    plain, recorded = [], []
    for round_ in range(ROUNDS):
        started = time.perf_counter()
        run_scenario(spec)
        plain.append(time.perf_counter() - started)
        recorder = RerunRecorder(tmp_path / f"sim1-{round_}.rrd")
        started = time.perf_counter()
        run_scenario(spec, observers=(recorder,))
        recorder.close()
        recorded.append(time.perf_counter() - started)
    ratio = float(np.median(recorded) / np.median(plain))
    size = (tmp_path / "sim1-0.rrd").stat().st_size
    print(f"\nsim1 lap: plain {np.median(plain):.2f} s, recorded {np.median(recorded):.2f} s "
          f"(medians of {ROUNDS}), ratio {ratio:.3f} (goal <= {GOAL}); {recorder.scans} scans, "
          f"{size / 1e6:.1f} MB; load {os.getloadavg()[0]:.1f}")
    assert ratio <= GOAL
