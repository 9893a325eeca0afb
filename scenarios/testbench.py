"""The closed loop as an object: PyBullet physics, the UGV's stack and the polyline mapper.

One physics tick (DESIGN.md "The closed loop"); observers are called at the marked points::

    people walk ------------------------------------------------------------------------
    wheel encoders -> odometry increment --------------------------------> EKF predict
    top laser scan -> reflective posts -> landmarks ----------------------> EKF update
    safety laser scan -+-> field policy -> warning/protective fields -> speed scale
                       +-> polyline mapper (EKF pose) -> local map of the current segment
                       +-> on_scan(bench, record)
    EKF pose + spline path -> chained-form follower (u1, u2) * speed scale -> wheel motors
    physics step, contacts -> on_tick(bench)
    lap over? -> on_lap_end(bench, lap_log); next lap's boxes; re-localise -> on_lap_start

Sensors and control run at their own rates, scheduled on the physics clock. Each lap
starts with the robot put back at the path start (it re-localises by triangulation) and
the semi-static boxes changed as the scenario says, "while the robot is not observing".
The tick does what the robot does; the simulator's ground truth is only read by
observers (scoring, the paper's Table 1 experiment, recording, progress).

Examples
--------
>>> with Testbench("pal1") as bench:
...     bench.reset(seed=0)
...     for _ in range(240):
...         bench.step()
...     bench.lap, round(bench.sim_time, 2), bench.zone
(1, 1.1, 'free')
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from robots.ekf import EKFLocalizer, EKFParams
from robots.follower import ChainedFormFollower, FollowerParams
from robots.landmarks import detect_landmarks
from robots.lasers import LaserSpec
from robots.path import SplinePath
from robots.presets import UGVSpec
from robots.safety import FieldState, SafetyPolicy, SafetySupervisor, scan_points_in_robot_frame
from scenarios.layout import lap_worlds, robot_preset
from scenarios.load import load_scenario
from scenarios.observers import GroundTruthScoring, GuiView, Table1Reference
from scenarios.policies import FieldPolicy, FieldView, counted_occupancy, field_policy
from scenarios.records import LapLog, RunLog, ScanRecord, Schedule
from scenarios.segments import PathSegment, path_segments, segment_index
from scenarios.sharing import SegmentPublisher
from scenarios.spec import ScenarioSpec
from semistatic.adaptation import minimum_protective_field
from semistatic.frames import compose
from semistatic.local_map import LocalMap
from semistatic.types import Scan
from sim.client import SimClient
from sim.contacts import ContactMonitor
from sim.encoders import WheelEncoders
from sim.laser import RaycastLaser
from sim.people import People
from sim.random_streams import RandomStreams
from sim.ugv import SimUGV
from sim.world_builder import SimWorld
from worlds.checks import build_spline
from worlds.spec import BoxSpec, WorldSpec

__all__ = ["RELOCALIZE_ATTEMPTS", "SETTLE_STEPS", "ZONES", "Testbench"]

SETTLE_STEPS = 24
"""Physics steps the robot rests after being put back at the start (0.1 s at 240 Hz)."""

RELOCALIZE_ATTEMPTS = 10
"""Localization scans tried at a lap start before the run gives up on triangulation."""

ZONES = {"clear": "free", "warning": "warning", "protective": "protective"}
"""The safety supervisor's zone names as the bench reports them."""


