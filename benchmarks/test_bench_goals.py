"""The table of issue 13's speed goals, as the README's speed section shows it.

One run prints, each figure with the machine load (``os.getloadavg``) beside it:

- the mapper update on the 20-polyline case (541 beams, goal <= 0.25 ms median) and on
  the safety scans recorded in a closed ``sim1`` lap, replayed through a fresh map;
- each stage of the stack per call in that lap (ray cast, landmark detection, EKF
  predict and update, follower, safety supervision, mapper, physics step, contact check);
- a whole ``sim1`` run (its laps as the scenario file says): real-time factor, wall time
  over time inside PyBullet (goal <= 1.5) and mapper against ray-cast medians per scan
  (goal <= 0.5);
- the kernels' start-up cost in a fresh process: compiling them (an empty numba cache,
  the first run after installation, goal <= 10 s) and loading them from the cache
  (every later run, goal <= 1 s).

Run alone on the machine with ``make bench`` or
``.venv/bin/python -m pytest -q -s -m bench benchmarks/test_bench_goals.py``.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict

import numpy as np
import pytest

import scenarios.bench.testbench as testbench_module
from benchmarks.test_bench_mapper import SCANS, hall, replayed_ms
from robots.ekf import EKFLocalizer
from robots.follower import ChainedFormFollower
from scenarios.bench.observer import ScanCallback
from scenarios.bench.runner import run_scenario
from scenarios.bench.sensors import VehicleSensors
from scenarios.bench.vehicle import Vehicle
from scenarios.spec.load import load_scenario
from semistatic.kernel_cache import SWITCH
from semistatic.local_map import LocalMap
from semistatic.mapper import PolylineMap
from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.laser import RaycastLaser
from tests.semistatic.synthetic import cast_scan

pytestmark = pytest.mark.bench

# Stages of one closed-loop tick: (owner, method, label).
STAGES = (
    (RaycastLaser, "hits", "ray cast (PyBullet rayTestBatch + hit lists)"),
    (RaycastLaser, "scan", "laser scan (cast + noise)"),
    (VehicleSensors, "landmarks", "landmark detection"),
    (Vehicle, "_predict", "odometry + EKF predict"),
    (EKFLocalizer, "update", "EKF update (gate + filterpy)"),
    (ChainedFormFollower, "command", "follower command"),
    (Vehicle, "_supervise_and_map", "safety supervision + mapper"),
    (LocalMap, "update", "mapper (local map update)"),
    (SimClient, "step", "physics step (PyBullet)"),
    (ContactMonitor, "check", "contact check"),
    (testbench_module.Testbench, "step", "whole tick"),
)


def _load() -> str:
    return f"load {os.getloadavg()[0]:.1f}"


def _median_ms(seconds) -> float:
    return 1e3 * float(np.median(seconds))


def _timed_stages(monkeypatch) -> dict[str, list[float]]:
    """Wrap every stage with a clock; return the lists the wrappers fill."""
    times: dict[str, list[float]] = defaultdict(list)
    for owner, name, label in STAGES:
        original = getattr(owner, name)

        def timed(*args, _original=original, _label=label, **kwargs):
            start = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                times[_label].append(time.perf_counter() - start)

        monkeypatch.setattr(owner, name, timed)
    return times


def _mapper_on_hall() -> float:
    rng = np.random.default_rng(0)
    segments = hall()
    steps = rng.uniform([-0.05, -0.05, -0.02], [0.05, 0.05, 0.02], (SCANS, 3))
    scans = [cast_scan(segments, pose, noise=0.01, rng=rng, stamp=0.08 * k)
             for k, pose in enumerate(steps)]
    mapper = PolylineMap()
    for scan, pose in zip(scans[:3], steps[:3], strict=True):
        mapper.update(scan, pose)
    assert len(mapper) == 20
    times = []
    for scan, pose in zip(scans[3:], steps[3:], strict=True):
        start = time.perf_counter()
        mapper.update(scan, pose)
        times.append(time.perf_counter() - start)
    return _median_ms(times)


def _startup_seconds(cache: str, *options: str, parallel: bool = True) -> str:
    result = subprocess.run(
        [sys.executable, "-m", "benchmarks.kernel_warmup", *options],
        env={**os.environ, "NUMBA_CACHE_DIR": cache, SWITCH: "1" if parallel else "0"},
        capture_output=True, text=True, check=True,
    )
    return result.stdout.strip().splitlines()[-1]


def test_speed_goals_table(monkeypatch):
    rows = []
    rows.append(("mapper update, 20 polylines, 541 beams (median)",
                 f"{_mapper_on_hall():.3f} ms", "<= 0.25 ms", _load()))
    # One closed lap of sim1 with every stage timed, its safety scans recorded.
    records = []
    lap = load_scenario("sim1", overrides=["laps=1"])
    with monkeypatch.context() as patch:
        times = _timed_stages(patch)
        with testbench_module.Testbench(lap) as bench:
            bench.add_observer(ScanCallback(records.append))
            bench.run()
            segments = bench.segments
    replayed = replayed_ms(records, segments, lap.mapper)
    rows.append((f"mapper, {len(records)} recorded sim1 scans replayed (median)",
                 f"{replayed:.3f} ms", "", _load()))
    for _, _, label in STAGES:
        calls = times[label]
        rows.append((f"  {label} per call (median, {len(calls)} calls)",
                     f"{1e6 * float(np.median(calls)):.1f} us", "", _load()))
    # The whole run as the user starts it.
    log = run_scenario(load_scenario("sim1"))
    wall, engine = log.wall_time_s, log.engine_time_s
    mapper, raycast = _median_ms(log.mapper_seconds), _median_ms(log.raycast_seconds)
    rows.append((f"sim1, {len(log.laps)} laps: real-time factor", f"x{log.sim_time_s / wall:.1f}",
                 "", _load()))
    rows.append(("sim1: wall time / time inside PyBullet", f"{wall / engine:.2f}", "<= 1.5",
                 _load()))
    rows.append(("sim1: mapper / ray cast, median per scan",
                 f"{mapper:.3f} / {raycast:.3f} ms = {mapper / raycast:.2f}", "<= 0.5", _load()))
    with tempfile.TemporaryDirectory() as cache:
        first = float(_startup_seconds(cache))
        rows.append(("kernels, first run (compile, empty cache)", f"{first:.1f} s", "<= 10 s",
                     _load()))
        later = float(_startup_seconds(cache))
        rows.append(("kernels, later run (load from cache)", f"{later:.2f} s", "<= 1 s", _load()))
    with tempfile.TemporaryDirectory() as cache:
        serial = float(_startup_seconds(cache, parallel=False))
        rows.append(("kernels, first run on one core (SEMISTATIC_PARALLEL_COMPILE=0)",
                     f"{serial:.1f} s", "", _load()))
    width = max(len(row[0]) for row in rows)
    print("\n| measure" + " " * (width - 7) + " | value | goal | machine |")
    print("|" + "-" * (width + 1) + "|---:|---|---|")
    for name, value, goal, load in rows:
        print(f"| {name:<{width}} | {value} | {goal} | {load} |")
    assert math.isfinite(wall / engine)


def test_recorded_kernel_signatures_are_what_a_first_run_compiles():
    """``semistatic/kernel_signatures.toml`` is current (else: ``kernel_warmup --record``).

    A stale file costs only speed: what it misses compiles lazily, in the run.
    """
    with tempfile.TemporaryDirectory() as cache:
        assert _startup_seconds(cache, "--check") == "same"
