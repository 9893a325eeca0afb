"""Campaign statistics: metric columns, per-group figures, bootstrap intervals."""

import json
import math

import numpy as np
import pytest
from scipy.stats import DegenerateDataWarning, bootstrap

from scenarios.campaign.stats import (
    bootstrap_ci,
    bootstrap_difference_ci,
    finite_values,
    group_statistics,
    metric_columns,
    status_counts,
)
from scenarios.campaign.tolerances import Tolerance, Tolerances

LOWER = Tolerance("safety.stops", "lower", 1.0)
HIGHER = Tolerance("detection.f1", "higher", 0.02)
TOLERANCES = Tolerances(0.05, {LOWER.metric: LOWER, HIGHER.metric: HIGHER})


def run(scenario="sim1", policy="adaptive", seed=0, status="ok", **metrics):
    row = {"run": f"{scenario} {policy} seed={seed}", "scenario": scenario, "policy": policy,
           "seed": seed, "sample": 0, "status": status, "reason": None, "digest": "abc"}
    row.update({name.replace("__", "."): value for name, value in metrics.items()})
    return row


# --------------------------------------------------------------------------------------
# Columns and values


def test_metric_columns_leave_out_identity_vary_and_non_numeric_columns_in_first_seen_order():
    rows = [
        {**run(), "vary.mapper.gate": 0.1, "safety.stops": None, "label": "x",
         "flag": True, "detection.f1": 1.0},
        {**run(seed=1), "vary.mapper.gate": 0.2, "safety.stops": 2, "label": "y",
         "flag": False, "localization.rmse_xy_m": 0.01, "mixed": 1.0},
        {**run(seed=2), "mixed": "text", "empty": None},
    ]
    assert metric_columns(rows) == ["safety.stops", "detection.f1", "localization.rmse_xy_m"]


def test_metric_columns_of_no_rows_is_empty():
    assert metric_columns([]) == []


def test_finite_values_drop_missing_nan_inf_and_non_numbers():
    rows = [{"m": 1}, {"m": None}, {"m": math.nan}, {"m": math.inf}, {}, {"m": "2"},
            {"m": True}, {"m": np.float64(2.5)}]
    np.testing.assert_array_equal(finite_values(rows, "m"), [1.0, 2.5])


def test_status_counts_list_every_status():
    assert status_counts([]) == {"ok": 0, "rejected": 0, "error": 0}
    assert status_counts([run(status="rejected"), run(), run()]) == {
        "ok": 2, "rejected": 1, "error": 0}


# --------------------------------------------------------------------------------------
# Group statistics against hand-computed figures


def test_group_statistics_match_hand_computed_means_and_stds():
    stops = [1, 2, 3, 4]
    f1 = [0.8, 0.9, 1.0, 0.7]
    rows = [run(seed=seed, safety__stops=s, detection__f1=f) for seed, (s, f)
            in enumerate(zip(stops, f1, strict=True))]
    rows += [run(policy="conservative", seed=seed, safety__stops=10 * seed, detection__f1=0.5)
             for seed in range(3)]
    rows.append(run(seed=9, status="error", safety__stops=1000))  # not ok: never counted
    stats = group_statistics(rows, np.random.default_rng(0), tolerances=TOLERANCES)
    assert stats["metrics"] == ["safety.stops", "detection.f1"]
    adaptive, conservative = stats["groups"]
    assert (adaptive["scenario"], adaptive["policy"]) == ("sim1", "adaptive")
    assert adaptive["runs"] == {"ok": 4, "rejected": 0, "error": 1}
    figures = adaptive["metrics"]["safety.stops"]
    assert figures["n"] == 4
    assert figures["mean"] == pytest.approx(2.5)
    assert figures["std"] == pytest.approx(math.sqrt(5 / 3))  # sum of squares 5, ddof 1
    assert (figures["min"], figures["max"], figures["worst"]) == (1.0, 4.0, 4.0)
    low, high = figures["ci95"]
    assert 1.0 <= low < 2.5 < high <= 4.0
    f1_figures = adaptive["metrics"]["detection.f1"]
    assert f1_figures["mean"] == pytest.approx(0.85)
    assert f1_figures["std"] == pytest.approx(math.sqrt(0.05 / 3))
    assert f1_figures["worst"] == pytest.approx(0.7)  # higher is better: the least
    constant = conservative["metrics"]["detection.f1"]
    assert (constant["std"], constant["ci95"]) == (0.0, [0.5, 0.5])
    assert conservative["metrics"]["safety.stops"]["mean"] == pytest.approx(10.0)


