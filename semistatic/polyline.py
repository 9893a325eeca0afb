"""The polyline: an ordered vertex list that remembers which laser beams it came from.

A polyline is an ``(N, 2)`` float64 vertex array plus the scan index of each vertex
(docs/design.md, Conventions). The restricted Hausdorff distance and the merge rely on the
vertex order, and scan polylines run counter-clockwise around the viewpoint. Both arrays
are read-only, so a ``Polyline`` can be shared and its derived quantities cached. Many
polylines travel together as :class:`PackedPolylines`: a read-only list of them that also
keeps all their vertices packed in one array for the compiled kernels.

Examples
--------
>>> line = Polyline([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])
>>> len(line), line.length, line.scan_indices
(3, 6.0, array([0, 1, 2]))
>>> as_polyline(line) is line
True
>>> as_polylines([line, [[5.0, 0.0], [6.0, 0.0]]]).offsets
array([0, 3, 5])
"""

from __future__ import annotations

import itertools
import math
import operator
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np
from numpy.typing import ArrayLike

from semistatic.frames import transform_points

__all__ = [
    "EMPTY_BOX",
    "PackedPolylines",
    "Polyline",
    "as_polyline",
    "as_polylines",
    "run_offsets",
]

EMPTY_BOX = (np.inf, np.inf, -np.inf, -np.inf)
"""The bounding box of no points: farther than anything from everything."""


def _read_only(array: np.ndarray) -> np.ndarray:
    # Never freeze the caller's own array: copy when it is still writeable.
    if array.flags.writeable:
        array = array.copy()
        array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Polyline:
    """An ordered 2D polyline with the scan (beam) index of every vertex.

    Parameters
    ----------
    points
        ``(N, 2)`` vertices in metres, in traversal order (for scan polylines: counter-
        clockwise around the viewpoint). Stored as a read-only float64 array. ``N`` may be
        0 or 1: the metrics document how they treat such degenerate polylines.
    scan_indices
        ``(N,)`` integer index of the beam (or of the merged beam position) of each
        vertex; defaults to ``arange(N)``. Stored read-only as int64.

    Examples
    --------
    >>> Polyline([[0, 0], [1, 0]], scan_indices=[10, 42]).scan_indices
    array([10, 42])
    >>> Polyline([[0, 0], [np.nan, 0]])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: Polyline: points must be finite ...
    """

    points: np.ndarray
    scan_indices: np.ndarray | None = None

    def __post_init__(self) -> None:
        points = np.asarray(self.points, dtype=np.float64)
        if points.size == 0:
            points = points.reshape(0, 2)
        if points.ndim != 2 or points.shape[1] != 2:
            raise ValueError(
                f"Polyline: points must have shape (N, 2), got {points.shape}; "
                "pass one (x, y) row per vertex"
            )
        if not np.isfinite(points).all():
            raise ValueError(
                "Polyline: points must be finite (no nan/inf); drop invalid laser "
                "readings before building a polyline"
            )
        if self.scan_indices is None:
            indices = np.arange(points.shape[0], dtype=np.int64)
        else:
            indices = np.asarray(self.scan_indices).reshape(-1)
            if indices.size and not np.issubdtype(indices.dtype, np.integer):
                raise ValueError(
                    f"Polyline: scan_indices must be integers, got dtype {indices.dtype}"
                )
            indices = indices.astype(np.int64, copy=False)
            if indices.shape[0] != points.shape[0]:
                raise ValueError(
                    f"Polyline: scan_indices has {indices.shape[0]} entries but points has "
                    f"{points.shape[0]} rows; pass one scan index per vertex"
                )
        object.__setattr__(self, "points", _read_only(points))
        object.__setattr__(self, "scan_indices", _read_only(indices))

    @classmethod
    def _view(cls, points: np.ndarray, scan_indices: np.ndarray) -> Polyline:
        """Wrap read-only arrays already known valid, without the checks (this module only).

        ``points`` must be a finite read-only ``(N, 2)`` float64 array and ``scan_indices``
        a read-only ``(N,)`` int64 array (views of frozen arrays, typically).
        """
        line = object.__new__(cls)
        # The frozen dataclass's fields, set item by item: as __init__ would without its
        # checks, and cheaper than an update with keywords (once per polyline of a scan).
        state = line.__dict__
        state["points"], state["scan_indices"] = points, scan_indices
        return line

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def __repr__(self) -> str:
        return f"Polyline({len(self)} vertices, length={self.length:.3f} m)"

    @cached_property
    def box(self) -> tuple[float, float, float, float]:
        """Return the axis-aligned bounding box ``(xmin, ymin, xmax, ymax)`` (Python floats).

        An empty polyline has the empty box ``(inf, inf, -inf, -inf)``.

        Examples
        --------
        >>> Polyline([[0.0, 1.0], [2.0, -1.0]]).box
        (0.0, -1.0, 2.0, 1.0)
        """
        if self.points.shape[0] == 0:
            return EMPTY_BOX
        xs, ys = self.points.T.tolist()
        return (min(xs), min(ys), max(xs), max(ys))

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """Return the ``(N - 1,)`` edge lengths (read-only; empty for N < 2).

        Examples
        --------
        >>> Polyline([[0, 0], [0, 2], [0, 2]]).edge_lengths
        array([2., 0.])
        """
        lengths = np.hypot(*np.diff(self.points, axis=0).T)
        lengths.flags.writeable = False
        return lengths

    @property
    def length(self) -> float:
        """Return the arc length in metres (0 for fewer than two vertices).

        Examples
        --------
        >>> Polyline([[0, 0], [1, 0], [1, 1]]).length
        2.0
        """
        return float(self.edge_lengths.sum())

    def reversed(self) -> Polyline:
        """Return the polyline traversed the other way (its scan indices reversed too).

        Examples
        --------
        >>> backwards = Polyline([[0.0, 0.0], [1.0, 0.0]], scan_indices=[3, 8]).reversed()
        >>> backwards.points.tolist(), backwards.scan_indices.tolist()
        ([[1.0, 0.0], [0.0, 0.0]], [8, 3])
        """
        # Views of valid read-only arrays: nothing to check or copy.
        return Polyline._view(self.points[::-1], self.scan_indices[::-1])

    def transformed(self, pose: ArrayLike) -> Polyline:
        """Return the polyline mapped from the frame of ``pose`` into its parent frame.

        The scan indices are kept, e.g. to move a scan polyline from the sensor frame into
        the map frame with the sensor pose.

        Examples
        --------
        >>> moved = Polyline([[1.0, 0.0]], scan_indices=[7]).transformed([0.0, 1.0, np.pi / 2])
        >>> moved.points.round(12), moved.scan_indices
        (array([[0., 2.]]), array([7]))
        """
        return Polyline(transform_points(pose, self.points), self.scan_indices)


