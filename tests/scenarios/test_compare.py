"""``semistatic compare``: tests, multiple testing, verdicts, reports, tolerance files, CLI."""

import argparse
import json
import math
import re
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from junitparser import Failure, JUnitXml, Skipped, TestSuite
from scipy.stats import wilcoxon

from scenarios.campaign.compare import (
    BETTER,
    NO_CHANGE,
    NOT_ENOUGH,
    NOT_MEASURED,
    WORSE,
    compare_campaigns,
)
from scenarios.campaign.tolerances import (
    DEFAULT_TOLERANCES,
    Tolerance,
    Tolerances,
    default_tolerances,
    read_tolerances,
)
from scenarios.commands.compare import add_parser, main_compare
from semistatic.errors import SpecError

ALPHA = 0.05
RESAMPLES = 999  # the intervals are not what these tests judge: fewer resamples, faster


def tolerances(*entries, alpha=ALPHA):
    """Tolerances of ``(metric, better, min_change)`` entries."""
    return Tolerances(alpha, {name: Tolerance(name, better, change)
                              for name, better, change in entries})


def run(scenario="sim1", policy="adaptive", seed=0, status="ok", vary=None, **metrics):
    row = {"run": f"{scenario} {policy} {seed}", "scenario": scenario, "policy": policy,
           "seed": seed, "sample": 0, "status": status, "reason": None, "digest": "d"}
    row.update({f"vary.{key}": value for key, value in (vary or {}).items()})
    row.update(metrics)
    return row


def column(values, seeds=None, name="m", **where):
    """Rows of one group, one per value, with ``seeds`` (default 0, 1, ...)."""
    seeds = range(len(values)) if seeds is None else seeds
    return [run(seed=seed, **where, **{name: value})
            for seed, value in zip(seeds, values, strict=True)]


def compare(baseline, candidate, judged, seed=0, **options):
    return compare_campaigns(baseline, candidate, judged, rng=np.random.default_rng(seed),
                             n_resamples=RESAMPLES, **options)


def normal_campaign(data, groups, metrics, seeds, shift=0.0):
    return [run(scenario=f"s{group}", policy="p", seed=seed,
                **{name: float(data.normal(10.0, 1.0)) + shift for name in metrics})
            for group in range(groups) for seed in seeds]


# --------------------------------------------------------------------------------------
# The tests against hand-computed p-values


def test_ten_positive_pairs_give_the_exact_wilcoxon_p_of_2_over_1024():
    baseline = column([1.0] * 10)
    candidate = column([1.0 + k for k in range(1, 11)])  # differences 1..10, all positive
    group = compare(baseline, candidate, tolerances(("m", "lower", 0.5))).metrics["m"].groups[0]
    assert group.paired
    assert group.p == pytest.approx(2 / 1024)
    assert group.p_adjusted == pytest.approx(2 / 1024)  # a family of one
    assert group.difference == pytest.approx(5.5)
    assert (group.baseline_mean, group.candidate_mean) == (1.0, pytest.approx(6.5))
    assert (group.n_baseline, group.n_candidate) == (10, 10)
    assert group.verdict == WORSE


@pytest.mark.parametrize(
    "differences",
    [
        [1, 1, 1, 1, 1, 1, 0, 0, 0, 0],  # ties and zeros: scipy's exact sign-flip test
        [2, -1, 1, 1, 3, 0, 2, 1, -1, 2, 1, 1],
        [0.5, 1.5, -0.25, 2.0, 1.0, 3.0],  # no ties: scipy's exact distribution
        [*range(1, 16), 3, 3, -4],  # more than 13 pairs with ties: the normal approximation
    ],
)
def test_paired_p_values_are_those_of_scipys_wilcoxon(differences):
    baseline = column([10.0] * len(differences))
    candidate = column([10.0 + d for d in differences])
    group = compare(baseline, candidate, tolerances(("m", "lower", 0.0))).metrics["m"].groups[0]
    assert group.paired
    assert group.p == pytest.approx(wilcoxon(np.array(differences, dtype=float)).pvalue,
                                    rel=1e-12)