def test_a_metric_without_a_tolerance_has_no_worst():
    rows = [run(seed=seed, localization__rmse_xy_m=0.01 * seed) for seed in range(3)]
    figures = group_statistics(rows, np.random.default_rng(0), tolerances=TOLERANCES)
    assert figures["groups"][0]["metrics"]["localization.rmse_xy_m"]["worst"] is None


def test_the_bundled_tolerances_give_worst_by_default():
    rows = [run(seed=seed, detection__f1=value) for seed, value in enumerate([0.9, 0.6, 1.0])]
    group = group_statistics(rows, np.random.default_rng(0))["groups"][0]
    assert group["metrics"]["detection.f1"]["worst"] == pytest.approx(0.6)


def test_few_missing_and_non_finite_values_give_none_never_nan():
    rows = [run(seed=0, status="rejected"), run(seed=1, detection__f1=0.9, safety__stops=None),
            run(seed=2, detection__f1=math.nan, safety__stops=None),
            run(scenario="pal1", seed=0, status="error")]
    stats = group_statistics(rows, np.random.default_rng(0), ["detection.f1", "safety.stops"],
                             tolerances=TOLERANCES)
    sim1, pal1 = stats["groups"]
    one = sim1["metrics"]["detection.f1"]
    assert one == {"n": 1, "mean": 0.9, "std": None, "ci95": None, "min": 0.9, "max": 0.9,
                   "worst": 0.9}
    empty = {"n": 0, "mean": None, "std": None, "ci95": None, "min": None, "max": None,
             "worst": None}
    assert sim1["metrics"]["safety.stops"] == empty
    assert pal1["runs"] == {"ok": 0, "rejected": 0, "error": 1}
    assert pal1["metrics"]["detection.f1"] == empty
    json.dumps(stats, allow_nan=False)  # raises on a NaN or a numpy scalar


def test_group_statistics_are_plain_json_values():
    rng = np.random.default_rng(5)
    rows = [run(seed=seed, safety__stops=int(rng.integers(0, 5)),
                detection__f1=np.float64(rng.uniform())) for seed in range(6)]
    stats = group_statistics(rows, np.random.default_rng(0), tolerances=TOLERANCES)
    assert json.loads(json.dumps(stats, allow_nan=False)) == stats


def test_same_rows_and_seed_give_the_same_statistics_and_another_seed_other_intervals():
    data = np.random.default_rng(1)
    rows = [run(policy=policy, seed=seed, detection__f1=float(data.uniform()),
                safety__stops=float(data.normal(3, 1)))
            for policy in ("adaptive", "conservative") for seed in range(8)]
    first = group_statistics(rows, np.random.default_rng(7), tolerances=TOLERANCES)
    again = group_statistics(rows, np.random.default_rng(7), tolerances=TOLERANCES)
    other = group_statistics(rows, np.random.default_rng(8), tolerances=TOLERANCES)
    assert first == again
    assert first != other
    for mine, theirs in zip(first["groups"], other["groups"], strict=True):
        for name, figures in mine["metrics"].items():  # only the intervals are random
            assert {k: v for k, v in figures.items() if k != "ci95"} == {
                k: v for k, v in theirs["metrics"][name].items() if k != "ci95"}


def test_the_global_numpy_generator_is_not_used():
    rows = [run(seed=seed, detection__f1=seed / 10) for seed in range(5)]
    np.random.seed(3)  # noqa: NPY002 -- the legacy global state must be left untouched
    before = np.random.get_state()[1].copy()  # noqa: NPY002
    group_statistics(rows, np.random.default_rng(0), tolerances=TOLERANCES)
    np.testing.assert_array_equal(np.random.get_state()[1], before)  # noqa: NPY002


