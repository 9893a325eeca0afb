"""Observers: what an experiment adds to a run without touching the robot's tick.

An observer is any object with some of these methods; the
:class:`~scenarios.bench.testbench.Testbench` calls the ones it has, in the order the
observers were added:

- ``on_lap_start(bench, lap)``: the robot stands re-localised at the path start, the
  lap's boxes are in place;
- ``on_scan(bench, record)``: after each safety-laser scan was used by the safety fields
  and the local map (``record`` is a :class:`~scenarios.bench.records.ScanRecord`);
- ``on_tick(bench)``: after each physics step;
- ``on_lap_end(bench, lap_log)``: the lap is over (``lap_log`` is a
  :class:`~scenarios.bench.records.LapLog` that the observer may complete).

Observers read the bench (``bench.true_pose``, ``bench.local_maps``, ``bench.world`` ...);
they must not drive the robot. An ``on_scan`` observer that never reads the record's
``polylines`` (the segment's whole map, costly to build per scan) says so with a class
attribute ``reads_map_polylines = False``. The bench attaches :class:`GroundTruthScoring` and
:class:`Table1Reference` itself (their results are part of every
:class:`~scenarios.bench.records.RunLog`); :class:`ProgressReporter` and :class:`ScanCallback`
turn a plain callable into an observer.

Examples
--------
>>> class CountScans:
...     def __init__(self):
...         self.scans = 0
...     def on_scan(self, bench, record):
...         self.scans += 1
>>> CountScans().scans
0
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
import shapely

from scenarios.bench.records import LapLog, ScanRecord
from scenarios.results.metrics import (
    MATCH_DISTANCE,
    false_objects_near,
    match_polylines_to_boxes,
    score_lap,
)
from scenarios.spec.scenario import ScenarioSpec
from semistatic.frames import transform_points
from sim.debug_view import DebugView
from sim.ground_truth import box_outlines

__all__ = [
    "GUI_REFRESH_HZ",
    "OBSERVED_DISTANCE",
    "OBSERVED_READINGS",
    "STATUS_COLOURS",
    "GroundTruthScoring",
    "GuiView",
    "ProgressReporter",
    "ScanCallback",
    "Table1Reference",
    "hook_table",
    "moved_boxes",
]

OBSERVED_READINGS = 5
"""Safety-laser readings within ``OBSERVED_DISTANCE`` of a box that count as seeing it."""

OBSERVED_DISTANCE = 0.03
"""Metres from a true box outline within which a reading counts as a hit on the box."""


HOOKS = ("on_tick", "on_scan", "on_lap_start", "on_lap_end")
"""The points of the closed loop where observers are called (module docstring)."""


def hook_table(observers: list) -> dict:
    """Return each hook's bound methods among ``observers``, and ``"wants_polylines"``.

    Built once per observer set by whoever calls the observers (the bench, a fleet's
    vehicle), so the per-scan path does not ask every observer again. ``"wants_polylines"``
    says whether an ``on_scan`` observer may read ``ScanRecord.polylines`` (observers say
    ``reads_map_polylines = False`` to spare the map copy).

    Examples
    --------
    >>> class Counter:
    ...     reads_map_polylines = False
    ...     def on_scan(self, bench, record): ...
    >>> table = hook_table([Counter()])
    >>> len(table["on_scan"]), len(table["on_tick"]), table["wants_polylines"]
    (1, 0, False)
    """
    table: dict = {hook: [getattr(o, hook) for o in observers if hasattr(o, hook)]
                   for hook in HOOKS}
    table["wants_polylines"] = any(getattr(o, "reads_map_polylines", True)
                                   for o in observers if hasattr(o, "on_scan"))
    return table


GUI_REFRESH_HZ = 4.0
"""Redraws per simulated second of the GUI's debug items (each redraw costs a frame)."""

STATUS_COLOURS = {
    "new": (0.1, 0.45, 1.0),
    "confirmed": (0.0, 0.65, 0.0),
    "blank": (0.55, 0.55, 0.55),
}
"""Colour (RGB) of a local-map polyline by its life-cycle status."""

WARNING_COLOUR = (1.0, 0.6, 0.0)
PROTECTIVE_COLOUR = (0.9, 0.0, 0.0)
RETURNS_COLOUR = (0.75, 0.0, 0.75)


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


class GroundTruthScoring:
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

    reads_map_polylines = False

    def __init__(self) -> None:
        self._truth: dict[str, np.ndarray] = {}
        self._revision = -1
        self._watch: tuple[str, ...] = ()
        self._first_seen: dict[str, int] = {}
        self._detected_at: dict[str, int] = {}
        self._person_tracks: list[np.ndarray] = []
        self._vehicle_outlines: list[tuple[float, list[np.ndarray]]] = []

    def _current_truth(self, bench) -> dict[str, np.ndarray]:
        if self._revision != bench.layout_revision:
            self._truth = box_outlines(bench.world)
            self._revision = bench.layout_revision
        return self._truth

    def on_lap_start(self, bench, lap: int) -> None:
        """Read the lap's boxes and decide which ones to time."""
        self._current_truth(bench)
        self._watch = moved_boxes(bench.spec, lap)
        self._first_seen, self._detected_at = {}, {}
        self._person_tracks = []

    def on_scan(self, bench, record: ScanRecord) -> None:
        """Note where people stand and whether a watched box was seen and mapped."""
        self._person_tracks.extend(p for p in bench.person_positions.values() if p is not None)
        outlines = getattr(bench, "vehicle_outlines", None)
        if outlines is not None:
            self._vehicle_outlines.append((record.scan.stamp, outlines()))
        if not self._watch:
            return
        truth = self._current_truth(bench)
        scan = record.scan
        scans_so_far = bench.lap_log.safety_scans
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
            if name in self._first_seen and _mapped(bench.local_maps.values(), outline):
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

    def on_lap_end(self, bench, lap_log: LapLog) -> None:
        """Score the lap's maps and write the figures into ``lap_log``."""
        truth = self._current_truth(bench)
        lap_log.latencies = self.latencies()
        lap_log.detection, lap_log.false_objects_from_people = score_lap(
            bench.local_maps, bench.segments, truth, self._person_tracks
        )
        if hasattr(bench, "vehicle_outlines"):
            lap_log.false_objects_from_vehicles = false_objects_near(
                bench.local_maps, bench.segments, truth, self._vehicles_at)
        bench.log.truth_after_lap.append(truth)

    def _vehicles_at(self, t: float) -> shapely.Geometry:
        """Return where the vehicles stood at the safety scan nearest ``t`` (of the run)."""
        if not self._vehicle_outlines:
            return shapely.Polygon()
        stamps = np.array([stamp for stamp, _ in self._vehicle_outlines])
        outlines = self._vehicle_outlines[int(np.argmin(np.abs(stamps - t)))][1]
        return shapely.union_all(shapely.polygons(outlines)) if outlines else shapely.Polygon()


