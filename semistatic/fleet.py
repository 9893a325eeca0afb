"""Sharing segment maps between vehicles: a compact message format and a fleet map store.

The paper's polylines "require limited storage and bandwidth for their transmission among
the LGVs working together". A vehicle leaving a path segment publishes that segment's local
map; a vehicle entering it fetches the latest one and merges it into its own with the same
association and merge as a scan.

Message format (version 1, little endian; ``varint`` is an unsigned LEB128 integer)::

    b"SM" 0x01                      magic and version
    varint  segment                 index of the path segment
    varint  sender                  index of the publishing vehicle
    float32 stamp                   publication time (s)
    float32 since                   when the sender entered the segment (s)
    varint  count                   number of polylines, then per polyline:
        varint  id                  the sender's polyline id
        uint8   status              0 new, 1 confirmed, 2 blank
        varint  hits, varint misses
        float32 first_seen, float32 last_seen
        varint  vertices            then ``vertices`` x (float32 x, float32 y), segment frame

Coordinates are in the segment frame (metres from the segment start, within tens of
metres), where float32 keeps 4 um or better. The same area as a ROS
``nav_msgs/OccupancyGrid`` takes one byte per cell (:func:`occupancy_grid_bytes`).

Conflict rule: the store keeps, per segment, the latest publication (by stamp; on equal
stamps the lower sender index). Every vehicle merges the segment's stored map into its own
when it enters the segment, before it publishes on leaving, so the latest publication
already carries what the earlier ones knew, and in a merge the newer sighting of an
object wins over the older one (:func:`merge_segment_map`).

Examples
--------
>>> from semistatic.local_map import LocalMap
>>> segment = LocalMap(origin=(0.0, 0.0, 0.0), segment="aisle")
>>> segment.add([[1.0, -1.0], [1.0, 1.0]], stamp=2.0)
0
>>> message = encode_segment_map(3, 0, segment, stamp=5.0, since=1.0)
>>> len(message)   # 14 header + 13 state + 16 vertex bytes
43
>>> decoded = decode_segment_map(message)
>>> decoded.segment, decoded.sender, decoded.entries[0].polyline.points.tolist()
(3, 0, [[1.0, -1.0], [1.0, 1.0]])
"""

from __future__ import annotations

import dataclasses
import math
import struct
from collections.abc import Iterable

import numpy as np
import shapely

from semistatic.association import associate, orient_ccw
from semistatic.local_map import LocalMap
from semistatic.mapper import STATUSES, MapPolyline
from semistatic.merge import merge
from semistatic.polyline import Polyline

__all__ = [
    "GRID_RESOLUTION",
    "MAGIC",
    "FleetMapStore",
    "SegmentMessage",
    "decode_segment_map",
    "encode_segment_map",
    "merge_segment_map",
    "occupancy_grid_bytes",
]

MAGIC = b"SM\x01"
"""The first bytes of every message: format name and version."""

GRID_RESOLUTION = 0.05
"""Cell size (m) of the occupancy grid the messages are measured against."""

_FLOAT2 = struct.Struct("<2f")


@dataclasses.dataclass(frozen=True)
class SegmentMessage:
    """One published segment map.

    Parameters
    ----------
    segment, sender
        Indices of the path segment and of the publishing vehicle.
    stamp
        Publication time (s).
    since
        When the sender entered the segment (s): it drove the whole segment after that.
    entries
        The map polylines (segment frame) with their life-cycle state.

    Examples
    --------
    >>> SegmentMessage(0, 1, 4.0, 2.0, ()).stamp
    4.0
    """

    segment: int
    sender: int
    stamp: float
    since: float
    entries: tuple[MapPolyline, ...]

    def __post_init__(self) -> None:
        for name in ("segment", "sender"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 0):
                raise ValueError(f"SegmentMessage.{name} must be an int >= 0, got {value!r}")
        if not (math.isfinite(self.stamp) and math.isfinite(self.since)):
            raise ValueError("SegmentMessage: stamp and since must be finite")