def test_separated_unpaired_samples_give_the_exact_mann_whitney_p():
    # Different seeds: no partners. Three against three, fully separated: the most
    # extreme of C(6, 3) = 20 orderings on either side, p = 2 / 20.
    baseline = column([1.0, 2.0, 3.0], seeds=[0, 1, 2])
    candidate = column([4.0, 5.0, 6.0], seeds=[7, 8, 9])
    group = compare(baseline, candidate, tolerances(("m", "lower", 0.5))).metrics["m"].groups[0]
    assert not group.paired
    assert group.p == pytest.approx(0.1)
    assert group.difference == pytest.approx(3.0)
    assert group.verdict == NO_CHANGE  # 0.1 is not significant


def test_all_zero_differences_and_identical_values_give_p_one():
    same = compare(column([2.0, 3.0, 4.0]), column([2.0, 3.0, 4.0]),
                   tolerances(("m", "lower", 0.0))).metrics["m"].groups[0]
    assert (same.paired, same.p, same.difference, same.ci) == (True, 1.0, 0.0, (0.0, 0.0))
    flat = compare(column([2.0, 2.0]), column([2.0, 2.0, 2.0], seeds=[5, 6, 7]),
                   tolerances(("m", "lower", 0.0))).metrics["m"].groups[0]
    assert (flat.paired, flat.p, flat.ci) == (False, 1.0, (0.0, 0.0))


def test_benjamini_hochberg_over_every_metric_and_group_matches_a_hand_computed_list():
    # Five against five, unpaired (other seeds). Mann-Whitney's exact two-sided p:
    # U = 0 -> 2/252, U = 1 -> 4/252, U = 2 -> 8/252; identical values -> 1.
    # BH with m = 4, sorted p_(k) * m / k, made monotone from the top:
    #   1 -> 1; 8/252 * 4/3 = 32/756; 4/252 * 4/2 = 8/252; 2/252 * 4 = 8/252.
    baseline_a = {"g1": [1, 2, 3, 4, 5], "g2": [1, 2, 3, 4, 6]}
    candidate_a = {"g1": [6, 7, 8, 9, 10], "g2": [5, 7, 8, 9, 10]}
    baseline_b = {"g1": [1, 2, 3, 5, 6], "g2": [3, 3, 3, 3, 3]}
    candidate_b = {"g1": [4, 7, 8, 9, 10], "g2": [3, 3, 3, 3, 3]}

    def rows(a, b, seeds):
        return [run(scenario=group, seed=seed, a=float(x), b=float(y))
                for group in ("g1", "g2")
                for seed, x, y in zip(seeds, a[group], b[group], strict=True)]

    comparison = compare(rows(baseline_a, baseline_b, range(5)),
                         rows(candidate_a, candidate_b, range(10, 15)),
                         tolerances(("a", "lower", 0.0), ("b", "lower", 0.0)))
    found = {(name, g.scenario): (g.p, g.p_adjusted)
             for name, metric in comparison.metrics.items() for g in metric.groups}
    expected = {("a", "g1"): (2 / 252, 8 / 252), ("a", "g2"): (4 / 252, 8 / 252),
                ("b", "g1"): (8 / 252, 32 / 756), ("b", "g2"): (1.0, 1.0)}
    assert found == {key: (pytest.approx(p), pytest.approx(q)) for key, (p, q) in expected.items()}
    assert [comparison.metrics[n].verdict for n in "ab"] == [WORSE, WORSE]


# --------------------------------------------------------------------------------------
# False alarms under the global null


METRICS = [f"metric{k}" for k in range(12)]
NULL_TOLERANCES = tolerances(*((name, "lower", 0.0) for name in METRICS))  # p alone decides


def null_comparison(seed, paired):
    data = np.random.default_rng(seed)
    baseline = normal_campaign(data, 10, METRICS, range(12))
    candidate = normal_campaign(data, 10, METRICS, range(12) if paired else range(100, 112))
    # The intervals play no part in a verdict: few resamples keep 40 comparisons quick.
    return compare_campaigns(baseline, candidate, NULL_TOLERANCES,
                             rng=np.random.default_rng(seed), n_resamples=99)