def as_polyline(obj: Polyline | ArrayLike) -> Polyline:
    """Return ``obj`` as a :class:`Polyline` (a ``Polyline`` passes through unchanged).

    Parameters
    ----------
    obj
        A ``Polyline`` or an ``(N, 2)`` array-like of vertices (scan indices ``0..N-1``).

    Examples
    --------
    >>> as_polyline([[0, 0], [2, 0]]).length
    2.0
    >>> len(as_polyline(np.empty((0, 2))))
    0
    """
    if isinstance(obj, Polyline):
        return obj
    return Polyline(obj)



class PackedPolylines(list):
    """Polylines stored one after the other in one vertex array: the package's polyline set.

    The one form in which many polylines travel: a read-only list of :class:`Polyline`
    (what :func:`semistatic.extraction.extract_polylines` returns, and what every function
    taking many polylines takes, through :func:`as_polylines`) that also holds all their
    vertices packed for the compiled kernels, polyline ``k`` being
    ``points[offsets[k]:offsets[k + 1]]``, with their bounding boxes and scan indices.
    A scan's polylines are packed once and serve every step of a map update.

    Parameters
    ----------
    polylines
        Polylines or ``(N, 2)`` arrays (made polylines as :func:`as_polyline` makes them).

    Attributes
    ----------
    points : numpy.ndarray
        ``(N, 2)`` C-contiguous float64 vertices of all polylines: the kernels' copy,
        writeable as the kernels are compiled for (nothing writes to it).
    offsets : numpy.ndarray
        ``(K + 1,)`` int64 start of each polyline's vertices in ``points``, and the end.

    Examples
    --------
    >>> lines = PackedPolylines([[[0.0, 0.0], [1.0, 0.0]], [[2.0, 2.0], [3.0, 2.0]]])
    >>> isinstance(lines, list), len(lines), lines.offsets, lines.boxes[1]
    (True, 2, array([0, 2, 4]), array([2., 2., 3., 2.]))
    >>> lines.append(Polyline([[0.0, 0.0]]))
    Traceback (most recent call last):
    ...
    TypeError: PackedPolylines is read-only: build a new one from the polylines wanted
    """

    __slots__ = ("_boxes", "_recipe", "_scan_indices", "offsets", "points")

    def __init__(self, polylines: Iterable[Polyline | ArrayLike] = ()) -> None:
        # (The type test inline: most sets are made of polylines, several per scan.)
        lines = [line if type(line) is Polyline else as_polyline(line) for line in polylines]
        list.extend(self, lines)
        vertices = [line.points for line in lines]
        # (len is the row count: a map over arrays costs no generator frame per polyline.)
        self.offsets = run_offsets(map(len, vertices), len(vertices))
        self.points = np.concatenate(vertices) if vertices else np.empty((0, 2))
        self._boxes: np.ndarray | None = None
        self._scan_indices: np.ndarray | None = None
        self._recipe: tuple | None = None

    @classmethod
    def from_runs(
        cls, points: np.ndarray, offsets: ArrayLike, scan_indices: ArrayLike | None = None,
        *, check_finite: bool = True,
    ) -> PackedPolylines:
        """Return the polylines that are the consecutive runs of one fresh vertex array.

        For code that makes many polylines at once (a scan's extraction, a merge): polyline
        ``k`` is ``points[offsets[k]:offsets[k + 1]]``, a view of one read-only copy, so
        no polyline is copied or checked on its own. ``points`` itself becomes the set's
        :attr:`points`: it is taken over, write nothing to it afterwards.

        Parameters
        ----------
        points
            ``(N, 2)`` finite float64 vertices.
        offsets
            ``(K + 1,)`` non-decreasing integers from 0 to ``N``.
        scan_indices
            ``(N,)`` integer scan index of each vertex; default: the vertex order
            ``0..n-1`` within each polyline.
        check_finite
            Whether to check that ``points`` are finite (as scipy's ``check_finite``). Only
            code whose points are finite by construction passes ``False`` (a kernel's output
            from finite input): the check is one numpy reduction, and in a map update, with
            the caches cold, each such call costs several microseconds, as much as a small
            kernel. Shapes and offsets are checked either way.

        Examples
        --------
        >>> points = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 2.0], [3.0, 2.0], [4.0, 2.0]])
        >>> lines = PackedPolylines.from_runs(points, [0, 2, 5], scan_indices=[7, 8, 1, 2, 3])
        >>> [line.scan_indices.tolist() for line in lines], lines[1].points[0].tolist()
        ([[7, 8], [1, 2, 3]], [2.0, 2.0])
        >>> [len(line) for line in PackedPolylines.from_runs(points, [0, 3, 3, 5])]
        [3, 0, 2]
        >>> PackedPolylines.from_runs(points * np.nan, [0, 5])  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: PackedPolylines.from_runs: need finite (N, 2) points and offsets from 0 to ...
        """
        points = np.ascontiguousarray(points, dtype=np.float64)
        offsets = np.asarray(offsets, dtype=np.int64)
        bounds = offsets.tolist()
        if not (
            points.ndim == 2 and points.shape[1] == 2 and offsets.ndim == 1 and bounds
            and bounds[0] == 0 and bounds[-1] == points.shape[0]
            # A nan or inf anywhere makes the sum nan or inf; finite metres cannot overflow.
            and (not check_finite or math.isfinite(np.add.reduce(points, axis=None)))
        ):
            raise ValueError(
                "PackedPolylines.from_runs: need finite (N, 2) points and offsets from 0 to "
                f"N, got points of shape {points.shape} and offsets {bounds}"
            )
        if scan_indices is not None:
            scan_indices = _read_only(np.asarray(scan_indices).astype(np.int64, copy=False))
            if scan_indices.shape != (points.shape[0],):
                raise ValueError(
                    f"PackedPolylines.from_runs: scan_indices has shape {scan_indices.shape}, "
                    f"points {points.shape[0]} rows; pass one scan index per vertex"
                )
        if bounds != sorted(bounds):
            raise ValueError(f"PackedPolylines.from_runs: offsets decrease: {bounds}")
        return _Unmade.of(points, offsets, scan_indices, ("runs", bounds))

    def take(self, indices: ArrayLike, reverse: ArrayLike | None = None) -> PackedPolylines:
        """Return the polylines ``indices``, in that order, each reversed where ``reverse`` is.

        As ``PackedPolylines([self[k] for k in indices])`` (reversed ones as
        :meth:`Polyline.reversed`), with the vertices gathered from :attr:`points` in one
        compiled pass instead of packed again polyline by polyline: the association takes
        its candidates and its pairs so, several times per scan.

        Parameters
        ----------
        indices
            ``(K,)`` positions in this set (repeats allowed).
        reverse
            ``(K,)`` booleans: which of the taken polylines run backwards. Default: none.

        Examples
        --------
        >>> lines = PackedPolylines([[[0.0, 0.0], [1.0, 0.0]], [[5.0, 5.0]],
        ...                          [[2.0, 0.0], [3.0, 1.0]]])
        >>> taken = lines.take([2, 0], reverse=[True, False])
        >>> taken.points.tolist(), taken.offsets.tolist(), taken[1] is lines[0]
        ([[3.0, 1.0], [2.0, 0.0], [0.0, 0.0], [1.0, 0.0]], [0, 2, 4], True)
        >>> lines.take([0, 1, 2]) is lines  # all of them in order: nothing to gather
        True
        """
        # (Over Python ints and bools: a map update takes sets of one to a few polylines,
        # where each numpy call costs more than the gathering itself.)
        positions = indices.reshape(-1).tolist() if isinstance(indices, np.ndarray) else indices
        count = len(self)
        try:
            positions = [operator.index(k) for k in positions]
            flipped = ([False] * len(positions) if reverse is None
                       else np.asarray(reverse, dtype=np.bool_).reshape(-1).tolist())
        except TypeError:
            positions, flipped = [], None
        if flipped is None or len(flipped) != len(positions) or not all(
            0 <= k < count for k in positions
        ):
            raise IndexError(
                f"PackedPolylines.take: need integer indices in [0, {count}) and one reverse "
                f"flag each, got indices {indices!r} and flags {reverse!r}"
            )
        first = positions[0] if positions else 0
        if not any(flipped) and positions == list(range(first, first + len(positions))):
            if len(positions) == count:
                return self  # all of them, in order: the set itself (it is read-only)
            # Consecutive polylines in order: their vertices are one block of rows already
            # (a C-contiguous view, which nothing writes to, as the set's own points).
            bounds = self.offsets[first : first + len(positions) + 1]
            points, offsets = self.points[bounds[0] : bounds[-1]], bounds - bounds[0]
        else:
            points, offsets = _take_runs(
                self.points, self.offsets, np.array(positions, dtype=np.int64),
                np.array(flipped, dtype=np.bool_),
            )
        return _Unmade.of(points, offsets, None, ("take", self, positions, flipped))

    @property
    def boxes(self) -> np.ndarray:
        """Return the ``(K, 4)`` bounding boxes ``(xmin, ymin, xmax, ymax)`` (computed once).

        An empty polyline has the empty box :data:`EMPTY_BOX`. One compiled pass over all
        vertices, however many polylines; like :attr:`points`, nothing writes to it.

        Examples
        --------
        >>> PackedPolylines([[[0.0, 1.0], [2.0, -1.0]], np.empty((0, 2)), [[5.0, 5.0]]]).boxes
        array([[ 0., -1.,  2.,  1.],
               [ inf,  inf, -inf, -inf],
               [ 5.,  5.,  5.,  5.]])
        """
        if self._boxes is None:
            self._boxes = _run_boxes(self.points, self.offsets).reshape(-1, 4)
        return self._boxes

    @property
    def scan_indices(self) -> np.ndarray:
        """Return the ``(N,)`` scan indices of all vertices, packed as :attr:`points` (read-only).

        Examples
        --------
        >>> PackedPolylines([Polyline([[0.0, 0.0], [1.0, 0.0]], [4, 6]), [[2.0, 0.0]]]).scan_indices
        array([4, 6, 0])
        """
        if self._scan_indices is None:
            indices = [line.scan_indices for line in self]
            self._scan_indices = _read_only(
                np.concatenate(indices) if indices else np.empty(0, np.int64)
            )
        return self._scan_indices

    def __eq__(self, other: object) -> bool:
        # Equal to a tuple of the same polylines too: what a report held before packing.
        return list.__eq__(
            self, list(other) if isinstance(other, tuple | PackedPolylines) else other
        )

    def __ne__(self, other: object) -> bool:
        equal = self.__eq__(other)
        return equal if equal is NotImplemented else not equal

    def __reduce__(self) -> tuple:
        return (PackedPolylines, (list(self),))

    def _refuse(self, *args: object, **kwargs: object) -> None:
        """Refuse to change the list: its polylines are packed with it.

        Examples
        --------
        >>> PackedPolylines([[[0.0, 0.0], [1.0, 0.0]]]).pop()
        Traceback (most recent call last):
        ...
        TypeError: PackedPolylines is read-only: build a new one from the polylines wanted
        """
        raise TypeError("PackedPolylines is read-only: build a new one from the polylines wanted")

    append = extend = insert = remove = pop = clear = sort = reverse = _refuse
    __setitem__ = __delitem__ = __iadd__ = __imul__ = _refuse


