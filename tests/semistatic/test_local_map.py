"""Per-segment local maps: safety-area filter, frames, life cycle, GeoJSON.

(docs/design.md#detail-9, #detail-10.)
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
import shapely

from semistatic.frames import compose, transform_points
from semistatic.local_map import LocalMap
from semistatic.params import MapperParams
from tests.semistatic.synthetic import box, cast_scan, scene, wall

# The segment starts at (10, 5) heading north; its safety area is a 3 m x 2 m field ahead.
ORIGIN = np.array([10.0, 5.0, math.pi / 2])
AREA = np.array([[0.3, -1.0], [3.0, -1.0], [3.0, 1.0], [0.3, 1.0]])


def to_world(local_points):
    return transform_points(ORIGIN, local_points)


def world_box(local_center, length=0.4, width=0.3):
    center = to_world([local_center])[0]
    return box(tuple(center), length, width, yaw=ORIGIN[2])


INSIDE = world_box((2.0, 0.3))  # in the safety area
OUTSIDE = world_box((2.0, 2.5))  # to the left of it
SENSOR = compose(ORIGIN, (0.5, 0.0, 0.0))  # half a metre into the segment


def distance_to_outline(points, segments):
    """Return the largest distance from ``points`` to the outline made of ``segments``."""
    outline = shapely.MultiLineString([segment.tolist() for segment in segments])
    return max(outline.distance(shapely.Point(point)) for point in np.asarray(points))


def segment_map(**kwargs):
    kwargs.setdefault("safety_areas", [AREA])
    return LocalMap(ORIGIN, segment="s1", **kwargs)


def test_only_polylines_touching_the_safety_area_are_kept():
    local_map = segment_map()
    report = local_map.update(cast_scan(scene(INSIDE, OUTSIDE), SENSOR), SENSOR)
    assert len(report.scan_polylines) == 2
    assert len(report.new_ids) == 1
    (kept,) = local_map.world_polylines().values()
    assert distance_to_outline(kept.points, INSIDE) < 0.03
    assert distance_to_outline(kept.points, OUTSIDE) > 1.0


def test_safety_area_kinds():
    as_polygon = segment_map(safety_areas=[shapely.Polygon(AREA)])
    as_polygon.update(cast_scan(scene(INSIDE, OUTSIDE), SENSOR), SENSOR)
    assert len(as_polygon) == 1
    keep_all = segment_map(safety_areas=None)
    keep_all.update(cast_scan(scene(INSIDE, OUTSIDE), SENSOR), SENSOR)
    assert len(keep_all) == 2
    keep_none = segment_map(safety_areas=[])
    keep_none.update(cast_scan(scene(INSIDE, OUTSIDE), SENSOR), SENSOR)
    assert len(keep_none) == 0
    with pytest.raises(ValueError, match=r"safety_areas\[0\]"):
        segment_map(safety_areas=[[(0.0, 0.0), (1.0, 1.0)]])
    with pytest.raises(ValueError, match="origin"):
        LocalMap((0.0, 0.0))


def test_polylines_are_stored_in_the_segment_frame():
    local_map = segment_map()
    local_map.update(cast_scan(scene(INSIDE), SENSOR), SENSOR)
    (map_id,) = local_map.polylines()
    local = local_map.polylines()[map_id].points
    world = local_map.world_polylines()[map_id].points
    np.testing.assert_allclose(to_world(local), world, atol=1e-12)
    # The near face of the box is 1.8 m ahead of the segment start in its own frame.
    assert local[:, 0].min() == pytest.approx(1.8, abs=0.02)
    np.testing.assert_allclose(local_map.to_local(SENSOR), [0.5, 0.0, 0.0], atol=1e-12)


def test_life_cycle_in_a_moved_frame():
    params = MapperParams(miss_limit=2)
    local_map = segment_map(params=params)
    backdrop = wall(tuple(to_world([[4.0, -2.0]])[0]), tuple(to_world([[4.0, 2.0]])[0]))
    first = local_map.update(cast_scan(scene(INSIDE, backdrop), SENSOR), SENSOR)
    assert len(first.scan_polylines) == 3  # the box and the wall on both sides of it
    (box_id,) = first.new_ids  # the wall lies beyond the safety area
    local_map.update(cast_scan(scene(INSIDE, backdrop), SENSOR), SENSOR)
    assert local_map[box_id].status == "confirmed"
    turned = compose(SENSOR, (0.0, 0.0, math.pi))  # box in the blind spot: never counted
    for _ in range(5):
        assert box_id not in local_map.update(cast_scan(scene(backdrop), turned), turned).missed_ids
    missed = [local_map.update(cast_scan(scene(backdrop), SENSOR), SENSOR) for _ in range(2)]
    assert [report.missed_ids for report in missed] == [(box_id,), (box_id,)]
    assert missed[-1].deleted_ids == (box_id,)
    assert box_id not in local_map


def test_association_only_changes_nothing():
    local_map = segment_map()
    local_map.update(cast_scan(scene(INSIDE), SENSOR), SENSOR)
    before = dict(local_map.entries)
    report = local_map.associate(cast_scan(scene(INSIDE, world_box((1.5, -0.5))), SENSOR), SENSOR)
    assert dict(local_map.entries) == before
    assert len(report.associated) == 1


def test_geojson_is_in_world_coordinates_with_the_contract_properties():
    local_map = segment_map()
    local_map.update(cast_scan(scene(INSIDE), SENSOR, stamp=3.5), SENSOR)
    collection = local_map.to_geojson()
    assert collection["type"] == "FeatureCollection"
    assert collection["properties"]["origin"] == ORIGIN.tolist()
    assert collection["properties"]["segment"] == "s1"
    (feature,) = collection["features"]
    assert feature["geometry"]["type"] == "LineString"
    properties = feature["properties"]
    assert {"id", "segment", "status", "hits", "misses"} <= set(properties)
    assert (properties["segment"], properties["status"], properties["hits"]) == ("s1", "new", 1)
    assert properties["first_seen"] == 3.5
    world = np.array(feature["geometry"]["coordinates"])
    assert distance_to_outline(world, INSIDE) < 0.03  # on the box in world coordinates
    json.dumps(collection, allow_nan=False)


def test_save_and_load_restore_the_map(tmp_path):
    local_map = segment_map(params=MapperParams(miss_limit=3))
    local_map.update(cast_scan(scene(INSIDE), SENSOR, stamp=1.0), SENSOR)
    local_map.update(cast_scan(scene(INSIDE), SENSOR, stamp=2.0), SENSOR)
    local_map.update(cast_scan(scene(), SENSOR, stamp=3.0), SENSOR)  # one miss: blank
    local_map.add([[1.0, 0.0]], stamp=4.0)  # a one-vertex polyline is a Point
    path = tmp_path / "lap_01.geojson"
    local_map.save(path)
    loaded = LocalMap.load(path, params=MapperParams(miss_limit=3))
    assert np.array_equal(loaded.origin, local_map.origin)
    assert loaded.segment == "s1"
    assert loaded.next_id == local_map.next_id
    assert loaded.safety_area.equals(local_map.safety_area)
    assert set(loaded.entries) == set(local_map.entries)
    for map_id, entry in local_map.entries.items():
        copy = loaded[map_id]
        assert (copy.status, copy.hits, copy.misses, copy.first_seen, copy.last_seen) == (
            entry.status,
            entry.hits,
            entry.misses,
            entry.first_seen,
            entry.last_seen,
        )
        np.testing.assert_allclose(copy.polyline.points, entry.polyline.points, atol=1e-12)
    statuses = sorted(entry.status for entry in loaded)
    assert statuses == ["blank", "new"]
    # The loaded map carries on: the box is recognised, not reported as new.
    report = loaded.update(cast_scan(scene(INSIDE), SENSOR, stamp=5.0), SENSOR)
    assert report.new_ids == ()
    assert len(report.associated) == 1


def test_save_is_atomic(tmp_path, monkeypatch):
    local_map = segment_map()
    path = tmp_path / "map.geojson"
    local_map.save(path)
    local_map.update(cast_scan(scene(INSIDE), SENSOR), SENSOR)
    original = path.read_text()

    def broken_replace(source, target):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        local_map.save(path)
    monkeypatch.undo()
    assert path.read_text() == original  # the old file is untouched
    assert [entry.name for entry in tmp_path.iterdir()] == ["map.geojson"]  # no temp file
    local_map.save(path)
    assert len(json.loads(path.read_text())["features"]) == 1
    assert [entry.name for entry in tmp_path.iterdir()] == ["map.geojson"]
    with pytest.raises(FileNotFoundError):
        local_map.save(tmp_path / "missing" / "map.geojson")


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (lambda c: c.update(type="Feature"), "type"),
        (lambda c: c.pop("properties"), "properties"),
        (lambda c: c["properties"].update(origin=[1.0, 2.0]), "properties.origin"),
        (lambda c: c["properties"].update(next_id=-1), "properties.next_id"),
        (lambda c: c.update(features={}), "features"),
        (lambda c: c["features"][0]["properties"].update(status="gone"), "status"),
        (lambda c: c["features"][0]["properties"].update(hits=1.5), "hits"),
        (lambda c: c["features"][0].update(geometry={"type": "Polygon"}), "geometry"),
        (lambda c: c["features"].append(c["features"][0]), "appears twice"),
    ],
)
def test_malformed_files_are_rejected_with_file_and_key(tmp_path, change, key):
    local_map = segment_map()
    local_map.update(cast_scan(scene(INSIDE), SENSOR), SENSOR)
    collection = local_map.to_geojson()
    change(collection)
    path = tmp_path / "bad.geojson"
    path.write_text(json.dumps(collection))
    with pytest.raises(ValueError, match=r"bad\.geojson") as error:
        LocalMap.load(path)
    assert key in str(error.value)


def test_invalid_json_is_rejected(tmp_path):
    path = tmp_path / "broken.geojson"
    path.write_text("{not json")
    with pytest.raises(ValueError, match=r"broken\.geojson: not valid JSON"):
        LocalMap.load(path)


def test_empty_polyline_round_trips_as_a_null_geometry():
    local_map = segment_map()
    local_map.add(np.empty((0, 2)))
    collection = local_map.to_geojson()
    assert collection["features"][0]["geometry"] is None
    assert len(LocalMap.from_geojson(collection)[0].polyline) == 0
