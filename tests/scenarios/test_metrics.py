"""Metrics on hand-made inputs: each number is checked against what it must be."""

from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from scenarios.bench.ground_truth import (
    clip_to_area,
    detection_scores,
    match_polylines_to_boxes,
    score_lap,
)
from scenarios.results.metrics import ekf_correction_metrics, localization_metrics, table1_cm
from semistatic.polyline import Polyline

BOX = np.array([[1.0, -1.0], [2.0, -1.0], [2.0, -0.5], [1.0, -0.5]])


class FakeMap:
    def __init__(self, *lines):
        self.lines = [Polyline(np.asarray(line, dtype=float)) for line in lines]

    def world_polylines(self):
        return dict(enumerate(self.lines))


AREA = shapely.box(0.0, -1.5, 4.0, 1.5)


def segment(name="s", area=AREA):
    return SimpleNamespace(name=name, safety_area_world=area)


def test_box_face_is_a_true_positive_and_a_stray_line_a_false_one():
    maps = {"s": FakeMap([[1.0, -0.51], [2.0, -0.49]], [[3.0, 1.0], [3.5, 1.2]])}
    scores, from_people = score_lap(maps, [segment()], {"box": BOX})
    assert (scores["tp"], scores["fp"], scores["fn"]) == (1, 1, 0)
    assert scores["precision"] == 0.5
    assert scores["recall"] == 1.0
    assert from_people == 0


def test_missing_box_is_a_false_negative_and_empty_map_is_precise():
    scores, _ = score_lap({"s": FakeMap()}, [segment()], {"box": BOX})
    assert (scores["tp"], scores["fp"], scores["fn"]) == (0, 0, 1)
    assert scores["precision"] == 1.0
    assert scores["recall"] == 0.0
    assert scores["f1"] == 0.0


def test_box_outside_the_safety_area_is_not_expected():
    far_area = shapely.box(10.0, 10.0, 12.0, 12.0)
    scores, _ = score_lap({"s": FakeMap()}, [segment(area=far_area)], {"box": BOX})
    assert scores["fn"] == 0


def test_wall_continuation_outside_the_area_does_not_spoil_a_box_face():
    # One polyline: the box's face in the area, then on along a wall far outside it.
    line = [[1.0, -0.5], [2.0, -0.5], [2.2, -3.0], [6.0, -3.0]]
    area = shapely.box(0.0, -0.8, 4.0, 1.5)
    scores, _ = score_lap({"s": FakeMap(line)}, [segment(area=area)], {"box": BOX})
    assert (scores["tp"], scores["fp"]) == (1, 0)


def test_false_polyline_where_a_person_walked_is_counted():
    maps = {"s": FakeMap([[3.0, 0.9], [3.2, 1.0]])}
    track = [[3.1, 1.1], [3.1, 0.0]]
    scores, from_people = score_lap(maps, [segment()], {"box": BOX}, track)
    assert scores["fp"] == 1
    assert from_people == 1


def test_clip_keeps_points_inside_and_drops_outside():
    area = shapely.box(0.0, 0.0, 1.0, 1.0)
    assert clip_to_area([[0.5, 0.5]], area).shape == (1, 2)
    assert clip_to_area([[5.0, 5.0]], area).shape == (0, 2)
    assert clip_to_area([[5.0, 5.0], [6.0, 5.0]], area).shape == (0, 2)


def test_match_requires_the_whole_polyline_on_the_outline():
    face = [[1.0, -0.5], [2.0, -0.5]]
    face_and_more = [[1.0, -0.5], [2.0, -0.5], [2.5, 0.0]]
    matches = match_polylines_to_boxes([face, face_and_more], {"box": BOX})
    assert matches[:, 0].tolist() == [True, False]


def test_detection_scores_handle_nothing_expected_nothing_found():
    assert detection_scores(0, 0, 0)["f1"] == 1.0


def test_table1_averages_per_polyline_statistics_in_cm():
    table = table1_cm({"a": [0.01] * 5, "b": [0.03, 0.05] * 3, "c": [0.5]}, min_samples=5)
    assert table["polylines"] == 2
    assert table["mean"] == {"avg": 2.5, "min": 1.0, "max": 4.0}
    assert table["std"]["min"] == 0.0
    assert table["std"]["max"] == pytest.approx(1.0)


def test_table1_without_samples_reports_none():
    assert table1_cm({})["mean"] == {"avg": None, "min": None, "max": None}


def test_localization_nees_is_three_for_a_consistent_filter():
    rng = np.random.default_rng(0)
    cov = np.diag([1e-4, 4e-4, 1e-5])
    errors = rng.multivariate_normal(np.zeros(3), cov, size=20000)
    covariances = np.broadcast_to(cov, (20000, 3, 3))
    metrics = localization_metrics(np.zeros((20000, 3)), errors, covariances)
    assert metrics["nees_mean"] == pytest.approx(3.0, rel=0.05)
    assert metrics["max_sigma_xy_m"] == pytest.approx(0.02)


def test_ekf_correction_statistics_leave_the_lap_start_jumps_out():
    rng = np.random.default_rng(2)
    sigmas = np.tile([0.002, 0.002, 0.004], (500, 1))
    corrections = rng.normal(0.0, sigmas)
    restarts = np.zeros(500, dtype=bool)
    restarts[[0, 125, 250, 375]] = True
    corrections[restarts] = [[3.0, -2.0, 1.5]] * 4  # carried back to the start: metres
    stats = ekf_correction_metrics(corrections, sigmas, restarts)
    assert (stats["updates"], stats["relocalizations"]) == (496, 4)
    # Gaussian corrections: RMS near sigma, ~68 % within 1 sigma, ~99.7 % within 3.
    np.testing.assert_allclose(stats["rms"], [0.002, 0.002, 0.004], rtol=0.1)
    assert all(0.62 < share < 0.74 for share in stats["within_1_sigma"])
    assert all(share > 0.98 for share in stats["within_3_sigma"])
    with_jumps = ekf_correction_metrics(corrections, sigmas)
    assert with_jumps["rms"][0] > 0.2  # what the figure used to show