class _Unmade(PackedPolylines):
    """A :class:`PackedPolylines` whose :class:`Polyline` objects are not made yet.

    What :meth:`PackedPolylines.from_runs` and :meth:`PackedPolylines.take` return: the
    kernels read only :attr:`~PackedPolylines.points` and
    :attr:`~PackedPolylines.offsets`, and many sets (the association's candidates and
    pairs) are never looked into, so making a Python object per polyline up front would be
    most of their cost. The first look at an element makes them all and turns the set into
    a plain ``PackedPolylines`` (this very object, its class swapped): from then on it is
    indexed and iterated at list speed. The list methods that read the storage are
    overridden here so that they make it first.

    ``_recipe`` says how: ``("runs", bounds)``, views of runs of a read-only copy of the
    points (scan indices from ``_scan_indices`` or the vertex order), or ``("take", source,
    positions, flips)``, the source set's polylines, reversed where flipped.
    """

    __slots__ = ()

    @classmethod
    def of(
        cls, points: np.ndarray, offsets: np.ndarray, scan_indices: np.ndarray | None,
        recipe: tuple,
    ) -> _Unmade:
        unmade = cls.__new__(cls)
        unmade.points, unmade.offsets = points, offsets
        unmade._boxes, unmade._scan_indices, unmade._recipe = None, scan_indices, recipe
        return unmade

    def _made(self) -> PackedPolylines:
        """Make the polylines, become a plain :class:`PackedPolylines` and return self."""
        recipe = self._recipe
        if recipe[0] == "take":
            _, source, positions, flips = recipe
            lines = [
                line.reversed() if flip else line
                for line, flip in zip(map(source.__getitem__, positions), flips, strict=True)
            ]
        else:
            frozen = self.points.copy()
            frozen.flags.writeable = False
            indices = self._scan_indices
            new = object.__new__
            lines = []
            for start, stop in itertools.pairwise(recipe[1]):
                # Polyline._view written out: once per polyline of every scan.
                line = new(Polyline)
                state = line.__dict__
                state["points"] = frozen[start:stop]
                state["scan_indices"] = (
                    _vertex_order(stop - start) if indices is None else indices[start:stop]
                )
                lines.append(line)
        list.extend(self, lines)
        self._recipe = None
        self.__class__ = PackedPolylines
        return self

    def __len__(self) -> int:
        return self.offsets.shape[0] - 1

    def __getitem__(self, index):
        return self._made()[index]

    def __iter__(self) -> Iterator[Polyline]:
        return iter(self._made())

    def __reversed__(self) -> Iterator[Polyline]:
        return reversed(self._made())

    def __contains__(self, item: object) -> bool:
        return item in self._made()

    def __eq__(self, other: object) -> bool:
        return self._made() == other

    def __ne__(self, other: object) -> bool:
        return self._made() != other

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return repr(self._made())

    def __add__(self, other: object) -> list:
        return self._made() + other

    def __mul__(self, times: int) -> list:
        return self._made() * times

    def index(self, *args: object) -> int:
        return self._made().index(*args)

    def count(self, item: object) -> int:
        return self._made().count(item)

    def copy(self) -> list:
        return self._made().copy()


