"""The closed loop: PyBullet physics, the UGV's stack and the polyline mapper, lap after lap.

One physics step at a time (DESIGN.md "The closed loop")::

    wheel encoders -> odometry increment ----------------------------> EKF predict
    top laser scan -> reflective posts -> landmarks -------------------> EKF update
    safety laser scan -+-> warning/protective fields -> speed scale
                       +-> polyline mapper (EKF pose) -> local map of the current segment
    EKF pose + spline path -> chained-form follower (u1, u2) * speed scale -> wheel motors

Sensors and control run at their own rates, scheduled on the physics clock. Each lap
starts with the robot put back at the path start (it re-localises by triangulation) and
the semi-static boxes changed as the scenario says, "while the robot is not observing".

Two maps are fed by the same scans:

- the paper's Table 1 experiment: lap 1 builds a reference map per segment; later laps
  only associate against it (no merge) and record the restricted Hausdorff distances;
- the operating system of Sec. 4: one :class:`~semistatic.local_map.LocalMap` per
  segment, updated every scan with the life cycle, whose known objects drive the
  ``adaptive`` field policy.

The simulator's ground truth is only read for scoring, never by the robot's stack.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import shapely

from robots.ekf import EKFLocalizer, EKFParams
from robots.follower import ChainedFormFollower, FollowerParams
from robots.landmarks import detect_landmarks
from robots.lasers import LaserSpec
from robots.path import SplinePath
from robots.presets import UGVSpec, get_preset
from robots.safety import SafetyPolicy, SafetySupervisor, scan_points_in_robot_frame
from scenarios.layout import lap_worlds
from scenarios.metrics import match_polylines_to_boxes, score_lap
from scenarios.segments import PathSegment, path_segments, segment_index
from scenarios.spec import ScenarioSpec
from semistatic.adaptation import explained_readings, minimum_protective_field
from semistatic.frames import compose, transform_points
from semistatic.local_map import LocalMap
from semistatic.polyline import Polyline
from semistatic.types import Scan
from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.encoders import WheelEncoders
from sim.ground_truth import box_outlines
from sim.laser import RaycastLaser
from sim.people import People
from sim.ugv import SimUGV
from sim.world_builder import SimWorld
from worlds.spec import WorldSpec

__all__ = ["LapLog", "RunLog", "ScanRecord", "Schedule", "known_objects", "run_scenario"]

SETTLE_STEPS = 24
"""Physics steps the robot rests after being put back at the start (0.1 s at 240 Hz)."""

RELOCALIZE_ATTEMPTS = 10
"""Localization scans tried at a lap start before the run gives up on triangulation."""

OBSERVED_READINGS = 5
"""Safety-laser readings within ``OBSERVED_DISTANCE`` of a box that count as seeing it."""

OBSERVED_DISTANCE = 0.03
"""Metres from a true box outline within which a reading counts as a hit on the box."""


class Schedule:
    """Fire at ``rate_hz`` on a physics clock of ``physics_hz``, with no drift.

    Step ``n`` is due when ``floor(n * rate / physics)`` increases, so a 50 Hz task on a
    240 Hz clock fires 50 times per simulated second, every 4 or 5 steps.

    Examples
    --------
    >>> schedule = Schedule(50.0, 240.0)
    >>> sum(schedule.due(n) for n in range(1, 241))
    50
    """

    def __init__(self, rate_hz: float, physics_hz: float) -> None:
        self.ratio = rate_hz / physics_hz

    def due(self, step: int) -> bool:
        """Return whether the task runs at physics step ``step`` (counted from 1)."""
        return math.floor(step * self.ratio + 1e-9) > math.floor((step - 1) * self.ratio + 1e-9)


@dataclass
class LapLog:
    """What happened in one lap."""

    lap: int
    start_time: float
    first_tick: int = 0
    duration_s: float = 0.0
    completed: bool = False
    stops: int = 0
    slowdowns: int = 0
    collisions: int = 0
    safety_scans: int = 0
    stopped_time_s: float = 0.0
    slowed_time_s: float = 0.0
    detection: dict = field(default_factory=dict)
    false_objects_from_people: int = 0
    latencies: dict[str, int | None] = field(default_factory=dict)
    person_stopped_robot: bool = False


@dataclass(frozen=True, eq=False)
class ScanRecord:
    """What the robot knew when one safety-laser scan reached the mapper (for recording).

    Parameters
    ----------
    lap
        The lap, counted from 1.
    segment
        Name of the path segment whose local map the scan updated.
    scan
        The safety-laser scan; its ``pose`` is the simulator's true sensor pose.
    odom_pose
        ``(x, y, theta)`` of the robot from wheel odometry alone, world frame: the
        increments the EKF predicts with, integrated from the triangulated pose at the
        lap start, so it drifts as a real robot's odometry does.
    ekf_pose, ekf_covariance
        The EKF's robot pose (world frame) and its ``(3, 3)`` covariance over
        ``(x, y, theta)``: the pose the mapper placed the scan with.
    polylines
        The current segment's local map after this scan, world frame, ``(N, 2)`` each.

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=0.5)
    >>> record = ScanRecord(lap=1, segment="corridor", scan=scan, odom_pose=np.zeros(3),
    ...                     ekf_pose=np.zeros(3), ekf_covariance=np.eye(3) * 1e-4,
    ...                     polylines=(np.array([[0.0, 1.0], [2.0, 1.0]]),))
    >>> record.segment, len(record.polylines)
    ('corridor', 1)
    """

    lap: int
    segment: str
    scan: Scan
    odom_pose: np.ndarray
    ekf_pose: np.ndarray
    ekf_covariance: np.ndarray
    polylines: tuple[np.ndarray, ...] = ()


@dataclass
class RunLog:
    """Everything a run recorded; ``scenarios.metrics`` turns it into numbers."""

    spec: ScenarioSpec
    world: WorldSpec
    robot: UGVSpec
    segments: tuple[PathSegment, ...]
    laps: list[LapLog] = field(default_factory=list)
    stamps: list[float] = field(default_factory=list)
    true_poses: list[np.ndarray] = field(default_factory=list)
    estimated_poses: list[np.ndarray] = field(default_factory=list)
    covariances: list[np.ndarray] = field(default_factory=list)
    ekf_history: dict[str, np.ndarray] = field(default_factory=dict)
    table1_distances: dict[str, list[float]] = field(default_factory=dict)
    reference_maps: dict[str, LocalMap] = field(default_factory=dict)
    maps_after_lap: list[dict] = field(default_factory=list)
    truth_after_lap: list[dict[str, np.ndarray]] = field(default_factory=list)
    example_pair: tuple[np.ndarray, np.ndarray] | None = None
    mapper_seconds: list[float] = field(default_factory=list)
    raycast_seconds: list[float] = field(default_factory=list)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    engine_time_s: float = 0.0


class _Robot:
    """The simulated vehicle and its onboard stack for one run (not part of the API)."""

    def __init__(self, sim: SimClient, world: SimWorld, spec: ScenarioSpec, robot: UGVSpec,
                 path: SplinePath, rng: np.random.Generator) -> None:
        self.spec = robot
        self.start = path.pose(0.0)
        self.body = SimUGV(sim, robot, self.start)
        self.encoders = WheelEncoders(_scaled_robot(robot, spec.noise.odometry), rng)
        localization_spec = _scaled_laser(robot.localization_laser.laser, spec.noise.range)
        self.localization_laser = RaycastLaser(
            sim, localization_spec, world, rng, ignore_body_ids=(self.body.body_id,)
        )
        self.shared_laser = robot.safety_laser is robot.localization_laser
        if self.shared_laser:
            self.safety_laser = self.localization_laser
        else:
            safety_spec = _scaled_laser(robot.safety_laser.laser, spec.noise.range)
            self.safety_laser = RaycastLaser(
                sim, safety_spec, world, rng, ignore_body_ids=(self.body.body_id,)
            )
        self.localization_mount = robot.localization_laser
        self.safety_mount = robot.safety_laser
        posts = world.posts
        # The laser's systematic range error (constant per unit, uniform in +-b) is the
        # filter's fourth state; without it the EKF is overconfident (NEES ~100 on pal1).
        bias_sigma = localization_spec.range_bias_max / math.sqrt(3.0)
        self.ekf = EKFLocalizer(
            [post.xy for post in posts],
            EKFParams(mount=tuple(robot.localization_laser.pose2d()), range_bias_sigma=bias_sigma),
        )
        self.post_radius = posts[0].radius if posts else 0.04
        self.follower = ChainedFormFollower(path, FollowerParams(speed=world.spec.path.speed))

    def landmarks(self, scan: Scan) -> list:
        laser = self.localization_mount.laser
        return detect_landmarks(
            scan,
            post_radius=self.post_radius,
            range_sigma=max(laser.range_sigma, 1e-3),
            bearing_sigma=laser.angular_resolution / math.sqrt(12.0),
        )


def _scaled_robot(robot: UGVSpec, factor: float) -> UGVSpec:
    return robot.replace(encoder_slip_sigma=robot.encoder_slip_sigma * factor)


def _scaled_laser(laser: LaserSpec, factor: float) -> LaserSpec:
    return dataclasses.replace(laser, range_sigma=laser.range_sigma * factor)


def run_scenario(
    spec: ScenarioSpec,
    *,
    gui: bool = False,
    progress: Callable[[float], None] | None = None,
    on_scan: Callable[[ScanRecord], None] | None = None,
) -> RunLog:
    """Run every lap of ``spec`` in a fresh PyBullet world and return the log.

    ``progress``, when given, is called with the simulated seconds advanced (for a
    progress bar). ``on_scan``, when given, is called once per safety-laser scan, after
    the local map update, with a :class:`ScanRecord` (e.g. to write a ROS 2 bag with
    ``scenarios.bag``); without it the run pays nothing for recording. Same spec (and
    seed) -> identical log and records, except the timing figures.
    """
    wall_start = time.perf_counter()
    rng = np.random.default_rng(spec.seed)
    worlds = lap_worlds(spec)
    base_world = worlds[0]
    robot_spec = get_preset(spec.robot)
    path = SplinePath(base_world.path.knots)
    segments = path_segments(base_world, path)
    log = RunLog(spec=spec, world=base_world, robot=robot_spec, segments=segments)
    physics_hz = spec.rates.physics_hz
    with SimClient(gui=gui, time_step=1.0 / physics_hz) as sim:
        world = SimWorld(sim, base_world)
        robot = _Robot(sim, world, spec, robot_spec, path, rng)
        people = People(world)
        contacts = ContactMonitor(sim, robot.body.body_id, world)
        loop = _Loop(sim, world, robot, people, contacts, spec, segments, log, progress, on_scan)
        for lap, lap_world in enumerate(worlds, start=1):
            _apply_layout(world, lap_world)
            loop.run_lap(lap)
        log.engine_time_s = sim.engine_time_s
        log.sim_time_s = sim.sim_time
    log.ekf_history = robot.ekf.history_arrays()
    log.wall_time_s = time.perf_counter() - wall_start
    return log


def _apply_layout(world: SimWorld, layout: WorldSpec) -> None:
    """Make the simulated boxes match ``layout`` (move, add, remove by name)."""
    wanted = {box.name: box for box in layout.boxes}
    current = {box.name: box for box in world.boxes}
    for name in current.keys() - wanted.keys():
        world.remove_box(name)
    for name, box in wanted.items():
        if name not in current:
            world.add_box(box)
        elif tuple(current[name].pose) != tuple(box.pose):
            world.move_box(name, box.pose)


class _Loop:
    """The per-step logic of a run, split from ``run_scenario`` to keep each part small."""

    def __init__(self, sim, world, robot, people, contacts, spec, segments, log, progress,
                 on_scan):
        self.sim, self.world, self.robot = sim, world, robot
        self.people, self.contacts = people, contacts
        self.spec, self.segments, self.log = spec, segments, log
        self.progress, self.on_scan = progress, on_scan
        rates = spec.rates
        self.control = Schedule(rates.control_hz, rates.physics_hz)
        self.localization = Schedule(rates.localization_hz, rates.physics_hz)
        self.safety = Schedule(rates.safety_hz, rates.physics_hz)
        self.control_dt = 1.0 / rates.control_hz
        policy = SafetyPolicy(
            warning_speed_scale=spec.safety.slowdown,
            release_delay=spec.safety.release_delay,
            min_points=spec.safety.min_points,
        )
        self.supervisor = SafetySupervisor(segments[0].fields, policy)
        self.minimum_fields = [
            minimum_protective_field(seg.fields.protective, spec.safety.min_protective_depth)
            for seg in segments
        ]
        self.local_maps = {
            seg.name: LocalMap(
                seg.origin, [seg.safety_area], params=spec.mapper, segment=seg.name
            )
            for seg in segments
        }
        # The paper's Table 1 reference: the local maps as lap 1 left them (set after lap 1).
        self.reference: dict[str, LocalMap] = {}
        self.known_objects: dict[str, list[np.ndarray]] = {seg.name: [] for seg in segments}
        self.step_count = 0
        self.speed_scale = 1.0
        # Wheel odometry alone (what /odom would carry), integrated beside the EKF.
        self.odom_pose = np.zeros(3)

    # ------------------------------------------------------------------ lap
    def run_lap(self, lap: int) -> None:
        sim, robot, spec = self.sim, self.robot, self.spec
        robot.body.reset(robot.start)
        sim.step(SETTLE_STEPS)
        robot.encoders.reset(robot.body.wheel_angles())
        robot.follower.reset()
        self.supervisor.reset()
        self.supervisor.set_fields(self.segments[0].fields)
        self.contacts.reset()
        self.speed_scale = 1.0
        lap_log = LapLog(lap=lap, start_time=sim.sim_time, first_tick=len(self.log.stamps))
        self._relocalize(lap)
        # Like the EKF, odometry restarts from the triangulated pose: the robot was carried.
        self.odom_pose = robot.ekf.pose.copy()
        if spec.policy == "adaptive":
            self.known_objects = {
                name: known_objects(local_map) for name, local_map in self.local_maps.items()
            }
        truth = box_outlines(self.world)
        watch = _moved_boxes(spec, lap)
        first_seen: dict[str, int] = {}
        detected_at: dict[str, int] = {}
        person_tracks: list[np.ndarray] = []
        while True:
            positions = self.people.update(sim.sim_time, lap_start=lap_log.start_time)
            self.step_count += 1
            n = self.step_count
            control_due = self.control.due(n)
            localization_due = self.localization.due(n)
            safety_due = self.safety.due(n)
            if control_due or localization_due or safety_due:
                self._predict()
            scan = None
            if localization_due:
                scan = self._scan(robot.localization_laser, robot.localization_mount)
                robot.ekf.update(robot.landmarks(scan), scan.stamp)
            if safety_due:
                if not (robot.shared_laser and scan is not None):
                    scan = self._scan(robot.safety_laser, robot.safety_mount)
                self._safety_and_mapping(scan, lap, lap_log)
                lap_log.safety_scans += 1
                self._watch_boxes(scan, watch, truth, first_seen, detected_at, lap_log)
                person_tracks.extend(p for p in positions.values() if p is not None)
            if control_due:
                self._record_pose()
                v, omega = robot.follower.command(
                    robot.ekf.pose, self.control_dt, speed_scale=self.speed_scale
                )
                robot.body.command(v, omega)
            sim.step()
            self.contacts.check()
            if self.progress is not None:
                self.progress(sim.time_step)
            elapsed = sim.sim_time - lap_log.start_time
            if robot.follower.done or elapsed > spec.lap_timeout:
                break
        robot.body.stop()
        lap_log.duration_s = sim.sim_time - lap_log.start_time
        lap_log.completed = robot.follower.done
        lap_log.stops = self.supervisor.stops
        lap_log.slowdowns = self.supervisor.slowdowns
        lap_log.collisions = self.contacts.collisions
        lap_log.latencies = {
            name: (detected_at[name] - first_seen[name]) if name in detected_at else None
            for name in watch
            if name in first_seen
        }
        self._finish_lap(lap_log, truth, person_tracks)
        self.log.laps.append(lap_log)

    # ------------------------------------------------------------------ pieces
    def _relocalize(self, lap: int) -> None:
        robot = self.robot
        for _ in range(RELOCALIZE_ATTEMPTS):
            scan = self._scan(robot.localization_laser, robot.localization_mount)
            if robot.ekf.relocalize(robot.landmarks(scan), scan.stamp):
                return
            self.sim.step(max(1, int(self.spec.rates.physics_hz / self.spec.rates.localization_hz)))
        raise RuntimeError(
            f"lap {lap}: could not triangulate the start pose from the reflective posts "
            f"({RELOCALIZE_ATTEMPTS} scans); check that >= 3 posts are visible from the path "
            "start of the world"
        )

    def _predict(self) -> None:
        robot = self.robot
        increment = robot.encoders.odometry_increment(robot.body.wheel_angles())
        covariance = robot.encoders.increment_covariance(robot.encoders.last_tick_deltas)
        robot.ekf.predict(increment, covariance)
        self.odom_pose = compose(self.odom_pose, increment)

    def _scan(self, laser: RaycastLaser, mount) -> Scan:
        scan = laser.scan(self.robot.body.sensor_pose(mount), stamp=self.sim.sim_time)
        self.log.raycast_seconds.append(laser.last_raycast_s)
        return scan

    def _record_pose(self) -> None:
        log = self.log
        log.stamps.append(self.sim.sim_time)
        log.true_poses.append(self.robot.body.true_pose())
        log.estimated_poses.append(self.robot.ekf.pose.copy())
        log.covariances.append(self.robot.ekf.covariance.copy())

    def _safety_and_mapping(self, scan: Scan, lap: int, lap_log: LapLog) -> None:
        robot, spec = self.robot, self.spec
        index = segment_index(self.segments, robot.follower.progress)
        segment = self.segments[index]
        if self.supervisor.field_set is not segment.fields:
            self.supervisor.set_fields(segment.fields)
        points = scan_points_in_robot_frame(scan, robot.safety_mount.pose2d())
        if spec.policy == "adaptive" and self.known_objects[segment.name]:
            world_points = transform_points(robot.ekf.pose, points)
            explained = explained_readings(
                world_points, self.known_objects[segment.name], spec.safety.adaptive_margin
            )
            kept = shapely.contains_xy(self.minimum_fields[index], points[:, 0], points[:, 1])
            points = points[~explained | kept]
        output = self.supervisor.observe(points, scan.stamp)
        dt = 1.0 / spec.rates.safety_hz
        if output.zone == "protective":
            lap_log.stopped_time_s += dt
        elif output.zone == "warning":
            lap_log.slowed_time_s += dt
        self.speed_scale = output.speed_scale

        sensor_world = compose(robot.ekf.pose, robot.safety_mount.pose2d())
        started = time.perf_counter()
        mapped = self.local_maps[segment.name].update(scan, sensor_world)
        self.log.mapper_seconds.append(time.perf_counter() - started)
        if self.on_scan is not None:
            self._report_scan(scan, lap, segment)
        if lap > 1:
            # Table 1: associate against the lap-1 reference without merging (paper Sec. 6).
            reference = self.reference[segment.name]
            # Same segment frame, same scan: the polylines extracted for the local map serve.
            report = reference.update(
                scan, sensor_world, merge=False, scan_polylines=mapped.scan_polylines
            )
            for pair in report.associated:
                key = f"{segment.name}/{pair.map_id}"
                self.log.table1_distances.setdefault(key, []).append(pair.distance)
                if self.log.example_pair is None:
                    self._keep_example(report.scan_polylines[pair.scan_index],
                                       reference[pair.map_id].polyline, segment)

    def _report_scan(self, scan: Scan, lap: int, segment: PathSegment) -> None:
        robot = self.robot
        polylines = self.local_maps[segment.name].world_polylines().values()
        self.on_scan(
            ScanRecord(
                lap=lap,
                segment=segment.name,
                scan=scan,
                odom_pose=self.odom_pose.copy(),
                ekf_pose=robot.ekf.pose,  # the EKF returns copies
                ekf_covariance=robot.ekf.covariance,
                polylines=tuple(line.points for line in polylines),
            )
        )

    def _keep_example(self, scan_line: Polyline, map_line: Polyline, segment) -> None:
        if len(scan_line) >= 3 and len(map_line) >= 3:
            self.log.example_pair = (
                transform_points(segment.origin, map_line.points),
                transform_points(segment.origin, scan_line.points),
            )

    def _watch_boxes(self, scan, watch, truth, first_seen, detected_at, lap_log) -> None:
        if not watch:
            return
        true_points = scan.world_points()[scan.valid_mask()]
        for name in watch:
            if name in detected_at or name not in truth:
                continue
            outline = truth[name]
            closed = np.vstack([outline, outline[:1]])
            if name not in first_seen:
                hits = np.count_nonzero(
                    shapely.distance(shapely.LinearRing(closed), shapely.points(true_points))
                    <= OBSERVED_DISTANCE
                )
                if hits >= OBSERVED_READINGS:
                    first_seen[name] = lap_log.safety_scans
            if name in first_seen:
                lines = [
                    line.points
                    for local_map in self.local_maps.values()
                    for line in local_map.world_polylines().values()
                ]
                if match_polylines_to_boxes(lines, {name: outline}).any():
                    detected_at[name] = lap_log.safety_scans

    def _finish_lap(self, lap_log: LapLog, truth: dict, person_tracks: list) -> None:
        if lap_log.lap == 1:
            self.reference = copy.deepcopy(self.local_maps)
            self.log.reference_maps = self.reference
        lap_log.detection, lap_log.false_objects_from_people = score_lap(
            self.local_maps, self.segments, truth, person_tracks
        )
        self.log.maps_after_lap.append(
            {name: local_map.to_geojson() for name, local_map in self.local_maps.items()}
        )
        self.log.truth_after_lap.append(truth)


def known_objects(local_map: LocalMap) -> list[np.ndarray]:
    """Return the confirmed semi-static objects of a local map (world frame) for adaptation.

    Only ``confirmed`` polylines count: seen again after their first scan, so a person
    who walked past once is not "known" and never shrinks a field.
    """
    return [
        line.points
        for map_id, line in local_map.world_polylines().items()
        if local_map[map_id].status == "confirmed"
    ]


def _moved_boxes(spec: ScenarioSpec, lap: int) -> tuple[str, ...]:
    """Return the boxes moved or added before ``lap`` (their detection latency is measured)."""
    return tuple(m.box for m in spec.moves if m.lap == lap and m.action in ("move", "add"))
