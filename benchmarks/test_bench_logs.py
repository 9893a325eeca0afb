"""Speed of the log readers and extraction quality of the paper pipeline vs split-and-merge.

Run with ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_logs.py``.
"""

import time
from pathlib import Path

import numpy as np
import pytest

from semistatic.baseline import extract_split_and_merge
from semistatic.extraction import extract_polylines
from semistatic.logs import (
    BagFrame,
    extraction_quality,
    inlier_mask,
    read_bag,
    read_carmen,
    summarize_quality,
    write_ros2_bag,
)
from semistatic.params import MapperParams

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LOGS = [
    "intel-corrected.log.gz",
    "aces-corrected.log.gz",
    "freiburg-079-corrected.log.gz",
    "csail-robotlaser1-corrected.log.gz",
]
REPEATS = 3

pytestmark = pytest.mark.bench


def log_path(name):
    path = DATA / name
    if not path.is_file():
        pytest.skip(f"real CARMEN logs not found at {DATA}")
    return path


def best_of(repeats, run):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return min(times), result


@pytest.mark.parametrize("name", LOGS)
def test_read_carmen_speed(name):
    path = log_path(name)
    seconds, scans = best_of(REPEATS, lambda: list(read_carmen(path)))
    fixed, _ = best_of(REPEATS, lambda: list(read_carmen(path, max_range=80.0)))
    print(
        f"\n{name}: {len(scans)} scans in {seconds:.3f} s "
        f"({seconds / len(scans) * 1e6:.0f} us/scan)"
        f"; with max_range given (no inference pass) {fixed:.3f} s"
    )


def test_ros2_bag_round_trip_speed(tmp_path):
    scans = list(read_carmen(log_path("intel-corrected.log.gz")))
    frames = [
        BagFrame(
            scan=s,
            odom_pose=s.pose,
            ekf_pose=s.pose,
            polylines=[p.transformed(s.pose).points for p in extract_polylines(s)],
        )
        for s in scans
    ]
    start = time.perf_counter()
    write_ros2_bag(tmp_path / "intel", frames)
    written = time.perf_counter() - start
    start = time.perf_counter()
    back = list(read_bag(tmp_path / "intel"))
    read = time.perf_counter() - start
    assert len(back) == len(scans)
    size = sum(f.stat().st_size for f in (tmp_path / "intel").iterdir()) / 1e6
    print(f"\nintel as ROS 2 bag: write {written:.2f} s, read {read:.2f} s, {size:.1f} MB")


@pytest.mark.parametrize("name", LOGS)
def test_extraction_quality_paper_vs_split_and_merge(name):
    scans = list(read_carmen(log_path(name)))
    params = MapperParams()
    keys = ("douglas-peucker (paper)", "split-and-merge, same V", "split-and-merge, eps")
    rows = {key: [] for key in keys}
    times = {key: 0.0 for key in rows}
    for scan in scans:
        start = time.perf_counter()
        paper = extract_polylines(scan, params)
        middle = time.perf_counter()
        same = extract_split_and_merge(scan, params, vertex_counts=[len(p) for p in paper])
        end = time.perf_counter()
        threshold = extract_split_and_merge(scan, params)
        times["douglas-peucker (paper)"] += middle - start
        times["split-and-merge, same V"] += end - middle
        times["split-and-merge, eps"] += time.perf_counter() - end
        inliers = inlier_mask(scan, params)
        for key, lines in zip(rows, (paper, same, threshold), strict=True):
            rows[key].append(extraction_quality(scan, lines, params.epsilon, inliers=inliers))
    epsilon_cm = params.epsilon * 100
    print(f"\n{name} ({len(scans)} scans, epsilon {epsilon_cm:.0f} cm; rms/max over inliers)")
    for key, qualities in rows.items():
        s = summarize_quality(qualities)
        print(
            f"  {key:24s} coverage {s.coverage:.4f} (in span {s.in_span_fraction:.4f}) "
            f"rms {s.rms_distance * 100:.2f} cm max {s.max_distance * 100:.1f} cm "
            f"V/scan {s.vertices_per_scan:.1f} polylines/scan {s.polylines_per_scan:.1f} "
            f"{times[key] / len(scans) * 1e3:.2f} ms/scan"
        )
    assert np.isfinite(summarize_quality(rows["douglas-peucker (paper)"]).coverage)