def test_the_same_distribution_with_other_seeds_is_no_change_for_every_metric():
    comparison = null_comparison(0, paired=False)
    assert {m.verdict for m in comparison.metrics.values()} == {NO_CHANGE}
    assert comparison.regressions == ()
    assert comparison.exit_status == 0
    groups = [g for m in comparison.metrics.values() for g in m.groups]
    assert len(groups) == 120
    assert not any(g.paired for g in groups)


@pytest.mark.parametrize(("paired", "generators"), [(False, 20), (True, 10)])
def test_the_false_alarm_rate_over_many_generators_is_about_alpha(paired, generators):
    alarms = raw_alarms = 0
    for seed in range(generators):
        comparison = null_comparison(seed, paired)
        groups = [g for m in comparison.metrics.values() for g in m.groups]
        assert all(g.paired == paired for g in groups)
        alarms += any(m.verdict in (WORSE, BETTER) for m in comparison.metrics.values())
        raw_alarms += any(g.p < ALPHA for g in groups)
    # Benjamini-Hochberg under the global null: P(any alarm) <= alpha, so about one
    # comparison in 20 may raise one; allow 10 %.
    assert alarms <= generators // 10
    # Without the adjustment, 120 tests at 5 % nearly always raise one (1 - 0.95^120).
    assert raw_alarms >= generators - 1


# --------------------------------------------------------------------------------------
# Verdicts and min_change


def test_a_shift_far_beyond_min_change_is_worse_and_exits_1():
    data = np.random.default_rng(3)
    judged = tolerances(("table1_cm.mean.avg", "lower", 0.2), ("detection.f1", "higher", 0.02))
    baseline = [run(scenario=s, seed=seed, **{"table1_cm.mean.avg": data.normal(2.0, 0.1),
                                              "detection.f1": data.normal(0.9, 0.01)})
                for s in ("sim1", "pal1") for seed in range(12)]
    candidate = [{**row, "table1_cm.mean.avg": row["table1_cm.mean.avg"] + 1.0,
                  "detection.f1": row["detection.f1"] + 0.05} for row in baseline]
    comparison = compare(baseline, candidate, judged)
    table1 = comparison.metrics["table1_cm.mean.avg"]
    assert table1.verdict == WORSE
    assert {g.verdict for g in table1.groups} == {WORSE}
    low, high = table1.groups[0].ci
    assert (low, high) == (pytest.approx(1.0), pytest.approx(1.0))  # constant differences
    assert comparison.metrics["detection.f1"].verdict == BETTER  # higher F1 is better
    assert comparison.regressions == ("table1_cm.mean.avg",)
    assert comparison.exit_status == 1


def test_a_significant_shift_below_min_change_is_no_significant_change():
    data = np.random.default_rng(4)
    baseline = column(list(data.normal(2.0, 0.01, 12)))
    candidate = column(list(data.normal(2.3, 0.01, 12)))
    comparison = compare(baseline, candidate, tolerances(("m", "lower", 0.5)))
    group = comparison.metrics["m"].groups[0]
    assert group.p_adjusted < 1e-3  # clearly significant
    assert group.difference == pytest.approx(0.3, abs=0.02)
    assert group.verdict == NO_CHANGE
    assert comparison.metrics["m"].verdict == NO_CHANGE
    assert comparison.exit_status == 0
    stricter = compare(baseline, candidate, tolerances(("m", "lower", 0.25)))
    assert stricter.metrics["m"].verdict == WORSE


def test_one_worse_group_makes_the_metric_worse_even_if_another_is_better():
    baseline = (column([1.0] * 10, scenario="a") + column([5.0] * 10, scenario="b"))
    candidate = (column([2.0 + k / 100 for k in range(10)], scenario="a")
                 + column([4.0 - k / 100 for k in range(10)], scenario="b"))
    metric = compare(baseline, candidate, tolerances(("m", "lower", 0.5))).metrics["m"]
    assert [g.verdict for g in metric.groups] == [WORSE, BETTER]
    assert metric.verdict == WORSE
    assert metric.worst_group.scenario == "a"


