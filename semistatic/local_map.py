"""The semi-static local map of one path segment (paper Sec. 4).

Life cycle and maps as in docs/design.md#detail-9 and #detail-10.

A :class:`LocalMap` is a :class:`~semistatic.mapper.PolylineMap` stored in a frame anchored
at the segment start (``origin``, a pose in the world), that only takes in new polylines
touching the segment's safety areas (e.g. the union of the warning fields swept along the
segment, given in the segment frame). Everything else - association, merge, join and the
object life cycle - is the polyline map's.

Maps are saved as GeoJSON in world coordinates (docs/design.md#contract-outputs): one
``LineString`` feature per polyline with properties ``id``, ``segment``, ``status``,
``hits``, ``misses`` (and ``first_seen``, ``last_seen``). The collection's own
``properties`` (a foreign member, RFC 7946 sec. 6.1) hold the ``origin``, ``next_id`` and
the safety area in the segment frame, so that :meth:`LocalMap.load` restores the map in its
local frame.

Examples
--------
>>> from semistatic.types import Scan
>>> area = [(0.5, -1.0), (3.0, -1.0), (3.0, 1.0), (0.5, 1.0)]
>>> segment = LocalMap(origin=(10.0, 5.0, np.pi / 2), safety_areas=[area], segment="s1")
>>> angles = np.radians(np.arange(-45.0, 45.5, 0.5))
>>> scan = Scan(ranges=2.0 / np.cos(angles), angle_min=angles[0],
...             angle_increment=np.radians(0.5))
>>> segment.update(scan, pose=(10.0, 5.0, np.pi / 2)).new_ids  # sensor at the segment start
(0,)
>>> segment.polylines()[0].points.round(2)  # local frame: 2 m ahead of the segment start
array([[ 2.  , -2.02],
       [ 2.  ,  2.02]])
>>> segment.world_polylines()[0].points.round(2)
array([[12.02,  7.  ],
       [ 7.98,  7.  ]])
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from numpy.typing import ArrayLike
from shapely.geometry import mapping, shape

from semistatic.frames import compose, inverse, transform_points, untransform_points
from semistatic.mapper import STATUSES, MapPolyline, PolylineMap, UpdateReport
from semistatic.params import MapperParams
from semistatic.polyline import EMPTY_BOX, Polyline
from semistatic.types import Scan
from semistatic.validation import loads_json

__all__ = ["LocalMap"]

SafetyArea = shapely.Geometry | ArrayLike


def _area_union(safety_areas: Iterable[SafetyArea] | None) -> shapely.Geometry | None:
    """Return the union of the safety areas (``None``: no filter)."""
    if safety_areas is None:
        return None
    polygons = []
    for index, area in enumerate(safety_areas):
        if isinstance(area, shapely.Geometry):
            polygon = area
        else:
            corners = np.asarray(area, dtype=float)
            if corners.ndim != 2 or corners.shape[1] != 2 or corners.shape[0] < 3:
                raise ValueError(
                    f"LocalMap: safety_areas[{index}] must be a shapely geometry or a (K, 2) "
                    f"array of K >= 3 polygon corners, got shape {corners.shape}"
                )
            polygon = shapely.Polygon(corners)
        if not polygon.is_valid:
            polygon = shapely.make_valid(polygon)
        polygons.append(polygon)
    union = shapely.union_all(polygons) if polygons else shapely.Polygon()
    shapely.prepare(union)
    return union


def _geometry(points: np.ndarray) -> dict[str, Any] | None:
    """Return the GeoJSON geometry of polyline vertices (Point for one, null for none)."""
    if points.shape[0] == 0:
        return None
    if points.shape[0] == 1:
        return {"type": "Point", "coordinates": points[0].tolist()}
    return {"type": "LineString", "coordinates": points.tolist()}


class LocalMap:
    """The polyline map of one path segment and the life cycle of its semi-static objects.

    Parameters
    ----------
    origin
        Pose ``(x, y, theta)`` of the segment start in the world: the map's frame.
    safety_areas
        Polygons in the segment frame (shapely geometries or ``(K, 2)`` corner arrays),
        e.g. the warning fields swept along the segment. Only new polylines that intersect
        their union are inserted. ``None`` inserts every polyline; an empty list none.
    segment
        Name (or number) of the path segment, written to the GeoJSON properties.
    params
        Mapper thresholds; ``MapperParams()`` when omitted.

    Examples
    --------
    >>> field = [(0.3, -0.5), (2.0, -0.5), (2.0, 0.5), (0.3, 0.5)]
    >>> segment = LocalMap(origin=(4.0, 1.0, 0.0), safety_areas=[field], segment="s2")
    >>> segment.safety_area.area, len(segment)
    (1.7, 0)
    """

    def __init__(
        self,
        origin: ArrayLike = (0.0, 0.0, 0.0),
        safety_areas: Iterable[SafetyArea] | None = None,
        *,
        segment: str | int = 0,
        params: MapperParams | None = None,
    ) -> None:
        origin = np.array(origin, dtype=float).reshape(-1)
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise ValueError(f"LocalMap: origin must be a finite (x, y, theta), got {origin}")
        origin.flags.writeable = False
        self.origin = origin
        # to_local is between(origin, pose), i.e. compose(inverse(origin), pose): the
        # inverse of the fixed origin is computed once.
        self._world_in_local = inverse(origin)
        self._world_in_local.flags.writeable = False
        self.segment = segment
        self.safety_area = _area_union(safety_areas)
        self._area_box = (
            tuple(shapely.bounds(self.safety_area).tolist())
            if self.safety_area is not None and not self.safety_area.is_empty
            else EMPTY_BOX
        )
        self._map = PolylineMap(
            params,
            keep=self._touches_safety_area,
            keep_box=None if self.safety_area is None else self._area_box,
        )

    @property
    def params(self) -> MapperParams:
        """Return the mapper thresholds."""
        return self._map.params

    def __len__(self) -> int:
        return len(self._map)

    def __iter__(self) -> Iterator[MapPolyline]:
        return iter(self._map)

    def __contains__(self, map_id: object) -> bool:
        return map_id in self._map

    def __getitem__(self, map_id: int) -> MapPolyline:
        return self._map[map_id]

    @property
    def entries(self) -> Mapping[int, MapPolyline]:
        """Return the map polylines by id (local frame), read-only."""
        return self._map.entries

    @property
    def next_id(self) -> int:
        """Return the id the next new object will get."""
        return self._map.next_id

    def polylines(self) -> dict[int, Polyline]:
        """Return every polyline by id in the segment (local) frame."""
        return self._map.polylines()

    def world_polylines(self) -> dict[int, Polyline]:
        """Return every polyline by id in the world frame."""
        return {
            map_id: line.transformed(self.origin) for map_id, line in self._map.polylines().items()
        }

    def add(self, polyline: Polyline | ArrayLike, *, stamp: float = 0.0) -> int:
        """Insert a polyline (segment frame) as a new object, whatever the safety area.

        Examples
        --------
        >>> LocalMap().add([[1.0, 0.0], [1.0, 1.0]], stamp=3.0)
        0
        """
        return self._map.add(polyline, stamp=stamp)

    def restore(self, entry: MapPolyline, *, replace: bool = False) -> None:
        """Put an entry (segment frame) into the map with its id and state.

        See :meth:`semistatic.mapper.PolylineMap.restore`; ``replace`` overwrites the
        entry of the same id (e.g. merged with another vehicle's map).

        Examples
        --------
        >>> segment = LocalMap()
        >>> segment.restore(MapPolyline(4, Polyline([[1.0, 0.0], [1.0, 1.0]]), "confirmed", 3))
        >>> segment.next_id, segment[4].status
        (5, 'confirmed')
        """
        self._map.restore(entry, replace=replace)

    def remove(self, map_id: int) -> None:
        """Delete polyline ``map_id`` from the map."""
        self._map.remove(map_id)

    @property
    def world_in_local(self) -> np.ndarray:
        """Return the world frame's pose in the segment frame (``inverse(origin)``, read-only).

        Examples
        --------
        >>> LocalMap(origin=(1.0, 0.0, 0.0)).world_in_local
        array([-1.,  0.,  0.])
        """
        return self._world_in_local

    def to_local(self, pose: ArrayLike) -> np.ndarray:
        """Return a world pose expressed in the segment frame.

        Examples
        --------
        >>> LocalMap(origin=(1.0, 0.0, 0.0)).to_local((3.0, 1.0, 0.5))
        array([2. , 1. , 0.5])
        """
        return compose(self._world_in_local, pose)

    def _touches_safety_area(self, polyline: Polyline) -> bool:
        if self.safety_area is None:
            return True
        if len(polyline) == 0:
            return False
        # Most new scan polylines lie well away from the area: their boxes tell at once.
        xmin, ymin, xmax, ymax = polyline.box
        area_xmin, area_ymin, area_xmax, area_ymax = self._area_box
        if xmin > area_xmax or xmax < area_xmin or ymin > area_ymax or ymax < area_ymin:
            return False
        if len(polyline) == 1:
            geometry = shapely.points(polyline.points[0])
        else:
            geometry = shapely.linestrings(polyline.points)
        return bool(shapely.intersects(self.safety_area, geometry))

    def update(
        self, scan: Scan, pose: ArrayLike, *, timings: dict[str, float] | None = None
    ) -> UpdateReport:
        """Update the map with one scan taken from sensor ``pose`` (world frame).

        See :meth:`semistatic.mapper.PolylineMap.update`; the report's polylines are in
        the segment frame.
        """
        return self._map.update(scan, self.to_local(pose), timings=timings)

    def associate(
        self, scan: Scan, pose: ArrayLike, *, scan_polylines: tuple[Polyline, ...] | None = None,
        find_missed: bool = True,
    ) -> UpdateReport:
        """Associate one scan taken from sensor ``pose`` (world frame) without changing the map.

        See :meth:`semistatic.mapper.PolylineMap.associate`. ``scan_polylines``, when
        given, are this scan's polylines in the segment frame (e.g. the update report of
        another map of the same segment for the same scan), so extraction is skipped;
        without ``find_missed`` the report's ``missed_ids`` is left empty.

        Examples
        --------
        >>> scan = Scan(ranges=np.full(61, 2.0), angle_min=-0.3, angle_increment=0.01)
        >>> segment = LocalMap(origin=(1.0, 0.0, 0.0))
        >>> _ = segment.update(scan, (2.0, 0.0, 0.0))
        >>> [pair.map_id for pair in segment.associate(scan, (2.0, 0.0, 0.0)).associated]
        [0]
        >>> len(segment)
        1
        """
        return self._map.associate(scan, self.to_local(pose), scan_polylines=scan_polylines,
                                   find_missed=find_missed)

    def to_geojson(self) -> dict[str, Any]:
        """Return the map as a GeoJSON FeatureCollection in world coordinates.

        Examples
        --------
        >>> segment = LocalMap(origin=(1.0, 0.0, 0.0), segment="s1")
        >>> segment.add([[0.0, 0.0], [0.0, 1.0]])
        0
        >>> collection = segment.to_geojson()
        >>> feature = collection["features"][0]
        >>> feature["geometry"]["coordinates"], feature["properties"]["status"]
        ([[1.0, 0.0], [1.0, 1.0]], 'new')
        """
        features = []
        for entry in self._map:
            world = transform_points(self.origin, entry.polyline.points)
            features.append(
                {
                    "type": "Feature",
                    "geometry": _geometry(world),
                    "properties": {
                        "id": entry.id,
                        "segment": self.segment,
                        "status": entry.status,
                        "hits": entry.hits,
                        "misses": entry.misses,
                        "first_seen": entry.first_seen,
                        "last_seen": entry.last_seen,
                    },
                }
            )
        return {
            "type": "FeatureCollection",
            "properties": {
                "segment": self.segment,
                "frame": "world",
                "origin": self.origin.tolist(),
                "next_id": self._map.next_id,
                "safety_area_local": (
                    None if self.safety_area is None else mapping(self.safety_area)
                ),
            },
            "features": features,
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`to_geojson` to ``path`` atomically (temporary file + ``os.replace``).

        A reader never sees a half-written file, and a failed save leaves any previous
        file untouched.

        Examples
        --------
        >>> import tempfile
        >>> segment = LocalMap(origin=(1.0, 2.0, 0.0), segment="s1")
        >>> segment.add([[0.0, 0.0], [1.0, 0.0]])
        0
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     segment.save(Path(folder) / "lap_01.geojson")
        ...     copy = LocalMap.load(Path(folder) / "lap_01.geojson")
        >>> copy.polylines()[0].points.tolist(), copy.segment
        ([[0.0, 0.0], [1.0, 0.0]], 's1')
        """
        path = Path(path)
        text = json.dumps(self.to_geojson(), indent=1, allow_nan=False)
        temporary = None
        try:
            with tempfile.NamedTemporaryFile(
                "w", dir=path.parent, prefix=f".{path.name}.", suffix=".tmp", delete=False
            ) as handle:
                temporary = handle.name
                handle.write(text)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(temporary, path)
        except BaseException:
            if temporary is not None:
                Path(temporary).unlink(missing_ok=True)
            raise

    @classmethod
    def load(cls, path: str | os.PathLike[str], *, params: MapperParams | None = None) -> LocalMap:
        """Read a map written by :meth:`save` (ids, states and local frame restored).

        Raises ``ValueError`` naming the file and the offending key on malformed input.
        See :meth:`save` for an example.
        """
        path = Path(path)
        try:
            collection = loads_json(path.read_text(), file=str(path))
        except json.JSONDecodeError as error:
            raise ValueError(f"{path}: not valid JSON ({error})") from None
        return cls.from_geojson(collection, params=params, source=str(path))

    @classmethod
    def from_geojson(
        cls,
        collection: Mapping[str, Any],
        *,
        params: MapperParams | None = None,
        source: str = "<geojson>",
    ) -> LocalMap:
        """Build a map from a :meth:`to_geojson` collection.

        Examples
        --------
        >>> segment = LocalMap(origin=(1.0, 2.0, 0.3), safety_areas=[[(0, 0), (1, 0), (0, 1)]])
        >>> segment.add([[0.0, 0.0], [0.0, 1.0]], stamp=4.0)
        0
        >>> copy = LocalMap.from_geojson(segment.to_geojson())
        >>> bool(np.allclose(copy.polylines()[0].points, segment.polylines()[0].points))
        True
        >>> copy[0].first_seen, copy.safety_area.area
        (4.0, 0.5)
        """

        def fail(key: str, what: str) -> ValueError:
            return ValueError(f"{source}: {key}: {what}")

        if not isinstance(collection, Mapping) or collection.get("type") != "FeatureCollection":
            raise fail("type", "expected a GeoJSON FeatureCollection")
        header = collection.get("properties")
        if not isinstance(header, Mapping):
            raise fail("properties", "missing the map properties (origin, segment, next_id)")
        origin = _numbers(header.get("origin"), 3, fail, "properties.origin")
        area = header.get("safety_area_local")
        try:
            areas = None if area is None else [shape(area)]
        except (AttributeError, KeyError, TypeError, ValueError, shapely.errors.GEOSException):
            raise fail("properties.safety_area_local", "not a GeoJSON geometry") from None
        local_map = cls(origin, areas, segment=header.get("segment", 0), params=params)
        features = collection.get("features")
        if not isinstance(features, list):
            raise fail("features", "expected a list of features")
        next_id = header.get("next_id", 0)
        if not (isinstance(next_id, int) and next_id >= 0):
            raise fail("properties.next_id", f"expected an integer >= 0, got {next_id!r}")
        for index, feature in enumerate(features):
            entry = _entry(feature, local_map.origin, fail, f"features[{index}]")
            if entry.id in local_map:
                raise fail(f"features[{index}].properties.id", f"id {entry.id} appears twice")
            local_map._map.restore(entry, next_id=next_id)
        return local_map


