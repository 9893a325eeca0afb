"""Speed of RaycastLaser: one rayTestBatch per scan, the engine should dominate.

Run with ``.venv/bin/python -m pytest -m bench benchmarks/test_raycast_bench.py -s``.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from robots.lasers import LMS100, S300
from sim.client import SimClient
from sim.laser import RaycastLaser
from sim.world_builder import SimWorld
from tests.sim.random_scenes import free_pose, random_world

SCANS = 400


@pytest.mark.bench
@pytest.mark.parametrize("num_threads", [1, 2, 0])
@pytest.mark.parametrize("spec", [S300, LMS100], ids=["S300", "LMS100"])
def test_scan_time_is_dominated_by_the_engine(spec, num_threads):
    rng = np.random.default_rng(0)
    world_spec = random_world(rng, walls=True)
    poses = [free_pose(rng, world_spec, 0.3) for _ in range(20)]
    with SimClient() as sim:
        laser = RaycastLaser(
            sim, spec, SimWorld(sim, world_spec), np.random.default_rng(1), num_threads=num_threads
        )
        laser.scan(poses[0])
        totals, casts = [], []
        for index in range(SCANS):
            start = time.perf_counter()
            laser.scan(poses[index % len(poses)], stamp=float(index))
            totals.append(time.perf_counter() - start)
            casts.append(laser.last_raycast_s)
    total_ms = 1e3 * float(np.median(totals))
    cast_ms = 1e3 * float(np.median(casts))
    print(
        f"\n{spec.name} {spec.num_beams} rays, num_threads={num_threads}: "
        f"scan {total_ms:.3f} ms median, rayTestBatch {cast_ms:.3f} ms "
        f"({100.0 * cast_ms / total_ms:.0f}% in the engine)"
    )
    assert math.isfinite(total_ms)
    assert cast_ms > 0.4 * total_ms