def test_too_few_runs_and_unmeasured_metrics_are_reported_not_judged():
    baseline = column([1.0], scenario="one") + column([1.0, 2.0], scenario="two")
    baseline += [run(scenario="none", seed=0, m=None), run(scenario="none", seed=1, m=None)]
    candidate = [dict(row) for row in baseline]
    candidate[0]["m"] = 9.0
    judged = tolerances(("m", "lower", 0.0), ("detection.f1", "higher", 0.02),
                        ("detection.f2", "higher", 0.02))
    for row in candidate:
        row["detection.f1"] = 1.0
    comparison = compare(baseline, candidate, judged)
    metric = comparison.metrics["m"]
    assert [g.verdict for g in metric.groups] == [NOT_ENOUGH, NO_CHANGE, NOT_MEASURED]
    assert metric.verdict == NO_CHANGE
    f1 = comparison.metrics["detection.f1"]
    assert f1.verdict == NOT_MEASURED
    assert "no column 'detection.f1' in baseline" in f1.note
    typo = comparison.metrics["detection.f2"]
    assert typo.verdict == NOT_MEASURED
    assert "did you mean 'detection.f1'" in typo.note
    only_short = compare(column([1.0]), column([2.0]), tolerances(("m", "lower", 0.0)))
    assert only_short.metrics["m"].verdict == NOT_ENOUGH
    assert only_short.exit_status == 0


def test_runs_that_are_not_ok_are_left_out():
    baseline = [*column([1.0, 2.0, 3.0]), run(seed=3, status="error", m=None)]
    candidate = [*column([1.0, 2.0, 3.0]), run(seed=3, status="rejected", m=None),
                 run(seed=4, status="error", m=1e9)]
    comparison = compare(baseline, candidate, tolerances(("m", "lower", 0.0)))
    group = comparison.metrics["m"].groups[0]
    assert group.paired  # the ok runs all have partners
    assert (group.n_baseline, group.difference) == (3, 0.0)
    assert comparison.runs["candidate"] == {"ok": 3, "rejected": 1, "error": 1}


# --------------------------------------------------------------------------------------
# Pairing


def test_runs_pair_by_seed_and_drawn_values():
    judged = tolerances(("m", "lower", 0.0))
    same = [run(seed=s, vary={"mapper.gate": g}, m=float(s)) for s in (0, 1) for g in (0.1, 0.2)]
    shuffled = list(reversed(same))
    assert compare(same, shuffled, judged).metrics["m"].groups[0].paired
    other_draws = [{**row, "vary.mapper.gate": row["vary.mapper.gate"] + 0.05} for row in same]
    assert not compare(same, other_draws, judged).metrics["m"].groups[0].paired
    repeated = [run(seed=0, m=1.0), run(seed=0, m=2.0)]  # one key twice: no partners
    assert not compare(repeated, repeated, judged).metrics["m"].groups[0].paired


def test_a_pair_missing_the_metric_on_one_side_is_left_out_of_the_paired_test():
    baseline = column([1.0, 2.0, 3.0, 4.0])
    candidate = column([2.0, 3.0, None, 5.0])
    group = compare(baseline, candidate, tolerances(("m", "lower", 0.0))).metrics["m"].groups[0]
    assert group.paired
    assert (group.n_baseline, group.n_candidate) == (3, 3)
    assert group.baseline_mean == pytest.approx(7 / 3)  # seeds 0, 1, 3 only
    assert group.difference == pytest.approx(1.0)


# --------------------------------------------------------------------------------------
# Bad input


def test_different_result_formats_are_refused_naming_both_campaigns():
    with pytest.raises(SpecError, match="mismatched versions of the result format") as caught:
        compare(column([1.0]), column([1.0]), tolerances(("m", "lower", 0.0)),
                baseline_manifest={"format": 1}, candidate_manifest={"format": 2},
                baseline_name="runs/main", candidate_name="runs/branch")
    assert (caught.value.file, caught.value.key) == ("runs/branch", "format")
    assert "runs/main has 1" in str(caught.value)
    assert "runs/branch has 2" in str(caught.value)


