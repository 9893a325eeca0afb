"""Ground truth against the local maps: which map polylines lie on which true boxes.

The scoring observers (:mod:`scenarios.bench.scoring`) judge each lap's maps with these
pure functions on arrays and small dicts, each tested on hand-made input.

Examples
--------
>>> detection_scores(true_positives=4, false_positives=0, false_negatives=1)
{'tp': 4, 'fp': 0, 'fn': 1, 'precision': 1.0, 'recall': 0.8, 'f1': 0.888889}
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import shapely
from numpy.typing import ArrayLike

__all__ = [
    "AREA_MARGIN",
    "MATCH_DISTANCE",
    "PERSON_DISTANCE",
    "VEHICLE_DISTANCE",
    "clip_to_area",
    "detection_scores",
    "false_objects_near",
    "match_polylines_to_boxes",
    "score_lap",
]

MATCH_DISTANCE = 0.10
"""A map polyline is a box's when every point of it lies within this (m) of the box outline."""

PERSON_DISTANCE = 0.35
"""A false polyline this close (m) to where a person walked is counted as made of a person."""

VEHICLE_DISTANCE = 0.1
"""A false polyline this close (m) to where another vehicle stood counts as made of it."""

AREA_MARGIN = 0.10
"""Metres around the safety area within which a map polyline is scored."""

DENSIFY_STEP = 0.02
"""Metres between points when a polyline is compared with an outline as a curve."""


def _densified(points: np.ndarray) -> np.ndarray:
    line = shapely.LineString(points) if len(points) > 1 else shapely.Point(points[0])
    return shapely.get_coordinates(shapely.segmentize(line, DENSIFY_STEP))


