"""Record a run on a timeline for the Rerun viewer: ``semistatic run ... --rrd FILE``.

:class:`RerunRecorder` is an observer of every vehicle of a run
(:attr:`~scenarios.bench.observer.Observer.every_vehicle`). On the simulation clock
(timeline ``sim_time``, :data:`~scenarios.logs.rrd_layout.TIMELINE`) it logs, per
vehicle:

- under ``/map`` (a top-down 2D view in the world frame, x east and y north as REP-103
  has it): the walls, posts and path once; the true boxes whenever the layout changes;
  the people; each vehicle's true footprint and pose, its EKF pose, both trajectories
  of the lap so far, the safety-laser returns, the warning, protective and minimum
  protective fields where the EKF places the vehicle, the readings the field policy did
  not count, and every segment's local-map polylines coloured by status (new, confirmed,
  blank; :mod:`semistatic.colours`);
- under ``/series/KEY/NAME``: time series (:data:`~scenarios.logs.rrd_layout.SERIES`) of
  speed (m/s), speed scale, zone (0 free, 1 warning, 2 protective), separation from the
  nearest person (m) and the EKF's position and heading standard deviations (m, rad);
- under ``/events/NAME``: the events as a text log: stops, slowdowns and releases,
  objects detected and confirmed, infractions, lap starts and ends and box moves.

A replayed real log (``semistatic replay LOG --rrd FILE``) is recorded the same way by
:meth:`RerunRecorder.replayed_scan`: its scans and its maps, at the log's poses.

The file is written beside its final name and renamed into place by :meth:`close`
(``finish=True``), so an interrupted run leaves no half recording; ``viewer`` streams
to a running Rerun viewer as well (``rerun`` started beforehand). Recording only reads
the run: the metrics are bit-identical with or without it.

What a command checks before it records (``--rrd``, ``--viewer``) is in
:mod:`scenarios.logs.rrd_options`; the entity paths, the viewer's default layout and the
recorder's buffers in :mod:`scenarios.logs.rrd_layout`.

Examples
--------
>>> import tempfile, pathlib
>>> from scenarios.bench.testbench import Testbench
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> recorder = RerunRecorder(folder / "pal1.rrd", recording_id="pal1-doctest")
>>> with Testbench("pal1") as bench:
...     bench.add_observer(recorder)
...     bench.reset()
...     for _ in range(50):
...         bench.step()
>>> recorder.close().name
'pal1.rrd'
>>> recorder.scans["robot"] > 0, (folder / "pal1.rrd").stat().st_size > 0
(True, True)
"""

from __future__ import annotations

import math
import os
import secrets
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from scenarios.bench.observer import Observer, VehicleView
from scenarios.bench.records import LapLog, ScanRecord
from scenarios.logs.rrd_layout import (
    EVENTS_ROOT,
    MAP_ROOT,
    SERIES,
    SERIES_ROOT,
    TIMELINE,
    Column,
    VehicleTrack,
    blueprint,
    closed,
    person_separation,
    transform,
)
from semistatic.colours import (
    BOX_COLOUR,
    EKF_COLOUR,
    FIELD_COLOURS,
    PERSON_COLOUR,
    POST_COLOUR,
    RETURNS_COLOUR,
    STATUS_COLOURS,
    TRUE_COLOUR,
    WALL_COLOUR,
    rgba8,
)
from semistatic.local_map import LocalMap
from semistatic.types import Scan

__all__ = ["APPLICATION_ID", "RerunRecorder"]

APPLICATION_ID = "semistatic"
"""The Rerun application id of every recording (the viewer groups recordings by it)."""

TRAIL_S = 0.5
"""Simulated seconds between two updates of the trajectories drawn (each resends the lap)."""

FLUSH_S = 2.0
"""Simulated seconds of per-scan rows buffered before they are sent in columns (a log call
per value and scan cost a third of a run; a viewer streamed to lags by at most this)."""

CLOSE_TIMEOUT_S = 30.0
"""Seconds :meth:`RerunRecorder.close` waits for the data to reach the file and viewer."""

ARROW_M = 0.4
"""Length (m) of the heading arrows."""

