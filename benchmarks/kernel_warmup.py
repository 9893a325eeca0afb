"""Call every compiled kernel once and print the seconds it took (the start-up cost).

Run in a fresh process: with an empty ``NUMBA_CACHE_DIR`` it measures compilation (the
first run after installation), with the cache filled by that run it measures loading the
cached machine code (every later run). ``benchmarks/test_bench_goals.py`` runs it both
ways; by hand::

    NUMBA_CACHE_DIR=$(mktemp -d) .venv/bin/python -m benchmarks.kernel_warmup
"""

from __future__ import annotations

import time

import numpy as np

# Imports first: they are start-up cost too, but not the kernels'.
from benchmarks.test_bench_mapper import hall
from robots.ekf import EKFLocalizer, EKFParams
from robots.landmarks import LandmarkObservation, detect_landmarks
from robots.path import SplinePath
from semistatic.association import associate, sort_ccw
from semistatic.hausdorff import hausdorff, restrict, restricted_hausdorff
from semistatic.mapper import PolylineMap
from semistatic.merge import project_onto
from semistatic.polyline import Polyline
from semistatic.similarity import similarity
from semistatic.types import Scan
from tests.semistatic.synthetic import cast_scan


def warm_up() -> float:
    """Run each kernel once (as the closed loop calls them); return the seconds taken."""
    rng = np.random.default_rng(0)
    segments = hall()
    scans = [cast_scan(segments, np.zeros(3), noise=0.01, rng=rng, stamp=0.1 * k) for k in range(3)]
    path = SplinePath([(0.0, 0.0), (2.0, 0.0), (3.0, 1.0)])
    start = time.perf_counter()
    mapper = PolylineMap()
    for scan in scans:
        mapper.update(scan, np.zeros(3))
    wall, part = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]]), [[1.0, 0.1], [3.0, 0.1]]
    hausdorff(wall, part)
    restrict(wall, part, mode="projection")
    restricted_hausdorff(wall, part, mode="projection")
    similarity(wall, part)
    project_onto(part, Polyline(wall))  # as join does it: a polyline's read-only vertices
    sort_ccw([wall, part], (0.0, 0.0, 0.0))
    associate([part], [wall], 0.12, viewpoint=(0.0, 0.0, 0.0))
    angles = np.radians(np.arange(-10.0, 10.5, 0.5))
    ranges = np.full(angles.size, 12.0)
    intensities = np.full(angles.size, 0.2)
    ranges[20], intensities[20] = 7.96, 0.95
    detect_landmarks(Scan(ranges=ranges, angle_min=angles[0], angle_increment=0.5 * np.pi / 180,
                          intensities=intensities))
    ekf = EKFLocalizer([[4.0, 0.0], [0.0, 4.0]], EKFParams(range_bias_sigma=0.01))
    ekf.initialize([0.0, 0.0, 0.0], np.diag([0.01, 0.01, 0.001]), stamp=0.0)
    ekf.update([LandmarkObservation(4.0, 0.0, np.diag([1e-4, 1e-6]), [0])], stamp=0.1)
    path._track(1.0, 0.1, 0.9, 1.0)  # the follower's projection
    return time.perf_counter() - start


if __name__ == "__main__":
    print(f"{warm_up():.3f}")
