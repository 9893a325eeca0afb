import pickle

import numpy as np
import pytest
import shapely

from semistatic.frames import inverse
from semistatic.polyline import EMPTY_BOX, PackedPolylines, Polyline, as_polyline, as_polylines


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


def test_reversed_runs_backwards_and_keeps_the_indices_with_their_vertices():
    line = Polyline([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]], scan_indices=[4, 5, 9])
    back = line.reversed()
    np.testing.assert_array_equal(back.points, line.points[::-1])
    np.testing.assert_array_equal(back.scan_indices, [9, 5, 4])
    assert back.length == line.length
    assert not back.points.flags.writeable
    assert len(Polyline(np.empty((0, 2))).reversed()) == 0


def test_packed_boxes_are_the_bounds_of_each_polyline():
    rng = np.random.default_rng(3)
    runs = [rng.normal(size=(int(rng.integers(0, 4)), 2)) for _ in range(30)]
    lines = PackedPolylines(runs)
    for run, box in zip(runs, lines.boxes.tolist(), strict=True):
        if len(run) == 0:
            assert tuple(box) == EMPTY_BOX
        else:
            assert box == shapely.bounds(shapely.multipoints(run)).tolist()


def test_packed_polylines_hold_their_vertices_and_scan_indices_packed():
    first, second = Polyline([[0.0, 0.0], [1.0, 0.0]], [3, 7]), Polyline([[2.0, 2.0]], [1])
    lines = as_polylines([first, second, []])
    assert lines[0] is first
    assert lines[1] is second
    assert len(lines[2]) == 0
    np.testing.assert_array_equal(lines.points, [[0.0, 0.0], [1.0, 0.0], [2.0, 2.0]])
    np.testing.assert_array_equal(lines.offsets, [0, 2, 3, 3])
    np.testing.assert_array_equal(lines.scan_indices, [3, 7, 1])
    assert as_polylines(lines) is lines
    assert len(as_polylines([])) == 0
    assert as_polylines([]).points.shape == (0, 2)


def test_polylines_from_runs_are_views_of_one_read_only_copy():
    points = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 2.0], [3.0, 2.0], [4.0, 2.0]])
    lines = PackedPolylines.from_runs(points, [0, 2, 2, 5], [9, 8, 1, 2, 3])
    assert [len(line) for line in lines] == [2, 0, 3]
    np.testing.assert_array_equal(lines[2].points, points[2:])
    np.testing.assert_array_equal(lines[2].scan_indices, [1, 2, 3])
    assert lines.points is points  # the kernels' array, taken over
    assert not lines[0].points.flags.writeable
    assert not np.shares_memory(lines[0].points, points)
    default = PackedPolylines.from_runs(points.copy(), [0, 2, 5])
    assert [line.scan_indices.tolist() for line in default] == [[0, 1], [0, 1, 2]]


@pytest.mark.parametrize(
    ("points", "offsets", "indices", "message"),
    [
        ([[0.0, np.nan]], [0, 1], None, "finite"),
        ([[0.0, 0.0], [1.0, 0.0]], [0, 1], None, "offsets from 0 to N"),
        ([[0.0, 0.0], [1.0, 0.0]], [0, 2, 1, 2], None, "decrease"),
        ([[0.0, 0.0], [1.0, 0.0]], [0, 2], [4], "one scan index per vertex"),
    ],
)
def test_runs_that_make_no_polylines_are_rejected(points, offsets, indices, message):
    with pytest.raises(ValueError, match=message):
        PackedPolylines.from_runs(np.array(points), offsets, indices)


def test_packed_polylines_are_read_only_compare_as_sequences_and_pickle():
    lines = PackedPolylines([[[0.0, 0.0], [1.0, 0.0]], [[2.0, 0.0]]])
    for change in (lambda: lines.append(lines[0]), lambda: lines.pop(), lines.clear,
                   lambda: lines.__setitem__(0, lines[1]), lambda: lines.__delitem__(0)):
        with pytest.raises(TypeError, match="read-only"):
            change()
    assert lines == tuple(lines)
    assert tuple(lines) == lines
    assert lines == list(lines)
    assert lines != (lines[0],)
    assert PackedPolylines() == ()
    copy = pickle.loads(pickle.dumps(lines))
    assert isinstance(copy, PackedPolylines)
    assert len(copy) == 2
    np.testing.assert_array_equal(copy.points, lines.points)
    np.testing.assert_array_equal(copy.offsets, lines.offsets)


def _made_by_hand(lines, indices, flips):
    """The polylines ``take`` must give: picked one by one, reversed ones by reversing rows."""
    return [
        (lines[k].points[::-1], lines[k].scan_indices[::-1]) if flip
        else (lines[k].points, lines[k].scan_indices)
        for k, flip in zip(indices, flips, strict=True)
    ]