def test_different_groups_are_refused_naming_them():
    baseline = column([1.0, 2.0], scenario="sim1") + column([1.0, 2.0], scenario="pal1")
    candidate = column([1.0, 2.0], scenario="sim1") + column([1.0, 2.0], policy="guarded")
    with pytest.raises(SpecError) as caught:
        compare(baseline, candidate, tolerances(("m", "lower", 0.0)),
                baseline_name="A", candidate_name="B")
    message = str(caught.value)
    assert caught.value.key == "groups"
    assert "only in A: pal1 / adaptive" in message
    assert "only in B: sim1 / guarded" in message


# --------------------------------------------------------------------------------------
# Reports


def report_comparison():
    data = np.random.default_rng(9)
    judged = tolerances(("table1_cm.mean.avg", "lower", 0.2), ("detection.f1", "higher", 0.02),
                        ("safety.stops", "lower", 1.0), ("safety.min_ttc_s", "higher", 0.2),
                        ("localization.rmse_xy_m", "lower", 0.005))
    baseline = [run(scenario=s, policy=p, seed=seed,
                    **{"table1_cm.mean.avg": data.normal(2.0, 0.1),
                       "detection.f1": data.normal(0.9, 0.01),
                       "safety.stops": float(data.integers(0, 3)),
                       "safety.min_ttc_s": None})
                for s in ("sim1", "pal1") for p in ("adaptive", "conservative")
                for seed in range(10)]
    candidate = [{**row, "table1_cm.mean.avg": row["table1_cm.mean.avg"] + 1.0,
                  "safety.stops": row["safety.stops"] + 3.0,
                  "detection.f1": row["detection.f1"] + data.normal(0, 0.001)}
                 for row in baseline]
    manifest = {"format": 1, "kind": "semistatic-campaign", "version": "0.1.0"}
    return compare(baseline, candidate, judged, baseline_manifest=manifest,
                   candidate_manifest={**manifest, "version": "0.2.0"},
                   baseline_name="runs/main", candidate_name="runs/branch")


def test_junit_xml_has_one_case_per_judged_metric_and_a_failure_per_regression():
    comparison = report_comparison()
    assert set(comparison.regressions) == {"table1_cm.mean.avg", "safety.stops"}
    text = comparison.junit_xml()
    assert ElementTree.fromstring(text).tag == "testsuite"  # one suite, not wrapped
    suites = list(JUnitXml.fromstring(text))
    assert len(suites) == 1
    xml = suites[0]
    assert isinstance(xml, TestSuite)
    assert xml.name == "semistatic compare"
    cases = {case.name: case for case in xml}
    assert list(cases) == ["runs.error", *comparison.metrics]
    assert all(case.classname == "semistatic.compare" for case in cases.values())
    outcomes = {name: [type(result) for result in case.result] for name, case in cases.items()}
    assert outcomes == {"runs.error": [], "table1_cm.mean.avg": [Failure], "detection.f1": [],
                        "safety.stops": [Failure], "safety.min_ttc_s": [Skipped],
                        "localization.rmse_xy_m": [Skipped]}
    assert (xml.tests, xml.failures, xml.errors, xml.skipped) == (6, 2, 0, 2)
    failure = cases["table1_cm.mean.avg"].result[0]
    assert "worse" in failure.message
    assert "sim1 / adaptive" in failure.text
    assert "no column 'localization.rmse_xy_m'" in cases["localization.rmse_xy_m"].result[0].message


def table_rows(lines):
    return [line for line in lines if line.startswith("|")]