def _varint(value: int) -> bytes:
    if value < 0:
        raise ValueError(f"varint: value must be >= 0, got {value}")
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _read_varint(data: bytes, offset: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if offset >= len(data):
            raise ValueError("decode_segment_map: message ends inside a varint")
        byte = data[offset]
        offset += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, offset
        shift += 7


def encode_segment_map(segment: int, sender: int, local_map: LocalMap | Iterable[MapPolyline],
                       *, stamp: float, since: float) -> bytes:
    """Encode a segment's map polylines as a message (format in the module notes).

    Examples
    --------
    >>> len(encode_segment_map(0, 0, [], stamp=0.0, since=0.0))  # header only
    14
    """
    message = SegmentMessage(segment, sender, float(stamp), float(since), ())
    entries = list(local_map)
    parts = [MAGIC, _varint(message.segment), _varint(message.sender),
             struct.pack("<2f", message.stamp, message.since), _varint(len(entries))]
    for entry in entries:
        points = np.asarray(entry.polyline.points, dtype="<f4")
        parts += [
            _varint(entry.id), bytes([STATUSES.index(entry.status)]), _varint(entry.hits),
            _varint(entry.misses), struct.pack("<2f", entry.first_seen, entry.last_seen),
            _varint(points.shape[0]), points.tobytes(),
        ]
    return b"".join(parts)


def decode_segment_map(data: bytes) -> SegmentMessage:
    """Decode a message of :func:`encode_segment_map`; ``ValueError`` if it is malformed.

    Examples
    --------
    >>> decode_segment_map(b"XY")
    Traceback (most recent call last):
    ...
    ValueError: decode_segment_map: not a segment map message (bad magic)
    """
    data = bytes(data)
    if data[: len(MAGIC)] != MAGIC:
        raise ValueError("decode_segment_map: not a segment map message (bad magic)")
    try:
        offset = len(MAGIC)
        segment, offset = _read_varint(data, offset)
        sender, offset = _read_varint(data, offset)
        stamp, since = _FLOAT2.unpack_from(data, offset)
        offset += _FLOAT2.size
        count, offset = _read_varint(data, offset)
        entries = []
        for _ in range(count):
            map_id, offset = _read_varint(data, offset)
            status = STATUSES[data[offset]]
            hits, offset = _read_varint(data, offset + 1)
            misses, offset = _read_varint(data, offset)
            first_seen, last_seen = _FLOAT2.unpack_from(data, offset)
            vertices, offset = _read_varint(data, offset + _FLOAT2.size)
            size = 8 * vertices
            if offset + size > len(data):
                raise ValueError("decode_segment_map: message ends inside a polyline")
            points = np.frombuffer(data, dtype="<f4", count=2 * vertices, offset=offset)
            offset += size
            entries.append(MapPolyline(map_id, Polyline(points.reshape(-1, 2).astype(float)),
                                       status, hits, misses, first_seen, last_seen))
    except (IndexError, struct.error) as error:
        raise ValueError(f"decode_segment_map: truncated or malformed message ({error})") from None
    if offset != len(data):
        raise ValueError(f"decode_segment_map: {len(data) - offset} bytes after the last polyline")
    return SegmentMessage(segment, sender, stamp, since, tuple(entries))


def occupancy_grid_bytes(area: shapely.Geometry, resolution: float = GRID_RESOLUTION) -> int:
    """Return the bytes of an occupancy grid (one byte per cell) covering ``area``'s bounds.

    Examples
    --------
    >>> occupancy_grid_bytes(shapely.box(0.0, 0.0, 2.0, 1.0))   # 40 x 20 cells of 5 cm
    800
    """
    if not resolution > 0:
        raise ValueError(f"occupancy_grid_bytes: resolution must be > 0 m, got {resolution!r}")
    xmin, ymin, xmax, ymax = shapely.bounds(area).tolist()
    if not math.isfinite(xmin):
        return 0
    columns = math.ceil((xmax - xmin) / resolution - 1e-9)
    rows = math.ceil((ymax - ymin) / resolution - 1e-9)
    return max(columns, 1) * max(rows, 1)


def merge_segment_map(local_map: LocalMap, message: SegmentMessage) -> int:
    """Merge a fetched segment map into a vehicle's own map of that segment.

    The message is the sender's view of the segment after a whole pass through it (it
    entered at ``message.since``, having merged the fleet's map of the segment then), so
    for everything it saw in that pass it is newer than what the receiver saw before.
    Received polylines are associated with the own ones (:func:`associate`, the mapper's
    gate, viewed from the segment's safety-area centre, always with the ``"projection"``
    restriction: two maps of one object often differ in extent, which the paper's vertex
    restriction reads as a distance of the overhang). Then:

    - **newer wins**: an own polyline last seen before the sender entered is replaced by
      the received polylines associated with it, with their geometry and state (one of
      them keeps its id; hits are the larger count). The sender's map already holds the
      fleet's earlier view of that object, so averaging the two would count that view
      twice and, for an object moved since, would place it between where it was and
      where it is;
    - two sightings of one object in the same time (the receiver saw it after the sender
      entered) are merged (:func:`merge`, weighted by hit counts);
    - **seen in the pass**: a received polyline the sender associated during its pass
      more than once (``last_seen >= since``, ``hits > 1``) is ``confirmed`` for the
      receiver, whatever the sender's last scan said: a box passed and seen from behind
      at a grazing angle is often read as missing by the last scans (``blank``, fewer
      misses than the mapper's ``miss_limit``); what was truly taken away is missed from
      the start of the pass and never seen in it;
    - **stale**: an own polyline with no partner, last seen before the sender entered,
      is dropped (the sender drove the segment since and its life cycle no longer holds
      it). A received polyline with no partner joins unless it is ``blank`` or the
      receiver's own view of the segment is newer than the sender's last sighting of it
      (the receiver drove past later and its life cycle did not keep it).

    Returns the number of polylines changed, added or dropped.

    Examples
    --------
    >>> mine = LocalMap()
    >>> mine.add([[2.0, -1.0], [2.0, 1.0]], stamp=1.0)     # a wall
    0
    >>> mine.add([[1.0, 3.0], [1.5, 3.0]], stamp=1.0)      # a carton since taken away
    1
    >>> theirs = LocalMap()
    >>> theirs.add([[2.02, -1.0], [2.02, 1.5]], stamp=9.0)
    0
    >>> merge_segment_map(mine, SegmentMessage(0, 1, 10.0, 8.0, tuple(theirs)))
    2
    >>> [(entry.id, entry.polyline.points.round(2).tolist()) for entry in mine]
    [(0, [[2.02, -1.0], [2.02, 1.5]])]
    """
    params = local_map.params
    own = list(local_map)
    received = list(message.entries)
    if not received and not own:
        return 0
    area = local_map.safety_area
    centre = (0.0, 0.0) if area is None or area.is_empty else area.centroid.coords[0]
    viewpoint = (centre[0], centre[1], 0.0)
    pairs = []
    if received and own:
        scan_order = sorted(range(len(received)),
                            key=lambda i: _bearing(received[i].polyline, viewpoint))
        scan_lines = [orient_ccw(received[i].polyline, viewpoint) for i in scan_order]
        pairs = [
            (scan_order[i], j)
            for i, j in associate(scan_lines, [entry.polyline for entry in own], params.gate,
                                  viewpoint=viewpoint, mode="projection")
        ]
    since = message.since
    received = [_pass_summary(entry, since) for entry in received]
    own_latest = max((entry.last_seen for entry in own), default=-math.inf)
    # Own polylines last seen before the sender entered are superseded: the received
    # polylines associated with them take their place (a pairing may be one to many).
    superseded = {j for _, j in pairs if own[j].last_seen < since}
    concurrent = [(i, j) for i, j in pairs if j not in superseded]
    replacing = {i for i, j in pairs if j in superseded} - {i for i, _ in concurrent}
    changed = 0
    for i, j in concurrent:
        theirs, mine = received[i], local_map[own[j].id]
        newer = theirs if theirs.last_seen > mine.last_seen else mine
        weight = mine.hits / max(theirs.hits, 1)
        (geometry, _), = merge([mine.polyline], [[theirs.polyline]], params.epsilon,
                               edge_weights=np.full(max(len(mine.polyline) - 1, 0), weight),
                               end_weights=[weight])
        # Two vehicles saw it: confirmed, unless the later sighting found it missing.
        status = "blank" if newer.status == "blank" else "confirmed"
        local_map.restore(
            MapPolyline(mine.id, geometry, status, max(mine.hits, theirs.hits), newer.misses,
                        min(mine.first_seen, theirs.first_seen),
                        max(mine.last_seen, theirs.last_seen)),
            replace=True,
        )
        changed += 1
    free_ids = set()
    for j in sorted(superseded):
        local_map.remove(own[j].id)
        free_ids.add(own[j].id)
        changed += 1
    for i in sorted(replacing):
        mates = [own[j] for k, j in pairs if k == i and j in superseded]
        reused = next((mate.id for mate in mates if mate.id in free_ids), None)
        free_ids.discard(reused)
        theirs = received[i]
        local_map.restore(dataclasses.replace(
            theirs, id=local_map.next_id if reused is None else reused,
            hits=max(theirs.hits, *(mate.hits for mate in mates)),
            first_seen=min(theirs.first_seen, *(mate.first_seen for mate in mates))))
        changed += reused is None
    matched_own = {j for _, j in pairs}
    matched_received = {i for i, _ in pairs}
    for j, entry in enumerate(own):
        if j not in matched_own and entry.last_seen < since:
            local_map.remove(entry.id)
            changed += 1
    for i, entry in enumerate(received):
        if i not in matched_received and entry.status != "blank" \
                and entry.last_seen > own_latest:
            local_map.restore(dataclasses.replace(entry, id=local_map.next_id))
            changed += 1
    return changed


def _pass_summary(entry: MapPolyline, since: float) -> MapPolyline:
    """Return ``entry`` confirmed if its sender saw it more than once after ``since``."""
    if entry.last_seen >= since and entry.hits > 1 and entry.status != "confirmed":
        return dataclasses.replace(entry, status="confirmed")
    return entry


def _bearing(polyline: Polyline, viewpoint: tuple[float, float, float]) -> float:
    middle = polyline.points.mean(axis=0)
    return math.atan2(middle[1] - viewpoint[1], middle[0] - viewpoint[0])


@dataclasses.dataclass
class _Traffic:
    stamp: float
    sender: int
    segment: int
    bytes: int
    grid_bytes: int


class FleetMapStore:
    """The shared store of segment maps: the latest publication of each segment.

    Parameters
    ----------
    grid_resolution
        Cell size (m) of the occupancy grid every message is measured against.

    Examples
    --------
    >>> store = FleetMapStore()
    >>> segment = LocalMap(safety_areas=[[(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (0.0, 2.0)]])
    >>> segment.add([[1.0, 0.5], [2.0, 0.5]])
    0
    >>> store.publish(2, 0, segment, stamp=30.0, since=20.0)
    >>> store.fetch(2).sender, store.fetch(5) is None
    (0, True)
    >>> store.totals()                  # messages, bytes, 5 cm grid bytes (80 x 40 cells)
    {'messages': 1, 'bytes': 43, 'grid_bytes': 3200}
    """

    def __init__(self, grid_resolution: float = GRID_RESOLUTION) -> None:
        self.grid_resolution = float(grid_resolution)
        self._latest: dict[int, tuple[bytes, SegmentMessage]] = {}
        self.traffic: list[_Traffic] = []

    def publish(self, segment: int, sender: int, local_map: LocalMap, *, stamp: float,
                since: float) -> None:
        """Encode and store vehicle ``sender``'s map of ``segment`` (latest stamp wins)."""
        data = encode_segment_map(segment, sender, local_map, stamp=stamp, since=since)
        message = decode_segment_map(data)  # what every receiver gets: float32 and all
        grid = occupancy_grid_bytes(local_map.safety_area, self.grid_resolution) \
            if local_map.safety_area is not None else 0
        self.traffic.append(_Traffic(float(stamp), sender, segment, len(data), grid))
        held = self._latest.get(segment)
        if held is None or (message.stamp, -message.sender) > (held[1].stamp, -held[1].sender):
            self._latest[segment] = (data, message)

    def fetch(self, segment: int) -> SegmentMessage | None:
        """Return the latest message of ``segment``, or ``None`` if none was published."""
        held = self._latest.get(segment)
        return None if held is None else held[1]

    def totals(self) -> dict[str, int]:
        """Return the messages sent, their encoded bytes and their areas' grid bytes."""
        return {
            "messages": len(self.traffic),
            "bytes": sum(item.bytes for item in self.traffic),
            "grid_bytes": sum(item.grid_bytes for item in self.traffic),
        }

    def traffic_arrays(self) -> dict[str, np.ndarray]:
        """Return the traffic by field (``stamp``, ``sender``, ``segment``, ``bytes``, ...)."""
        fields = ("stamp", "sender", "segment", "bytes", "grid_bytes")
        return {name: np.array([getattr(item, name) for item in self.traffic]) for name in fields}