class Table1Reference:
    """The paper's Table 1 experiment (Sec. 6) beside the operating maps.

    Lap 1 builds the local maps; at its end they are copied as the reference. In every
    later lap each safety scan's polylines are associated with the reference of their
    segment without changing it, and the restricted Hausdorff distance of every pair is
    recorded under ``"segment/map id"`` in ``bench.log.table1_distances``. The first pair
    of two polylines with at least three vertices each is kept as ``example_pair`` (paper
    Fig. 2).

    Examples
    --------
    >>> Table1Reference().reference
    {}
    """

    reads_map_polylines = False

    def __init__(self) -> None:
        self.reference: dict = {}

    def on_scan(self, bench, record: ScanRecord) -> None:
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
        log = bench.log
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

    def on_lap_end(self, bench, lap_log: LapLog) -> None:
        """After lap 1, keep a copy of the local maps as the reference."""
        if lap_log.lap == 1:
            self.reference = copy.deepcopy(dict(bench.local_maps))
            bench.log.reference_maps = self.reference


class ProgressReporter:
    """Call ``advance(seconds)`` with the simulated time of every physics step (a progress bar).

    Examples
    --------
    >>> seen = []
    >>> ProgressReporter(seen.append).advance is not None
    True
    """

    def __init__(self, advance: Callable[[float], None]) -> None:
        self.advance = advance

    def on_tick(self, bench) -> None:
        """Report one physics step."""
        self.advance(bench.time_step)


class ScanCallback:
    """Call ``callback(record)`` with every scan's :class:`~scenarios.bench.records.ScanRecord`.

    E.g. a :class:`~scenarios.logs.bag.BagRecorder`.

    Examples
    --------
    >>> records = []
    >>> ScanCallback(records.append).callback == records.append
    True
    """

    def __init__(self, callback: Callable[[ScanRecord], None]) -> None:
        self.callback = callback

    def on_scan(self, bench, record: ScanRecord) -> None:
        """Pass the record on."""
        self.callback(record)


class GuiView:
    """Show the run in PyBullet's window (the bench adds it when ``gui=True``).

    A few times per simulated second (``refresh_hz``) the camera is put above the robot
    and the debug items are redrawn: the current segment's warning (orange) and
    protective (red) fields where the EKF places the robot, the last safety scan's
    returns (magenta) and every local map's polylines, coloured by life-cycle status
    (:data:`STATUS_COLOURS`). Headless, it draws nothing.

    Examples
    --------
    >>> GuiView().refresh_hz
    4.0
    """

    reads_map_polylines = False

    def __init__(self, refresh_hz: float = GUI_REFRESH_HZ) -> None:
        self.refresh_hz = float(refresh_hz)
        self.view: DebugView | None = None
        self._returns = np.empty((0, 2))
        self._drawn_at = -np.inf

    def on_lap_start(self, bench, lap: int) -> None:
        """Bind to the bench's client and draw at once: the robot is back at the start."""
        if self.view is None or self.view.sim is not bench.sim:
            self.view = DebugView(bench.sim)
        self._returns = np.empty((0, 2))
        self.draw(bench)

    def on_scan(self, bench, record: ScanRecord) -> None:
        """Keep the scan's returns (world frame) for the next redraw."""
        scan = record.scan
        self._returns = scan.world_points()[scan.valid_mask()]

    def on_tick(self, bench) -> None:
        """Redraw when ``1 / refresh_hz`` simulated seconds have passed."""
        if bench.sim_time - self._drawn_at >= 1.0 / self.refresh_hz:
            self.draw(bench)

    def draw(self, bench) -> None:
        """Move the camera and redraw every item now."""
        view = self.view
        if view is None or not view.active:
            return
        self._drawn_at = bench.sim_time
        view.follow(bench.true_pose)
        pose, fields = bench.ekf_pose, bench.segment.fields
        view.draw_polylines(
            "fields",
            [transform_points(pose, fields.warning), transform_points(pose, fields.protective)],
            [WARNING_COLOUR, PROTECTIVE_COLOUR],
            closed=True,
        )
        view.draw_points("returns", self._returns, RETURNS_COLOUR)
        lines, colours = [], []
        for local_map in bench.local_maps.values():
            for map_id, line in local_map.world_polylines().items():
                lines.append(line.points)
                colours.append(STATUS_COLOURS[local_map[map_id].status])
        view.draw_polylines("maps", lines, colours, width=3.0)
