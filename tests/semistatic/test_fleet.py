"""The fleet map store: message round trips, malformed input, merge rules, sizes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import shapely

from semistatic.fleet import (
    FleetMapStore,
    SegmentMessage,
    decode_segment_map,
    encode_segment_map,
    merge_segment_map,
    occupancy_grid_bytes,
)
from semistatic.local_map import LocalMap
from semistatic.mapper import STATUSES, MapPolyline
from semistatic.polyline import Polyline

AISLE = [(0.0, -1.5), (10.0, -1.5), (10.0, 1.5), (0.0, 1.5)]


def random_map(rng: np.random.Generator, count: int) -> LocalMap:
    local_map = LocalMap(origin=(3.0, 4.0, 0.5), safety_areas=[AISLE])
    for map_id in rng.permutation(1000)[:count]:
        vertices = int(rng.integers(1, 7))
        local_map.restore(MapPolyline(
            int(map_id) * 37, Polyline(rng.uniform(-20.0, 20.0, size=(vertices, 2))),
            STATUSES[int(rng.integers(3))], int(rng.integers(1, 100_000)),
            int(rng.integers(0, 300)), float(rng.uniform(0, 500)), float(rng.uniform(500, 900)),
        ))
    return local_map


@pytest.mark.parametrize("seed", range(5))
def test_round_trip_keeps_every_field(seed):
    rng = np.random.default_rng(seed)
    local_map = random_map(rng, int(rng.integers(0, 12)))
    data = encode_segment_map(7, 300, local_map, stamp=123.25, since=100.5)
    message = decode_segment_map(data)
    header = (message.segment, message.sender, message.stamp, message.since)
    assert header == (7, 300, 123.25, 100.5)
    originals = list(local_map)
    assert len(message.entries) == len(originals)
    for got, want in zip(message.entries, originals, strict=True):
        assert (got.id, got.status, got.hits, got.misses) == (want.id, want.status, want.hits,
                                                              want.misses)
        np.testing.assert_allclose(got.polyline.points, want.polyline.points, atol=2e-6)
        assert got.first_seen == pytest.approx(want.first_seen, abs=1e-4)
        assert got.last_seen == pytest.approx(want.last_seen, abs=1e-4)


def test_size_is_header_plus_state_plus_float32_vertices():
    local_map = LocalMap()
    local_map.restore(MapPolyline(200, Polyline([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]),
                                  "confirmed", 128, 0))
    # Hand count: 3 magic, 1 segment, 1 sender, 8 stamps, 1 count; id 200 and hits 128
    # take two varint bytes each, status 1, misses 1, stamps 8, vertex count 1, 3 x 8.
    data = encode_segment_map(0, 0, local_map, stamp=0.0, since=0.0)
    assert len(data) == 14 + 2 + 1 + 2 + 1 + 8 + 1 + 24


def test_every_truncation_is_rejected():
    data = encode_segment_map(1, 2, random_map(np.random.default_rng(9), 4), stamp=1.0, since=0.0)
    for end in range(len(data)):
        with pytest.raises(ValueError, match="decode_segment_map"):
            decode_segment_map(data[:end])
    with pytest.raises(ValueError, match="bytes after"):
        decode_segment_map(data + b"\x00")


def test_grid_bytes_match_a_hand_count():
    assert occupancy_grid_bytes(shapely.Polygon(AISLE)) == 200 * 60
    assert occupancy_grid_bytes(shapely.box(0.0, 0.0, 1.01, 0.5), resolution=0.1) == 11 * 5
    assert occupancy_grid_bytes(shapely.Polygon()) == 0


def test_a_typical_segment_map_is_far_smaller_than_a_grid():
    # Six objects of four vertices in a 10 m x 3 m aisle (as the warehouse maps hold).
    local_map = LocalMap(safety_areas=[AISLE])
    for k in range(6):
        x = 1.5 * k
        local_map.add([[x, 1.0], [x + 0.6, 1.0], [x + 0.6, 1.4], [x, 1.4]])
    store = FleetMapStore()
    store.publish(0, 0, local_map, stamp=1.0, since=0.0)
    totals = store.totals()
    assert totals["grid_bytes"] == 12_000
    assert totals["grid_bytes"] / totals["bytes"] > 10.0


def test_store_keeps_the_latest_publication_and_breaks_ties_by_sender():
    store = FleetMapStore()
    empty = LocalMap(safety_areas=[AISLE])
    store.publish(3, 2, empty, stamp=10.0, since=5.0)
    store.publish(3, 1, empty, stamp=10.0, since=6.0)
    store.publish(3, 0, empty, stamp=9.0, since=1.0)
    assert store.fetch(3).sender == 1
    store.publish(3, 2, empty, stamp=11.0, since=7.0)
    assert store.fetch(3).sender == 2
    assert store.totals()["messages"] == 4
    assert store.traffic_arrays()["bytes"].tolist() == [14, 14, 14, 14]


def test_merge_drops_what_the_sender_no_longer_holds_and_keeps_what_it_did_not_pass():
    mine = LocalMap()
    wall = mine.add([[2.0, -1.0], [2.0, 1.0]], stamp=1.0)
    old_box = mine.add([[5.0, 1.0], [5.5, 1.0]], stamp=1.0)
    fresh_box = mine.add([[8.0, -1.0], [8.5, -1.0]], stamp=12.0)  # seen after the sender came
    theirs = (
        MapPolyline(0, Polyline([[2.01, -1.0], [2.01, 1.0]]), "confirmed", 50, 0, 2.0, 15.0),
        MapPolyline(1, Polyline([[3.0, 2.0], [3.4, 2.0]]), "new", 1, 0, 14.0, 14.0),
        MapPolyline(2, Polyline([[6.0, 2.0], [6.4, 2.0]]), "blank", 3, 2, 3.0, 4.0),
        # Seen 40 times in the sender's pass, missed by its last two scans.
        MapPolyline(3, Polyline([[0.0, 3.0], [0.5, 3.0]]), "blank", 40, 2, 11.0, 13.0),
        # Last seen before we drove past (12 s) and we do not hold it: contradicted.
        MapPolyline(4, Polyline([[0.0, -3.0], [0.5, -3.0]]), "confirmed", 9, 0, 10.5, 11.0),
    )
    changed = merge_segment_map(mine, SegmentMessage(0, 1, 16.0, 10.0, theirs))
    assert changed == 4
    assert sorted(mine.entries) == [wall, fresh_box, 3, 4]
    # The wall: our sighting is older than the sender's pass, so its view wins outright.
    assert mine[wall].status == "confirmed"
    assert mine[wall].hits == 50
    assert (mine[wall].first_seen, mine[wall].last_seen) == (1.0, 15.0)
    np.testing.assert_allclose(mine[wall].polyline.points, [[2.01, -1.0], [2.01, 1.0]])
    assert old_box not in mine
    assert mine[3].status == "new"
    np.testing.assert_allclose(mine[3].polyline.points, [[3.0, 2.0], [3.4, 2.0]])
    assert (mine[4].status, mine[4].hits) == ("confirmed", 40)
    np.testing.assert_allclose(mine[4].polyline.points, [[0.0, 3.0], [0.5, 3.0]])


def test_merge_averages_sightings_of_the_same_time():
    mine = LocalMap()
    wall = mine.add([[2.0, -1.0], [2.0, 1.0]], stamp=12.0)  # we saw it after the sender came
    theirs = (MapPolyline(0, Polyline([[2.01, -1.0], [2.01, 1.0]]), "confirmed", 50, 0, 2.0,
                          15.0),)
    merge_segment_map(mine, SegmentMessage(0, 1, 16.0, 10.0, theirs))
    assert (mine[wall].status, mine[wall].hits, mine[wall].last_seen) == ("confirmed", 50, 15.0)
    # One hit of ours against 50 of theirs: 50/51 of the way to their wall.
    np.testing.assert_allclose(mine[wall].polyline.points[:, 0], 2.0 + 0.01 * 50 / 51, atol=1e-9)


def test_a_box_moved_along_a_rack_is_where_the_newer_map_says():
    """A pallet face pushed 0.5 m along the rack: not averaged with where it was."""
    mine = LocalMap()
    rack = mine.add([[0.0, -2.0], [12.0, -2.0]], stamp=3.0)
    face = mine.add([[3.0, -1.2], [4.2, -1.2]], stamp=3.0)
    mine.restore(dataclasses.replace(mine[face], status="confirmed", hits=100), replace=True)
    moved = Polyline([[3.5, -1.2], [4.7, -1.2]])
    theirs = (
        MapPolyline(7, Polyline([[0.0, -2.0], [12.0, -2.0]]), "confirmed", 300, 0, 1.0, 25.0),
        MapPolyline(9, moved, "confirmed", 80, 0, 21.0, 24.0),
    )
    merge_segment_map(mine, SegmentMessage(0, 1, 26.0, 20.0, theirs))
    assert sorted(mine.entries) == [rack, face]
    np.testing.assert_allclose(mine[face].polyline.points, moved.points)
    assert (mine[face].status, mine[face].hits, mine[face].last_seen) == ("confirmed", 100, 24.0)


def test_merge_of_an_identical_map_changes_no_geometry():
    rng = np.random.default_rng(4)
    mine = LocalMap()
    for k in range(4):
        mine.add(np.array([[k * 2.0, 1.0], [k * 2.0 + 0.5, 1.2]]) + rng.normal(0, 0.001, 2),
                 stamp=5.0)
    before = {entry.id: entry.polyline.points.copy() for entry in mine}
    message = decode_segment_map(encode_segment_map(0, 1, mine, stamp=6.0, since=4.0))
    merge_segment_map(mine, message)
    assert sorted(mine.entries) == sorted(before)
    for map_id, points in before.items():
        np.testing.assert_allclose(mine[map_id].polyline.points, points, atol=1e-5)


def test_every_received_piece_replaces_the_older_polyline_it_pairs_with():
    """A wall we saw whole, seen by the sender in two pieces (a pallet before it since)."""
    mine = LocalMap()
    wall = mine.add([[0.0, 2.0], [10.0, 2.0]], stamp=1.0)
    pieces = ([[0.0, 2.0], [4.0, 2.0]], [[6.0, 2.0], [10.0, 2.0]])
    theirs = tuple(MapPolyline(k, Polyline(piece), "confirmed", 30, 0, 21.0, 24.0)
                   for k, piece in enumerate(pieces))
    merge_segment_map(mine, SegmentMessage(0, 1, 26.0, 20.0, theirs))
    held = sorted(entry.polyline.points.tolist() for entry in mine)
    assert held == sorted(pieces)
    assert wall in mine                       # one piece carries the wall's id on
    assert all(entry.status == "confirmed" and entry.first_seen == 1.0 for entry in mine)
