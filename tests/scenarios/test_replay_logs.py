"""Revisit consistency on the real Intel and ACES logs (issue 6), both ways.

Marked slow (about 10 s for both logs, aligned and at the logged poses); skipped when the
data directory ``../shared/data`` (relative to the repository root) is missing. The
figures are regression bounds around the measured values, not targets (issue 10's
defaults: intel 4.27 cm aligned, aces 4.32 cm).
"""

from pathlib import Path

import pytest

from scenarios.logs.real_log import ReplayOptions, open_log, replay_log

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not DATA.is_dir(), reason=f"no real logs in {DATA}"),
]


@pytest.fixture(scope="module", params=["intel", "aces"])
def summary(request):
    scans = open_log(DATA / f"{request.param}-corrected.log.gz")
    return request.param, replay_log(scans, ReplayOptions(align=True)).summary()


def test_alignment_lowers_the_revisit_distance(summary):
    _, metrics = summary
    aligned = metrics["table1_cm"]["mean"]["avg"]
    at_log_pose = metrics["alignment"]["table1_cm_log_pose"]["mean"]["avg"]
    assert aligned < at_log_pose - 0.3
    # With corridors corrected across only (partial alignments) and 10 matched points
    # enough: intel 583/763 (460 when partial ones were refused, 549 at 30 points), ACES
    # 126/152 (84, 123).
    assert metrics["alignment"]["accepted"] >= 0.65 * metrics["alignment"]["attempted"]
    assert metrics["alignment"]["partial"] > 0
    # Corrections of a few centimetres, nowhere near the bounds.
    assert 1.0 < metrics["alignment"]["translation_cm"]["median"] < 5.0
    assert metrics["alignment"]["rotation_deg"]["median"] < 1.0


def test_revisit_consistency_figures(summary):
    log, metrics = summary
    aligned = metrics["table1_cm"]["mean"]["avg"]
    # Issue 10's lines are 4.3 (intel) and 4.5 cm (aces), every polyline under 10 cm:
    # measured 4.27 and 4.32 cm, largest per-polyline means 9.99 and 8.81 cm. These pin
    # the figures against regressions; the paper's real environments: 2.5-4.6 cm.
    if log == "intel":
        assert aligned < 4.3
    else:
        # ACES: range noise ~3.5x intel's, 2.5 cm range quantisation, cluttered.
        assert 4.2 < aligned < 4.5
    assert metrics["table1_cm"]["mean"]["max"] < 10.0
    assert metrics["extraction"]["coverage"] > 0.95
