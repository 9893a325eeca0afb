"""Acceptance on real laser logs: extraction keeps what the scanner saw.

Over every scan of the Intel Research Lab and ACES CARMEN logs (180 beams at 1 deg),
at least 90% of the valid readings must end up in a polyline (between its first and last
beam) and within ``epsilon`` of it. Takes a few seconds; skipped when the data directory
``../shared/data`` (relative to the repository root) is missing.
"""

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from semistatic.extraction import extract_polylines, remove_invalid
from semistatic.logs.carmen import read_carmen
from semistatic.params import MapperParams

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
LOGS = ("intel-corrected.log.gz", "aces-corrected.log.gz")

# 1 deg beams (twice the default scanner's spacing) and range readings quantised to 1 cm:
# a 3 cm range noise term and 3-beam intervals (3 deg, like 6 beams at 0.5 deg).
REAL_LOG_PARAMS = MapperParams(
    breakpoint_lambda=math.radians(10.0), breakpoint_sigma_r=0.03, min_points=3
)
MIN_COVERED = 0.90


def coverage(scans, params):
    """Return (fraction of valid readings in a polyline within epsilon, vertices per scan)."""
    covered = valid_total = vertices = scan_count = 0
    for scan in scans:
        valid = remove_invalid(scan, params.max_range)
        points = scan.points()
        inside = np.zeros(len(scan), dtype=bool)
        for line in extract_polylines(scan, params):
            beams = np.arange(line.scan_indices[0], line.scan_indices[-1] + 1)
            beams = beams[valid[beams]]
            distance = shapely.distance(
                shapely.points(points[beams]), shapely.LineString(line.points)
            )
            inside[beams[distance <= params.epsilon + 1e-9]] = True
            vertices += len(line)
        covered += int(inside[valid].sum())
        valid_total += int(valid.sum())
        scan_count += 1
    return covered / valid_total, vertices / scan_count


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"real logs not available: {DATA} is missing")
@pytest.mark.parametrize("log", LOGS)
def test_real_logs_keep_at_least_90_percent_of_readings(log):
    path = DATA / log
    if not path.is_file():
        pytest.skip(f"{path} is missing")
    fraction, vertices_per_scan = coverage(read_carmen(path), REAL_LOG_PARAMS)
    print(f"{log}: {fraction:.2%} of valid readings covered, {vertices_per_scan:.1f} vertices/scan")
    assert fraction >= MIN_COVERED, (
        f"{log}: only {fraction:.2%} of the valid readings lie in a polyline within epsilon"
    )
