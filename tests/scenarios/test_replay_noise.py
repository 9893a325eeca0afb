"""The range noise of a log, and replay thresholds fitted to it (``auto_noise``).

Synthetic logs from ``test_replay``: a room with boxes ray cast with CARMEN's 180
one-degree beams and Gaussian range noise. The real-log checks at the end are marked slow
(about 8 s for Intel and ACES) and skipped without ``../shared/data``.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from scenarios.logs.real_log import (
    NOISE_EPSILON_SIGMAS,
    REPLAY_PARAMS,
    ReplayOptions,
    estimate_range_noise,
    noise_params,
    open_log,
    replay_log,
)
from semistatic.noise import spec_noise_params
from semistatic.params import MapperParams
from semistatic.types import Scan
from tests.scenarios.test_replay import OPTIONS, synthetic_log
from tests.semistatic.synthetic import cast_scan, scene, wall

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
AUTO = dataclasses.replace(OPTIONS, auto_noise=True)
PLAIN = dataclasses.replace(OPTIONS, auto_noise=False)


def without_run_details(summary):
    """Return a summary without what differs between equivalent runs (timing, the flag)."""
    summary = dict(summary)
    summary.pop("performance")
    summary["params"] = {k: v for k, v in summary["params"].items() if k != "auto_noise"}
    summary["noise"] = {k: v for k, v in summary["noise"].items() if k != "rule"}
    return summary


@pytest.mark.parametrize("noise", [0.005, 0.01, 0.02])
def test_noise_estimate_follows_the_range_noise(noise):
    scans = synthetic_log(offset=(0.0, 0.0, 0.0), seed=5, noise=noise)[:50]
    # Across the surface: range noise times the cosine of the incidence angle.
    assert 0.7 * noise < estimate_range_noise(scans) < 1.0 * noise


def test_corners_and_depth_jumps_are_not_noise():
    # A noise-free room with boxes: every corner and occlusion edge is in the scans.
    scans = synthetic_log(offset=(0.0, 0.0, 0.0), seed=5, noise=0.0)[:50]
    assert estimate_range_noise(scans) < 1e-4


def test_round_wall_seen_from_its_centre_gives_the_range_noise():
    rng = np.random.default_rng(7)
    angles = np.radians(np.arange(-90.0, 90.0, 1.0))
    scans = [Scan(ranges=3.0 + rng.normal(0.0, 0.02, angles.size), angle_min=angles[0],
                  angle_increment=np.radians(1.0)) for _ in range(30)]
    assert estimate_range_noise(scans) == pytest.approx(0.02, rel=0.1)


@pytest.mark.parametrize(
    "ranges",
    [[], [np.inf] * 20, [2.0, np.inf, 2.0, np.inf, 2.0, np.inf], [1.0, 5.0, 1.0, 5.0, 1.0]],
    ids=["no beams", "no returns", "no three in a row", "depth spikes"],
)
def test_nothing_to_measure_gives_nan(ranges):
    scan = Scan(ranges=np.asarray(ranges, dtype=float), angle_min=0.0,
                angle_increment=math.radians(1.0), range_max=50.0)
    assert math.isnan(estimate_range_noise([scan]))
    assert math.isnan(estimate_range_noise([]))


def test_noise_params_follow_the_noise_and_raise_the_breakpoint_noise_only():
    assert noise_params(REPLAY_PARAMS, math.nan) is REPLAY_PARAMS
    quiet = noise_params(REPLAY_PARAMS, 0.004)
    assert quiet.epsilon == pytest.approx(NOISE_EPSILON_SIGMAS * 0.004)  # lowered
    assert quiet.breakpoint_sigma_r == REPLAY_PARAMS.breakpoint_sigma_r  # never lowered
    fitted = noise_params(REPLAY_PARAMS, 0.05)
    assert fitted.epsilon == pytest.approx(NOISE_EPSILON_SIGMAS * 0.05)
    assert fitted.breakpoint_sigma_r == pytest.approx(0.05)
    # Nothing else moves.
    assert fitted.replace(epsilon=REPLAY_PARAMS.epsilon,
                          breakpoint_sigma_r=REPLAY_PARAMS.breakpoint_sigma_r) == REPLAY_PARAMS
    assert noise_params(REPLAY_PARAMS, 0.0) is REPLAY_PARAMS  # no noise: no tolerance to set


def test_noise_params_reject_negative_sigma():
    with pytest.raises(ValueError, match="sigma must be >= 0"):
        noise_params(REPLAY_PARAMS, -0.01)


def test_auto_noise_is_the_default_and_reported():
    assert ReplayOptions().auto_noise
    scans = synthetic_log(seed=6, noise=0.005)
    plain, auto = replay_log(scans, PLAIN).summary(), replay_log(scans, AUTO).summary()
    assert auto["params"]["epsilon_m"] == pytest.approx(
        NOISE_EPSILON_SIGMAS * auto["noise"]["sigma_cm"] / 100.0, abs=1e-5)
    assert plain["params"]["epsilon_m"] == REPLAY_PARAMS.epsilon
    assert auto["noise"]["rule"] is not None
    assert plain["noise"]["rule"] is None


def test_auto_noise_simplifies_the_noise_not_the_shape():
    scans = synthetic_log(offset=(0.0, 0.0, 0.0), seed=5, noise=0.02)
    clean = replay_log(synthetic_log(offset=(0.0, 0.0, 0.0), seed=5, noise=0.0), PLAIN).summary()
    plain, auto = replay_log(scans, PLAIN).summary(), replay_log(scans, AUTO).summary()
    sigma = auto["noise"]["sigma_cm"] / 100.0
    assert auto["params"]["epsilon_m"] == pytest.approx(NOISE_EPSILON_SIGMAS * sigma, abs=1e-5)
    # At 3 cm the polylines follow the noise: several times the vertices of the noise-free
    # room. Fitted to the noise they keep the room's corners and little else.
    vertices = {name: s["extraction"]["vertices_per_scan"]
                for name, s in (("clean", clean), ("plain", plain), ("auto", auto))}
    assert vertices["plain"] > 3 * vertices["clean"]
    assert vertices["clean"] <= vertices["auto"] < 0.5 * vertices["plain"]
    assert auto["extraction"]["coverage"] > 0.95
    assert auto["extraction"]["rms_distance_m"] < sigma * 1.5


def test_noise_is_reported_without_auto_noise():
    summary = replay_log(synthetic_log(seed=6, noise=0.01), PLAIN).summary()
    assert summary["noise"]["scans"] == OPTIONS.noise_scans
    assert 0.7 < summary["noise"]["sigma_cm"] < 1.0
    assert summary["params"]["auto_noise"] is False


@pytest.fixture(scope="module")
def plain_replay():
    """A synthetic log and its replay with the default noise sample, without auto_noise."""
    scans = synthetic_log(seed=6)
    return scans, replay_log(scans, PLAIN).summary()


@pytest.mark.parametrize("noise_scans", [1, 7, 10_000])
def test_every_scan_is_replayed_whatever_the_noise_sample(noise_scans, plain_replay):
    # without auto_noise: the sample only measures the noise, it changes no threshold
    scans, reference = plain_replay
    options = dataclasses.replace(PLAIN, noise_scans=noise_scans)
    summary = replay_log(iter(scans), options).summary()  # a stream, as open_log gives
    assert summary["scans"] == len(scans)
    assert summary["table1_cm"] == reference["table1_cm"]
    limited = replay_log(iter(scans), dataclasses.replace(options, max_scans=5, every=2))
    assert limited.scans == 5


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"auto_noise": 1}, "ReplayOptions.auto_noise"),
        ({"noise_scans": 0}, "ReplayOptions.noise_scans"),
        ({"noise_scans": 2.5}, "ReplayOptions.noise_scans"),
    ],
)
def test_noise_options_are_validated(changes, message):
    with pytest.raises(ValueError, match=message):
        ReplayOptions(**changes)


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"no real logs in {DATA}")
@pytest.mark.parametrize(
    ("log", "sigma_cm", "epsilon_m", "table1_cm"),
    [
        # Intel: 0.47 cm noise, epsilon 1.4 cm: 4.19 cm (4.70 with the fixed 3 cm and the
        # paper's extraction; 4.35 before mixed-pixel ends and 10-point alignments, 4.27
        # before the fit along the beams). The target: under 4.3 cm.
        ("intel", (0.4, 0.6), (0.012, 0.018), (4.1, 4.3)),
        # ACES: 1.67 cm noise, epsilon 5.0 cm: 4.29 cm (6.10 before issue 10; 4.397 before
        # mixed-pixel ends and 10-point alignments, 4.32 before the fit along the beams).
        ("aces", (1.5, 2.0), (0.045, 0.06), (4.2, 4.5)),
    ],
)
def test_real_logs_with_auto_noise(log, sigma_cm, epsilon_m, table1_cm):
    summary = replay_log(open_log(DATA / f"{log}-corrected.log.gz"), ReplayOptions()).summary()
    assert sigma_cm[0] < summary["noise"]["sigma_cm"] < sigma_cm[1]
    assert epsilon_m[0] <= summary["params"]["epsilon_m"] <= epsilon_m[1]
    assert table1_cm[0] < summary["table1_cm"]["mean"]["avg"] < table1_cm[1]
    assert summary["extraction"]["coverage"] > 0.95
    assert summary["extraction"]["vertices_per_scan"] < 35  # ACES without: 54.7


def test_spec_sigmas_match_three_measured_sigmas_on_simulated_scans():
    # The data sheet's noise is along the beam, the measured one across the surface: on
    # a room and a corridor cast with 1.2 cm noise, 2.5 data-sheet sigmas lie within 25 %
    # of three measured sigmas (the rule replay applies to real logs).
    rng = np.random.default_rng(0)
    room = scene(wall((-4, -4), (4, -4)), wall((4, -4), (4, 4)), wall((4, 4), (-4, 4)),
                 wall((-4, 4), (-4, -4)))
    corridor = scene(wall((-10, -1.5), (10, -1.5)), wall((-10, 1.5), (10, 1.5)))
    for segments, poses in ((room, [(x, y, 0.3) for x, y in rng.uniform(-2, 2, (30, 2))]),
                            (corridor, [(x, 0.0, 0.0) for x in np.linspace(-6, 6, 30)])):
        scans = [cast_scan(segments, pose, noise=0.012, rng=rng) for pose in poses]
        measured = NOISE_EPSILON_SIGMAS * estimate_range_noise(scans)
        assert spec_noise_params(MapperParams(), 0.012).epsilon == pytest.approx(measured,
                                                                                  rel=0.25)
    with pytest.raises(ValueError, match="sigma must be >= 0"):
        spec_noise_params(MapperParams(), -0.01)
