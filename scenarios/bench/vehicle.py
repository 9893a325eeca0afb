"""One vehicle's stack in a :class:`~scenarios.bench.testbench.Testbench`: body, sensors, EKF, maps.

A :class:`Vehicle` is what drives: its simulated body, wheel encoders, localization and
safety lasers, EKF, path follower, safety supervisor with its field policy, one local map
per path segment and its lap logs, all on its own random streams (spawned from the
scenario seed by vehicle index: the first vehicle's streams keep the names a
single-vehicle run always used, so its draws never change). The bench owns what the
vehicles share: the physics client, the world, the people and the box layouts.

A vehicle reads like a bench to observers (``true_pose``, ``local_maps``, ``lap_log``,
``log``, ``segments``, ``world``, ``person_positions`` ...), so the scoring observers of
:mod:`scenarios.bench.observers` score each vehicle of a fleet as they score a single robot.

In a fleet the other vehicles are dynamic obstacles. Their bodies are in every other
vehicle's laser (``sim.laser.vehicle_laser_group``) and in its safety fields, so a
vehicle stops for another one; but the mapper never sees them: the readings that fall
on another vehicle's footprint, placed where that vehicle's own EKF says it is (the pose
every fleet vehicle reports to the others), become ``nan`` (no information) before the
local-map update. Why not ground truth: a real fleet knows its vehicles' reported poses,
not the truth; why not the mapper's life cycle: a vehicle standing still in a queue would
be confirmed like a pallet, and a safety map must not hold it.

Examples
--------
>>> from scenarios.bench.testbench import Testbench
>>> with Testbench("pal1") as bench:
...     bench.reset()
...     vehicle = bench.vehicles["robot"]
...     vehicle.lap, vehicle.zone, bool(np.allclose(vehicle.true_pose, bench.true_pose))
(1, 'free', True)
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
import shapely

from robots.ekf import EKFLocalizer, EKFParams
from robots.follower import ChainedFormFollower, FollowerParams
from robots.landmarks import detect_landmarks
from robots.lasers import LaserSpec
from robots.presets import UGVSpec
from robots.safety import FieldState, SafetyPolicy, SafetySupervisor, scan_points_in_robot_frame
from robots.stopping import blind_reach, stop_envelope, stopping_distance
from scenarios.bench.observers import hook_table
from scenarios.bench.policies import FieldView, checked_readings, counted_occupancy, field_policy
from scenarios.bench.records import LapLog, RunLog, ScanRecord
from scenarios.spec.routes import fleet_frames
from scenarios.spec.segments import PathSegment, path_segments, segment_index
from semistatic.fleet import FleetMapStore, merge_segment_map
from semistatic.frames import compose, transform_points
from semistatic.local_map import LocalMap
from semistatic.types import Scan
from sim.contacts import ContactMonitor
from sim.encoders import WheelEncoders
from sim.laser import RaycastLaser, vehicle_laser_group
from sim.ugv import SimUGV
from worlds.checks import build_spline
from worlds.spec import WorldSpec

__all__ = ["FLEET_POSE_MARGIN", "RELOCALIZE_ATTEMPTS", "SETTLE_STEPS", "ZONES", "Vehicle"]

SETTLE_STEPS = 24
"""Physics steps the robot rests after being put back at the start (0.1 s at 240 Hz)."""

RELOCALIZE_ATTEMPTS = 10
"""Localization scans tried at a lap start before the run gives up on triangulation."""

ZONES = {"clear": "free", "warning": "warning", "protective": "protective"}
"""The safety supervisor's zone names as the bench reports them."""

FLEET_POSE_MARGIN = 0.25
"""Metres around another vehicle's reported footprint whose readings the mapper skips.

Covers both vehicles' EKF errors (a few cm) and the scan's motion during a sweep."""


def _scaled_robot(robot: UGVSpec, factor: float) -> UGVSpec:
    return robot.replace(encoder_slip_sigma=robot.encoder_slip_sigma * factor)


def _scaled_laser(laser: LaserSpec, factor: float) -> LaserSpec:
    return dataclasses.replace(laser, range_sigma=laser.range_sigma * factor)


