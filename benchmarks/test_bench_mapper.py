"""Speed of the full mapper update: extract + associate + merge + join + life cycle.

One 541-beam scan (270 deg, 0.5 deg, 1 cm noise) of 14 boxes and 6 wall panels around
the sensor against a map of their 20 polylines, built from the first scans. Prints the
median per update and the split by stage.

Why the closed loop's mapper median per scan is higher than the same scans replayed
through the mapper alone: the safety scans of one ``sim1`` lap are replayed through
fresh local maps back to back (warm caches), then with an array of 1, 8 or 32 MB read
before each update, as the closed loop's ray casts, physics steps and EKF run between
two scans and evict the mapper's code and data from the caches (here 2 MB of L2 per
core, 32 MB of L3 shared by all processes).

Run with ``.venv/bin/python -m pytest -m bench benchmarks/test_bench_mapper.py -s``.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

import scenarios.bench.testbench as testbench_module
from scenarios.bench.observer import ScanCallback
from scenarios.spec.load import load_scenario
from semistatic.local_map import LocalMap
from semistatic.mapper import PolylineMap
from tests.semistatic.synthetic import box, cast_scan, scene, wall

SCANS = 300
STAGES = ("extract", "associate", "merge", "join", "life_cycle")


def hall() -> np.ndarray:
    """Twenty objects around the sensor, none hiding another: 14 boxes and 6 wall panels."""
    parts = []
    for k in range(20):
        bearing = math.radians(-128.0 + 256.0 * k / 19)
        reach = 2.5 + 0.5 * (k % 3)
        center = (reach * math.cos(bearing), reach * math.sin(bearing))
        if k % 10 in (0, 3, 7):
            tangent = (-math.sin(bearing) * 0.3, math.cos(bearing) * 0.3)
            parts.append(
                wall(
                    (center[0] - tangent[0], center[1] - tangent[1]),
                    (center[0] + tangent[0], center[1] + tangent[1]),
                )
            )
        else:
            parts.append(box(center, 0.4, 0.3, yaw=bearing + 0.4))
    return scene(*parts)


def _measure(scans, poses):
    """Return the map size, the last report, the update times and the per-stage times."""
    mapper = PolylineMap()
    for scan, pose in zip(scans[:3], poses[:3], strict=True):
        mapper.update(scan, pose)
    polylines = len(mapper)
    totals, stages = [], {stage: [] for stage in STAGES}
    for scan, pose in zip(scans[3:], poses[3:], strict=True):
        timings: dict[str, float] = {}
        start = time.perf_counter()
        report = mapper.update(scan, pose, timings=timings)
        totals.append(time.perf_counter() - start)
        for stage in STAGES:
            stages[stage].append(timings.get(stage, 0.0))
    assert len(mapper) == polylines
    return polylines, report, totals, stages


def _summary(label, totals, stages):
    median_ms = 1e3 * float(np.median(totals))
    split = ", ".join(f"{stage} {1e3 * float(np.median(stages[stage])):.3f}" for stage in STAGES)
    return (
        f"{label}: median {median_ms:.3f} ms (p90 {1e3 * float(np.percentile(totals, 90)):.3f} "
        f"ms); by stage (ms): {split}"
    )


@pytest.mark.bench
def test_mapper_update_time():
    rng = np.random.default_rng(0)
    segments = hall()
    base = np.zeros(3)
    steps = rng.uniform([-0.05, -0.05, -0.02], [0.05, 0.05, 0.02], (SCANS, 3))
    poses = [base + step for step in steps]
    scans = [
        cast_scan(segments, pose, noise=0.01, rng=rng, stamp=0.08 * k)
        for k, pose in enumerate(poses)
    ]
    polylines, report, totals, stages = _measure(scans, poses)
    print(
        f"\nmapper update, {polylines} map polylines, {len(report.scan_polylines)} scan "
        f"polylines, {len(report.associated)} pairs\n" + _summary("mapper", totals, stages)
    )
    assert polylines == 20
    assert math.isfinite(float(np.median(totals)))


def replayed_ms(records, segments, params, between=None) -> float:
    """Median ms of the recorded safety scans through fresh local maps, in order.

    The maps are built as the testbench builds them, one per path segment;
    ``between()``, when given, runs before each update (outside the clock).
    """
    maps = {
        segment.name: LocalMap(segment.origin, [segment.safety_area], params=params,
                               segment=segment.name)
        for segment in segments
    }
    times = []
    for record in records:
        if between is not None:
            between()
        start = time.perf_counter()
        maps[record.segment].update(record.scan, record.sensor_pose)
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


@pytest.mark.bench
def test_mapper_replay_with_cold_caches():
    lap = load_scenario("sim1", overrides=["laps=1"])
    records = []
    with testbench_module.Testbench(lap) as bench:
        bench.add_observer(ScanCallback(records.append))
        log = bench.run()
        segments = bench.segments
    closed = 1e3 * float(np.median(log.mapper_seconds))
    warm = replayed_ms(records, segments, lap.mapper)
    after = {
        megabytes: replayed_ms(records, segments, lap.mapper,
                                between=np.ones(megabytes * 131_072).sum)
        for megabytes in (1, 8, 32)
    }
    print(
        f"\nsim1 lap, {len(records)} safety scans, mapper median per scan: closed loop "
        f"{closed:.3f} ms; replayed {warm:.3f} ms back to back, "
        + ", ".join(f"{ms:.3f} ms after a {mb} MB read" for mb, ms in after.items())
        + f" (load {os.getloadavg()[0]:.1f})"
    )
    assert math.isfinite(after[32])
