"""One vehicle's stack in a :class:`~scenarios.bench.testbench.Testbench`: body, sensors, EKF, maps.

A :class:`Vehicle` is what drives: its simulated body, wheel encoders, localization and
safety lasers, EKF, path follower, safety fields with their policy
(:class:`~scenarios.bench.fields.VehicleFields`), one local map per path segment and its
lap logs, all on its own random streams (spawned from the scenario seed by vehicle index:
the first vehicle's streams keep the names a single-vehicle run always used, so its draws
never change). What the vehicles share (the physics client, the world, the people and the
box layouts) is the bench's :class:`~scenarios.bench.scene.Scene`, which the vehicle reads
and never the bench.

A vehicle is a :class:`~scenarios.bench.observer.VehicleView`: the observers it carries
(:meth:`Vehicle.add_observer`) are called with it, or with the view they were added with
(the bench's own observers receive the bench). In a fleet the other vehicles' readings
never reach the mapper (:mod:`scenarios.bench.fleet`).

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
import time
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from robots.follower import ChainedFormFollower, FollowerParams
from robots.presets import UGVSpec
from robots.safety import scan_points_in_robot_frame
from scenarios.bench.fields import VehicleFields
from scenarios.bench.fleet import without_vehicles
from scenarios.bench.observer import Observer, ObserverSet
from scenarios.bench.policies import FieldPolicy
from scenarios.bench.records import LapLog, RunLog, ScanRecord
from scenarios.bench.scene import Scene
from scenarios.bench.sensors import VehicleSensors
from scenarios.spec.field_sizing import vehicle_deceleration
from scenarios.spec.routes import fleet_frames
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment, path_segments, segment_index
from scenarios.spec.starts import start_localizer
from semistatic.fleet import FleetMapStore, merge_segment_map
from semistatic.frames import compose, transform_points
from semistatic.local_map import LocalMap
from semistatic.types import Scan
from sim.contacts import ContactMonitor
from sim.ugv import SimUGV
from worlds.checks import build_spline
from worlds.spec import WorldSpec

__all__ = ["RELOCALIZE_ATTEMPTS", "SETTLE_STEPS", "ZONES", "Vehicle"]

SETTLE_STEPS = 24
"""Physics steps the robot rests after being put back at the start (0.1 s at 240 Hz)."""

RELOCALIZE_ATTEMPTS = 10
"""Localization scans tried at a lap start before the run gives up on triangulation."""

ZONES = {"clear": "free", "warning": "warning", "protective": "protective"}
"""The safety supervisor's zone names as the bench reports them."""


