"""The polyline: an ordered vertex list that remembers which laser beams it came from.

A polyline is an ``(N, 2)`` float64 vertex array plus the scan index of each vertex
(DESIGN.md, conventions). The restricted Hausdorff distance and the merge rely on the
vertex order, and scan polylines run counter-clockwise around the viewpoint. Both arrays
are read-only, so a ``Polyline`` can be shared and its derived quantities cached.

Examples
--------
>>> line = Polyline([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])
>>> len(line), line.length, line.scan_indices
(3, 6.0, array([0, 1, 2]))
>>> as_polyline(line) is line
True
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
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
    "pack_vertices",
    "run_boxes",
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
    def _trusted(cls, points: np.ndarray, scan_indices: np.ndarray) -> Polyline:
        """Wrap fresh arrays already known valid, skipping the checks (hot paths only).

        ``points`` must be a finite ``(N, 2)`` float64 array and ``scan_indices`` an
        ``(N,)`` int64 array, both owned by the new polyline (they are frozen in place).
        """
        points.flags.writeable = False
        scan_indices.flags.writeable = False
        line = object.__new__(cls)
        # The frozen dataclass's fields, set as __init__ would without its checks.
        line.__dict__.update(points=points, scan_indices=scan_indices)
        return line

    @classmethod
    def _split(
        cls, points: np.ndarray, scan_indices: np.ndarray, bounds: list[int] | np.ndarray
    ) -> PackedPolylines:
        """Return one polyline per run ``bounds[k]:bounds[k + 1]`` of fresh, valid arrays.

        The arrays are frozen once and each polyline holds views of them (hot paths only,
        as :meth:`_trusted`: a whole scan's polylines come out of one array). The boxes of
        all runs are found in one pass; the result keeps the packed vertices and the boxes
        for the kernels (:class:`PackedPolylines`).
        """
        offsets = np.asarray(bounds, dtype=np.int64)  # (an int64 array as it is)
        bounds = offsets.tolist()
        # (The boxes and the kernels' copy first: kernels are compiled for writeable arrays.)
        boxes = run_boxes(points, offsets)
        packed = PackedPolylines(points.copy(), offsets, boxes)
        points.flags.writeable = False
        scan_indices.flags.writeable = False
        new = object.__new__
        lines = []
        for start, stop in itertools.pairwise(bounds):
            line = new(cls)
            # (Item by item: cheaper than an update with keywords, once per scan polyline.)
            state = line.__dict__
            state["points"], state["scan_indices"] = points[start:stop], scan_indices[start:stop]
            lines.append(line)
        packed.extend(lines)
        return packed

    @classmethod
    def _views(
        cls, points: np.ndarray, bounds: list[int], scan_indices: Sequence[np.ndarray]
    ) -> list[Polyline]:
        """Return one polyline per run ``bounds[k]:bounds[k + 1]`` of fresh, valid vertices.

        As :meth:`_split`, but each polyline takes the read-only ``scan_indices[k]`` given
        (e.g. those of the polyline whose vertices were copied and moved) and no box.
        """
        points.flags.writeable = False
        new = object.__new__
        lines = []
        for start, stop, indices in zip(bounds, bounds[1:], scan_indices, strict=False):
            line = new(cls)
            state = line.__dict__  # (as in _split)
            state["points"], state["scan_indices"] = points[start:stop], indices
            lines.append(line)
        return lines

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
    """A list of polylines that are the consecutive runs of one vertex array.

    What :func:`semistatic.extraction.extract_polylines` returns: a plain list of
    :class:`Polyline` that also keeps, for compiled kernels, all vertices packed
    (:func:`pack_vertices`) and the bounding boxes (:func:`run_boxes`), so that nothing
    downstream packs the same scan again.

    Parameters
    ----------
    points
        ``(N, 2)`` vertices of all polylines one after the other: a writeable copy the
        polylines do not share (a kernel may take it, none may write to it).
    offsets
        ``(K + 1,)`` int64: polyline ``k`` is ``points[offsets[k]:offsets[k + 1]]``.
    boxes
        ``(K, 4)`` bounding boxes ``(xmin, ymin, xmax, ymax)``.
    lines
        The polylines themselves (appended by the producer when not given).

    Examples
    --------
    >>> points = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 2.0], [3.0, 2.0]])
    >>> lines = Polyline._split(points.copy(), np.arange(4), [0, 2, 4])
    >>> isinstance(lines, list), len(lines), lines.offsets, lines.boxes[1]
    (True, 2, array([0, 2, 4]), array([2., 2., 3., 2.]))
    """

    def __init__(
        self, points: np.ndarray, offsets: np.ndarray, boxes: np.ndarray,
        lines: Iterable[Polyline] = (),
    ) -> None:
        super().__init__(lines)
        self.points = points
        self.offsets = offsets
        self.boxes = boxes


class PackedPolylineTuple(tuple):
    """A tuple of polylines that keeps the packed vertices and boxes of its source.

    What :class:`semistatic.mapper.UpdateReport` stores as ``scan_polylines``: a plain
    tuple to read, that still brings a :class:`PackedPolylines`' ``points``, ``offsets``
    and ``boxes`` to a later association of the same polylines (no repacking).

    Examples
    --------
    >>> lines = Polyline._split(np.array([[0.0, 0.0], [1.0, 0.0]]), np.arange(2), [0, 2])
    >>> frozen = PackedPolylineTuple.of(lines)
    >>> isinstance(frozen, tuple), frozen == tuple(lines), frozen.offsets
    (True, True, array([0, 2]))
    """

    @classmethod
    def of(cls, lines: PackedPolylines) -> PackedPolylineTuple:
        """Return ``lines`` as a tuple that keeps their packed vertices and boxes."""
        frozen = cls(lines)
        frozen.points, frozen.offsets, frozen.boxes = lines.points, lines.offsets, lines.boxes
        return frozen


def frozen_polylines(lines: Sequence[Polyline]) -> tuple[Polyline, ...]:
    """Return ``lines`` as a tuple, keeping packed vertices and boxes when they have them.

    Examples
    --------
    >>> lines = Polyline._split(np.array([[0.0, 0.0], [1.0, 0.0]]), np.arange(2), [0, 2])
    >>> type(frozen_polylines(lines)).__name__, type(frozen_polylines(list(lines))).__name__
    ('PackedPolylineTuple', 'tuple')
    >>> (frozen := frozen_polylines(lines)) is frozen_polylines(frozen)
    True
    """
    if isinstance(lines, PackedPolylineTuple):
        return lines  # frozen already (e.g. another map's report of the same scan)
    if is_packed(lines):
        return PackedPolylineTuple.of(lines)
    return tuple(lines)


def is_packed(lines: Sequence[Polyline]) -> bool:
    """Return whether ``lines`` bring packed vertices and boxes (``points``, ``offsets``).

    Examples
    --------
    >>> is_packed(Polyline._split(np.zeros((1, 2)), np.arange(1), [0, 1])), is_packed([])
    (True, False)
    """
    return isinstance(lines, (PackedPolylines, PackedPolylineTuple))


def run_offsets(sizes: Iterable[int], count: int) -> np.ndarray:
    """Return where each of ``count`` consecutive runs of ``sizes`` starts, and the end.

    Examples
    --------
    >>> run_offsets([2, 0, 3], 3)
    array([0, 2, 2, 5])
    """
    return np.fromiter(itertools.accumulate(sizes, initial=0), np.int64, count + 1)


def pack_vertices(vertices: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(N_k, 2)`` vertex arrays one after the other and their :func:`run_offsets`.

    How compiled kernels take many polylines at once: polyline ``k`` is
    ``points[offsets[k]:offsets[k + 1]]``.

    Examples
    --------
    >>> points, offsets = pack_vertices([np.zeros((2, 2)), np.ones((1, 2))])
    >>> points.shape, offsets
    ((3, 2), array([0, 2, 3]))
    """
    # (len is the row count: a map over arrays costs no generator frame per polyline.)
    offsets = run_offsets(map(len, vertices), len(vertices))
    points = np.concatenate(vertices) if vertices else np.empty((0, 2))
    return points, offsets