def test_markdown_report_has_the_header_one_line_per_metric_and_details_of_changes():
    comparison = report_comparison()
    text = comparison.markdown()
    lines = text.splitlines()
    assert lines[0] == "# semistatic compare"
    assert "| campaign | `runs/main` | `runs/branch` |" in lines
    assert "| version | 0.1.0 | 0.2.0 |" in lines
    assert "| runs (ok / rejected / error) | 40 / 0 / 0 | 40 / 0 / 0 |" in lines
    assert any(line.startswith("alpha = 0.05 over ") for line in lines)
    assert "**Regressions: table1_cm.mean.avg, safety.stops**" in lines
    summary = [line for line in lines if line.startswith("| ") and line.split(" | ")[0][2:]
               in comparison.metrics]
    assert [line.split(" | ")[0][2:] for line in summary] == list(comparison.metrics)
    by_metric = {line.split(" | ")[0][2:]: line for line in summary}
    assert " | lower | worse | " in by_metric["table1_cm.mean.avg"]
    assert by_metric["table1_cm.mean.avg"].endswith(" | +1 [+1, +1] |")
    assert by_metric["safety.min_ttc_s"].endswith(" | not measured | - | - |")
    assert "no column 'localization.rmse_xy_m' in runs/main or runs/branch" in (
        by_metric["localization.rmse_xy_m"])
    headings = [line for line in lines if line.startswith("## ")]
    assert headings == ["## table1_cm.mean.avg: worse", "## safety.stops: worse"]
    # Every table row has as many cells as its header: a well-formed GitHub table.
    blocks = re.split(r"\n\s*\n", text)
    for block in blocks:
        rows = table_rows(block.splitlines())
        if rows:
            assert len({row.count("|") for row in rows}) == 1, block


def test_a_comparison_is_deterministic_for_a_seeded_generator():
    assert report_comparison().markdown() == report_comparison().markdown()
    assert report_comparison().junit_xml() == report_comparison().junit_xml()


def test_a_clean_comparison_says_no_regression():
    comparison = compare(column([1.0, 2.0, 3.0]), column([1.0, 2.0, 3.0]),
                         tolerances(("m", "lower", 0.0)))
    assert "**No regression.**" in comparison.markdown().splitlines()
    xml = JUnitXml.fromstring(comparison.junit_xml())
    assert (xml.tests, xml.failures, xml.skipped) == (2, 0, 0)  # runs.error and m


# --------------------------------------------------------------------------------------
# Tolerance files


