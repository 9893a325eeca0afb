"""Warm starts: a sample of a scenario's last lap from the saved mapping laps vs its full run.

The 3-lap tiny crossing scenario of the tests (``tests/scenarios/tiny_world.py``): a
person limited to lap 3 steps out past the box when the robot comes; the samples vary
how far ahead (``trigger_distance``) and how fast. Each sample runs in full
(:func:`scenarios.tuning.run.run_point`: set-up, 3 laps, metrics) and warm
(:meth:`scenarios.tuning.warm.WarmStart.run`: restore the last checkpoint before the
person steps out, the rest of lap 3, metrics), interleaved so that the machine's load
weighs on both alike; the metrics must agree (``performance`` aside). Goal: the median
warm sample costs <= 1/3 of the median full run (wall time).

Printed after the ratio: a full run's pieces (CPU seconds: set-up, each lap, metrics),
what building the warm start cost once, and how far into lap 3 each sample starts
(the person who steps out 3 m ahead does so at the lap's start: that sample replays all
of lap 3). Load
changes every figure: ``os.getloadavg()`` is printed beside them. About 2 minutes.

Run: ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_warm_start.py``
"""

import dataclasses
import os
import time

import numpy as np
import pytest

from scenarios.bench.testbench import Testbench
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario
from scenarios.tuning.run import run_point
from scenarios.tuning.warm import WarmStart
from sim.client import DEFAULT_TIME_STEP
from tests.scenarios.tiny_world import write_crossing

pytestmark = pytest.mark.bench

# (trigger_distance m, speed m/s): gone before the robot comes, a stop, two stops.
VARIATIONS = [(3.0, 1.5), (0.9, 0.6), (0.5, 1.4)]
ROUNDS = 2
GOAL = 1 / 3


def _samples(folder):
    spec = load_scenario(write_crossing(folder))
    samples = []
    for index, (distance, speed) in enumerate(VARIATIONS):
        path = write_crossing(folder, name=f"sample_{index}", trigger_distance=distance,
                              speed=speed)
        samples.append(dataclasses.replace(spec, world=load_scenario(path).world))
    return spec, samples


def _timed(run, clock=time.perf_counter):
    start = clock()
    result = run()
    return result, clock() - start


def _without_timing(metrics):
    return {key: value for key, value in metrics.items() if key != "performance"}


def _breakdown(sample):
    """Return the CPU seconds of a full run's pieces."""
    clock = time.process_time
    bench = Testbench(sample)
    _, setup = _timed(bench.reset, clock)
    laps = [_timed(bench.run_lap, clock)[1] for _ in range(sample.laps)]
    _, metrics = _timed(lambda: summarize(bench.log), clock)
    bench.close()
    return {"set-up": setup, **{f"lap {k}": s for k, s in enumerate(laps, 1)},
            "metrics": metrics}


def test_a_warm_sample_costs_at_most_a_third_of_a_full_run(tmp_path):
    print(f"\nload: {os.getloadavg()}")
    spec, samples = _samples(tmp_path)
    (warm, built_s) = _timed(lambda: WarmStart(spec, lap=spec.laps), time.process_time)
    with warm:
        full_times, warm_times = [], []
        for _ in range(ROUNDS):
            for sample in samples:
                (full, error), full_s = _timed(lambda sample=sample: run_point(sample))
                assert error is None
                metrics, warm_s = _timed(lambda sample=sample: warm.run(sample))
                assert _without_timing(metrics) == _without_timing(full)
                full_times.append(full_s)
                warm_times.append(warm_s)
        starts = [warm.start_tick(sample) * DEFAULT_TIME_STEP for sample in samples]
    full_median, warm_median = float(np.median(full_times)), float(np.median(warm_times))
    ratio = warm_median / full_median
    print(f"full run {full_median:.2f} s, warm sample {warm_median:.2f} s (medians of "
          f"{len(full_times)}): ratio {ratio:.3f} (goal <= {GOAL:.3f}); "
          f"load {os.getloadavg()[0]:.2f}")
    print("full run (CPU s): " + ", ".join(f"{name} {s:.3f}"
                                          for name, s in _breakdown(samples[1]).items()))
    print(f"warm start: built once in {built_s:.2f} CPU s (laps 1-{spec.laps}, checkpoints); "
          f"samples start {', '.join(f'{s:.1f}' for s in starts)} s into lap {spec.laps}")
    assert ratio <= GOAL, ratio