def run_boxes(points: np.ndarray, offsets: Sequence[int] | np.ndarray) -> np.ndarray:
    """Return the ``(K, 4)`` bounding boxes ``(xmin, ymin, xmax, ymax)`` of packed runs.

    Run ``k`` is ``points[offsets[k]:offsets[k + 1]]`` (as :func:`pack_vertices` gives
    them); an empty run has the empty box :data:`EMPTY_BOX`. One compiled pass over all
    vertices, however many polylines.

    Examples
    --------
    >>> run_boxes(np.array([[0.0, 1.0], [2.0, -1.0], [5.0, 5.0]]), [0, 2, 2, 3])
    array([[ 0., -1.,  2.,  1.],
           [ inf,  inf, -inf, -inf],
           [ 5.,  5.,  5.,  5.]])
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    return _run_boxes(points, offsets).reshape(-1, 4)


@numba.njit(cache=True)
def _run_boxes(points, offsets):  # pragma: no cover - compiled
    """Return the boxes of :func:`run_boxes`, flat (four values per run)."""
    boxes = np.empty(4 * (offsets.size - 1))
    for run in range(offsets.size - 1):
        xmin, ymin, xmax, ymax = math.inf, math.inf, -math.inf, -math.inf
        for k in range(offsets[run], offsets[run + 1]):
            xmin, xmax = min(xmin, points[k, 0]), max(xmax, points[k, 0])
            ymin, ymax = min(ymin, points[k, 1]), max(ymax, points[k, 1])
        boxes[4 * run], boxes[4 * run + 1] = xmin, ymin
        boxes[4 * run + 2], boxes[4 * run + 3] = xmax, ymax
    return boxes