class _Robot:
    """The simulated vehicle and its onboard stack for one run (not part of the API)."""

    def __init__(self, sim: SimClient, world: SimWorld, spec: ScenarioSpec, robot: UGVSpec,
                 path: SplinePath, streams: RandomStreams) -> None:
        self.spec = robot
        self.start = path.pose(0.0)
        self.body = SimUGV(sim, robot, self.start)
        # Each noisy component draws from its own stream (sim.random_streams).
        self.encoders = WheelEncoders(
            _scaled_robot(robot, spec.noise.odometry), streams.generator("encoders")
        )
        localization_spec = _scaled_laser(robot.localization_laser.laser, spec.noise.range)
        self.localization_laser = RaycastLaser(
            sim, localization_spec, world, streams.generator("laser/localization"),
            ignore_body_ids=(self.body.body_id,),
        )
        self.shared_laser = robot.safety_laser is robot.localization_laser
        if self.shared_laser:
            self.safety_laser = self.localization_laser
        else:
            safety_spec = _scaled_laser(robot.safety_laser.laser, spec.noise.range)
            self.safety_laser = RaycastLaser(
                sim, safety_spec, world, streams.generator("laser/safety"),
                ignore_body_ids=(self.body.body_id,),
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


class Testbench:
    """A scenario's closed loop with an explicit life cycle, state to read and observers.

    Parameters
    ----------
    scenario
        A :class:`~scenarios.spec.ScenarioSpec`, or a bundled scenario name or file path.
    world
        A :class:`~worlds.spec.WorldSpec` (e.g. built in code) to drive in instead of the
        scenario's ``world``; the scenario's people and box moves apply to it.
    robot
        A :class:`~robots.presets.UGVSpec` or a preset name instead of the scenario's.
    policy
        A field policy name or object (:mod:`scenarios.policies`) instead of the
        scenario's ``policy``.
    gui
        Open PyBullet's window (the camera follows the robot; fields, laser returns and
        local maps are drawn).

    Life cycle: :meth:`reset` builds the simulation and starts lap 1; :meth:`step`
    advances one physics tick; :meth:`run_lap` and :meth:`run` advance to the end of the
    lap or of the run; :meth:`close` (or leaving a ``with`` block) frees PyBullet. Between
    laps the robot is carried back to the start and the scenario's box moves for the next
    lap are applied; :meth:`move_box`, :meth:`add_box` and :meth:`remove_box` change the
    boxes at any moment (until the scenario's next lap layout replaces them).

    Observers (:mod:`scenarios.observers`) added before :meth:`reset` see lap 1 start.

    Examples
    --------
    >>> with Testbench("pal1") as bench:
    ...     bench.reset()
    ...     lap = bench.run_lap()
    ...     lap.lap, lap.completed, bench.lap, sorted(bench.local_maps)
    (1, True, 2, ['east', 'niches', 'side_corridor'])
    """

    __test__ = False  # a name starting with "Test" is not a test class

    def __init__(
        self,
        scenario: ScenarioSpec | str,
        *,
        world: WorldSpec | None = None,
        robot: UGVSpec | str | None = None,
        policy: str | FieldPolicy | None = None,
        gui: bool = False,
    ) -> None:
        spec = scenario if isinstance(scenario, ScenarioSpec) else load_scenario(scenario)
        if policy is not None:
            spec = dataclasses.replace(spec, policy=policy)
        self.spec = spec
        self.gui = bool(gui)
        self._world_override = world
        self._robot_spec = robot_preset(spec.robot if robot is None else robot, file=spec.source)
        self.observers: list = [GroundTruthScoring(), Table1Reference()]
        if spec.sharing:
            self.observers.append(SegmentPublisher())
        if self.gui:
            self.observers.append(GuiView())
        self.log: RunLog | None = None
        self._sim: SimClient | None = None
        self._hooks: dict | None = None
        self.done = False

    # ------------------------------------------------------------------ life cycle
    def add_observer(self, observer) -> None:
        """Call ``observer``'s ``on_tick``, ``on_scan``, ``on_lap_start``, ``on_lap_end`` hooks.

        Examples
        --------
        >>> bench = Testbench("pal1")
        >>> bench.add_observer(object())   # no hooks: never called
        >>> len(bench.observers)
        3
        """
        self.observers.append(observer)
        self._hooks = None

    def reset(self, *, seed: int | None = None) -> None:
        """Build the simulation and start lap 1: robot at the start, re-localised.

        ``seed`` replaces the scenario's seed. A second ``reset`` starts over.

        Examples
        --------
        >>> with Testbench("pal1") as bench:
        ...     bench.reset(seed=4)
        ...     error = np.abs(bench.ekf_pose - bench.true_pose).max()
        ...     bench.lap, bench.log.spec.seed, bool(error < 0.05)
        (1, 4, True)
        """
        self.close()
        self._wall_start = time.perf_counter()
        spec = self.spec if seed is None else dataclasses.replace(self.spec, seed=seed)
        self._worlds = lap_worlds(spec, world=self._world_override)
        base_world = self._worlds[0]
        path = build_spline(base_world.path)
        self.segments: tuple[PathSegment, ...] = path_segments(base_world, path)
        self.log = RunLog(spec=spec, world=base_world, robot=self._robot_spec,
                          segments=self.segments)
        self.streams = RandomStreams(spec.seed)
        rates = spec.rates
        self._sim = sim = SimClient(gui=self.gui, time_step=1.0 / rates.physics_hz)
        self.world = SimWorld(sim, base_world)
        self._robot = _Robot(sim, self.world, spec, self._robot_spec, path, self.streams)
        self._people = People(self.world)
        self._contacts = ContactMonitor(sim, self._robot.body.body_id, self.world)
        self._control = Schedule(rates.control_hz, rates.physics_hz)
        self._localization = Schedule(rates.localization_hz, rates.physics_hz)
        self._safety = Schedule(rates.safety_hz, rates.physics_hz)
        self._control_dt = 1.0 / rates.control_hz
        self._safety_dt = 1.0 / rates.safety_hz
        self._supervisor = SafetySupervisor(
            self.segments[0].fields,
            SafetyPolicy(
                warning_speed_scale=spec.safety.slowdown,
                release_delay=spec.safety.release_delay,
                min_points=spec.safety.min_points,
            ),
        )
        self._minimum_fields = [
            minimum_protective_field(seg.fields.protective, spec.safety.min_protective_depth)
            for seg in self.segments
        ]
        self._local_maps = {
            seg.name: LocalMap(seg.origin, [seg.safety_area], params=spec.mapper, segment=seg.name)
            for seg in self.segments
        }
        self.policy = field_policy(spec.policy)
        self._step_count = 0
        self._speed_scale = 1.0
        self._zone = "clear"
        # Wheel odometry alone (what /odom would carry), integrated beside the EKF.
        self._odom_pose = np.zeros(3)
        self.person_positions: dict[str, np.ndarray | None] = {}
        self.layout_revision = 0
        self.done = False
        self._hooks = None
        self._begin_lap(1)

    def close(self) -> None:
        """Disconnect from PyBullet (the log stays readable); safe to call twice.

        Examples
        --------
        >>> bench = Testbench("pal1")
        >>> bench.reset()
        >>> bench.close()
        >>> bench.close()
        >>> bench.sim is None, bench.log.spec.name
        (True, 'pal1')
        """
        if self._sim is not None:
            self._sim.close()
            self._sim = None

    def __enter__(self) -> Testbench:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # ------------------------------------------------------------------ running
    def step(self) -> None:
        """Advance one physics tick; at the end of a lap, set up the next one.

        Raises ``RuntimeError`` before :meth:`reset` and after the last lap.

        Examples
        --------
        >>> with Testbench("pal1") as bench:
        ...     bench.reset()
        ...     start = bench.sim_time
        ...     bench.step()
        ...     round((bench.sim_time - start) * 240)
        1
        """
        self._require_running()
        sim, robot = self._sim, self._robot
        lap_log = self.lap_log
        self.person_positions = self._people.update(sim.sim_time, lap_start=lap_log.start_time)
        self._step_count += 1
        n = self._step_count
        control_due = self._control.due(n)
        localization_due = self._localization.due(n)
        safety_due = self._safety.due(n)
        if control_due or localization_due or safety_due:
            self._predict()
        scan = None
        if localization_due:
            scan = self._scan(robot.localization_laser, robot.localization_mount)
            robot.ekf.update(robot.landmarks(scan), scan.stamp)
        if safety_due:
            if not (robot.shared_laser and scan is not None):
                scan = self._scan(robot.safety_laser, robot.safety_mount)
            record = self._supervise_and_map(scan)
            lap_log.safety_scans += 1
            for hook in self._observer_hooks("on_scan"):
                hook(self, record)
        if control_due:
            self._record_pose()
            v, omega = robot.follower.command(
                robot.ekf.pose, self._control_dt, speed_scale=self._speed_scale
            )
            robot.body.command(v, omega)
        sim.step()
        self._contacts.check()
        for hook in self._observer_hooks("on_tick"):
            hook(self)
        elapsed = sim.sim_time - lap_log.start_time
        if robot.follower.done or elapsed > self.log.spec.lap_timeout:
            self._end_lap()

    def run_lap(self) -> LapLog:
        """Run to the end of the current lap and return its log; the next lap is set up.

        Examples
        --------
        >>> with Testbench("pal1") as bench:
        ...     bench.reset()
        ...     bench.run_lap().lap, bench.run_lap().lap
        (1, 2)
        """
        self._require_running()
        lap = self.lap
        while not self.done and self.lap == lap:
            self.step()
        return self.log.laps[-1]

    def run(self) -> RunLog:
        """Run every remaining lap (resetting first if needed) and return the run's log.

        Examples
        --------
        >>> from scenarios.load import load_scenario
        >>> with Testbench(load_scenario("pal1", overrides=["laps=1"])) as bench:
        ...     log = bench.run()
        >>> len(log.laps), log.laps[0].completed
        (1, True)
        """
        if self.log is None:
            self.reset()
        while not self.done:
            self.step()
        return self.log

    # ------------------------------------------------------------------ state
    @property
    def lap(self) -> int:
        """Return the current lap, counted from 1 (the last lap once the run is done)."""
        return self.lap_log.lap

    @property
    def time_step(self) -> float:
        """Return the physics time step (s)."""
        return 1.0 / self.log.spec.rates.physics_hz

    @property
    def sim_time(self) -> float:
        """Return the simulated seconds since the run started."""
        return self._sim.sim_time if self._sim is not None else self.log.sim_time_s

    @property
    def true_pose(self) -> np.ndarray:
        """Return the simulator's true robot pose ``(x, y, theta)`` (for scoring only)."""
        return self._robot.body.true_pose()

    @property
    def true_twist(self) -> np.ndarray:
        """Return the simulator's true ``(v_forward, v_left, omega)`` of the robot (m/s, rad/s)."""
        return self._robot.body.true_twist()

    @property
    def ekf_pose(self) -> np.ndarray:
        """Return the EKF's robot pose estimate ``(x, y, theta)``, world frame."""
        return self._robot.ekf.pose

    @property
    def ekf_covariance(self) -> np.ndarray:
        """Return the EKF's ``(3, 3)`` pose covariance."""
        return self._robot.ekf.covariance

    @property
    def local_maps(self) -> Mapping[str, LocalMap]:
        """Return the local map of every path segment by segment name (read-only mapping)."""
        return MappingProxyType(self._local_maps)

    @property
    def zone(self) -> str:
        """Return the safety zone after the last safety scan: free, warning or protective."""
        return ZONES[self._zone]

    @property
    def speed_scale(self) -> float:
        """Return the speed factor the safety fields impose (1 free, 0 stopped)."""
        return self._speed_scale

    @property
    def segment(self) -> PathSegment:
        """Return the path segment the robot is on (by the follower's progress)."""
        return self.segments[segment_index(self.segments, self._robot.follower.progress)]

    @property
    def sim(self) -> SimClient:
        """Return the PyBullet client (e.g. for drawing or a camera); ``None`` once closed."""
        return self._sim

    def random_stream(self, name: str) -> np.random.Generator:
        """Return a generator on the run's stream for component ``name`` (e.g. a script's).

        Streams are spawned from the run's seed by name (:mod:`sim.random_streams`), so
        a script's draws never change the robot's noise. The robot's own components use
        ``encoders``, ``laser/localization`` and ``laser/safety``.

        Examples
        --------
        >>> with Testbench("pal1") as bench:
        ...     bench.reset(seed=1)
        ...     first = bench.random_stream("pusher").uniform()
        ...     bench.reset(seed=1)
        ...     first == bench.random_stream("pusher").uniform()
        True
        """
        if self.log is None:
            raise RuntimeError("Testbench: call reset() first (the streams come from its seed)")
        return self.streams.generator(name)

    # ------------------------------------------------------------------ boxes
    def move_box(self, name: str, pose: tuple[float, float, float]) -> None:
        """Teleport semi-static box ``name`` to ``pose`` = (x, y, yaw) now.

        :meth:`add_box` and :meth:`remove_box` likewise change the boxes at once; the
        scenario's layout of the next lap replaces them when that lap is set up.

        Examples
        --------
        >>> from worlds.spec import BoxSpec
        >>> with Testbench("pal1") as bench:
        ...     bench.reset()
        ...     bench.move_box("carton_west", (2.5, -0.75, 0.0))
        ...     bench.add_box(BoxSpec("crate", (0.4, 0.4, 0.5), (6.0, 0.9, 0.0)))
        ...     bench.remove_box("trolley_niche")
        ...     [(box.name, box.pose) for box in bench.world.boxes]
        [('carton_west', (2.5, -0.75, 0.0)), ('crate_corridor', (6.4, 1.0, 0.3)), \
('crate', (6.0, 0.9, 0.0))]
        """
        self._require_running()
        self.world.move_box(name, tuple(float(value) for value in pose))
        self.layout_revision += 1

    def add_box(self, box: BoxSpec) -> None:
        """Put a new semi-static box into the world now."""
        self._require_running()
        self.world.add_box(box)
        self.layout_revision += 1

    def remove_box(self, name: str) -> None:
        """Take semi-static box ``name`` out of the world now."""
        self._require_running()
        self.world.remove_box(name)
        self.layout_revision += 1

    # ------------------------------------------------------------------ pieces
    def _require_running(self) -> None:
        if self._sim is None:
            raise RuntimeError("Testbench: call reset() first (or the bench was closed)")
        if self.done:
            raise RuntimeError("Testbench: every lap has run; call reset() to start over")

    def _observer_hooks(self, name: str) -> Any:
        """Return the observers' ``name`` hooks, or ``"wants_polylines"``; cached."""
        if self._hooks is None:
            self._hooks = {
                hook: [getattr(o, hook) for o in self.observers if hasattr(o, hook)]
                for hook in ("on_tick", "on_scan", "on_lap_start", "on_lap_end")
            }
            # Whether an ``on_scan`` observer may read ``ScanRecord.polylines``.
            self._hooks["wants_polylines"] = any(
                getattr(observer, "reads_map_polylines", True)
                for observer in self.observers
                if hasattr(observer, "on_scan")
            )
        return self._hooks[name]

    def _apply_layout(self, layout: WorldSpec) -> None:
        """Make the simulated boxes match ``layout`` (move, add, remove by name)."""
        world = self.world
        wanted = {box.name: box for box in layout.boxes}
        current = {box.name: box for box in world.boxes}
        changed = False
        for name in current.keys() - wanted.keys():
            world.remove_box(name)
            changed = True
        for name, box in wanted.items():
            if name not in current:
                world.add_box(box)
                changed = True
            elif tuple(current[name].pose) != tuple(box.pose):
                world.move_box(name, box.pose)
                changed = True
        if changed:
            self.layout_revision += 1

    def _begin_lap(self, lap: int) -> None:
        sim, robot = self._sim, self._robot
        self._apply_layout(self._worlds[lap - 1])
        if lap > 1 and robot.follower.path.closed:
            self._continue_loop(lap)
            return
        robot.body.reset(robot.start)
        sim.step(SETTLE_STEPS)
        robot.encoders.reset(robot.body.wheel_angles())
        robot.follower.reset()
        self._supervisor.reset()
        self._supervisor.set_fields(self.segments[0].fields)
        self._contacts.reset()
        self._lap_counters = (0, 0, 0)
        self._speed_scale = 1.0
        self._zone = "clear"
        self.lap_log = LapLog(lap=lap, start_time=sim.sim_time, first_tick=len(self.log.stamps))
        self._relocalize(lap)
        # Like the EKF, odometry restarts from the triangulated pose: the robot was carried.
        self._odom_pose = robot.ekf.pose.copy()
        self._start_lap_hooks(lap)

    def _continue_loop(self, lap: int) -> None:
        """Start lap ``lap`` of a closed route where the last one ended, at speed.

        The vehicle is not carried anywhere: the EKF keeps tracking, odometry keeps
        integrating, and the follower's progress wraps from the path end to its start
        (the same pose on a closed spline).
        """
        self._robot.follower.reset(keep_speed=True)
        stops, slowdowns = self._supervisor.stops, self._supervisor.slowdowns
        self._lap_counters = (stops, slowdowns, self._contacts.collisions)
        self.lap_log = LapLog(lap=lap, start_time=self._sim.sim_time,
                              first_tick=len(self.log.stamps))
        self._start_lap_hooks(lap)

    def _start_lap_hooks(self, lap: int) -> None:
        start_lap = getattr(self.policy, "start_lap", None)
        if start_lap is not None:
            start_lap(self.local_maps)
        for hook in self._observer_hooks("on_lap_start"):
            hook(self, lap)

    def _end_lap(self) -> None:
        sim, robot, lap_log, log = self._sim, self._robot, self.lap_log, self.log
        closed = robot.follower.path.closed
        if not closed or lap_log.lap == log.spec.laps:
            robot.body.stop()
        lap_log.duration_s = sim.sim_time - lap_log.start_time
        lap_log.completed = robot.follower.done
        # On a closed route the counters run on across laps: a lap's events are the change.
        stops, slowdowns, collisions = self._lap_counters
        lap_log.stops = self._supervisor.stops - stops
        lap_log.slowdowns = self._supervisor.slowdowns - slowdowns
        lap_log.collisions = self._contacts.collisions - collisions
        log.maps_after_lap.append(
            {name: local_map.to_geojson() for name, local_map in self._local_maps.items()}
        )
        for hook in self._observer_hooks("on_lap_end"):
            hook(self, lap_log)
        log.laps.append(lap_log)
        if lap_log.lap < log.spec.laps:
            self._begin_lap(lap_log.lap + 1)
            return
        self.done = True
        log.engine_time_s = sim.engine_time_s
        log.sim_time_s = sim.sim_time
        log.ekf_history = robot.ekf.history_arrays()
        log.wall_time_s = time.perf_counter() - self._wall_start

    def _relocalize(self, lap: int) -> None:
        robot, rates = self._robot, self.log.spec.rates
        for _ in range(RELOCALIZE_ATTEMPTS):
            scan = self._scan(robot.localization_laser, robot.localization_mount)
            if robot.ekf.relocalize(robot.landmarks(scan), scan.stamp):
                return
            self._sim.step(max(1, int(rates.physics_hz / rates.localization_hz)))
        raise RuntimeError(
            f"lap {lap}: could not triangulate the start pose from the reflective posts "
            f"({RELOCALIZE_ATTEMPTS} scans); check that >= 3 posts are visible from the path "
            "start of the world"
        )

    def _predict(self) -> None:
        encoders, ekf = self._robot.encoders, self._robot.ekf
        increment = encoders.odometry_increment(self._robot.body.wheel_angles())
        ekf.predict(increment, encoders.increment_covariance(encoders.last_tick_deltas))
        self._odom_pose = compose(self._odom_pose, increment)

    def _scan(self, laser: RaycastLaser, mount) -> Scan:
        scan = laser.scan(self._robot.body.sensor_pose(mount), stamp=self._sim.sim_time)
        self.log.raycast_seconds.append(laser.last_raycast_s)
        return scan

    def _record_pose(self) -> None:
        log, robot = self.log, self._robot
        log.stamps.append(self._sim.sim_time)
        log.true_poses.append(robot.body.true_pose())
        log.estimated_poses.append(robot.ekf.pose.copy())
        log.covariances.append(robot.ekf.covariance.copy())

    def _supervise_and_map(self, scan: Scan) -> ScanRecord:
        robot = self._robot
        index = segment_index(self.segments, robot.follower.progress)
        segment = self.segments[index]
        if self._supervisor.field_set is not segment.fields:
            self._supervisor.set_fields(segment.fields)
        points = scan_points_in_robot_frame(scan, robot.safety_mount.pose2d())
        local_map = self._local_maps[segment.name]
        output = self._supervisor.update(self._occupancy(points, segment, index, local_map),
                                         scan.stamp)
        if output.zone == "protective":
            self.lap_log.stopped_time_s += self._safety_dt
        elif output.zone == "warning":
            self.lap_log.slowed_time_s += self._safety_dt
        self._speed_scale = output.speed_scale
        self._zone = output.zone

        ekf_pose = robot.ekf.pose
        sensor_world = compose(ekf_pose, robot.safety_mount.pose2d())
        started = time.perf_counter()
        report = local_map.update(scan, sensor_world)
        self.log.mapper_seconds.append(time.perf_counter() - started)
        return ScanRecord(
            lap=self.lap_log.lap,
            segment=segment.name,
            scan=scan,
            odom_pose=self._odom_pose.copy(),
            ekf_pose=ekf_pose,  # the EKF returns copies
            ekf_covariance=robot.ekf.covariance,
            # Reading the whole map costs; only observers that may read it pay for it.
            polylines=tuple(line.points for line in local_map.world_polylines().values())
            if self._observer_hooks("wants_polylines")
            else (),
            sensor_pose=sensor_world,
            report=report,
        )

    def _occupancy(self, points: np.ndarray, segment: PathSegment, index: int,
                   local_map: LocalMap) -> FieldState:
        """Ask the policy which readings count; the protective floor is enforced there."""
        minimum = self._minimum_fields[index]
        readings = self.policy.counted_readings(
            FieldView(points, segment, minimum, self._robot.ekf.pose, local_map,
                      self.log.spec.safety)
        )
        return counted_occupancy(points, segment.fields, minimum, readings,
                                 self._supervisor.policy.min_points)
