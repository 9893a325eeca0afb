"""Benchmark: cost growth of a fleet, wall time per simulated second for 1, 2, 3 LGVs.

Issue 15's figure: the warehouse with the first 1, 2 and 3 vehicles of
``warehouse_fleet`` (sharing on) and one Pioneer in ``sim1``, each driven for
``SIM_SECONDS`` simulated seconds on the full Testbench (physics, lasers, EKF, safety
fields, mapper, scoring). The runs are interleaved (1, 2, 3, sim1, 1, 2, 3, sim1 ...)
and each figure is the median over ``ROUNDS``, so that other work on the machine loads
every configuration alike; the ratios are the result. CPU time of the process is
reported beside wall time (PyBullet runs in-process). Goal: 3 vehicles at most 3.3x one.

Run alone: ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_fleet.py``
"""

import dataclasses
import os
import time

import numpy as np
import pytest

from scenarios import Testbench
from scenarios.spec.load import load_scenario

SIM_SECONDS = 20.0
ROUNDS = 3


def seconds_per_sim_second(spec):
    """Return (wall, cpu) seconds per simulated second over SIM_SECONDS after reset."""
    with Testbench(spec) as bench:
        bench.reset()
        start_sim = bench.sim_time
        wall, cpu = time.perf_counter(), time.process_time()
        while bench.sim_time - start_sim < SIM_SECONDS and not bench.done:
            bench.step()
        simulated = bench.sim_time - start_sim
        return ((time.perf_counter() - wall) / simulated,
                (time.process_time() - cpu) / simulated)


@pytest.mark.bench
def test_wall_time_per_simulated_second_grows_at_most_linearly_with_vehicles():
    fleet = load_scenario("warehouse_fleet")
    configs = {
        f"warehouse, {n} LGV": dataclasses.replace(fleet, vehicles=fleet.vehicles[:n])
        for n in (1, 2, 3)
    }
    configs["sim1, 1 Pioneer"] = load_scenario("sim1")
    results = {name: [] for name in configs}
    for _ in range(ROUNDS):
        for name, spec in configs.items():
            results[name].append(seconds_per_sim_second(spec))
    median = {name: np.median(np.array(values), axis=0) for name, values in results.items()}
    one = median["warehouse, 1 LGV"]
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end; medians of {ROUNDS} "
          f"interleaved runs of {SIM_SECONDS:g} simulated s")
    print("| configuration | wall s / sim s | CPU s / sim s | wall vs 1 LGV |")
    print("|---|---:|---:|---:|")
    for name, (wall, cpu) in median.items():
        print(f"| {name} | {wall:.3f} | {cpu:.3f} | {wall / one[0]:.2f}x |")
    three = median["warehouse, 3 LGV"]
    assert three[0] / one[0] <= 3.3