class Vehicle:
    """One vehicle of a bench: its stack, its state and its run log.

    Parameters
    ----------
    scene
        What the bench's vehicles share (physics client, world, people, layouts).
    index
        Position in the fleet (0 for a single vehicle): picks its random streams and its
        laser group.
    name
        The vehicle's name.
    robot
        Its :class:`~robots.presets.UGVSpec`.
    route
        The world with the path the vehicle drives, starting where it starts
        (:func:`scenarios.spec.routes.vehicle_route`).
    store
        The fleet map store a vehicle fetches segment maps from when it enters a segment
        (``None``: no fetching).
    start_time
        Simulated time (s) until which the vehicle stands at its start (lap 1 starts then).
    """

    def __init__(self, scene: Scene, index: int, name: str, robot: UGVSpec, route: WorldSpec,
                 *, store: FleetMapStore | None = None, start_time: float = 0.0) -> None:
        self.scene = scene
        self.start_time = float(start_time)
        self.waiting = self.start_time > 0.0
        self.index = int(index)
        self.name = name
        self.robot = robot
        self.store = store
        self.observers = ObserverSet()
        spec = scene.spec
        sim, world = scene.sim, scene.world
        self._sim = sim
        self._lap_timeout = spec.lap_timeout
        path = build_spline(route.path)
        self.path = path
        # The fleet's segment frames, whatever part of the loop this vehicle drives.
        self.segments: tuple[PathSegment, ...] = fleet_frames(path_segments(route, path),
                                                              scene.segments)
        self.log = RunLog(spec=spec, world=route, robot=robot, segments=self.segments)
        self.start = path.pose(0.0)
        self.body = SimUGV(sim, robot, self.start)
        # (A single vehicle's log becomes the bench's after this: looked up at each scan.)
        self.sensors = VehicleSensors(scene, self.index, robot, self.body,
                                      lambda seconds: self.log.raycast_seconds.append(seconds))
        # The filter the start check localises with (scenarios.spec.starts) is this one.
        self.ekf = start_localizer(robot, [post.xy for post in world.posts])
        follower = FollowerParams(speed=route.path.speed)
        braking = spec.faults.braking_factor
        if braking != 1.0:
            # The seeded weak brakes: a share of the deceleration the field sizing assumes
            # (the lower of the follower's and the motors' limits), which the follower's
            # braking ramp then binds below the motors' limit.
            follower = dataclasses.replace(
                follower, max_deceleration=braking * vehicle_deceleration(robot, follower))
        self.follower = ChainedFormFollower(path, follower)
        self.contacts = ContactMonitor(sim, self.body.body_id, world)
        self.fields = VehicleFields(spec, robot, route)
        self._local_maps = {
            seg.name: LocalMap(seg.origin, [seg.safety_area], params=spec.mapper, segment=seg.name)
            for seg in self.segments
        }
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

    # ------------------------------------------------------------------ the view
    @property
    def spec(self) -> ScenarioSpec:
        """Return the scenario spec of the run."""
        return self.log.spec

    @property
    def world(self) -> Any:
        """Return the simulated world as it stands now (shared by the fleet)."""
        return self.scene.world

    @property
    def fleet_size(self) -> int:
        """Return how many vehicles drive in the world."""
        return len(self.scene.fleet)

    @property
    def sim_time(self) -> float:
        """Return the simulated seconds since the run started."""
        return self._sim.sim_time

    @property
    def time_step(self) -> float:
        """Return the physics time step (s)."""
        return self._sim.time_step

    @property
    def layout_revision(self) -> int:
        """Return the scene's box-layout revision (it changes when a box moves)."""
        return self.scene.layout_revision

    @property
    def person_positions(self) -> Mapping[str, np.ndarray | None]:
        """Return where the people stand now (``None`` for people not in the scene)."""
        return self.scene.person_positions

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

    @property
    def policy(self) -> FieldPolicy:
        """Return the vehicle's field policy."""
        return self.fields.policy

    @property
    def supervisor(self):
        """Return the vehicle's :class:`~robots.safety.SafetySupervisor`."""
        return self.fields.supervisor

    def vehicle_outlines(self) -> list[np.ndarray]:
        """Return the true ``(N, 2)`` footprints of the fleet's vehicles on the route.

        For scoring only (ground truth); the mapper uses the poses vehicles report.
        """
        return [
            transform_points(other.body.true_pose(), np.asarray(other.robot.footprint))
            for other in self.scene.fleet
            if not other.done
        ]

    def add_observer(self, observer: Observer, view: Any = None) -> None:
        """Call ``observer``'s hooks with ``view`` (default: this vehicle) from now on."""
        self.observers.add(observer, self if view is None else view)

    # ------------------------------------------------------------------ one tick
    def sense_and_command(self, control_due: bool, localization_due: bool,
                          safety_due: bool) -> None:
        """Run the vehicle's sensors, safety fields, mapper and controller due this tick."""
        if self.done:
            return
        if self.waiting:
            if self._sim.sim_time < self.start_time:
                return  # standing still at the start: nothing senses, nothing moves
            self._depart()
        if control_due or localization_due or safety_due:
            self._predict()
        sensors, scan = self.sensors, None
        if localization_due:
            scan = sensors.localization_scan()
            self.ekf.update(sensors.landmarks(scan), scan.stamp)
        if safety_due:
            record = self._supervise_and_map(sensors.safety_scan(scan))
            self.lap_log.safety_scans += 1
            self.observers.emit("on_scan", record)
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

    # ------------------------------------------------------------------ laps
    def begin_lap(self, lap: int) -> None:
        """Start lap ``lap``: at the route start, re-localised (closed routes: at speed)."""
        if lap > 1 and self.follower.path.closed:
            self._continue_loop(lap)
            return
        sim = self._sim
        self.body.reset(self.start)
        sim.step(SETTLE_STEPS)
        self.sensors.encoders.reset(self.body.wheel_angles())
        self.follower.reset()
        self.fields.reset(self.segments[0], sim.sim_time)
        self.contacts.reset()
        self._lap_counters = (0, 0, 0)
        self.speed_scale = 1.0
        self._zone = "clear"
        self.lap_log = LapLog(lap=lap, start_time=sim.sim_time, first_tick=len(self.log.stamps))
        self._relocalize(lap)
        # Like the EKF, odometry restarts from the triangulated pose: the robot was carried.
        self.odom_pose = self.ekf.pose.copy()
        self._start_lap_hooks(lap)

    def _depart(self) -> None:
        """End the wait at the start: lap 1 starts now, from the pose localised at reset."""
        self.waiting = False
        self.lap_log.start_time = self._sim.sim_time
        self.lap_log.first_tick = len(self.log.stamps)

    def _continue_loop(self, lap: int) -> None:
        """Start lap ``lap`` of a closed route where the last one ended, at speed.

        The vehicle is not carried anywhere: the EKF keeps tracking, odometry keeps
        integrating, and the follower's progress wraps from the path end to its start
        (the same pose on a closed spline).
        """
        self.follower.reset(keep_speed=True)
        supervisor = self.supervisor
        self._lap_counters = (supervisor.stops, supervisor.slowdowns, self.contacts.collisions)
        self.lap_log = LapLog(lap=lap, start_time=self._sim.sim_time,
                              first_tick=len(self.log.stamps))
        self._start_lap_hooks(lap)

    def _start_lap_hooks(self, lap: int) -> None:
        self.policy.start_lap(self.local_maps)
        self.observers.emit("on_lap_start", lap)

    def end_lap(self) -> bool:
        """Close the current lap's log; return whether the vehicle has more laps to drive."""
        lap_log, log, supervisor = self.lap_log, self.log, self.supervisor
        closed = self.follower.path.closed
        if not closed or lap_log.lap == log.spec.laps:
            self.body.stop()
        lap_log.duration_s = self._sim.sim_time - lap_log.start_time
        lap_log.completed = self.follower.done
        # On a closed route the counters run on across laps: a lap's events are the change.
        stops, slowdowns, collisions = self._lap_counters
        lap_log.stops = supervisor.stops - stops
        lap_log.slowdowns = supervisor.slowdowns - slowdowns
        lap_log.collisions = self.contacts.collisions - collisions
        log.maps_after_lap.append(
            {name: local_map.to_geojson() for name, local_map in self._local_maps.items()}
        )
        self.observers.emit("on_lap_end", lap_log)
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
            scan = self.sensors.localization_scan()
            if self.ekf.relocalize(self.sensors.landmarks(scan), scan.stamp):
                return
            self._sim.step(max(1, int(rates.physics_hz / rates.localization_hz)))
        raise RuntimeError(
            f"lap {lap}: could not triangulate the start pose of {self.name} from the "
            f"reflective posts ({RELOCALIZE_ATTEMPTS} scans); check that >= 3 posts are "
            "visible from its start"
        )

    # ------------------------------------------------------------------ pieces
    def _predict(self) -> None:
        increment, covariance = self.sensors.odometry()
        self.fields.travel(increment[0])
        self.ekf.predict(increment, covariance)
        self.odom_pose = compose(self.odom_pose, increment)

    def _record_pose(self, ekf_pose: np.ndarray) -> None:
        log = self.log
        log.stamps.append(self._sim.sim_time)
        log.true_poses.append(self.body.true_pose())
        log.estimated_poses.append(ekf_pose)
        log.covariances.append(self.ekf.covariance)

    def _supervise_and_map(self, scan: Scan) -> ScanRecord:
        segment = self.segments[segment_index(self.segments, self.follower.progress)]
        points = scan_points_in_robot_frame(scan, self.sensors.safety_mount_pose)
        local_map = self._local_maps[segment.name]
        ekf_pose = self.ekf.pose  # a copy; nothing below changes the EKF
        output = self.fields.supervise(points, segment, scan.stamp, local_map, ekf_pose)
        if output.zone == "protective":
            self.lap_log.stopped_time_s += self._safety_dt
        elif output.zone == "warning":
            self.lap_log.slowed_time_s += self._safety_dt
        # The zone is the scanner's decision, when it was taken (a stop's record starts
        # there and so counts a seeded latency as travel); the speed scale is what has
        # reached the follower by now.
        self.speed_scale = self.fields.reaching_vehicle(output).speed_scale
        self._zone = output.zone
        if segment.name != self._mapped_segment:
            self._mapped_segment = segment.name
            self._fetch(segment.name, local_map)

        sensor_world = compose(ekf_pose, self.sensors.safety_mount_pose)
        scan = without_vehicles(scan, sensor_world, [
            transform_points(other.ekf.pose, np.asarray(other.robot.footprint))
            for other in self.scene.fleet if other is not self and not other.done
        ])
        started = time.perf_counter()
        report = local_map.update(scan, sensor_world)
        self.log.mapper_seconds.append(time.perf_counter() - started)
        # Reading the whole map and the fields costs; only observers that read them pay.
        wants = self.observers.wants_polylines
        lines = local_map.world_polylines() if wants else {}
        return ScanRecord(
            lap=self.lap_log.lap,
            segment=segment.name,
            scan=scan,
            odom_pose=self.odom_pose.copy(),
            ekf_pose=ekf_pose,  # the EKF returns copies
            ekf_covariance=self.ekf.covariance,
            polylines=tuple(line.points for line in lines.values()),
            sensor_pose=sensor_world,
            report=report,
            polyline_status=tuple(local_map[map_id].status for map_id in lines),
            fields=self.fields.applied(self.speed_scale) if wants else None,
        )

    def _fetch(self, name: str, local_map: LocalMap) -> None:
        """Merge the fleet's latest map of segment ``name`` into ours as we enter it."""
        if self.store is None:
            return
        message = self.store.fetch(self.scene.segment_key(name))
        if message is None or message.sender == self.index:
            return
        if merge_segment_map(local_map, message):
            # What the fleet knows of this segment serves the field policy from now on.
            self.policy.refresh_segment(name, local_map)