MAP_RADIUS = 0.03
"""Half-width (m) of the local-map polylines drawn."""

SEGMENT_COLOUR = (0.8, 0.8, 0.8)
IGNORED_COLOUR = (0.0, 0.75, 0.75)

ZONE_LEVELS = {"clear": 0, "warning": 1, "protective": 2}
"""The zone time series: 0 free, 1 warning, 2 protective."""


class RerunRecorder(Observer):
    """Log every vehicle of a run to a Rerun recording (see the module docstring).

    Parameters
    ----------
    path
        The ``.rrd`` file to write (``None``: none). It appears when :meth:`close` is
        called with ``finish=True``; until then the data goes to a hidden file beside it.
    viewer
        A Rerun viewer's gRPC URL to stream to as well (``None``: none), e.g.
        :data:`~scenarios.logs.rrd_options.DEFAULT_VIEWER_URL`.
    recording_id
        The recording's id (the viewer shows one entry per id); ``None``: a random one.
    staging_dir
        Where the hidden file is written (default: ``path``'s directory; give another
        directory on the same file system when ``path``'s does not exist yet).

    Attributes
    ----------
    scans : dict[str, int]
        Scans logged per vehicle name.
    """

    wants_polylines = True
    every_vehicle = True

    def __init__(self, path: str | os.PathLike[str] | None = None, *,
                 viewer: str | None = None, recording_id: str | None = None,
                 staging_dir: str | os.PathLike[str] | None = None) -> None:
        import rerun as rr

        self._rr = rr
        self.path = None if path is None else Path(path)
        self.stream = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        sinks: list[Any] = []
        self._staged: Path | None = None
        if self.path is not None:
            folder = Path(staging_dir) if staging_dir is not None else self.path.parent
            self._staged = folder / f".{self.path.name}.{secrets.token_hex(4)}.partial"
            self._staged.open("x").close()  # ours alone, with the user's umask
            sinks.append(rr.FileSink(str(self._staged)))
        if viewer is not None:
            sinks.append(rr.GrpcSink(viewer))
        self.stream.set_sinks(*sinks, default_blueprint=blueprint())
        self.scans: dict[str, int] = {}
        self._world_logged = False
        self._lead: str | None = None
        self._layout: int | None = None
        self._vehicles: dict[str, VehicleTrack] = {}
        self._buffers: dict[str, Column] = {}
        self._flushed_at = -math.inf
        self._closed = False

    # ------------------------------------------------------------------ observer hooks
    def on_lap_start(self, vehicle: VehicleView, lap: int) -> None:
        """Log the world once, the boxes of this lap and a lap-start event."""
        self._time(vehicle.sim_time)
        if not self._world_logged:
            self._log_world(vehicle.world, vehicle.segments)
            self._world_logged = True
        if self._lead is None:
            self._lead = vehicle.name
        track = self._track(vehicle.name)
        if not track.started:
            self._log_vehicle(vehicle.name, vehicle.robot.footprint)
            track.started = True
        if self._lead == vehicle.name:
            self._log_boxes(vehicle)
        track.start_lap()
        self._event(vehicle.name, f"lap {lap} starts in segment {vehicle.segment.name}",
                    "INFO")

    def on_scan(self, vehicle: VehicleView, record: ScanRecord) -> None:
        """Buffer one safety scan (poses, returns, fields, map, series) and log its events."""
        name, stamp = vehicle.name, record.scan.stamp
        track = self._track(name)
        root = f"{MAP_ROOT}/{name}"
        true_pose = np.asarray(vehicle.true_pose, dtype=float)
        ekf_pose = np.asarray(record.ekf_pose, dtype=float)
        self._row(f"{root}/true", stamp, **transform(true_pose))
        self._row(f"{root}/ekf", stamp, **transform(ekf_pose))
        # The returns where the beams hit: at the true sensor pose the simulator used.
        scan = record.scan
        self._row(f"{root}/laser/returns", stamp, positions=scan.world_points()[scan.valid_mask()])
        track.add(true_pose, ekf_pose)
        fields = record.fields
        if fields is not None:
            self._time(stamp)
            if track.fields is not fields.protective:  # another segment's fields
                track.fields = fields.protective
                for kind in ("warning", "protective"):
                    self.stream.log(f"{root}/ekf/fields/{kind}", self._rr.LineStrips2D(
                        [closed(getattr(fields, kind))]))
            self._row(f"{root}/ekf/fields/minimum", stamp,
                      strips=[closed(fields.minimum)] if len(fields.minimum) else [])
            self._row(f"{root}/ekf/fields/ignored", stamp, positions=fields.ignored)
            self._row(f"{SERIES_ROOT}/zone/{name}", stamp,
                      scalars=[float(ZONE_LEVELS[fields.zone])])
            self._row(f"{SERIES_ROOT}/speed_scale/{name}", stamp,
                      scalars=[float(fields.speed_scale)])
            self._zone_events(name, track, fields.zone, fields.speed_scale)
        self._log_map(root, stamp, record.segment, record.polylines, record.polyline_status,
                      name, track)
        self._row(f"{SERIES_ROOT}/speed/{name}", stamp, scalars=[float(vehicle.true_twist[0])])
        covariance = np.asarray(record.ekf_covariance, dtype=float)
        self._row(f"{SERIES_ROOT}/ekf_sigma_xy/{name}", stamp, scalars=[
            math.sqrt(max(np.linalg.eigvalsh(covariance[:2, :2])[-1], 0.0))])
        self._row(f"{SERIES_ROOT}/ekf_sigma_theta/{name}", stamp,
                  scalars=[math.sqrt(max(covariance[2, 2], 0.0))])
        separation = person_separation(vehicle, true_pose)
        if separation is not None:
            self._row(f"{SERIES_ROOT}/separation/{name}", stamp, scalars=[separation])
        self._infractions(vehicle, track, stamp)
        if self._lead == name:
            present = [(who, xy) for who, xy in vehicle.person_positions.items()
                       if xy is not None]
            radius = {person.name: person.radius for person in vehicle.world.people}
            self._row(f"{MAP_ROOT}/people", stamp,
                      positions=np.array([xy for _, xy in present], float).reshape(-1, 2),
                      radii=[radius[who] for who, _ in present],
                      labels=[who for who, _ in present])
            if vehicle.layout_revision != self._layout:
                self._time(stamp)
                self._log_boxes(vehicle)
                self._event(name, "boxes moved", "INFO")
        if stamp - track.trail_at >= TRAIL_S:
            track.trail_at = stamp
            self._time(stamp)
            self._log_trails(root, track)
        if stamp - self._flushed_at >= FLUSH_S:
            self._flush()
            self._flushed_at = stamp
        self.scans[name] = self.scans.get(name, 0) + 1

    def on_lap_end(self, vehicle: VehicleView, lap_log: LapLog) -> None:
        """Log the lap's trajectories and a lap-end event."""
        self._flush()
        self._time(vehicle.sim_time)
        self._log_trails(f"{MAP_ROOT}/{vehicle.name}", self._track(vehicle.name))
        how = "completed" if lap_log.completed else "did not complete"
        self._event(vehicle.name, f"lap {lap_log.lap} {how} in {lap_log.duration_s:.1f} s "
                    f"({lap_log.stops} stops, {lap_log.slowdowns} slowdowns)", "INFO")

    # ------------------------------------------------------------------ real logs
    def replayed_scan(self, scan: Scan, pose: np.ndarray, local_map: LocalMap, *,
                      name: str = "log") -> None:
        """Buffer one scan of a replayed real log at ``pose`` with the place's map after it.

        ``pose`` is the laser pose the mapper used (the logged one, or aligned on a
        revisit); ``local_map`` is the map the scan updated.
        """
        track = self._track(name)
        root, stamp = f"{MAP_ROOT}/{name}", scan.stamp
        if not track.started:
            self._log_vehicle(name, None)
            track.started = True
        pose = np.asarray(pose, dtype=float)
        self._row(f"{root}/ekf", stamp, **transform(pose))
        self._row(f"{root}/laser/returns", stamp,
                  positions=scan.world_points(pose)[scan.valid_mask()])
        track.add(pose, pose)
        lines = local_map.world_polylines()
        self._log_map(root, stamp, local_map.segment or "map",
                      [line.points for line in lines.values()],
                      [local_map[map_id].status for map_id in lines], name, track)
        if stamp - track.trail_at >= TRAIL_S:
            track.trail_at = stamp
            self._time(stamp)
            self.stream.log(f"{root}/trajectory/ekf", self._rr.LineStrips2D(
                [np.array(track.ekf)], colors=rgba8(EKF_COLOUR), radii=0.01))
        if stamp - self._flushed_at >= FLUSH_S:
            self._flush()
            self._flushed_at = stamp
        self.scans[name] = self.scans.get(name, 0) + 1

    # ------------------------------------------------------------------ life cycle
    def close(self, *, finish: bool = True) -> Path | None:
        """Flush and close the recording; with ``finish``, move the file into place.

        Without ``finish`` (the run failed or was interrupted) the hidden file is removed
        and nothing appears at ``path``. Returns ``path`` when a file was written.
        """
        if self._closed:
            return self.path if finish and self._staged is not None else None
        self._closed = True
        if finish:
            self._flush()
        # Bounded: a viewer that went away must not hold the command forever.
        self.stream.flush(timeout_sec=CLOSE_TIMEOUT_S)
        self.stream.disconnect()
        if self._staged is None:
            return None
        if finish:
            os.replace(self._staged, self.path)
            return self.path
        self._staged.unlink(missing_ok=True)
        return None

    # ------------------------------------------------------------------ pieces
    def _time(self, seconds: float) -> None:
        self.stream.set_time(TIMELINE, duration=float(seconds))

    def _track(self, name: str) -> VehicleTrack:
        track = self._vehicles.get(name)
        if track is None:
            track = self._vehicles[name] = VehicleTrack()
        return track

    def _row(self, path: str, stamp: float, **components: Any) -> None:
        """Buffer one scan's values of entity ``path`` (sent in columns by :meth:`_flush`)."""
        self._buffers.setdefault(path, Column(path)).add(stamp, components)

    def _flush(self) -> None:
        """Send every buffered row: one ``send_columns`` per entity, not a log per scan."""
        for column in self._buffers.values():
            column.send(self._rr, self.stream)

    def _event(self, name: str, text: str, level: str) -> None:
        self.stream.log(f"{EVENTS_ROOT}/{name}", self._rr.TextLog(text, level=level))

    def _log_world(self, world: Any, segments: Sequence[Any]) -> None:
        rr, stream = self._rr, self.stream
        # The viewer's 2D views draw y downwards (image rows); the map frame has y north.
        stream.log(MAP_ROOT, rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        walls = [closed(wall.corners()) for wall in world.walls]
        if walls:
            stream.log(f"{MAP_ROOT}/walls", rr.LineStrips2D(walls, colors=rgba8(WALL_COLOUR),
                                                        radii=0.02), static=True)
        if world.posts:
            stream.log(f"{MAP_ROOT}/posts", rr.Points2D(
                [post.xy for post in world.posts], radii=[post.radius for post in world.posts],
                colors=rgba8(POST_COLOUR)), static=True)
        areas = [segment for segment in segments if not segment.safety_area_world.is_empty]
        if areas:
            stream.log(f"{MAP_ROOT}/segments", rr.LineStrips2D(
                [shapely.get_coordinates(segment.safety_area_world.boundary)
                 for segment in areas],
                colors=rgba8(SEGMENT_COLOUR), radii=0.005,
                labels=[segment.name for segment in areas]), static=True)
        stream.log(f"{MAP_ROOT}/people", rr.Points2D.from_fields(colors=rgba8(PERSON_COLOUR, 0.8)),
                   static=True)

    def _log_vehicle(self, name: str, footprint: Any) -> None:
        """Log what stays the same of a vehicle: outline, headings, colours (static)."""
        rr, stream, root = self._rr, self.stream, f"{MAP_ROOT}/{name}"
        heading = rr.Arrows2D(origins=[[0.0, 0.0]], vectors=[[ARROW_M, 0.0]], radii=0.015,
                              colors=rgba8(EKF_COLOUR))
        stream.log(f"{root}/ekf/heading", heading, static=True)
        if footprint is not None:
            stream.log(f"{root}/true/heading", rr.Arrows2D(
                origins=[[0.0, 0.0]], vectors=[[ARROW_M, 0.0]], radii=0.015,
                colors=rgba8(TRUE_COLOUR)), static=True)
            stream.log(f"{root}/true/footprint", rr.LineStrips2D(
                [closed(footprint)], colors=rgba8(TRUE_COLOUR), radii=0.015, labels=[name]),
                static=True)
        for kind, colour in FIELD_COLOURS.items():
            stream.log(f"{root}/ekf/fields/{kind}", rr.LineStrips2D.from_fields(
                colors=rgba8(colour), radii=0.015), static=True)
        stream.log(f"{root}/ekf/fields/ignored", rr.Points2D.from_fields(
            colors=rgba8(IGNORED_COLOUR), radii=0.03), static=True)
        stream.log(f"{root}/laser/returns", rr.Points2D.from_fields(
            colors=rgba8(RETURNS_COLOUR), radii=0.02), static=True)
        for key in SERIES:
            stream.log(f"{SERIES_ROOT}/{key}/{name}", rr.SeriesLines(names=name), static=True)

    def _log_boxes(self, vehicle: VehicleView) -> None:
        self._layout = vehicle.layout_revision
        boxes = list(vehicle.world.boxes)
        self.stream.log(f"{MAP_ROOT}/boxes", self._rr.LineStrips2D(
            [closed(box.corners()) for box in boxes], colors=rgba8(BOX_COLOUR), radii=0.025,
            labels=[box.name for box in boxes]))

    def _log_trails(self, root: str, track: VehicleTrack) -> None:
        if len(track.true) < 2:
            return
        for kind, points, colour in (("true", track.true, TRUE_COLOUR),
                                     ("ekf", track.ekf, EKF_COLOUR)):
            self.stream.log(f"{root}/trajectory/{kind}", self._rr.LineStrips2D(
                [np.array(points)], colors=rgba8(colour), radii=0.01))

    def _log_map(self, root: str, stamp: float, segment: str,
                 polylines: Sequence[np.ndarray], statuses: Sequence[str], name: str,
                 track: VehicleTrack) -> None:
        self._row(f"{root}/local_map/{segment}", stamp, strips=list(polylines),
                  colors=[rgba8(STATUS_COLOURS[status]) for status in statuses],
                  radii=[MAP_RADIUS] * len(polylines))
        counts = {status: statuses.count(status) for status in STATUS_COLOURS}
        before = track.map_counts.get(segment, dict.fromkeys(STATUS_COLOURS, 0))
        track.map_counts[segment] = counts
        for status, text, level in (("new", "new object polyline{} detected", "INFO"),
                                    ("confirmed", "polyline{} confirmed", "DEBUG")):
            found = counts[status] - before[status]
            if found > 0:
                self._time(stamp)
                self._event(name, f"{found} {text.format('s' * (found > 1))} in {segment}",
                            level)

    def _zone_events(self, name: str, track: VehicleTrack, zone: str,
                     speed_scale: float) -> None:
        if zone == track.zone:
            return
        # Named as the supervisor counts them: a stop enters the protective zone, a
        # slowdown enters the warning zone from the clear one.
        text = {"protective": "protective stop",
                "warning": "slowdown (warning field)" if track.zone == "clear"
                else "protective field clear, warning field still occupied",
                "clear": "fields clear: full speed"}[zone]
        level = "WARN" if zone == "protective" else "INFO"
        self._event(name, f"{text}, speed scale {speed_scale:.2f}", level)
        track.zone = zone

    def _infractions(self, vehicle: VehicleView, track: VehicleTrack, stamp: float) -> None:
        record = vehicle.log.safety_record
        if record is None or len(record.infractions) == track.infractions:
            return
        self._time(stamp)
        for infraction in record.infractions[track.infractions:]:
            level = "ERROR" if infraction["kind"] == "contact" else "WARN"
            self._event(vehicle.name, f"infraction {infraction['kind']} at "
                        f"({infraction['x']:.2f}, {infraction['y']:.2f}): "
                        f"{infraction['detail']}", level)
        track.infractions = len(record.infractions)
