"""Record a run on a timeline for the Rerun viewer: ``semistatic run ... --rrd FILE``.

:class:`RerunRecorder` is an observer of every vehicle of a run
(:attr:`~scenarios.bench.observer.Observer.every_vehicle`). On the simulation clock
(timeline ``sim_time``) it logs, per vehicle:

- under ``/map`` (a top-down 2D view in the world frame, x east and y north as REP-103
  has it): the walls, posts and path once; the true boxes whenever the layout changes;
  the people; each vehicle's true footprint and pose, its EKF pose, both trajectories
  of the lap so far, the safety-laser returns, the warning, protective and minimum
  protective fields where the EKF places the vehicle, the readings the field policy did
  not count, and every segment's local-map polylines coloured by status (new, confirmed,
  blank; :mod:`semistatic.colours`);
- under ``/series/KEY/NAME``: time series (:data:`SERIES`) of speed (m/s), speed scale,
  zone (0 free, 1 warning, 2 protective), separation from the nearest person (m) and
  the EKF's position and heading standard deviations (m, rad);
- under ``/events/NAME``: the events as a text log: stops, slowdowns and releases,
  objects detected and confirmed, infractions, lap starts and ends and box moves.

A replayed real log (``semistatic replay LOG --rrd FILE``) is recorded the same way by
:meth:`RerunRecorder.replayed_scan`: its scans and its maps, at the log's poses.

The file is written beside its final name and renamed into place by :meth:`close`
(``finish=True``), so an interrupted run leaves no half recording; ``viewer`` streams
to a running Rerun viewer as well (``rerun`` started beforehand). Recording only reads
the run: the metrics are bit-identical with or without it.

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
import socket
import urllib.parse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from scenarios.bench.observer import Observer, VehicleView
from scenarios.bench.records import LapLog, ScanRecord
from scenarios.process.errors import InputError
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
from semistatic.frames import transform_points
from semistatic.local_map import LocalMap
from semistatic.types import Scan

__all__ = [
    "APPLICATION_ID",
    "DEFAULT_VIEWER_URL",
    "TIMELINE",
    "RerunRecorder",
    "check_new_rrd_path",
    "check_viewer",
    "open_timeline",
    "rerun_missing",
]

APPLICATION_ID = "semistatic"
"""The Rerun application id of every recording (the viewer groups recordings by it)."""

TIMELINE = "sim_time"
"""The timeline: simulated seconds since the run started (a replay: the log's stamps)."""

DEFAULT_VIEWER_URL = "rerun+http://127.0.0.1:9876/proxy"
"""Where ``--viewer`` streams to by default: a ``rerun`` viewer started on this machine."""

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

_MAP = "/map"
_SERIES = "/series"
_EVENTS = "/events"

SERIES = {
    "speed": "speed (m/s)",
    "speed_scale": "speed scale (1 free, 0 stopped)",
    "zone": "zone (0 free, 1 warning, 2 protective)",
    "separation": "separation from the nearest person (m)",
    "ekf_sigma_xy": "EKF position sigma (m, major axis)",
    "ekf_sigma_theta": "EKF heading sigma (rad)",
}
"""The time series of each vehicle: ``/series/KEY/VEHICLE``, one plot per key."""


def rerun_missing() -> str | None:
    """Return why Rerun recordings cannot be made here, or ``None`` when they can.

    Examples
    --------
    >>> rerun_missing() is None   # the test extra installs rerun-sdk
    True
    """
    try:
        import rerun  # noqa: F401
    except ImportError:
        return ("Rerun recordings need the rerun-sdk package: pip install 'semistatic[rerun]' "
                "(or pip install rerun-sdk)")
    return None


def check_new_rrd_path(path: str | os.PathLike[str], *, option: str = "--rrd",
                       out: Path | None = None) -> Path:
    """Return ``path`` if a recording can be written there, else raise ``ValueError``.

    Called before a run, so a bad ``--rrd`` costs nothing: the name must end in ``.rrd``,
    its directory must exist, and it must not exist yet, unless it lies directly in
    ``out``, the run's output directory (written first, replacing a previous result whole).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> check_new_rrd_path(folder / "run.rrd").name
    'run.rrd'
    >>> check_new_rrd_path(folder / "run.txt")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: ...run.txt: --rrd: a Rerun recording's name ends in .rrd; e.g. --rrd run.rrd
    >>> folder.rmdir()
    """
    path = Path(path)
    if path.suffix != ".rrd":
        raise ValueError(f"{path}: {option}: a Rerun recording's name ends in .rrd; "
                         f"e.g. {option} run.rrd")
    parent = path.resolve().parent
    if out is not None and path.resolve() == out.resolve():
        raise ValueError(f"{path}: {option}: is the --out directory; e.g. {option} OUT/run.rrd")
    if out is not None and parent == out.resolve():
        return path  # lands in the new result, which replaces the old one whole
    if path.exists() or path.is_symlink():
        raise ValueError(f"{path}: {option}: exists already; choose a new file name or "
                         "remove the old recording")
    if not parent.is_dir():
        raise ValueError(f"{path}: {option}: the directory {path.parent} does not exist; "
                         "create it first")
    if not os.access(parent, os.W_OK):
        raise ValueError(f"{path}: {option}: the directory {path.parent} is not writable")
    return path


def check_viewer(url: str, *, timeout: float = 2.0) -> None:
    """Raise :class:`~scenarios.process.errors.InputError` unless a viewer listens at ``url``.

    Checked before a run: streaming to an address where nothing listens would hold the
    command at its end, waiting for a viewer.

    Examples
    --------
    >>> check_viewer("http://127.0.0.1:9876")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    scenarios.process.errors.InputError: --viewer: ... a Rerun viewer's address looks like rerun+http://127.0.0.1:9876/proxy
    """
    parsed = urllib.parse.urlsplit(url)
    if parsed.scheme not in ("rerun", "rerun+http", "rerun+https") or parsed.path != "/proxy":
        raise InputError(f"--viewer: {url!r} is not a Rerun viewer's address; a Rerun "
                         f"viewer's address looks like {DEFAULT_VIEWER_URL}")
    host, port = parsed.hostname or "127.0.0.1", parsed.port or 9876
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as error:
        raise InputError(f"--viewer: no Rerun viewer listens at {url} ({error.strerror or error}); "
                         "start one first with: rerun") from None


def open_timeline(rrd: Path | None, viewer: str | None, out: Path | None,
                  recording_id: str) -> RerunRecorder | None:
    """Return a :class:`RerunRecorder` for a command's ``--rrd``/``--viewer``, or ``None``.

    Checked before any work: the rerun-sdk package, and a new ``.rrd`` path (which may lie
    inside ``out``, the run's output directory, written before the recording lands).
    Bad input raises :class:`~scenarios.process.errors.InputError` (one line, exit 2).

    Examples
    --------
    >>> open_timeline(None, None, None, "run") is None
    True
    >>> open_timeline(Path("run.txt"), None, None, "run")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    scenarios.process.errors.InputError: run.txt: --rrd: a Rerun recording's name ends in .rrd...
    """
    if rrd is None and viewer is None:
        return None
    missing = rerun_missing()
    if missing is not None:
        raise InputError(f"--rrd/--viewer: {missing}")
    if viewer is not None:
        check_viewer(viewer)
    staging = None
    if rrd is not None:
        try:
            check_new_rrd_path(rrd, out=out)
        except ValueError as error:
            raise InputError(str(error)) from None
        parent = rrd.resolve().parent
        # A recording inside --out is staged beside --out (same file system), then moved
        # into the new result: staged inside, the result replacing the old one takes it.
        inside = out is not None and parent == out.resolve()
        staging = out.resolve().parent if inside else parent
    return RerunRecorder(rrd, viewer=viewer, recording_id=recording_id, staging_dir=staging)


class RerunRecorder(Observer):
    """Log every vehicle of a run to a Rerun recording (see the module docstring).

    Parameters
    ----------
    path
        The ``.rrd`` file to write (``None``: none). It appears when :meth:`close` is
        called with ``finish=True``; until then the data goes to a hidden file beside it.
    viewer
        A Rerun viewer's gRPC URL to stream to as well (``None``: none), e.g.
        :data:`DEFAULT_VIEWER_URL`.
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
        self.stream.set_sinks(*sinks, default_blueprint=_blueprint())
        self.scans: dict[str, int] = {}
        self._world_logged = False
        self._lead: str | None = None
        self._layout: int | None = None
        self._vehicles: dict[str, _VehicleTrack] = {}
        self._buffers: dict[str, _Column] = {}
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
        root = f"{_MAP}/{name}"
        true_pose = np.asarray(vehicle.true_pose, dtype=float)
        ekf_pose = np.asarray(record.ekf_pose, dtype=float)
        self._row(f"{root}/true", stamp, **_transform(true_pose))
        self._row(f"{root}/ekf", stamp, **_transform(ekf_pose))
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
                        [_closed(getattr(fields, kind))]))
            self._row(f"{root}/ekf/fields/minimum", stamp,
                      strips=[_closed(fields.minimum)] if len(fields.minimum) else [])
            self._row(f"{root}/ekf/fields/ignored", stamp, positions=fields.ignored)
            self._row(f"{_SERIES}/zone/{name}", stamp,
                      scalars=[float(ZONE_LEVELS[fields.zone])])
            self._row(f"{_SERIES}/speed_scale/{name}", stamp,
                      scalars=[float(fields.speed_scale)])
            self._zone_events(name, track, fields.zone, fields.speed_scale)
        self._log_map(root, stamp, record.segment, record.polylines, record.polyline_status,
                      name, track)
        self._row(f"{_SERIES}/speed/{name}", stamp, scalars=[float(vehicle.true_twist[0])])
        covariance = np.asarray(record.ekf_covariance, dtype=float)
        self._row(f"{_SERIES}/ekf_sigma_xy/{name}", stamp, scalars=[
            math.sqrt(max(np.linalg.eigvalsh(covariance[:2, :2])[-1], 0.0))])
        self._row(f"{_SERIES}/ekf_sigma_theta/{name}", stamp,
                  scalars=[math.sqrt(max(covariance[2, 2], 0.0))])
        separation = _person_separation(vehicle, true_pose)
        if separation is not None:
            self._row(f"{_SERIES}/separation/{name}", stamp, scalars=[separation])
        self._infractions(vehicle, track, stamp)
        if self._lead == name:
            present = [(who, xy) for who, xy in vehicle.person_positions.items()
                       if xy is not None]
            radius = {person.name: person.radius for person in vehicle.world.people}
            self._row(f"{_MAP}/people", stamp,
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
        self._log_trails(f"{_MAP}/{vehicle.name}", self._track(vehicle.name))
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
        root, stamp = f"{_MAP}/{name}", scan.stamp
        if not track.started:
            self._log_vehicle(name, None)
            track.started = True
        pose = np.asarray(pose, dtype=float)
        self._row(f"{root}/ekf", stamp, **_transform(pose))
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

    def _track(self, name: str) -> _VehicleTrack:
        track = self._vehicles.get(name)
        if track is None:
            track = self._vehicles[name] = _VehicleTrack()
        return track

    def _row(self, path: str, stamp: float, **components: Any) -> None:
        """Buffer one scan's values of entity ``path`` (sent in columns by :meth:`_flush`)."""
        self._buffers.setdefault(path, _Column(path)).add(stamp, components)

    def _flush(self) -> None:
        """Send every buffered row: one ``send_columns`` per entity, not a log per scan."""
        for column in self._buffers.values():
            column.send(self._rr, self.stream)

    def _event(self, name: str, text: str, level: str) -> None:
        self.stream.log(f"{_EVENTS}/{name}", self._rr.TextLog(text, level=level))

    def _log_world(self, world: Any, segments: Sequence[Any]) -> None:
        rr, stream = self._rr, self.stream
        # The viewer's 2D views draw y downwards (image rows); the map frame has y north.
        stream.log(_MAP, rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        walls = [_closed(wall.corners()) for wall in world.walls]
        if walls:
            stream.log(f"{_MAP}/walls", rr.LineStrips2D(walls, colors=rgba8(WALL_COLOUR),
                                                        radii=0.02), static=True)
        if world.posts:
            stream.log(f"{_MAP}/posts", rr.Points2D(
                [post.xy for post in world.posts], radii=[post.radius for post in world.posts],
                colors=rgba8(POST_COLOUR)), static=True)
        areas = [segment for segment in segments if not segment.safety_area_world.is_empty]
        if areas:
            stream.log(f"{_MAP}/segments", rr.LineStrips2D(
                [shapely.get_coordinates(segment.safety_area_world.boundary)
                 for segment in areas],
                colors=rgba8(SEGMENT_COLOUR), radii=0.005,
                labels=[segment.name for segment in areas]), static=True)
        stream.log(f"{_MAP}/people", rr.Points2D.from_fields(colors=rgba8(PERSON_COLOUR, 0.8)),
                   static=True)

    def _log_vehicle(self, name: str, footprint: Any) -> None:
        """Log what stays the same of a vehicle: outline, headings, colours (static)."""
        rr, stream, root = self._rr, self.stream, f"{_MAP}/{name}"
        heading = rr.Arrows2D(origins=[[0.0, 0.0]], vectors=[[ARROW_M, 0.0]], radii=0.015,
                              colors=rgba8(EKF_COLOUR))
        stream.log(f"{root}/ekf/heading", heading, static=True)
        if footprint is not None:
            stream.log(f"{root}/true/heading", rr.Arrows2D(
                origins=[[0.0, 0.0]], vectors=[[ARROW_M, 0.0]], radii=0.015,
                colors=rgba8(TRUE_COLOUR)), static=True)
            stream.log(f"{root}/true/footprint", rr.LineStrips2D(
                [_closed(footprint)], colors=rgba8(TRUE_COLOUR), radii=0.015, labels=[name]),
                static=True)
        for kind, colour in FIELD_COLOURS.items():
            stream.log(f"{root}/ekf/fields/{kind}", rr.LineStrips2D.from_fields(
                colors=rgba8(colour), radii=0.015), static=True)
        stream.log(f"{root}/ekf/fields/ignored", rr.Points2D.from_fields(
            colors=rgba8(IGNORED_COLOUR), radii=0.03), static=True)
        stream.log(f"{root}/laser/returns", rr.Points2D.from_fields(
            colors=rgba8(RETURNS_COLOUR), radii=0.02), static=True)
        for key in SERIES:
            stream.log(f"{_SERIES}/{key}/{name}", rr.SeriesLines(names=name), static=True)

    def _log_boxes(self, vehicle: VehicleView) -> None:
        self._layout = vehicle.layout_revision
        boxes = list(vehicle.world.boxes)
        self.stream.log(f"{_MAP}/boxes", self._rr.LineStrips2D(
            [_closed(box.corners()) for box in boxes], colors=rgba8(BOX_COLOUR), radii=0.025,
            labels=[box.name for box in boxes]))

    def _log_trails(self, root: str, track: _VehicleTrack) -> None:
        if len(track.true) < 2:
            return
        for kind, points, colour in (("true", track.true, TRUE_COLOUR),
                                     ("ekf", track.ekf, EKF_COLOUR)):
            self.stream.log(f"{root}/trajectory/{kind}", self._rr.LineStrips2D(
                [np.array(points)], colors=rgba8(colour), radii=0.01))

    def _log_map(self, root: str, stamp: float, segment: str,
                 polylines: Sequence[np.ndarray], statuses: Sequence[str], name: str,
                 track: _VehicleTrack) -> None:
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

    def _zone_events(self, name: str, track: _VehicleTrack, zone: str,
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

    def _infractions(self, vehicle: VehicleView, track: _VehicleTrack, stamp: float) -> None:
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


_VECTOR_SIZE = {"positions": 2, "translation": 3, "quaternion": 4}


class _Column:
    """The buffered per-scan rows of one entity: each a few components of N instances."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.times: list[float] = []
        self.rows: list[dict[str, Any]] = []

    def add(self, stamp: float, components: dict[str, Any]) -> None:
        self.times.append(stamp)
        self.rows.append(components)

    def send(self, rr: Any, stream: Any) -> None:
        if not self.times:
            return
        first = self.rows[0]
        archetype = (rr.Transform3D if "translation" in first else
                     rr.Scalars if "scalars" in first else
                     rr.LineStrips2D if "strips" in first else rr.Points2D)
        lengths = [len(row[next(iter(row))]) for row in self.rows]
        columns = {}
        for key in first:
            values = [row[key] for row in self.rows]
            if key in _VECTOR_SIZE:  # (N, d) numbers: one array
                columns[key] = np.concatenate(
                    [np.asarray(value, dtype=float).reshape(len(value), _VECTOR_SIZE[key])
                     for value in values])
            else:  # one item per instance (strips, colours, radii, labels, scalars)
                columns[key] = [item for value in values for item in value]
        stream.send_columns(
            self.path, indexes=[rr.TimeColumn(TIMELINE, duration=self.times)],
            columns=archetype.columns(**columns).partition(lengths))
        self.times, self.rows = [], []


class _VehicleTrack:
    """What the recorder remembers of one vehicle between scans."""

    def __init__(self) -> None:
        self.started = False
        self.true: list[np.ndarray] = []
        self.ekf: list[np.ndarray] = []
        self.trail_at = -math.inf
        self.zone = "clear"
        self.fields: np.ndarray | None = None
        self.infractions = 0
        self.map_counts: dict[str, dict[str, int]] = {}

    def start_lap(self) -> None:
        self.true, self.ekf, self.trail_at = [], [], -math.inf

    def add(self, true_pose: np.ndarray, ekf_pose: np.ndarray) -> None:
        self.true.append(true_pose[:2].copy())
        self.ekf.append(ekf_pose[:2].copy())


def _transform(pose: np.ndarray) -> dict[str, list]:
    """Return the Transform3D components that place a child frame at ``(x, y, theta)``."""
    x, y, theta = (float(value) for value in pose)
    return {"translation": [[x, y, 0.0]],
            "quaternion": [[0.0, 0.0, math.sin(theta / 2.0), math.cos(theta / 2.0)]]}


def _closed(points: np.ndarray) -> np.ndarray:
    """Return a polygon's ``(N, 2)`` vertices with the first repeated at the end."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    return np.vstack([points, points[:1]]) if len(points) > 2 else points


def _person_separation(vehicle: VehicleView, true_pose: np.ndarray) -> float | None:
    """Return the distance (m) from the true footprint to the nearest person's body."""
    people = [xy for xy in vehicle.person_positions.values() if xy is not None]
    if not people:
        return None
    radius = {person.name: person.radius for person in vehicle.world.people}
    outline = shapely.Polygon(transform_points(true_pose,
                                               np.asarray(vehicle.robot.footprint, float)))
    names = [name for name, xy in vehicle.person_positions.items() if xy is not None]
    distances = shapely.distance(outline, shapely.points(np.array(people, dtype=float)))
    gaps = distances - np.array([radius.get(name, 0.25) for name in names])
    return float(max(gaps.min(), 0.0))


def _blueprint() -> Any:
    """Return the default layout: the top-down map beside the time series and events."""
    import rerun.blueprint as rrb

    plots = [rrb.TimeSeriesView(origin=f"{_SERIES}/{key}", name=title)
             for key, title in SERIES.items()]
    return rrb.Blueprint(
        rrb.Horizontal(
            # From the root, so that the y flip logged at /map applies to what it shows.
            rrb.Spatial2DView(origin="/", contents=f"{_MAP}/**", name="map (top-down)"),
            rrb.Vertical(
                rrb.Grid(*plots, grid_columns=2),
                rrb.TextLogView(origin=_EVENTS, name="events"),
                row_shares=[3, 2],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