def as_polylines(obj: PackedPolylines | Iterable[Polyline | ArrayLike]) -> PackedPolylines:
    """Return ``obj`` as :class:`PackedPolylines` (which pass through unchanged).

    The door of every function that takes many polylines.

    Parameters
    ----------
    obj
        A ``PackedPolylines``, or polylines and ``(N, 2)`` arrays.

    Examples
    --------
    >>> lines = as_polylines([[[0.0, 0.0], [2.0, 0.0]], Polyline([[1.0, 1.0]])])
    >>> [line.length for line in lines], as_polylines(lines) is lines
    ([2.0, 0.0], True)
    """
    if isinstance(obj, PackedPolylines):
        return obj
    return PackedPolylines(obj)


def run_offsets(sizes: Iterable[int], count: int) -> np.ndarray:
    """Return where each of ``count`` consecutive runs of ``sizes`` starts, and the end.

    Examples
    --------
    >>> run_offsets([2, 0, 3], 3)
    array([0, 2, 2, 5])
    """
    return np.fromiter(itertools.accumulate(sizes, initial=0), np.int64, count + 1)


# The scan indices 0..n-1 of polylines whose vertices come from no one scan (a merge's),
# one read-only array per n, shared by every such polyline of that size.
_VERTEX_ORDER: dict[int, np.ndarray] = {}