def _numbers(value: Any, count: int, fail: Any, key: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise fail(key, f"expected {count} numbers, got {value!r}") from None
    if array.shape != (count,) or not np.all(np.isfinite(array)):
        raise fail(key, f"expected {count} finite numbers, got {value!r}")
    return array


def _entry(feature: Any, origin: np.ndarray, fail: Any, key: str) -> MapPolyline:
    """Return the map polyline of one GeoJSON feature (geometry back in the local frame)."""
    if not isinstance(feature, Mapping) or feature.get("type") != "Feature":
        raise fail(key, "expected a GeoJSON Feature")
    geometry = feature.get("geometry")
    if geometry is None:
        points = np.empty((0, 2))
    elif isinstance(geometry, Mapping) and geometry.get("type") in ("LineString", "Point"):
        coordinates = geometry.get("coordinates")
        try:
            points = np.asarray(coordinates, dtype=float).reshape(-1, 2)
        except (TypeError, ValueError):
            raise fail(f"{key}.geometry.coordinates", "expected [x, y] positions") from None
        if not np.all(np.isfinite(points)):
            raise fail(f"{key}.geometry.coordinates", "positions must be finite")
        points = untransform_points(origin, points)
    else:
        raise fail(f"{key}.geometry", "expected a LineString, a Point or null")
    properties = feature.get("properties")
    if not isinstance(properties, Mapping):
        raise fail(f"{key}.properties", "missing id, status, hits, misses")
    values = {}
    for name in ("id", "hits", "misses"):
        value = properties.get(name)
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= 0):
            raise fail(f"{key}.properties.{name}", f"expected an integer >= 0, got {value!r}")
        values[name] = value
    status = properties.get("status")
    if status not in STATUSES:
        raise fail(f"{key}.properties.status", f"expected one of {STATUSES}, got {status!r}")
    stamps = []
    for name in ("first_seen", "last_seen"):
        value = properties.get(name, 0.0)
        if not (isinstance(value, int | float) and math.isfinite(value)):
            raise fail(f"{key}.properties.{name}", f"expected a finite stamp, got {value!r}")
        stamps.append(float(value))
    return MapPolyline(
        values["id"], Polyline(points), status, values["hits"], values["misses"], *stamps
    )
