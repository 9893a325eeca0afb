import numpy as np
import pytest
import shapely

from semistatic.frames import inverse
from semistatic.polyline import EMPTY_BOX, Polyline, as_polyline, pack_vertices, run_boxes


def test_defaults_and_dtypes():
    line = Polyline([[0, 0], [3, 4]])
    assert line.points.dtype == np.float64
    assert line.scan_indices.dtype == np.int64
    np.testing.assert_array_equal(line.scan_indices, [0, 1])
    assert len(line) == 2
    assert line.length == pytest.approx(5.0)


def test_arrays_are_read_only_and_caller_array_untouched():
    points = np.array([[0.0, 0.0], [1.0, 0.0]])
    line = Polyline(points, scan_indices=np.array([4, 9]))
    with pytest.raises(ValueError, match="read-only"):
        line.points[0, 0] = 5.0
    with pytest.raises(ValueError, match="read-only"):
        line.scan_indices[0] = 1
    points[0, 0] = 7.0  # the caller's array stays writeable and is not shared
    assert line.points[0, 0] == 0.0


@pytest.mark.parametrize(
    ("points", "indices", "message"),
    [
        ([[0, 0, 0]], None, r"shape \(N, 2\)"),
        ([0.0, 1.0], None, r"shape \(N, 2\)"),
        ([[0, 0], [np.inf, 0]], None, "finite"),
        ([[0, 0], [1, 0]], [1], "one scan index per vertex"),
        ([[0, 0], [1, 0]], [0.5, 1.5], "integers"),
    ],
)
def test_invalid_input_is_rejected_with_a_clear_message(points, indices, message):
    with pytest.raises(ValueError, match=message):
        Polyline(points, scan_indices=indices)


def test_nasty_polylines_construct(nasty_polyline):
    line = as_polyline(nasty_polyline)
    assert len(line) == nasty_polyline.shape[0]
    assert line.points.shape == (len(line), 2)
    assert line.length >= 0.0
    assert np.isfinite(line.length)
    assert line.edge_lengths.shape == (max(len(line) - 1, 0),)


def test_length_counts_repeated_vertices_as_zero():
    assert Polyline([[0, 0], [0, 0], [0, 2], [2, 2]]).length == pytest.approx(4.0)


def test_transformed_moves_points_and_keeps_indices():
    line = Polyline([[1.0, 0.0], [2.0, 0.0]], scan_indices=[3, 8])
    pose = np.array([1.0, -2.0, np.pi / 2])
    moved = line.transformed(pose)
    np.testing.assert_allclose(moved.points, [[1.0, -1.0], [1.0, 0.0]], atol=1e-12)
    np.testing.assert_array_equal(moved.scan_indices, [3, 8])
    back = moved.transformed(inverse(pose))
    np.testing.assert_allclose(back.points, line.points, atol=1e-12)
    assert moved.length == pytest.approx(line.length)


def test_as_polyline_passes_polylines_through_and_wraps_arrays():
    line = Polyline([[0, 0], [1, 1]])
    assert as_polyline(line) is line
    wrapped = as_polyline(np.array([[0, 0], [1, 1]]))
    assert isinstance(wrapped, Polyline)
    np.testing.assert_array_equal(wrapped.points, line.points)
    assert len(as_polyline([])) == 0


def test_run_boxes_are_the_bounds_of_each_run():
    rng = np.random.default_rng(3)
    runs = [rng.normal(size=(int(rng.integers(0, 4)), 2)) for _ in range(30)]
    points, offsets = pack_vertices(runs)
    boxes = run_boxes(points, offsets)
    for run, box in zip(runs, boxes.tolist(), strict=True):
        if len(run) == 0:
            assert tuple(box) == EMPTY_BOX
        else:
            assert box == shapely.bounds(shapely.multipoints(run)).tolist()
