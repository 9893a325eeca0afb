"""A polyline map in one fixed frame and its update from one laser scan (paper Sec. 3-4).

:class:`PolylineMap` runs the whole pipeline of the paper's Fig. 1 for one scan:
extract polylines in the sensor frame, move them into the map frame with the sensor pose,
sort the map polylines counter-clockwise from that viewpoint, associate, merge, insert the
unassociated scan polylines as new objects, join overlapping polylines, and run the object
life cycle (docs/design.md#detail-10):

- an associated map polyline is ``"confirmed"`` (hits + 1, misses reset to 0);
- an unassociated scan polyline becomes a ``"new"`` map polyline, reported at once;
- an unassociated map polyline that *should have been visible* and is not where it was
  (the scan reads through it: ``missing`` of :func:`semistatic.visibility.visibility`) is
  ``"blank"``
  and counts a miss; after ``params.miss_limit`` consecutive misses it is deleted. One out
  of view, out of range or occluded counts nothing and is never deleted, and neither does
  one the scan still reads in place although the association did not pair it;
- where the scan reads through *part* of a map polyline it observed or still reads in place
  (``params.free_space_cut``, the ``pieces`` of :func:`semistatic.visibility.visibility`),
  that part is cut away: a box pushed along its own face leaves no stale face. Pieces of an
  observed polyline that this scan did not observe count a miss.

Two choices beyond the paper: association compares the scan polylines as extracted, but
what is merged or inserted has its ends moved half a beam gap outward
(:func:`semistatic.visibility.extend_ends`), which removes the shrinking of objects by the
beam spacing; and each edge of a map polyline moves toward each observation by
``1 / (1 + w)``, ``w`` the observations along that edge so far (``MapPolyline.support``,
see :func:`semistatic.merge.merge`). Joins use the projection restriction
(``JOIN_RESTRICTION``) and merge a group into its heaviest member by
:attr:`MapPolyline.weight` (hits, but no more than its most observed edge): by hits alone
a stub cut off a long wall, which keeps the wall's hits, was the heaviest and bent the
box joined to it onto the stub.

Ids are integers, never reused. The map has no notion of safety areas; a ``keep``
predicate decides which new polylines are inserted (see :class:`semistatic.local_map.LocalMap`).

Examples
--------
>>> angles = np.radians(np.arange(-45.0, 45.5, 0.5))
>>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0],
...             angle_increment=np.radians(0.5), stamp=1.0)
>>> world = PolylineMap()
>>> world.update(scan, (0.0, 0.0, 0.0)).new_ids
(0,)
>>> report = world.update(scan, (0.0, 0.0, 0.0))
>>> report.new_ids, [(a.scan_index, a.map_id) for a in report.associated]
((), [(0, 0)])
>>> world[0].status, world[0].hits
('confirmed', 2)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import NamedTuple

import numpy as np
import shapely
from numpy.typing import ArrayLike

from semistatic.association import ValidatedPairs, associate
from semistatic.extraction import extract_polylines
from semistatic.join import merge_group, overlapping_groups
from semistatic.merge import END_TOLERANCE_FACTOR, merge, transfer_weights
from semistatic.params import MapperParams
from semistatic.polyline import PackedPolylines, Polyline, as_polyline, as_polylines
from semistatic.types import Scan
from semistatic.visibility import MAX_END_EXTENSION, extend_ends, visibility

__all__ = [
    "JOIN_RESTRICTION",
    "MAX_MERGE_WEIGHT",
    "STATUSES",
    "Association",
    "MapPolyline",
    "PolylineMap",
    "UpdateReport",
]

STATUSES = ("new", "confirmed", "blank")

# A map polyline moves toward each new observation by 1 / (1 + min(hits, this)): the
# average of all its observations up to this many, so that an unchanged object's error
# keeps shrinking (at 30, the former cap, 200 observations at 2 cm noise stalled near
# 0.5-0.8 cm; uncapped to 1000 they reach 0.3-0.45 cm). A moved object is not followed
# by averaging but re-associated, cut where the scan contradicts it, or missed.
MAX_MERGE_WEIGHT = 1000

# The restriction of the restricted Hausdorff distance that decides which polylines are
# joined, whatever params.hausdorff_restriction says: joining removes redundant copies, and
# a copy of part of a long wall simplified to two vertices is exactly what the vertex
# restriction cannot recognise (docs/design.md#detail-5); with it, a robot driving along a
# corridor leaves dozens of overlapping wall fragments in the map.
JOIN_RESTRICTION = "projection"

@dataclass(frozen=True)
class MapPolyline:
    """One polyline of the map and its life-cycle state.

    Parameters
    ----------
    id
        Unique integer, never reused within a map.
    polyline
        The geometry, in the map's frame.
    status
        ``"new"`` (first seen in the last update that touched it), ``"confirmed"``
        (associated again) or ``"blank"`` (missed while it should have been visible).
    hits
        Number of scans it was observed in (summed when polylines are joined).
    misses
        Consecutive scans it was missed in while it should have been visible.
    first_seen, last_seen
        Stamps (s) of the first and the last scan that observed it.
    support
        ``(N - 1,)`` how many observations saw each edge (fractional where edges were
        joined: length-weighted), the per-edge weight of
        :func:`semistatic.merge.merge`; ``None`` when unknown (a polyline built
        elsewhere): then :attr:`edge_weights` takes ``hits`` for every edge.

    Examples
    --------
    >>> MapPolyline(3, Polyline([[0.0, 0.0], [1.0, 0.0]]), status="lost")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: MapPolyline.status must be one of ('new', 'confirmed', 'blank'), got 'lost'
    """

    id: int
    polyline: Polyline
    status: str = "new"
    hits: int = 1
    misses: int = 0
    first_seen: float = 0.0
    last_seen: float = 0.0
    support: np.ndarray | None = field(default=None, compare=False)

    @property
    def edge_weights(self) -> np.ndarray:
        """Return :attr:`support`, or ``hits`` per edge where it is unknown.

        (A support always fits its polyline: checked on construction, and dropped by the
        map's own updates whenever they replace the polyline without one.)

        Examples
        --------
        >>> MapPolyline(0, Polyline([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]), hits=4).edge_weights
        array([4., 4.])
        """
        support = self.support
        if support is not None:
            return support
        return np.full(max(len(self.polyline) - 1, 0), float(min(self.hits, MAX_MERGE_WEIGHT)))

    @property
    def weight(self) -> float:
        """Return how many observations the polyline stands for: hits, at most its best edge's.

        The hit count says how often the polyline was associated, not how often each part
        of it was seen: a piece cut off a long wall keeps the wall's hits although its one
        edge was seen a few times. Where the edges' weights are known, none counts more
        than the most observed edge; a polyline of one vertex weighs its hits.

        Examples
        --------
        >>> stub = Polyline([[0.0, 0.0], [0.3, 0.0]])
        >>> MapPolyline(0, stub, hits=900, support=np.array([4.0])).weight
        4.0
        >>> MapPolyline(0, stub, hits=900).weight   # edges unknown: its hits (at most 1000)
        900.0
        """
        weights = self.edge_weights
        hits = float(min(self.hits, MAX_MERGE_WEIGHT))
        return min(hits, float(weights.max())) if weights.size else hits

    def __post_init__(self) -> None:
        object.__setattr__(self, "polyline", as_polyline(self.polyline))
        if self.status not in STATUSES:
            raise ValueError(f"MapPolyline.status must be one of {STATUSES}, got {self.status!r}")
        for name in ("id", "hits", "misses"):
            value = getattr(self, name)
            if not (isinstance(value, int | np.integer) and value >= 0):
                raise ValueError(f"MapPolyline.{name} must be an integer >= 0, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.support is not None:
            support = np.array(self.support, dtype=float)
            if support.shape != (max(len(self.polyline) - 1, 0),) or not (support >= 0).all():
                raise ValueError(
                    "MapPolyline.support must hold one weight >= 0 per edge, got "
                    f"{self.support!r}"
                )
            support.flags.writeable = False
            object.__setattr__(self, "support", support)


def _replaced(entry: MapPolyline, **changes: object) -> MapPolyline:
    """Return ``dataclasses.replace(entry, **changes)`` without re-validating.

    Only for the update's own changes, which are valid by construction (a polyline, a
    status from ``STATUSES``, counts >= 0): a map update replaces every entry it touches.
    A new polyline without a new ``support`` has none (its edge weights are unknown).
    """
    if "polyline" in changes and "support" not in changes:
        changes["support"] = None
    copy = object.__new__(MapPolyline)
    copy.__dict__.update(entry.__dict__)
    copy.__dict__.update(changes)
    return copy


@dataclass(frozen=True)
class Association:
    """A validated pair of one update: scan polyline index, map id, restricted Hausdorff.

    Examples
    --------
    >>> Association(scan_index=0, map_id=7, distance=0.03).map_id
    7
    """

    scan_index: int
    map_id: int
    distance: float


@dataclass(frozen=True)
class UpdateReport:
    """What one :meth:`PolylineMap.update` did.

    Parameters
    ----------
    stamp
        The scan's stamp (s).
    scan_polylines
        The extracted scan polylines, in the map frame, in scan order (from an update, the
        :class:`~semistatic.polyline.PackedPolylines` of the extraction, which another
        map's :meth:`PolylineMap.associate` can take as they are).
    associated
        Validated pairs with their restricted Hausdorff distance (m), by scan index.
    unassociated
        Indices of the scan polylines associated with nothing.
    new_ids
        Ids of new map polylines (unassociated scan polylines that were kept and not
        joined into an older polyline).
    missed_ids
        Ids of map polylines not associated although they should have been visible, and
        not where they were (``missing`` of :func:`semistatic.visibility.visibility`).
    deleted_ids
        Ids deleted by the life cycle in this update.
    joined
        ``(absorbed id, surviving id)`` for polylines joined into another.

    Examples
    --------
    >>> report = UpdateReport(stamp=2.0, new_ids=(4,))
    >>> report.new_ids, report.deleted_ids
    ((4,), ())
    """

    stamp: float
    scan_polylines: Sequence[Polyline] = ()
    associated: tuple[Association, ...] = ()
    unassociated: tuple[int, ...] = ()
    new_ids: tuple[int, ...] = ()
    missed_ids: tuple[int, ...] = ()
    deleted_ids: tuple[int, ...] = ()
    joined: tuple[tuple[int, int], ...] = ()


class PolylineMap:
    """A polyline map in one fixed frame with the paper's per-scan update.

    Parameters
    ----------
    params
        Thresholds; ``MapperParams()`` when omitted.
    keep
        Predicate on a new polyline (map frame): insert it only when true. Default: all.
    keep_box
        ``(xmin, ymin, xmax, ymax)`` outside which ``keep`` is known to be false (e.g. the
        bounds of a safety area): new scan polylines far from it are dropped before any
        work is spent on them. Default: no such box.

    Examples
    --------
    >>> world = PolylineMap()
    >>> world.add([[0.0, 0.0], [1.0, 0.0]], stamp=2.0)
    0
    >>> len(world), world[0].status, world.polylines()[0].length
    (1, 'new', 1.0)
    """

    def __init__(
        self,
        params: MapperParams | None = None,
        *,
        keep: Callable[[Polyline], bool] | None = None,
        keep_box: tuple[float, float, float, float] | None = None,
    ) -> None:
        self.params = MapperParams() if params is None else params
        self._keep = keep
        self._keep_box = keep_box
        self._entries = _Entries()
        self._next_id = 0
        self._geometry_cache: _Geometry | None = None
        self._geometry_version = -1

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[MapPolyline]:
        return iter(list(self._entries.values()))

    def __contains__(self, map_id: object) -> bool:
        return map_id in self._entries

    def __getitem__(self, map_id: int) -> MapPolyline:
        return self._entries[map_id]

    @property
    def entries(self) -> Mapping[int, MapPolyline]:
        """Return a read-only view of the map polylines by id."""
        return MappingProxyType(self._entries)

    @property
    def next_id(self) -> int:
        """Return the id the next new polyline will get."""
        return self._next_id

    def polylines(self) -> dict[int, Polyline]:
        """Return the geometry of every map polyline by id."""
        return {map_id: entry.polyline for map_id, entry in self._entries.items()}

    def add(self, polyline: Polyline | ArrayLike, *, stamp: float = 0.0) -> int:
        """Insert a polyline as a new object (no association) and return its id.

        Examples
        --------
        >>> PolylineMap().add([[0.0, 0.0], [1.0, 0.0]])
        0
        """
        map_id = self._next_id
        self._next_id += 1
        line = as_polyline(polyline)
        self._entries[map_id] = MapPolyline(
            map_id, line, "new", 1, 0, stamp, stamp, support=np.ones(max(len(line) - 1, 0))
        )
        return map_id

    def restore(self, entry: MapPolyline, *, next_id: int | None = None,
                replace: bool = False) -> None:
        """Put back a saved entry with its id and state (e.g. when loading a map).

        Raises ``ValueError`` if the id is taken, unless ``replace`` (e.g. a map merged
        from another vehicle's). ``next_id`` (default: one past the largest id seen) keeps
        ids of deleted polylines from being reused.

        Examples
        --------
        >>> world = PolylineMap()
        >>> world.restore(MapPolyline(5, Polyline([[0.0, 0.0], [1.0, 0.0]]), "confirmed", 9))
        >>> world.next_id, world[5].hits
        (6, 9)
        """
        if entry.id in self._entries and not replace:
            raise ValueError(f"PolylineMap.restore: id {entry.id} is already in the map")
        self._entries[entry.id] = entry
        self._next_id = max(self._next_id, entry.id + 1, 0 if next_id is None else next_id)

    def remove(self, map_id: int) -> None:
        """Delete polyline ``map_id`` (its id is never reused).

        Examples
        --------
        >>> world = PolylineMap()
        >>> world.add([[0.0, 0.0], [1.0, 0.0]])
        0
        >>> world.remove(0)
        >>> len(world), world.next_id
        (0, 1)
        """
        del self._entries[map_id]

    def update(
        self, scan: Scan, pose: ArrayLike, *, timings: dict[str, float] | None = None
    ) -> UpdateReport:
        """Update the map with one scan (extract, associate, merge, insert, join, life cycle).

        Parameters
        ----------
        scan
            The laser scan; its own ``pose`` field is not used.
        pose
            Sensor pose ``(x, y, theta)`` in this map's frame (e.g. from the EKF).
        timings
            If given, the seconds spent in each stage are added to it under ``"extract"``,
            ``"associate"``, ``"merge"``, ``"join"`` and ``"life_cycle"``.

        Returns
        -------
        UpdateReport

        Examples
        --------
        >>> scan = Scan(ranges=np.full(61, 2.0), angle_min=-0.3, angle_increment=0.01)
        >>> world = PolylineMap()
        >>> world.update(scan, (1.0, 0.0, 0.0)).new_ids
        (0,)
        """
        clock = _StageClock(timings)
        params = self.params
        pose = _finite_pose(pose, "update")
        stamp = scan.stamp
        scan_lines = extract_polylines(scan, params, pose=pose)
        clock.lap("extract")
        associated, unassociated, unpaired_ids = self._associated(scan_lines, pose)
        clock.lap("associate")

        # Association compares what the scan saw; the map takes the unbiased ends.
        observed = extend_ends(scan_lines, scan.angle_increment, viewpoint=pose)
        changed = self._merge_associated(observed, associated, stamp)
        cut_away, seen = [], None
        if params.free_space_cut:
            cut_away, seen = self._cut_observed(scan, pose, observed, associated, changed)
        changed.difference_update(cut_away)
        new_ids = self._insert_new(
            [observed[index] for index in self._maybe_kept(scan_lines, unassociated)], stamp
        )
        changed.update(new_ids)
        clock.lap("merge")

        joined = self._join(changed, set(new_ids))
        inserted = set(new_ids)
        # A new polyline joined into an older one is that object seen again, not a new one.
        new_ids = [
            map_id
            for map_id in new_ids
            if all(gone != map_id for gone, _ in joined)
            and all(gone in inserted for gone, kept in joined if kept == map_id)
        ]
        clock.lap("join")

        joined_ids = {map_id for pair in joined for map_id in pair}
        unpaired = [map_id for map_id in unpaired_ids if map_id not in joined_ids]
        missed, deleted = self._life_cycle(scan, pose, unpaired, seen)
        clock.lap("life_cycle")
        return UpdateReport(
            stamp,
            scan_lines,
            associated,
            unassociated,
            new_ids=tuple(new_ids),
            missed_ids=tuple(missed),
            deleted_ids=tuple(cut_away + deleted),
            joined=tuple(joined),
        )

    def associate(
        self, scan: Scan, pose: ArrayLike, *, scan_polylines: Sequence[Polyline] | None = None,
        find_missed: bool = True,
    ) -> UpdateReport:
        """Associate one scan with the map without changing the map (paper Sec. 6, Table 1).

        No merge, no new polylines, no life cycle: the report lists the validated pairs
        with their restricted Hausdorff distances, the unassociated scan polylines and the
        map polylines missed although they should have been visible.

        Parameters
        ----------
        scan
            The laser scan; its own ``pose`` field is not used.
        pose
            Sensor pose ``(x, y, theta)`` in this map's frame.
        scan_polylines
            The polylines of this very scan from this pose in this map's frame, when
            another map in the same frame has extracted them already (its update report's
            ``scan_polylines``); extracted from ``scan`` when omitted.
        find_missed
            Whether to look for the missed map polylines (a pass over the beams); without,
            the report's ``missed_ids`` is empty (e.g. Table 1 reads only the pairs).

        Examples
        --------
        >>> scan = Scan(ranges=np.full(61, 2.0), angle_min=-0.3, angle_increment=0.01)
        >>> world = PolylineMap()
        >>> _ = world.update(scan, (1.0, 0.0, 0.0))
        >>> report = world.associate(scan, (1.0, 0.0, 0.0))
        >>> [(pair.scan_index, pair.map_id, round(pair.distance, 3)) for pair in report.associated]
        [(0, 0, 0.0)]
        """
        pose = _finite_pose(pose, "associate")
        if scan_polylines is None:
            scan_lines = extract_polylines(scan, self.params, pose=pose)
        else:
            scan_lines = as_polylines(scan_polylines)
        associated, unassociated, unpaired_ids = self._associated(scan_lines, pose)
        missed = ()
        if find_missed and unpaired_ids:
            seen = visibility(self._polylines_of(unpaired_ids), scan, pose, self.params,
                              cut=False)
            missed = tuple(
                map_id for map_id, missing in zip(unpaired_ids, seen.missing.tolist(),
                                                  strict=True) if missing
            )
        return UpdateReport(scan.stamp, scan_lines, associated, unassociated, missed_ids=missed)

    def _associated(
        self, scan_lines: PackedPolylines, pose: np.ndarray
    ) -> tuple[tuple[Association, ...], tuple[int, ...], list[int]]:
        """Return the validated pairs, the unpaired scan indices and the unpaired map ids."""
        geometry = self._geometry()
        ids = geometry.ids
        pairs = associate(scan_lines, geometry.lines, self.params.gate, viewpoint=pose,
                          mode=self.params.hausdorff_restriction)
        associated = _associations(pairs, ids)
        paired_scans = {i for i, _ in pairs}
        paired_ids = {pair.map_id for pair in associated}
        unassociated = tuple([i for i in range(len(scan_lines)) if i not in paired_scans])
        unpaired_ids = [map_id for map_id in ids if map_id not in paired_ids]
        return associated, unassociated, unpaired_ids

    def _geometry(self) -> _Geometry:
        """Return the ids and the polylines of the map, packed, once per map state.

        Association and join need the boxes of every map polyline; between two updates
        (and after an update that changed nothing) the same ones serve again.
        """
        cached = self._geometry_cache
        version = self._entries.version
        if cached is not None and version == self._geometry_version:
            return cached  # no entry replaced since
        self._geometry_version = version
        ids = list(self._entries)
        lines = [entry.polyline for entry in self._entries.values()]
        # (Polylines compare by identity: the same objects under the same ids.)
        if cached is not None and cached.ids == ids and cached.lines == lines:
            return cached
        positions = {map_id: k for k, map_id in enumerate(ids)}
        self._geometry_cache = _Geometry(ids, PackedPolylines(lines), positions)
        return self._geometry_cache

    def _cut_observed(
        self, scan: Scan, pose: np.ndarray, observed: PackedPolylines,
        associated: tuple[Association, ...], changed: set[int],
    ) -> tuple[list[int], dict[int, tuple[bool, PackedPolylines | None]]]:
        """Cut the free space out of the merged polylines; return the ids gone, and the rest.

        Adds the new pieces' ids to ``changed`` (they may join others like any changed
        polyline). The rest: whether each other map polyline is missing, and what the cut
        leaves of it (``None``: nothing cut), by id, as the scan found them before this
        update cut, inserted or joined anything. Nothing until then changes them (the merge,
        the cut and the join exclude them): the one pass over the beams serves both.
        """
        ids, lines, _ = self._geometry()
        seen = visibility(lines, scan, pose, self.params)
        cuts = {map_id: pieces for map_id, pieces in zip(ids, seen.pieces, strict=True)
                if pieces is not None and map_id in changed}
        # (Whether one is missing is worked out only when some polyline was not merged.)
        others = {
            map_id: (missing, pieces)
            for map_id, missing, pieces in zip(ids, seen.missing.tolist(), seen.pieces,
                                               strict=True)
            if map_id not in changed
        } if len(changed) < len(ids) else {}
        cut_away: list[int] = []
        if cuts:
            observations = {pair.map_id: observed[pair.scan_index] for pair in associated}
            cut_away, pieces = self._cut(cuts, observations)
            changed.update(pieces)
        return cut_away, others

    def _life_cycle(
        self, scan: Scan, pose: np.ndarray, unpaired: list[int],
        seen: dict[int, tuple[bool, PackedPolylines | None]] | None,
    ) -> tuple[list[int], list[int]]:
        """Count a miss of each ``unpaired`` polyline that is missing; return missed, deleted.

        ``seen``: what :meth:`_cut_observed` found of them, or ``None`` without the
        free-space cut (then they are checked here). A polyline missed ``miss_limit`` times
        in a row is deleted; one not missing loses what the scan reads through, if anything.
        """
        params = self.params
        if seen is None and unpaired:
            checked = visibility(self._polylines_of(unpaired), scan, pose, params, cut=False)
            seen = dict(zip(unpaired, zip(checked.missing.tolist(), checked.pieces, strict=True),
                            strict=True))
        missed, deleted, present = [], [], {}
        for map_id in unpaired:
            is_missing, pieces = seen[map_id]
            if not is_missing:
                if pieces is not None:
                    present[map_id] = pieces
                continue
            entry = self._entries[map_id]
            missed.append(map_id)
            if entry.misses + 1 >= params.miss_limit:
                del self._entries[map_id]
                deleted.append(map_id)
            else:
                self._entries[map_id] = _replaced(entry, status="blank", misses=entry.misses + 1)
        # Not associated and not missing: still where it was, except perhaps in part.
        deleted += self._cut(present, {})[0]
        return missed, deleted

    def _maybe_kept(self, scan_lines: PackedPolylines, indices: tuple[int, ...]) -> list[int]:
        """Return the ``indices`` of scan polylines that ``keep`` might accept once extended."""
        if self._keep_box is None or not indices:
            return list(indices)
        # Extending an end moves it at most MAX_END_EXTENSION: the box grows by no more.
        xmin, ymin, xmax, ymax = self._keep_box
        reach = MAX_END_EXTENSION
        boxes = scan_lines.boxes.tolist()
        return [
            index
            for index in indices
            if not (
                (box := boxes[index])[0] > xmax + reach
                or box[2] < xmin - reach
                or box[1] > ymax + reach
                or box[3] < ymin - reach
            )
        ]

    def _merge_associated(
        self,
        observed: PackedPolylines,
        associated: tuple[Association, ...],
        stamp: float,
    ) -> set[int]:
        if not associated:
            return set()
        # The association's packed map (nothing changed it since): taken, not packed again,
        # in map order (when every polyline was paired: the map's set itself).
        geometry = self._geometry()
        parts: dict[int, list[int]] = {}  # scan indices by map position
        for pair in associated:
            parts.setdefault(geometry.positions[pair.map_id], []).append(pair.scan_index)
        positions = sorted(parts)
        entries = [self._entries[geometry.ids[position]] for position in positions]
        epsilon = self.params.epsilon
        merged = merge(
            geometry.lines.take(positions),
            observed.take([index for position in positions for index in parts[position]]),
            epsilon,
            counts=[len(parts[position]) for position in positions],
            edge_weights=np.concatenate([entry.edge_weights for entry in entries]),
            end_weights=[float(min(entry.hits, MAX_MERGE_WEIGHT)) for entry in entries],
            end_tolerance=END_TOLERANCE_FACTOR * epsilon,
        )
        self._entries.update({
            entry.id: _replaced(
                entry,
                polyline=line,
                support=support if support.size else None,
                status="confirmed",
                hits=entry.hits + 1,
                misses=0,
                last_seen=stamp,
            )
            for entry, (line, support) in zip(entries, merged, strict=True)
        })
        return {entry.id for entry in entries}

    def _weights_along(self, line: Polyline, parts: list[MapPolyline]) -> np.ndarray | None:
        """Return the edge weights ``line`` takes over from the entries it was made of.

        (Within the merge's end tolerance: what merge averages lies that close.)
        """
        if len(line) < 2:
            return None
        tolerance = END_TOLERANCE_FACTOR * self.params.epsilon
        total = np.zeros(len(line) - 1)
        for part in parts:
            if len(part.polyline) > 1:
                total += transfer_weights(line, part.polyline, part.edge_weights, tolerance)
        return total

    def _polylines_of(self, ids: list[int]) -> list[Polyline]:
        return [self._entries[map_id].polyline for map_id in ids]

    def _cut(
        self, cuts: Mapping[int, PackedPolylines], seen: Mapping[int, Polyline]
    ) -> tuple[list[int], list[int]]:
        """Replace polylines by the pieces a scan left of them; return the ids gone and new.

        ``cuts`` are the free-space cut's pieces by map id (the ``pieces`` of
        :func:`semistatic.visibility.visibility` where it cut something). The piece nearest
        to what the scan saw of it (``seen``, by map id) keeps the id and state. The others
        are parts this scan did not confirm, and it contradicted the polyline they came
        from: new ids, counted as a miss (status ``"blank"``), so that what a moving thing
        leaves behind goes as a miss would. A polyline read through everywhere is deleted.
        """
        gone, added = [], []
        for map_id in sorted(cuts):
            entry = self._entries[map_id]
            pieces = cuts[map_id]
            if not pieces:
                del self._entries[map_id]
                gone.append(map_id)
                continue
            observation = shapely.LineString(seen[map_id].points) if map_id in seen else None
            nearest = 0 if observation is None else int(np.argmin([
                shapely.distance(shapely.LineString(piece.points), observation)
                for piece in pieces
            ]))
            self._entries[map_id] = _replaced(
                entry, polyline=pieces[nearest],
                support=self._weights_along(pieces[nearest], [entry]),
            )
            # Unobserved pieces of an observed polyline count a miss; of an unobserved one,
            # all keep its state.
            other = {} if observation is None else {
                "status": "blank", "misses": entry.misses + 1
            }
            for k, piece in enumerate(pieces):
                if k == nearest:
                    continue
                self._entries[self._next_id] = _replaced(
                    entry, id=self._next_id, polyline=piece,
                    support=self._weights_along(piece, [entry]), **other
                )
                added.append(self._next_id)
                self._next_id += 1
        return gone, added

    def _insert_new(self, new_lines: list[Polyline], stamp: float) -> list[int]:
        new_ids = []
        for line in new_lines:
            if self._keep is None or self._keep(line):
                new_ids.append(self.add(line, stamp=stamp))
        return new_ids

    def _join(self, changed: set[int], inserted: set[int]) -> list[tuple[int, int]]:
        if not changed or len(self._entries) < 2:
            return []
        ids, lines, _ = self._geometry()
        groups = overlapping_groups(
            lines,
            np.array([map_id in changed for map_id in ids], dtype=bool),
            self.params.gate,
            JOIN_RESTRICTION,
        )
        if not groups:
            return []
        entries = [self._entries[map_id] for map_id in ids]
        # Not by hits alone: a piece cut off a long wall keeps the wall's hits (module
        # docstring).
        weights = [0.0] * len(entries)
        for members in groups:
            for k in members:
                weights[k] = entries[k].weight
        epsilon = self.params.epsilon
        joined = []
        for members in groups:
            line = merge_group(lines, weights, members, epsilon)
            parts = [entries[k] for k in members]
            survivor = min(parts, key=lambda entry: entry.id)
            touched = any(part.id in changed for part in parts)
            # Parts all inserted by this scan are one new object seen in pieces; anything
            # older joined with what this scan saw has been observed again.
            if all(part.id in inserted for part in parts):
                status = "new"
            elif touched or any(part.status == "confirmed" for part in parts):
                status = "confirmed"
            else:
                status = survivor.status
            self._entries[survivor.id] = _replaced(
                survivor,
                polyline=line,
                support=self._weights_along(line, parts),
                status=status,
                hits=sum(part.hits for part in parts),
                misses=0 if touched else min(part.misses for part in parts),
                first_seen=min(part.first_seen for part in parts),
                last_seen=max(part.last_seen for part in parts),
            )
            for part in parts:
                if part.id != survivor.id:
                    del self._entries[part.id]
                    joined.append((part.id, survivor.id))
        return joined


class _Entries(dict):
    """The map polylines by id, counting the replacements and deletions.

    So that :meth:`PolylineMap._geometry` knows its cache still holds without comparing
    every entry (several times per update).
    """

    version = 0

    def __setitem__(self, map_id: int, entry: MapPolyline) -> None:
        self.version += 1
        super().__setitem__(map_id, entry)

    def __delitem__(self, map_id: int) -> None:
        self.version += 1
        super().__delitem__(map_id)

    def update(self, entries: Mapping[int, MapPolyline]) -> None:
        """Replace or add ``entries`` by id (one count for all: a merge replaces many)."""
        self.version += 1
        super().update(entries)


class _Geometry(NamedTuple):
    """The map's ids and polylines in map order (packed, with their boxes), and where each is."""

    ids: list[int]
    lines: PackedPolylines
    positions: dict[int, int]


def _associations(pairs: ValidatedPairs, ids: list[int]) -> tuple[Association, ...]:
    """Return the :class:`Association` of each pair of scan and map index, with its distance.

    Built field by field (it has nothing to check): a few per scan, twenty in a busy one.
    """
    new = object.__new__
    associations = []
    for (scan_index, map_index), distance in zip(pairs, pairs.distances, strict=True):
        pair = new(Association)
        fields = pair.__dict__
        fields["scan_index"], fields["map_id"], fields["distance"] = (
            scan_index, ids[map_index], distance
        )
        associations.append(pair)
    return tuple(associations)


def _finite_pose(pose: ArrayLike, method: str) -> np.ndarray:
    pose = np.asarray(pose, dtype=float).reshape(3)
    # (Three Python floats: numpy's per-call cost would exceed the test itself.)
    if not all(map(math.isfinite, pose.tolist())):
        raise ValueError(f"PolylineMap.{method}: pose must be a finite (x, y, theta), got {pose}")
    return pose


class _StageClock:
    """Add the wall time between laps to a dict of stage durations (when one is given)."""

    def __init__(self, timings: dict[str, float] | None) -> None:
        self._timings = timings
        self._last = time.perf_counter() if timings is not None else 0.0

    def lap(self, stage: str) -> None:
        if self._timings is None:
            return
        now = time.perf_counter()
        self._timings[stage] = self._timings.get(stage, 0.0) + now - self._last
        self._last = now