def _vertex_order(count: int) -> np.ndarray:
    indices = _VERTEX_ORDER.get(count)
    if indices is None:
        indices = _VERTEX_ORDER[count] = np.arange(count, dtype=np.int64)
        indices.flags.writeable = False
    return indices


@numba.njit(cache=True)
def _take_runs(points, offsets, picks, flips):  # pragma: no cover - compiled
    """Return the runs ``picks`` of packed ``points`` (reversed where ``flips``) and offsets."""
    taken_offsets = np.zeros(picks.size + 1, np.int64)
    for k in range(picks.size):
        taken_offsets[k + 1] = taken_offsets[k] + offsets[picks[k] + 1] - offsets[picks[k]]
    taken = np.empty((taken_offsets[picks.size], 2))
    for k in range(picks.size):
        start, stop = offsets[picks[k]], offsets[picks[k] + 1]
        base = taken_offsets[k]
        for v in range(stop - start):
            source = stop - 1 - v if flips[k] else start + v
            taken[base + v, 0] = points[source, 0]
            taken[base + v, 1] = points[source, 1]
    return taken, taken_offsets


@numba.njit(cache=True)
def _run_boxes(points, offsets):  # pragma: no cover - compiled
    """Return the boxes of :attr:`PackedPolylines.boxes`, flat (four values per run)."""
    boxes = np.empty(4 * (offsets.size - 1))
    for run in range(offsets.size - 1):
        xmin, ymin, xmax, ymax = math.inf, math.inf, -math.inf, -math.inf
        for k in range(offsets[run], offsets[run + 1]):
            xmin, xmax = min(xmin, points[k, 0]), max(xmax, points[k, 0])
            ymin, ymax = min(ymin, points[k, 1]), max(ymax, points[k, 1])
        boxes[4 * run], boxes[4 * run + 1] = xmin, ymin
        boxes[4 * run + 2], boxes[4 * run + 3] = xmax, ymax
    return boxes
