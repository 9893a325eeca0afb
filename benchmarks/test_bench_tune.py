"""Benchmarks of threshold tuning (issue 14): replay against re-simulation, Ray, TPE vs grid.

- pal1, 3 laps, conservative policy: three points of three mapper thresholds, each run
  by full re-simulation and replayed from one recording; the Table 1 and detection
  metrics must be identical, and the medians per point are reported (goal: replay at
  least 10x faster).
- Ray: the same four closed-loop trials (tiny world, >= 2 s each) on one and on two Ray
  workers (goal: two at least 1.7x faster on two cores).
- Search: on pal1's recording, minimise the Table 1 mean over ``mapper.gate`` x
  ``mapper.epsilon``; the 5 x 5 grid (25 evaluations) against TPE with 12 trials
  (goal: TPE at least as good as the grid's best with at most half its evaluations).
  The best-so-far curves are printed.

Machine load changes every figure: ``uptime`` is printed beside them.

Run: ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_tune.py``
"""

import os
import statistics
import time

import optuna
import pytest

from scenarios.load import load_scenario
from scenarios.outputs import summarize
from scenarios.recording import ScanRecorder, read_recording, replay
from scenarios.runner import run_scenario
from scenarios.tune_params import parse_params
from scenarios.tune_run import PoolBackend, RayBackend, RecordingSet
from scenarios.tune_search import SearchConfig, open_study, run_study
from tests.scenarios.tiny_world import write_tiny

pytestmark = pytest.mark.bench

POINTS = (
    ("mapper.gate=0.06", "mapper.epsilon=0.03", "mapper.outlier_k=4"),
    ("mapper.gate=0.12", "mapper.epsilon=0.02", "mapper.outlier_k=3"),
    ("mapper.gate=0.18", "mapper.epsilon=0.04", "mapper.outlier_k=2"),
)


def _load() -> str:
    return f"load average {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} cores"


@pytest.fixture(scope="module")
def pal1_recording(tmp_path_factory):
    spec = load_scenario("pal1", overrides=["laps=3"])
    recorder = ScanRecorder()
    started = time.perf_counter()
    log = run_scenario(spec, observers=(recorder,))
    run_s = time.perf_counter() - started
    metrics = summarize(log)
    path = tmp_path_factory.mktemp("rec") / "pal1"
    started = time.perf_counter()
    recorder.write(path, spec, metrics)
    print(f"\nrecording pal1 3 laps: run {run_s:.1f} s, writing {recorder.scans} scans "
          f"{time.perf_counter() - started:.2f} s")
    return path


def test_replay_equals_resimulation_and_is_faster(pal1_recording):
    recording = read_recording(pal1_recording)
    full, replayed = [], []
    for overrides in POINTS:
        spec = load_scenario("pal1", overrides=["laps=3", *overrides])
        started = time.perf_counter()
        simulated = summarize(run_scenario(spec))
        full.append(time.perf_counter() - started)
        started = time.perf_counter()
        metrics = replay(recording, spec)
        replayed.append(time.perf_counter() - started)
        assert metrics["table1_cm"] == simulated["table1_cm"], overrides
        assert metrics["detection"] == simulated["detection"], overrides
    full_s, replay_s = statistics.median(full), statistics.median(replayed)
    print(f"\npal1 3 laps, 3 points: re-simulation median {full_s:.2f} s, replay median "
          f"{replay_s:.2f} s per point: {full_s / replay_s:.1f}x ({_load()})")


def _ray_wall(workers: int, specs) -> float:
    with RayBackend(workers) as backend:
        backend.submit("warm-up", [], None)  # start the workers before the clock
        while not backend.finished(timeout=1.0):
            pass
        started = time.perf_counter()
        for index, spec in enumerate(specs):
            backend.submit(index, [spec], None)
        done = []
        while len(done) < len(specs):
            done += backend.finished(timeout=1.0)
        wall = time.perf_counter() - started
    assert all(error is None for _, outcomes in done for _, error in outcomes)
    return wall


def test_two_ray_workers_against_one(tmp_path):
    scenario = write_tiny(tmp_path)
    specs = [load_scenario(scenario, overrides=["laps=2", f"mapper.gate={gate}"])
             for gate in (0.06, 0.1, 0.14, 0.18)]
    started = time.perf_counter()
    run_scenario(specs[0])
    trial_s = time.perf_counter() - started
    one = _ray_wall(1, specs)
    two = _ray_wall(2, specs)
    print(f"\nRay, 4 trials of ~{trial_s:.1f} s: 1 worker {one:.1f} s, 2 workers {two:.1f} s: "
          f"{one / two:.2f}x ({_load()})")


def _search(recording, sampler: str, trials: int, tmp_path) -> list[float]:
    config = SearchConfig(
        "pal1", parse_params(["mapper.gate=0.04:0.2", "mapper.epsilon=0.01:0.05"]),
        seeds=(0,), laps=3, sampler=sampler, trials=trials, grid_points=5,
    )
    study, storage = open_study(config, f"sqlite:///{tmp_path / sampler}.db", sampler)
    with PoolBackend(2) as backend:
        run_study(study, storage, config, backend, RecordingSet((str(recording),)))
    trials_done = sorted((t for t in study.trials
                          if t.state == optuna.trial.TrialState.COMPLETE),
                         key=lambda t: t.number)
    curve, best = [], float("inf")
    for trial in trials_done:
        best = min(best, trial.values[0])
        curve.append(round(best, 4))
    return curve


def test_tpe_against_the_grid(pal1_recording, tmp_path):
    grid = _search(pal1_recording, "grid", 25, tmp_path)
    tpe = _search(pal1_recording, "tpe", 12, tmp_path)
    print(f"\nTable 1 mean (cm), best so far: grid (25) {grid}\n  TPE (12) {tpe}\n"
          f"  grid best {grid[-1]} after {grid.index(grid[-1]) + 1} evaluations; TPE best "
          f"{tpe[-1]} after {tpe.index(tpe[-1]) + 1} ({_load()})")