class Vehicle:
    """One vehicle of a bench: its stack, its state and its run log.

    Parameters
    ----------
    bench
        The :class:`~scenarios.bench.testbench.Testbench` (physics client, world, people, layouts).
    index
        Position in the fleet (0 for a single vehicle): picks its random streams and its
        laser group.
    name
        The vehicle's name.
    robot
        Its :class:`~robots.presets.UGVSpec`.
    route
        The world with the path the vehicle drives, starting where it starts
        (:func:`scenarios.spec.routes.route_from`).
    store
        The fleet map store a vehicle fetches segment maps from when it enters a segment
        (``None``: no fetching).
    start_time
        Simulated time (s) until which the vehicle stands at its start (lap 1 starts then).

    Attributes
    ----------
    observers
        Observers called with this vehicle (a fleet's scoring; add with
        :meth:`add_observer`); a single vehicle reports
        to the bench's observers instead.
    """

    def __init__(self, bench, index: int, name: str, robot: UGVSpec, route: WorldSpec, *,
                 store: FleetMapStore | None = None, start_time: float = 0.0) -> None:
        self.bench = bench
        self.start_time = float(start_time)
        self.waiting = self.start_time > 0.0
        self.index = int(index)
        self.name = name
        self.robot = robot
        self.store = store
        self.observers: list = []
        self._hooks: dict | None = None
        spec = bench.log_spec
        sim, world = bench.sim, bench.world
        self._sim = sim  # the bench's for its whole life (a reset builds new vehicles)
        self._lap_timeout = spec.lap_timeout
        path = build_spline(route.path)
        self.path = path
        # The fleet's segment frames, whatever part of the loop this vehicle drives.
        self.segments: tuple[PathSegment, ...] = fleet_frames(path_segments(route, path),
                                                              bench.segments)
        self.log = RunLog(spec=spec, world=route, robot=robot, segments=self.segments)
        self.start = path.pose(0.0)
        self.body = SimUGV(sim, robot, self.start)
        # Each noisy component draws from its own stream (sim.random_streams); the first
        # vehicle keeps a single robot's stream names.
        prefix = "" if self.index == 0 else f"vehicles/{self.index}/"
        streams = bench.streams
        group = vehicle_laser_group(self.index)
        self.encoders = WheelEncoders(_scaled_robot(robot, spec.noise.odometry),
                                      streams.generator(prefix + "encoders"))
        localization_spec = _scaled_laser(robot.localization_laser.laser, spec.noise.range)
        self.localization_laser = RaycastLaser(
            sim, localization_spec, world, streams.generator(prefix + "laser/localization"),
            ignore_body_ids=(self.body.body_id,), ignore_group=group,
        )
        self.shared_laser = robot.safety_laser is robot.localization_laser
        if self.shared_laser:
            self.safety_laser = self.localization_laser
        else:
            safety_spec = _scaled_laser(robot.safety_laser.laser, spec.noise.range)
            self.safety_laser = RaycastLaser(
                sim, safety_spec, world, streams.generator(prefix + "laser/safety"),
                ignore_body_ids=(self.body.body_id,), ignore_group=group,
            )
        self.localization_mount = robot.localization_laser
        self.safety_mount = robot.safety_laser
        # The mount's (x, y, yaw), read at every safety scan: built once, read-only.
        self._safety_mount_pose = robot.safety_laser.pose2d()
        self._safety_mount_pose.flags.writeable = False
        posts = world.posts
        # The laser's systematic range error (constant per unit, uniform in +-b) is the
        # filter's fourth state; without it the EKF is overconfident (NEES ~100 on pal1).
        bias_sigma = localization_spec.range_bias_max / math.sqrt(3.0)
        self.ekf = EKFLocalizer(
            [post.xy for post in posts],
            EKFParams(mount=tuple(robot.localization_laser.pose2d()), range_bias_sigma=bias_sigma),
        )
        self.post_radius = posts[0].radius if posts else 0.04
        self.follower = ChainedFormFollower(path, FollowerParams(speed=route.path.speed))
        self.contacts = ContactMonitor(sim, self.body.body_id, world)
        self.supervisor = SafetySupervisor(
            self.segments[0].fields,
            SafetyPolicy(
                warning_speed_scale=spec.safety.slowdown,
                release_delay=spec.safety.release_delay,
                min_points=spec.safety.min_points,
            ),
        )
        # The stop envelope's inputs: a stop request waits up to one safety scan period and
        # one control period, then the follower brakes at its deceleration limit.
        self._reaction_time = 1.0 / spec.rates.safety_hz + 1.0 / spec.rates.control_hz
        self._deceleration = self.follower.params.max_deceleration
        self._footprint = np.asarray(robot.footprint, dtype=float)
        # The envelope reaches at least min_protective_depth ahead, and past the safety
        # laser's blind zone: a reading it cannot see would never stop the vehicle.
        self._least_reach = max(
            spec.safety.min_protective_depth,
            blind_reach(self._footprint, robot.safety_laser.x, robot.safety_laser.laser.range_min),
        )
        # Forward travel (m, encoders) since the last safety scan, and that scan's time.
        self._travelled = 0.0
        self._travel_since = 0.0
        self._local_maps = {
            seg.name: LocalMap(seg.origin, [seg.safety_area], params=spec.mapper, segment=seg.name)
            for seg in self.segments
        }
        self.policy = field_policy(spec.policy)
        self.speed_scale = 1.0
        self._zone = "clear"
        # Wheel odometry alone (what /odom would carry), integrated beside the EKF.
        self.odom_pose = np.zeros(3)
        self.done = False
        self.lap_log: LapLog | None = None
        self._lap_counters = (0, 0, 0)
        self._mapped_segment: str | None = None
        self._safety_dt = 1.0 / spec.rates.safety_hz
        self._control_dt = 1.0 / spec.rates.control_hz

    # ------------------------------------------------------------------ what observers read
    @property
    def spec(self):
        """Return the scenario spec of the run."""
        return self.log.spec

    @property
    def world(self):
        """Return the bench's simulated world (shared by the fleet)."""
        return self.bench.world

    @property
    def sim(self):
        """Return the bench's PyBullet client."""
        return self.bench.sim

    @property
    def sim_time(self) -> float:
        """Return the simulated seconds since the run started."""
        return self.bench.sim_time

    @property
    def time_step(self) -> float:
        """Return the physics time step (s)."""
        return self.bench.time_step

    @property
    def layout_revision(self) -> int:
        """Return the bench's box-layout revision (it changes when a box moves)."""
        return self.bench.layout_revision

    @property
    def person_positions(self) -> dict:
        """Return where the people stand now (``None`` for people not in the scene)."""
        return self.bench.person_positions

    @property
    def lap(self) -> int:
        """Return the vehicle's current lap, counted from 1."""
        return self.lap_log.lap

    @property
    def true_pose(self) -> np.ndarray:
        """Return the simulator's true pose ``(x, y, theta)`` (for scoring only)."""
        return self.body.true_pose()

    @property
    def true_twist(self) -> np.ndarray:
        """Return the simulator's true ``(v_forward, v_left, omega)`` (m/s, rad/s)."""
        return self.body.true_twist()

    @property
    def ekf_pose(self) -> np.ndarray:
        """Return the EKF's pose estimate ``(x, y, theta)``, world frame."""
        return self.ekf.pose

    @property
    def ekf_covariance(self) -> np.ndarray:
        """Return the EKF's ``(3, 3)`` pose covariance."""
        return self.ekf.covariance

    @property
    def local_maps(self) -> Mapping[str, LocalMap]:
        """Return the local map of every path segment by name (read-only mapping)."""
        return MappingProxyType(self._local_maps)

    @property
    def zone(self) -> str:
        """Return the safety zone after the last safety scan: free, warning or protective."""
        return ZONES[self._zone]

    @property
    def segment(self) -> PathSegment:
        """Return the path segment the vehicle is on (by the follower's progress)."""
        return self.segments[segment_index(self.segments, self.follower.progress)]

    def vehicle_outlines(self) -> list[np.ndarray]:
        """Return the true ``(N, 2)`` footprints of the fleet's vehicles on the route.

        For scoring only (ground truth); the mapper uses the poses vehicles report.
        """
        return [
            transform_points(other.body.true_pose(), np.asarray(other.robot.footprint))
            for other in self.bench.fleet
            if not other.done
        ]

    # ------------------------------------------------------------------ observers
    def add_observer(self, observer) -> None:
        """Call ``observer``'s hooks with this vehicle (see :mod:`scenarios.bench.observers`)."""
        self.observers.append(observer)
        self._hooks = None

    def _own_hooks(self, name: str):
        if self._hooks is None:
            self._hooks = hook_table(self.observers)
        return self._hooks[name]

    def _wants_polylines(self) -> bool:
        return self._own_hooks("wants_polylines") or (
            self.index == 0 and self.bench.observer_hooks("wants_polylines"))

    def tick_observers(self) -> None:
        """Call the vehicle's own observers' ``on_tick`` with it (after each physics step)."""
        for method in self._own_hooks("on_tick"):
            method(self)

    def emit(self, hook: str, *args) -> None:
        """Call the vehicle's observers' ``hook`` with it, then (first vehicle) the bench's."""
        for method in self._own_hooks(hook):
            method(self, *args)
        if self.index == 0:
            # The bench's observers follow the first vehicle (bench.true_pose is its pose).
            for method in self.bench.observer_hooks(hook):
                method(self.bench, *args)

    # ------------------------------------------------------------------ one tick
    def sense_and_command(self, control_due: bool, localization_due: bool,
                          safety_due: bool) -> None:
        """Run the vehicle's sensors, safety fields, mapper and controller due this tick."""
        if self.done:
            return
        if self.waiting:
            if self.bench.sim_time < self.start_time:
                return  # standing still at the start: nothing senses, nothing moves
            self._depart()
        if control_due or localization_due or safety_due:
            self._predict()
        scan = None
        if localization_due:
            scan = self._scan(self.localization_laser, self.localization_mount)
            self.ekf.update(self.landmarks(scan), scan.stamp)
        if safety_due:
            if not (self.shared_laser and scan is not None):
                scan = self._scan(self.safety_laser, self.safety_mount)
            record = self._supervise_and_map(scan)
            self.lap_log.safety_scans += 1
            self.emit("on_scan", record)
        if control_due:
            pose = self.ekf.pose  # a copy: the log keeps it, the follower only reads it
            self._record_pose(pose)
            v, omega = self.follower.command(pose, self._control_dt,
                                             speed_scale=self.speed_scale)
            self.body.command(v, omega)

    def lap_over(self) -> bool:
        """Return whether the current lap reached its end or timed out."""
        if self.done or self.waiting:
            return False
        elapsed = self._sim.sim_time - self.lap_log.start_time
        return self.follower.done or elapsed > self._lap_timeout

    def landmarks(self, scan: Scan) -> list:
        """Return the reflective-post landmarks of a localization scan."""
        laser = self.localization_mount.laser
        return detect_landmarks(
            scan,
            post_radius=self.post_radius,
            range_sigma=max(laser.range_sigma, 1e-3),
            bearing_sigma=laser.angular_resolution / math.sqrt(12.0),
        )

    # ------------------------------------------------------------------ laps
    def begin_lap(self, lap: int) -> None:
        """Start lap ``lap``: at the route start, re-localised (closed routes: at speed)."""
        bench = self.bench
        if lap > 1 and self.follower.path.closed:
            self._continue_loop(lap)
            return
        sim = bench.sim
        self.body.reset(self.start)
        sim.step(SETTLE_STEPS)
        self.encoders.reset(self.body.wheel_angles())
        self.follower.reset()
        self.supervisor.reset()
        self.supervisor.set_fields(self.segments[0].fields)
        self.contacts.reset()
        self._lap_counters = (0, 0, 0)
        self.speed_scale = 1.0
        self._zone = "clear"
        self._travelled, self._travel_since = 0.0, sim.sim_time
        self.lap_log = LapLog(lap=lap, start_time=sim.sim_time, first_tick=len(self.log.stamps))
        self._relocalize(lap)
        # Like the EKF, odometry restarts from the triangulated pose: the robot was carried.
        self.odom_pose = self.ekf.pose.copy()
        self._start_lap_hooks(lap)

    def _depart(self) -> None:
        """End the wait at the start: lap 1 starts now, from the pose localised at reset."""
        self.waiting = False
        self.lap_log.start_time = self.bench.sim.sim_time
        self.lap_log.first_tick = len(self.log.stamps)

    def _continue_loop(self, lap: int) -> None:
        """Start lap ``lap`` of a closed route where the last one ended, at speed.

        The vehicle is not carried anywhere: the EKF keeps tracking, odometry keeps
        integrating, and the follower's progress wraps from the path end to its start
        (the same pose on a closed spline).
        """
        self.follower.reset(keep_speed=True)
        stops, slowdowns = self.supervisor.stops, self.supervisor.slowdowns
        self._lap_counters = (stops, slowdowns, self.contacts.collisions)
        self.lap_log = LapLog(lap=lap, start_time=self.bench.sim.sim_time,
                              first_tick=len(self.log.stamps))
        self._start_lap_hooks(lap)

    def _start_lap_hooks(self, lap: int) -> None:
        start_lap = getattr(self.policy, "start_lap", None)
        if start_lap is not None:
            start_lap(self.local_maps)
        self.emit("on_lap_start", lap)

    def end_lap(self) -> bool:
        """Close the current lap's log; return whether the vehicle has more laps to drive."""
        sim, lap_log, log = self.bench.sim, self.lap_log, self.log
        closed = self.follower.path.closed
        if not closed or lap_log.lap == log.spec.laps:
            self.body.stop()
        lap_log.duration_s = sim.sim_time - lap_log.start_time
        lap_log.completed = self.follower.done
        # On a closed route the counters run on across laps: a lap's events are the change.
        stops, slowdowns, collisions = self._lap_counters
        lap_log.stops = self.supervisor.stops - stops
        lap_log.slowdowns = self.supervisor.slowdowns - slowdowns
        lap_log.collisions = self.contacts.collisions - collisions
        log.maps_after_lap.append(
            {name: local_map.to_geojson() for name, local_map in self._local_maps.items()}
        )
        self.emit("on_lap_end", lap_log)
        log.laps.append(lap_log)
        if lap_log.lap < log.spec.laps:
            return True
        self.done = True
        log.ekf_history = self.ekf.history_arrays()
        return False

    def park(self, pose: tuple[float, float, float]) -> None:
        """Take the vehicle off the route (it drove its laps): stand it at ``pose``."""
        self.body.reset(np.asarray(pose, dtype=float))
        self.body.stop()

    def _relocalize(self, lap: int) -> None:
        rates = self.log.spec.rates
        for _ in range(RELOCALIZE_ATTEMPTS):
            scan = self._scan(self.localization_laser, self.localization_mount)
            if self.ekf.relocalize(self.landmarks(scan), scan.stamp):
                return
            self.bench.sim.step(max(1, int(rates.physics_hz / rates.localization_hz)))
        raise RuntimeError(
            f"lap {lap}: could not triangulate the start pose of {self.name} from the "
            f"reflective posts ({RELOCALIZE_ATTEMPTS} scans); check that >= 3 posts are "
            "visible from its start"
        )

    # ------------------------------------------------------------------ pieces
    def _predict(self) -> None:
        increment, covariance = self.encoders.read(self.body.wheel_angles())
        self._travelled += increment[0]
        self.ekf.predict(increment, covariance)
        self.odom_pose = compose(self.odom_pose, increment)

    def _scan(self, laser: RaycastLaser, mount) -> Scan:
        scan = laser.scan(self.body.sensor_pose(mount), stamp=self.bench.sim.sim_time)
        self.log.raycast_seconds.append(laser.last_raycast_s)
        return scan

    def _record_pose(self, ekf_pose: np.ndarray) -> None:
        log = self.log
        log.stamps.append(self._sim.sim_time)
        log.true_poses.append(self.body.true_pose())
        log.estimated_poses.append(ekf_pose)
        log.covariances.append(self.ekf.covariance)

    def _supervise_and_map(self, scan: Scan) -> ScanRecord:
        index = segment_index(self.segments, self.follower.progress)
        segment = self.segments[index]
        if self.supervisor.field_set is not segment.fields:
            self.supervisor.set_fields(segment.fields)
        points = scan_points_in_robot_frame(scan, self._safety_mount_pose)
        local_map = self._local_maps[segment.name]
        ekf_pose = self.ekf.pose  # a copy; nothing below changes the EKF
        output = self.supervisor.update(
            self._occupancy(points, segment, scan.stamp, local_map, ekf_pose), scan.stamp)
        if output.zone == "protective":
            self.lap_log.stopped_time_s += self._safety_dt
        elif output.zone == "warning":
            self.lap_log.slowed_time_s += self._safety_dt
        self.speed_scale = output.speed_scale
        self._zone = output.zone
        if segment.name != self._mapped_segment:
            self._mapped_segment = segment.name
            self._fetch(segment.name, local_map)

        sensor_world = compose(ekf_pose, self._safety_mount_pose)
        scan = self._without_other_vehicles(scan, sensor_world)
        started = time.perf_counter()
        report = local_map.update(scan, sensor_world)
        self.log.mapper_seconds.append(time.perf_counter() - started)
        return ScanRecord(
            lap=self.lap_log.lap,
            segment=segment.name,
            scan=scan,
            odom_pose=self.odom_pose.copy(),
            ekf_pose=ekf_pose,  # the EKF returns copies
            ekf_covariance=self.ekf.covariance,
            # Reading the whole map costs; only observers that may read it pay for it.
            polylines=tuple(line.points for line in local_map.world_polylines().values())
            if self._wants_polylines()
            else (),
            sensor_pose=sensor_world,
            report=report,
        )

    def _fetch(self, name: str, local_map: LocalMap) -> None:
        """Merge the fleet's latest map of segment ``name`` into ours as we enter it."""
        if self.store is None:
            return
        message = self.store.fetch(self.bench.segment_key(name))
        if message is None or message.sender == self.index:
            return
        if merge_segment_map(local_map, message):
            # What the fleet knows of this segment serves the field policy from now on.
            refresh = getattr(self.policy, "refresh_segment", None)
            if refresh is not None:
                refresh(name, local_map)

    def _without_other_vehicles(self, scan: Scan, sensor_world: np.ndarray) -> Scan:
        """Return ``scan`` with the readings on other vehicles' reported footprints as nan."""
        others = [v for v in self.bench.fleet if v is not self and not v.done]
        if not others:
            return scan
        areas = shapely.union_all([
            shapely.buffer(shapely.Polygon(transform_points(other.ekf.pose,
                                                            np.asarray(other.robot.footprint))),
                           FLEET_POSE_MARGIN)
            for other in others
        ])
        ranges = scan.ranges
        finite = np.isfinite(ranges)
        if not finite.any():
            return scan
        angles = scan.angle_min + scan.angle_increment * np.arange(ranges.size)
        heading = sensor_world[2] + angles[finite]
        xs = sensor_world[0] + ranges[finite] * np.cos(heading)
        ys = sensor_world[1] + ranges[finite] * np.sin(heading)
        on_vehicle = shapely.contains_xy(areas, xs, ys)
        if not on_vehicle.any():
            return scan
        masked = ranges.copy()
        masked[np.flatnonzero(finite)[on_vehicle]] = np.nan
        return dataclasses.replace(scan, ranges=masked)

    def _stop_envelope(self, stamp: float):
        """Return the stop envelope at the speed the encoders measured since the last scan."""
        elapsed = stamp - self._travel_since
        speed = self._travelled / elapsed if elapsed > 0.0 else 0.0
        self._travelled, self._travel_since = 0.0, stamp
        reach = max(stopping_distance(speed, self._reaction_time, self._deceleration),
                    self._least_reach)
        return stop_envelope(self._footprint, reach if speed >= 0.0 else -reach,
                             self.log.spec.safety.general_supplement)

    def _occupancy(self, points: np.ndarray, segment: PathSegment, stamp: float,
                   local_map: LocalMap, ekf_pose: np.ndarray) -> FieldState:
        """Ask the policy which readings count; the stop envelope counts whatever it says."""
        envelope = self._stop_envelope(stamp)
        answer = self.policy.counted_readings(
            FieldView(points, segment, envelope, ekf_pose, local_map, self.log.spec.safety)
        )
        readings = checked_readings(self.policy, answer, len(points))
        return counted_occupancy(points, segment.fields, envelope, readings,
                                 self.supervisor.policy.min_points)