# --------------------------------------------------------------------------------------
# Bootstrap intervals


def test_bootstrap_ci_of_constant_and_too_few_values():
    rng = np.random.default_rng(0)
    assert bootstrap_ci([3.5, 3.5, 3.5], rng) == (3.5, 3.5)
    assert bootstrap_ci([3.5, None, math.nan, 3.5], rng) == (3.5, 3.5)
    assert bootstrap_ci([], rng) is None
    assert bootstrap_ci([1.0], rng) is None
    assert bootstrap_ci([1.0, None, math.nan, math.inf], rng) is None


def test_bootstrap_ci_of_a_large_normal_sample_holds_the_true_mean_with_the_textbook_width():
    sample = np.random.default_rng(11).normal(5.0, 2.0, 400)
    low, high = bootstrap_ci(sample, np.random.default_rng(0))
    assert low < 5.0 < high
    # The normal interval: 2 * 1.96 * sigma / sqrt(n) = 0.392.
    assert high - low == pytest.approx(2 * 1.96 * 2.0 / 20.0, rel=0.15)


def test_bootstrap_ci_covers_the_true_mean_about_95_percent_of_the_time():
    data = np.random.default_rng(12)
    rng = np.random.default_rng(13)
    covered = 0
    trials = 200
    for _ in range(trials):
        low, high = bootstrap_ci(data.normal(1.0, 1.0, 30), rng, n_resamples=1999)
        covered += low < 1.0 < high
    assert 0.89 <= covered / trials <= 0.99


def test_bootstrap_ci_falls_back_to_the_percentile_interval_when_bca_degenerates():
    # BCa's acceleration overflows (cubes of 1e300): scipy gives NaN.
    values = np.array([1e300, -1e300, 0.0])
    with np.errstate(all="ignore"):
        with pytest.warns(DegenerateDataWarning):
            bca = bootstrap((values,), np.mean, n_resamples=999, rng=np.random.default_rng(4))
        percentile = bootstrap((values,), np.mean, n_resamples=999, method="percentile",
                               rng=np.random.default_rng(4))
    assert np.isnan(bca.confidence_interval.low)
    interval = bootstrap_ci(values, np.random.default_rng(4), n_resamples=999)
    assert interval == pytest.approx(tuple(percentile.confidence_interval))
    assert all(math.isfinite(end) for end in interval)


def test_bootstrap_ci_is_bca_when_bca_works():
    values = np.random.default_rng(2).exponential(1.0, 25)  # skewed: BCa != percentile
    bca = bootstrap((values,), np.mean, n_resamples=999, rng=np.random.default_rng(6))
    percentile = bootstrap((values,), np.mean, n_resamples=999, method="percentile",
                           rng=np.random.default_rng(6))
    interval = bootstrap_ci(values, np.random.default_rng(6), n_resamples=999)
    assert interval == pytest.approx(tuple(bca.confidence_interval))
    assert interval != pytest.approx(tuple(percentile.confidence_interval))


def test_bootstrap_difference_ci_of_constant_sides_too_few_and_a_clear_shift():
    rng = np.random.default_rng(0)
    assert bootstrap_difference_ci([1.0, 1.0], [4.0, 4.0, None], rng) == (3.0, 3.0)
    assert bootstrap_difference_ci([1.0], [4.0, 5.0], rng) is None
    assert bootstrap_difference_ci([1.0, 2.0], [math.nan, 5.0], rng) is None
    data = np.random.default_rng(3)
    baseline, candidate = data.normal(0.0, 1.0, 200), data.normal(1.0, 1.0, 150)
    low, high = bootstrap_difference_ci(baseline, candidate, rng)
    assert low < 1.0 < high
    # Normal interval of a difference of means: 2 * 1.96 * sqrt(1/200 + 1/150) = 0.424.
    assert high - low == pytest.approx(2 * 1.96 * math.sqrt(1 / 200 + 1 / 150), rel=0.15)
    assert bootstrap_difference_ci(candidate, baseline, np.random.default_rng(0))[1] < 0.0
