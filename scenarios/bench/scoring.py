"""Scoring observers: each lap's maps against ground truth, and the paper's Table 1.

The bench attaches both to every vehicle it runs; their results are part of every
:class:`~scenarios.bench.records.RunLog`. A recording's replay runs them again on recorded
scans (:mod:`scenarios.logs.recording`).

Examples
--------
>>> GroundTruthScoring().latencies(), Table1Reference().reference
({}, {})
"""

from __future__ import annotations

import copy

import numpy as np
import shapely

from scenarios.bench.ground_truth import (
    MATCH_DISTANCE,
    false_objects_near,
    match_polylines_to_boxes,
    score_lap,
)
from scenarios.bench.observer import Observer, VehicleView
from scenarios.bench.records import LapLog, ScanRecord
from scenarios.spec.scenario import ScenarioSpec
from semistatic.frames import transform_points
from sim.ground_truth import box_outlines

__all__ = [
    "OBSERVED_DISTANCE",
    "OBSERVED_READINGS",
    "GroundTruthScoring",
    "Table1Reference",
    "moved_boxes",
]

OBSERVED_READINGS = 5
"""Safety-laser readings within ``OBSERVED_DISTANCE`` of a box that count as seeing it."""

OBSERVED_DISTANCE = 0.03
"""Metres from a true box outline within which a reading counts as a hit on the box."""


def moved_boxes(spec: ScenarioSpec, lap: int) -> tuple[str, ...]:
    """Return the boxes moved or added before ``lap`` (their detection latency is measured).

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> moved_boxes(load_scenario("sim1"), 3), moved_boxes(load_scenario("sim1"), 4)
    (('carton_aisle',), ())
    """
    return tuple(m.box for m in spec.moves if m.lap == lap and m.action in ("move", "add"))


def _near_box(outline: np.ndarray, margin: float) -> tuple[float, float, float, float]:
    """Return the bounding box of ``outline`` grown by ``margin`` (m) on every side."""
    low, high = outline.min(axis=0) - margin, outline.max(axis=0) + margin
    return float(low[0]), float(low[1]), float(high[0]), float(high[1])


def _hits(outline: np.ndarray, points: np.ndarray) -> int:
    """Return how many ``points`` lie within ``OBSERVED_DISTANCE`` of the closed ``outline``.

    Only points in the outline's box grown by twice that distance can (the margin covers
    rounding), so GEOS measures those alone, and none when they are too few to count.
    """
    xmin, ymin, xmax, ymax = _near_box(outline, 2.0 * OBSERVED_DISTANCE)
    x, y = points[:, 0], points[:, 1]
    near = points[(x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)]
    if near.shape[0] < OBSERVED_READINGS:
        return 0
    ring = shapely.LinearRing(np.vstack([outline, outline[:1]]))
    return int(np.count_nonzero(shapely.distance(ring, shapely.points(near))
                                <= OBSERVED_DISTANCE))


def _mapped(local_maps, outline: np.ndarray) -> bool:
    """Return whether a polyline of ``local_maps`` lies on the box ``outline``.

    :func:`~scenarios.results.metrics.match_polylines_to_boxes` on the world-frame polylines whose
    vertices all lie in the outline's box grown by twice ``MATCH_DISTANCE``: a polyline
    with a vertex outside cannot lie on the outline. The test is made in each map's
    segment frame on the grown box's corners, so only candidates are moved to the world.
    """
    xmin, ymin, xmax, ymax = _near_box(outline, 2.0 * MATCH_DISTANCE)
    corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
    lines = []
    for local_map in local_maps:
        # The grown box in the segment frame, boxed again: a superset of the candidates.
        xs, ys = transform_points(local_map.world_in_local, corners).T.tolist()
        lx, ly, hx, hy = min(xs), min(ys), max(xs), max(ys)
        for line in local_map.polylines().values():
            bx0, by0, bx1, by1 = line.box
            if bx0 >= lx and by0 >= ly and bx1 <= hx and by1 <= hy:
                lines.append(line.transformed(local_map.origin).points)
    return bool(lines) and bool(match_polylines_to_boxes(lines, {"box": outline}).any())