def match_polylines_to_boxes(
    polylines: Sequence[ArrayLike],
    outlines: Mapping[str, ArrayLike],
    tolerance: float = MATCH_DISTANCE,
) -> np.ndarray:
    """Return ``(n_polylines, n_boxes)``: whether each polyline lies on each box outline.

    A polyline lies on a box when its farthest point (as a curve) is within ``tolerance``
    of the box's boundary: a face or a corner of the box, not a wall beside it.

    Examples
    --------
    >>> box = {"b": [[0, 0], [1, 0], [1, 1], [0, 1]]}
    >>> match_polylines_to_boxes([[[0.2, -0.01], [0.8, 0.02]], [[3, 3], [4, 4]]], box)
    array([[ True],
           [False]])
    """
    rings = [
        shapely.LinearRing(np.asarray(outline, dtype=float)) for outline in outlines.values()
    ]
    result = np.zeros((len(polylines), len(rings)), dtype=bool)
    for i, polyline in enumerate(polylines):
        pts = np.asarray(polyline, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            continue
        probes = shapely.points(_densified(pts))
        for j, ring in enumerate(rings):
            result[i, j] = shapely.distance(ring, probes).max() <= tolerance
    return result


def clip_to_area(points: ArrayLike, area: shapely.Geometry) -> np.ndarray:
    """Return the vertices of the longest piece of a polyline inside ``area`` (or none).

    Examples
    --------
    >>> clip_to_area([[0.0, 0.0], [4.0, 0.0]], shapely.box(1.0, -1.0, 2.0, 1.0))
    array([[1., 0.],
           [2., 0.]])
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) < 2:
        inside = len(pts) == 1 and area.contains(shapely.Point(pts[0]))
        return pts if inside else np.empty((0, 2))
    pieces = shapely.get_parts(shapely.intersection(shapely.LineString(pts), area))
    lines = [piece for piece in pieces if isinstance(piece, shapely.LineString)]
    if not lines:
        return np.empty((0, 2))
    longest = max(lines, key=lambda piece: piece.length)
    return shapely.get_coordinates(longest)


def detection_scores(true_positives: int, false_positives: int, false_negatives: int) -> dict:
    """Return precision, recall and F1 (1.0 where nothing was expected and nothing found).

    Examples
    --------
    >>> detection_scores(3, 1, 0)
    {'tp': 3, 'fp': 1, 'fn': 0, 'precision': 0.75, 'recall': 1.0, 'f1': 0.857143}
    """
    found = true_positives + false_positives
    expected = true_positives + false_negatives
    precision = true_positives / found if found else 1.0
    recall = true_positives / expected if expected else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {
        "tp": int(true_positives),
        "fp": int(false_positives),
        "fn": int(false_negatives),
        "precision": round(precision, 6),
        "recall": round(recall, 6),
        "f1": round(f1, 6),
    }


def score_lap(
    local_maps: Mapping[str, Any],
    segments: Sequence[Any],
    truth: Mapping[str, np.ndarray],
    person_track: Sequence[ArrayLike] = (),
) -> tuple[dict, int]:
    """Score the local maps at the end of a lap against the true boxes.

    A box is *expected* in a segment's map when its outline meets the segment's safety
    area. A local map describes what lies inside the safety area (paper Sec. 4), so each
    map polyline is judged by its part inside the area (plus ``AREA_MARGIN``): a wall that
    one scan polyline continued onto behind a box is context, not a false object. That
    part is a true positive when it lies on some box, else a false positive; an expected
    box with no polyline on it is a false negative. Returns the scores and how many false
    polylines lie where a person walked this lap.
    """
    names = list(truth)
    boxes = {name: shapely.Polygon(np.asarray(truth[name], dtype=float)) for name in names}
    track = (
        shapely.multipoints(np.asarray(person_track, dtype=float).reshape(-1, 2))
        if len(person_track)
        else None
    )
    tp = fp = fn = from_people = 0
    for segment in segments:
        lines, matches = _judged_lines(local_maps, segment, truth)
        on_box = matches.any(axis=1)
        tp += int(on_box.sum())
        fp += int((~on_box).sum())
        expected = [
            j for j, name in enumerate(names) if boxes[name].intersects(segment.safety_area_world)
        ]
        fn += sum(1 for j in expected if not matches[:, j].any())
        if track is not None:
            from_people += _count_near(
                [line for line, matched in zip(lines, on_box, strict=True) if not matched],
                track, PERSON_DISTANCE)
    return detection_scores(tp, fp, fn), from_people


def _judged_lines(local_maps: Mapping[str, Any], segment: Any,
                  truth: Mapping[str, np.ndarray]) -> tuple[list[np.ndarray], np.ndarray]:
    """Return a segment's map polylines clipped to its area and which box each lies on."""
    area = shapely.buffer(segment.safety_area_world, AREA_MARGIN)
    lines = [
        clipped
        for line in local_maps[segment.name].world_polylines().values()
        if len(clipped := clip_to_area(line.points, area))
    ]
    matches = match_polylines_to_boxes(lines, truth) if truth else np.zeros((len(lines), 0))
    return lines, matches


def _count_near(lines: Sequence[np.ndarray], geometry: shapely.Geometry, distance: float) -> int:
    count = 0
    for line in lines:
        shape = shapely.LineString(line) if len(line) > 1 else shapely.Point(line[0])
        count += int(shapely.distance(shape, geometry) <= distance)
    return count


def false_objects_near(
    local_maps: Mapping[str, Any],
    segments: Sequence[Any],
    truth: Mapping[str, np.ndarray],
    area_at: Callable[[float], shapely.Geometry],
    distance: float = VEHICLE_DISTANCE,
) -> int:
    """Return how many false map polylines (on no box) began within ``distance`` of an area.

    ``area_at(t)`` is e.g. where the fleet's vehicles stood at time ``t``: a false
    polyline first seen at ``t`` within ``distance`` of ``area_at(t)`` is counted as made
    of a vehicle (as :func:`score_lap` counts those where a person walked). Asking at the
    polyline's first sighting keeps a vehicle that later drove past an old false
    polyline from taking the blame.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> from semistatic.local_map import LocalMap
    >>> local_map = LocalMap()
    >>> local_map.add([[1.0, 0.0], [1.0, 1.0]], stamp=4.0)   # a vehicle's flank
    0
    >>> segment = SimpleNamespace(name="s", safety_area_world=shapely.box(-5, -5, 5, 5))
    >>> def vehicle_at(t):
    ...     return shapely.box(1.05, -0.2, 2.0, 1.2) if t < 5.0 else shapely.box(3, 3, 4, 4)
    >>> false_objects_near({"s": local_map}, [segment], {}, vehicle_at)
    1
    >>> false_objects_near({"s": local_map}, [segment], {}, lambda t: shapely.Polygon())
    0
    """
    count = 0
    for segment in segments:
        local_map = local_maps[segment.name]
        ids, lines = [], []
        area = shapely.buffer(segment.safety_area_world, AREA_MARGIN)
        for map_id, line in local_map.world_polylines().items():
            clipped = clip_to_area(line.points, area)
            if len(clipped):
                ids.append(map_id)
                lines.append(clipped)
        matches = match_polylines_to_boxes(lines, truth) if truth else np.zeros((len(lines), 0))
        for map_id, line, matched in zip(ids, lines, matches.any(axis=1), strict=True):
            if not matched:
                count += _count_near([line], area_at(local_map[map_id].first_seen), distance)
    return count
