"""PLE's published per-log figures: the table's shape and reading it at our vertex count."""

import pytest

from semistatic.published import (
    PLE_PUBLISHED,
    PLE_VERTEX_COUNTS,
    PublishedCurve,
    published_log,
    published_rmse,
)


def test_every_log_has_a_curve_per_method_falling_with_more_vertices():
    assert set(PLE_PUBLISHED) == {"intel", "aces", "freiburg-079", "csail"}
    for curve in PLE_PUBLISHED.values():
        for values in (curve.ple_plus, curve.ple):
            assert list(values) == sorted(values, reverse=True)
        # PLE+ refines PLE's vertices: never worse (the paper's Fig. 4a)
        assert all(plus <= ple for plus, ple in zip(curve.ple_plus, curve.ple, strict=True))
        assert all(0.0 < f <= 1.0 for f in curve.coverage)


@pytest.mark.parametrize(
    ("log", "vertices", "method", "expected_cm"),
    [
        ("aces", 24.8, "PLE+", 5.47 + 0.48 * (3.87 - 5.47)),  # by hand, between J 20 and 30
        ("intel", 34.0, "PLE+", 2.16 + 0.4 * (1.30 - 2.16)),
        ("freiburg-079", 80.9, "PLE+", 3.25),  # more than J = 50: its J = 50 figure
        ("csail", 10.0, "PLE", 10.18),
        ("csail", 4.0, "PLE", 10.18),
    ],
)
def test_published_rmse_interpolates_between_the_published_vertex_counts(
    log, vertices, method, expected_cm
):
    assert 100 * published_rmse(log, vertices, method) == pytest.approx(expected_cm)


@pytest.mark.parametrize(
    ("args", "message"),
    [(("kitchen", 20.0), "unknown log"), (("intel", 20.0, "VB"), "method"),
     (("intel", 0.0), "vertices_per_scan"), (("intel", float("nan")), "vertices_per_scan")],
)
def test_published_rmse_rejects_bad_arguments(args, message):
    with pytest.raises(ValueError, match=message):
        published_rmse(*args)


def test_published_log_names_carmen_files():
    assert published_log("intel-corrected") == "intel"
    assert published_log("csail-robotlaser1-corrected") == "csail"
    assert published_log("ACES") == "aces"
    assert published_log("intellab") is None


def test_curve_needs_one_value_per_vertex_count():
    with pytest.raises(ValueError, match="ple needs"):
        PublishedCurve(ple_plus=(0.1,) * len(PLE_VERTEX_COUNTS), ple=(0.1,),
                       coverage=(1.0,) * len(PLE_VERTEX_COUNTS))