class GroundTruthScoring(Observer):
    """Score each lap's local maps against the simulator's ground truth.

    Per lap: detection precision/recall (:func:`scenarios.results.metrics.score_lap`), objects
    made from people (their positions at every safety scan), in a fleet objects made from
    vehicles (false polylines first seen where a vehicle's true footprint stood, from the
    bench's ``vehicle_outlines()`` at every safety scan), and for each box moved or
    added before the lap the detection latency: safety scans from the first that sees it
    (``OBSERVED_READINGS`` readings within ``OBSERVED_DISTANCE`` of its true outline) to
    the first with a map polyline on it. Results go into the lap log (``detection``,
    ``false_objects_from_people``, ``false_objects_from_vehicles``, ``latencies``) and
    the run log's ``truth_after_lap``.
    The truth is read again whenever a box is moved, added or removed.

    Examples
    --------
    >>> GroundTruthScoring().latencies()
    {}
    """

    def __init__(self) -> None:
        self._truth: dict[str, np.ndarray] = {}
        self._revision = -1
        self._watch: tuple[str, ...] = ()
        self._first_seen: dict[str, int] = {}
        self._detected_at: dict[str, int] = {}
        self._person_tracks: list[np.ndarray] = []
        self._vehicle_outlines: list[tuple[float, list[np.ndarray]]] = []

    def _current_truth(self, vehicle: VehicleView) -> dict[str, np.ndarray]:
        if self._revision != vehicle.layout_revision:
            self._truth = box_outlines(vehicle.world)
            self._revision = vehicle.layout_revision
        return self._truth

    def on_lap_start(self, vehicle: VehicleView, lap: int) -> None:
        """Read the lap's boxes and decide which ones to time."""
        self._current_truth(vehicle)
        self._watch = moved_boxes(vehicle.spec, lap)
        self._first_seen, self._detected_at = {}, {}
        self._person_tracks = []

    def on_scan(self, vehicle: VehicleView, record: ScanRecord) -> None:
        """Note where people stand and whether a watched box was seen and mapped."""
        self._person_tracks.extend(p for p in vehicle.person_positions.values() if p is not None)
        if vehicle.fleet_size > 1:
            self._vehicle_outlines.append((record.scan.stamp, vehicle.vehicle_outlines()))
        if not self._watch:
            return
        truth = self._current_truth(vehicle)
        scan = record.scan
        scans_so_far = vehicle.lap_log.safety_scans
        true_points = None
        for name in self._watch:
            if name in self._detected_at or name not in truth:
                continue
            outline = truth[name]
            if name not in self._first_seen:
                if true_points is None:
                    true_points = scan.world_points()[scan.valid_mask()]
                if _hits(outline, true_points) >= OBSERVED_READINGS:
                    self._first_seen[name] = scans_so_far
            if name in self._first_seen and _mapped(vehicle.local_maps.values(), outline):
                self._detected_at[name] = scans_so_far

    def latencies(self) -> dict[str, int | None]:
        """Return the detection latency (safety scans) of each watched box seen this lap."""
        return {
            name: (self._detected_at[name] - self._first_seen[name])
            if name in self._detected_at
            else None
            for name in self._watch
            if name in self._first_seen
        }

    def on_lap_end(self, vehicle: VehicleView, lap_log: LapLog) -> None:
        """Score the lap's maps and write the figures into ``lap_log``."""
        truth = self._current_truth(vehicle)
        lap_log.latencies = self.latencies()
        lap_log.detection, lap_log.false_objects_from_people = score_lap(
            vehicle.local_maps, vehicle.segments, truth, self._person_tracks
        )
        if vehicle.fleet_size > 1:
            lap_log.false_objects_from_vehicles = false_objects_near(
                vehicle.local_maps, vehicle.segments, truth, self._vehicles_at)
        vehicle.log.truth_after_lap.append(truth)

    def _vehicles_at(self, t: float) -> shapely.Geometry:
        """Return where the vehicles stood at the safety scan nearest ``t`` (of the run)."""
        if not self._vehicle_outlines:
            return shapely.Polygon()
        stamps = np.array([stamp for stamp, _ in self._vehicle_outlines])
        outlines = self._vehicle_outlines[int(np.argmin(np.abs(stamps - t)))][1]
        return shapely.union_all(shapely.polygons(outlines)) if outlines else shapely.Polygon()


class Table1Reference(Observer):
    """The paper's Table 1 experiment (Sec. 6) beside the operating maps.

    Lap 1 builds the local maps; at its end they are copied as the reference. In every
    later lap each safety scan's polylines are associated with the reference of their
    segment without changing it, and the restricted Hausdorff distance of every pair is
    recorded under ``"segment/map id"`` in ``vehicle.log.table1_distances``. The first pair
    of two polylines with at least three vertices each is kept as ``example_pair`` (paper
    Fig. 2).

    Examples
    --------
    >>> Table1Reference().reference
    {}
    """

    def __init__(self) -> None:
        self.reference: dict = {}

    def on_scan(self, vehicle: VehicleView, record: ScanRecord) -> None:
        """Associate the scan's polylines with the lap-1 reference of its segment."""
        if record.lap == 1 or record.report is None:
            return
        reference = self.reference[record.segment]
        # Same segment frame, same scan: the polylines extracted for the local map serve.
        # Table 1 reads the pairs only, not which reference polylines were missed.
        report = reference.associate(
            record.scan, record.sensor_pose, scan_polylines=record.report.scan_polylines,
            find_missed=False,
        )
        log = vehicle.log
        for pair in report.associated:
            key = f"{record.segment}/{pair.map_id}"
            log.table1_distances.setdefault(key, []).append(pair.distance)
            if log.example_pair is None:
                scan_line = report.scan_polylines[pair.scan_index]
                map_line = reference[pair.map_id].polyline
                if len(scan_line) >= 3 and len(map_line) >= 3:
                    origin = reference.origin
                    log.example_pair = (
                        transform_points(origin, map_line.points),
                        transform_points(origin, scan_line.points),
                    )

    def on_lap_end(self, vehicle: VehicleView, lap_log: LapLog) -> None:
        """After lap 1, keep a copy of the local maps as the reference."""
        if lap_log.lap == 1:
            self.reference = copy.deepcopy(dict(vehicle.local_maps))
            vehicle.log.reference_maps = self.reference