def test_take_gathers_runs_in_order_reversing_the_flagged_ones():
    lines = PackedPolylines([
        Polyline([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], [4, 5, 6]),
        Polyline([[5.0, 5.0]], [9]),
        Polyline([[2.0, 0.0], [3.0, 1.0]], [1, 2]),
    ])
    indices, flips = [2, 0, 0, 1], [True, False, True, False]
    taken = lines.take(indices, reverse=flips)
    expected = _made_by_hand(lines, indices, flips)
    np.testing.assert_array_equal(taken.points, np.concatenate([p for p, _ in expected]))
    np.testing.assert_array_equal(taken.offsets, [0, 2, 5, 8, 9])
    assert len(taken) == 4
    for line, (points, indices_expected) in zip(taken, expected, strict=True):
        np.testing.assert_array_equal(line.points, points)
        np.testing.assert_array_equal(line.scan_indices, indices_expected)
    assert taken[1] is lines[0]  # not reversed: the very polyline
    np.testing.assert_array_equal(taken.scan_indices, [2, 1, 4, 5, 6, 6, 5, 4, 9])
    assert len(lines.take([])) == 0
    with pytest.raises(IndexError, match="indices in"):
        lines.take([3])
    with pytest.raises(IndexError, match="one reverse flag"):
        lines.take([0, 1], reverse=[True])


@pytest.mark.parametrize("indices", [[1, 2], np.array([0, 1]), [np.int64(1)], (2,)])
def test_take_of_consecutive_polylines_equals_them_picked_one_by_one(indices):
    lines = PackedPolylines([
        Polyline([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], [4, 5, 6]),
        Polyline([[5.0, 5.0]], [9]),
        Polyline([[2.0, 0.0], [3.0, 1.0]], [1, 2]),
    ])
    picked = [int(k) for k in indices]
    taken = lines.take(indices)
    expected = _made_by_hand(lines, picked, [False] * len(picked))
    np.testing.assert_array_equal(taken.points, np.concatenate([p for p, _ in expected]))
    np.testing.assert_array_equal(
        taken.offsets, np.cumsum([0] + [len(lines[k]) for k in picked])
    )
    # The one layout the kernels are compiled for.
    assert taken.points.flags.c_contiguous
    assert taken.points.dtype == np.float64
    assert taken.offsets.dtype == np.int64
    assert all(line is lines[k] for line, k in zip(taken, picked, strict=True))
    for bad in ([0.5], ["a"], [[0, 1]]):
        with pytest.raises(IndexError, match="integer indices"):
            lines.take(bad)


def test_from_runs_checks_shapes_and_offsets_without_the_finiteness_check():
    points = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert len(PackedPolylines.from_runs(points, [0, 2], check_finite=False)) == 1
    with pytest.raises(ValueError, match="offsets from 0 to N"):
        PackedPolylines.from_runs(points, [0, 1], check_finite=False)
    with pytest.raises(ValueError, match="decrease"):
        PackedPolylines.from_runs(points, [0, 2, 1, 2], check_finite=False)


@pytest.mark.parametrize("make", ["from_runs", "take"])
def test_sets_whose_polylines_are_made_late_behave_as_lists_of_them(make):
    points = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 2.0], [3.0, 2.0], [4.0, 2.0]])
    if make == "from_runs":
        def fresh():
            return PackedPolylines.from_runs(points.copy(), [0, 2, 5])
    else:
        source = PackedPolylines([points[:2], points[2:]])

        def fresh():
            return source.take([0, 1])
    reference = list(fresh())  # what a look at the elements makes
    assert len(fresh()) == 2  # no element needed
    assert fresh()
    checks = [
        lambda s: [line.points.tolist() for line in s]
        == [line.points.tolist() for line in reference],
        lambda s: s[1].points.tolist() == points[2:].tolist(),
        lambda s: s[-1].points.tolist() == points[2:].tolist(),
        lambda s: [line.points.tolist() for line in s[0:1]] == [points[:2].tolist()],
        lambda s: [line.points.tolist() for line in reversed(s)]
        == [points[2:].tolist(), points[:2].tolist()],
        lambda s: s == list(s) and list(s) == s and s == tuple(s) and tuple(s) == s,
        lambda s: s[0] in s and s.index(s[1]) == 1 and s.count(s[0]) == 1,
        lambda s: len(s + [None]) == 3 and len(s * 2) == 4,  # noqa: RUF005 - list's + on the set
        lambda s: len([None, *s]) == 3,
        lambda s: repr(s).startswith("[Polyline(2 vertices"),
        lambda s: len(pickle.loads(pickle.dumps(s))) == 2,
        lambda s: s.copy() == list(s),
    ]
    for check in checks:
        packed = fresh()  # each check is the first look at a fresh set
        assert isinstance(packed, PackedPolylines)
        assert check(packed)
        assert type(packed) is PackedPolylines  # looked into, it is a plain set from then on
    untouched = fresh()
    np.testing.assert_array_equal(untouched.points, points)  # kernels read it as it is
    np.testing.assert_array_equal(untouched.boxes, [[0.0, 0.0, 1.0, 0.0], [2.0, 2.0, 4.0, 2.0]])
