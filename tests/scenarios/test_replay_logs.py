"""Revisit consistency on the real Intel and ACES logs (issue 6), both ways.

Marked slow (about 10 s for both logs, aligned and at the logged poses); skipped when the
data directory ``../shared/data`` (relative to the repository root) is missing. The
figures are regression bounds around the measured values, not targets: intel 4.70 cm
aligned / 5.15 cm at the logged poses, aces 6.10 / 6.65 cm.
"""

from pathlib import Path

import pytest

from scenarios.replay import ReplayOptions, open_log, replay

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not DATA.is_dir(), reason=f"no real logs in {DATA}"),
]


@pytest.fixture(scope="module", params=["intel", "aces"])
def summary(request):
    scans = open_log(DATA / f"{request.param}-corrected.log.gz")
    return request.param, replay(scans, ReplayOptions(align=True)).summary()


def test_alignment_lowers_the_revisit_distance(summary):
    _, metrics = summary
    aligned = metrics["table1_cm"]["mean"]["avg"]
    at_log_pose = metrics["alignment"]["table1_cm_log_pose"]["mean"]["avg"]
    assert aligned < at_log_pose - 0.3
    assert metrics["alignment"]["accepted"] >= 0.6 * metrics["alignment"]["attempted"]
    # Corrections of a few centimetres, nowhere near the bounds.
    assert 1.0 < metrics["alignment"]["translation_cm"]["median"] < 5.0
    assert metrics["alignment"]["rotation_deg"]["median"] < 1.0


def test_revisit_consistency_figures(summary):
    log, metrics = summary
    aligned = metrics["table1_cm"]["mean"]["avg"]
    if log == "intel":
        assert aligned < 5.0  # the line; the paper's real environments: 2.5-4.6 cm
    else:
        # ACES is not under 5 cm: its first-pass scans are already 6.0 cm from the reference
        # they built (range noise ~4x intel's, 2.5 cm range quantisation, cluttered).
        assert 5.5 < aligned < 6.6
    assert metrics["extraction"]["coverage"] > 0.95