def write(tmp_path, text, name="tolerances.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = 'format = 1\nalpha = 0.1\n[metrics."detection.f1"]\nbetter = "higher"\nmin_change = 0.02\n'


def test_a_tolerance_file_is_read(tmp_path):
    read = read_tolerances(write(tmp_path, GOOD))
    assert read.alpha == 0.1
    assert read.metrics == {"detection.f1": Tolerance("detection.f1", "higher", 0.02)}
    no_alpha = read_tolerances(write(tmp_path, GOOD.replace("alpha = 0.1\n", "")))
    assert no_alpha.alpha == 0.05


@pytest.mark.parametrize(
    ("text", "key", "fragment"),
    [
        (GOOD.replace("alpha", "alhpa"), "alhpa", "did you mean 'alpha'"),
        (GOOD.replace("min_change", "min_chnage"), 'metrics."detection.f1".min_chnage',
         "did you mean 'min_change'"),
        (GOOD.replace("0.02", "-0.5"), 'metrics."detection.f1".min_change', "must be >= 0.0"),
        (GOOD.replace("0.02", '"big"'), 'metrics."detection.f1".min_change', "expected a number"),
        (GOOD.replace('"higher"', '"up"'), 'metrics."detection.f1".better',
         "must be 'lower' or 'higher'"),
        (GOOD.replace('"higher"', "1"), 'metrics."detection.f1".better', "expected a string"),
        (GOOD.replace("min_change = 0.02\n", ""), 'metrics."detection.f1".min_change',
         "missing required key"),
        (GOOD.replace("alpha = 0.1", "alpha = 0.7"), "alpha", "<= 0.5"),
        (GOOD.replace("alpha = 0.1", "alpha = 0"), "alpha", "> 0.0"),
        (GOOD.replace("alpha = 0.1", "alpha = nan"), "alpha", "finite"),
        (GOOD.replace("format = 1", "format = 2"), "format", "unsupported format 2"),
        (GOOD.replace("format = 1\n", ""), "format", "missing required key"),
        ("format = 1\nmetrics = 3\n", "metrics", "expected a table"),
        ('format = 1\n[metrics]\n"detection.f1" = 0.02\n', 'metrics."detection.f1"',
         "expected a table"),
        ("format = 1\n", "metrics", "no metric to judge"),
        ("format = 1\n[metrics.\n", "line 2, column 10", "not valid TOML"),
    ],
)
def test_bad_tolerance_files_are_refused_naming_file_and_key(tmp_path, text, key, fragment):
    path = write(tmp_path, text)
    with pytest.raises(SpecError) as caught:
        read_tolerances(path)
    assert (caught.value.file, caught.value.key) == (str(path), key)
    assert fragment in caught.value.message
    assert str(caught.value).startswith(f"{path}: {key}: ")


def test_a_missing_tolerance_file_is_refused(tmp_path):
    with pytest.raises(SpecError, match="no such file"):
        read_tolerances(tmp_path / "missing.toml")


def test_tolerance_objects_validate_themselves():
    with pytest.raises(SpecError, match="better: must be 'lower' or 'higher'"):
        Tolerance("m", "smaller", 1.0)
    with pytest.raises(SpecError, match=r"min_change: must be >= 0\.0"):
        Tolerance("m", "lower", -0.1)
    with pytest.raises(SpecError, match="min_change: must be a finite number"):
        Tolerance("m", "lower", math.inf)
    with pytest.raises(SpecError, match="holds the tolerance of 'n'"):
        Tolerances(0.05, {"m": Tolerance("n", "lower", 0.0)})


def test_the_bundled_tolerances_judge_the_documented_metrics():
    bundled = default_tolerances()
    assert DEFAULT_TOLERANCES.is_file()
    assert bundled.alpha == 0.05
    assert set(bundled.metrics) == {
        "table1_cm.mean.avg", "table1_cm.mean.min", "table1_cm.mean.max", "table1_cm.std.avg",
        "detection.precision", "detection.recall", "detection.f1",
        "detection.false_objects_from_people", "localization.rmse_xy_m", "safety.collisions",
        "safety.laps_completed", "safety.total_time_s", "safety.stops",
        "safety.min_separation_m.person", "safety.min_separation_m.box", "safety.min_ttc_s",
    }
    # NEES is best closest to 3 and timings measure the machine: neither is judged.
    assert "localization.nees_mean" not in bundled.metrics
    assert not any(name.startswith("performance.") for name in bundled.metrics)
    higher = {name for name, t in bundled.metrics.items() if t.better == "higher"}
    assert higher == {"detection.precision", "detection.recall", "detection.f1",
                      "safety.laps_completed", "safety.min_separation_m.person",
                      "safety.min_separation_m.box", "safety.min_ttc_s"}


# --------------------------------------------------------------------------------------
# The command


def write_campaign(folder, rows, version="0.1.0", fmt=1):
    from scenarios.campaign.table import write_runs

    folder.mkdir(parents=True)
    write_runs(rows, folder)
    manifest = {"format": fmt, "kind": "semistatic-campaign", "version": version,
                "command": ["semistatic", "campaign"], "scenarios": ["sim1"],
                "policies": ["adaptive"], "seeds": list(range(10)), "laps": 1, "samples": 1,
                "vary": {}}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def command(*argv):
    parser = argparse.ArgumentParser(prog="semistatic")
    add_parser(parser.add_subparsers(dest="command"))
    return main_compare(parser.parse_args(["compare", *map(str, argv)]))


@pytest.fixture
def campaigns(tmp_path):
    rows = [run(seed=seed, **{"table1_cm.mean.avg": 2.0 + seed / 100, "detection.f1": 0.9})
            for seed in range(10)]
    worse = [{**row, "table1_cm.mean.avg": row["table1_cm.mean.avg"] + 1.0} for row in rows]
    return (write_campaign(tmp_path / "main", rows), write_campaign(tmp_path / "same", rows),
            write_campaign(tmp_path / "worse", worse, version="0.2.0"))


def test_the_command_exits_0_without_and_1_with_a_regression(campaigns, capsys):
    main, same, worse = campaigns
    assert command(main, same) == 0
    assert "**No regression.**" in capsys.readouterr().out
    assert command(main, worse) == 1
    out = capsys.readouterr().out
    assert "**Regressions: table1_cm.mean.avg**" in out
    assert f"| campaign | `{main}` | `{worse}` |" in out


def test_the_command_writes_junit_and_markdown_atomically(campaigns, tmp_path, capsys):
    main, _, worse = campaigns
    junit, markdown = tmp_path / "reports" / "new" / "compare.xml", tmp_path / "compare.md"
    assert command(main, worse, "--junit", junit, "--markdown", markdown) == 1
    printed = capsys.readouterr().out
    assert markdown.read_text() == printed
    xml = JUnitXml.fromstring(junit.read_text())
    assert (xml.tests, xml.failures) == (1 + len(default_tolerances().metrics), 1)
    leftovers = [p.name for p in (*junit.parent.iterdir(), *tmp_path.iterdir())
                 if p.name.startswith(".")]
    assert leftovers == []


def test_the_command_refuses_bad_targets_and_campaigns_before_writing(campaigns, tmp_path):
    main, same, _ = campaigns
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(SpecError) as caught:
        command(main, same, "--junit", blocker / "compare.xml")
    assert caught.value.file == "--junit"
    with pytest.raises(SpecError) as caught:
        command(main, same, "--markdown", tmp_path)
    assert (caught.value.file, caught.value.message) == ("--markdown", "is a directory; name "
                                                                       "a file")
    report = tmp_path / "report.md"
    with pytest.raises(SpecError) as caught:
        command(main, tmp_path / "nowhere", "--markdown", report)
    assert caught.value.file == "CANDIDATE"
    assert not report.exists()
    newer = write_campaign(tmp_path / "newer", [run(seed=0, m=1.0)], fmt=2)
    with pytest.raises(SpecError, match="mismatched versions of the result format") as caught:
        command(main, newer)
    assert str(main) in str(caught.value)
    assert str(newer) in str(caught.value)


def test_the_command_reads_a_tolerance_file(campaigns, tmp_path, capsys):
    main, _, worse = campaigns
    loose = tmp_path / "loose.toml"
    loose.write_text('format = 1\n[metrics."table1_cm.mean.avg"]\nbetter = "lower"\n'
                     "min_change = 5.0\n")
    assert command(main, worse, "--tolerance", loose) == 0
    assert "**No regression.**" in capsys.readouterr().out
    with pytest.raises(SpecError) as caught:
        command(main, worse, "--tolerance", tmp_path / "none.toml")
    assert caught.value.file == str(tmp_path / "none.toml")


def test_tolerance_file_paths_in_errors_are_the_given_ones(tmp_path):
    path = Path(write(tmp_path, GOOD.replace('"higher"', '"more"')))
    with pytest.raises(SpecError) as caught:
        command(tmp_path, tmp_path, "--tolerance", path)
    assert str(caught.value) == (f"{path}: metrics.\"detection.f1\".better: must be 'lower' "
                                 "or 'higher', got 'more'")


def test_a_candidate_whose_runs_raise_is_a_regression_even_without_metrics():
    rows = column([1.0, 2.0, 3.0])
    crashed = [{**row, "status": "error", "m": None} for row in rows]
    comparison = compare(rows, crashed, tolerances(("m", "lower", 0.0)))
    assert comparison.metrics["m"].verdict == "not measured"
    assert comparison.regressions == ("runs.error",)
    assert comparison.exit_status == 1
    group = comparison.errors.groups[0]
    assert (group.baseline_mean, group.candidate_mean) == (0.0, 3.0)
    xml = JUnitXml.fromstring(comparison.junit_xml())
    assert (xml.tests, xml.failures, xml.skipped) == (2, 1, 1)
