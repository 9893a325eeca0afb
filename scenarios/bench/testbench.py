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

A scenario with ``[[vehicles]]`` drives a fleet in one world: each vehicle
(:class:`~scenarios.bench.vehicle.Vehicle`, in ``bench.vehicles`` by name) runs the tick above
with its own stack and laps, scored by observers of its own; the bench's observers and
its single-robot properties (``true_pose``, ``local_maps``, ``lap`` ...) follow the
first vehicle. A lap's box moves happen when the first vehicle starts it; a vehicle that
drove its laps leaves the hall (:data:`PARKING`) and the run ends when all have.

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
import time
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from robots.presets import UGVSpec
from scenarios.bench.observers import GroundTruthScoring, GuiView, Table1Reference, hook_table
from scenarios.bench.policies import FieldPolicy
from scenarios.bench.records import LapLog, RunLog, Schedule, combine_logs
from scenarios.bench.sharing import SegmentPublisher
from scenarios.bench.vehicle import RELOCALIZE_ATTEMPTS, SETTLE_STEPS, ZONES, Vehicle
from scenarios.spec.layout import lap_worlds, robot_preset
from scenarios.spec.load import load_scenario
from scenarios.spec.routes import fleet_vehicles, vehicle_route
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment, path_segments
from semistatic.fleet import FleetMapStore
from semistatic.kernel_cache import warm_kernel_cache
from semistatic.local_map import LocalMap
from sim.client import SimClient
from sim.people import People
from sim.random_streams import RandomStreams
from sim.world_builder import SimWorld
from worlds.checks import build_spline
from worlds.spec import BoxSpec, WorldSpec

__all__ = ["PARKING", "RELOCALIZE_ATTEMPTS", "SETTLE_STEPS", "ZONES", "Testbench"]

PARKING = (-5.0, -5.0, 0.0)
"""Where a fleet vehicle that drove its laps leaves the hall (outside the walls, the
next one 3 m further west): it must not block the route of the others."""


class Testbench:
    """A scenario's closed loop with an explicit life cycle, state to read and observers.

    Parameters
    ----------
    scenario
        A :class:`~scenarios.spec.scenario.ScenarioSpec`, or a bundled scenario name or file path.
    world
        A :class:`~worlds.spec.WorldSpec` (e.g. built in code) to drive in instead of the
        scenario's ``world``; the scenario's people and box moves apply to it.
    robot
        A :class:`~robots.presets.UGVSpec` or a preset name instead of the scenario's.
    policy
        A field policy name or object (:mod:`scenarios.bench.policies`) instead of the
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

    Observers (:mod:`scenarios.bench.observers`) added before :meth:`reset` see lap 1 start.

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
        self.fleet_size = len(fleet_vehicles(spec))
        # One vehicle reports to the bench's observers; a fleet scores each vehicle with
        # observers of its own (Vehicle.observers) and the bench's follow the first one.
        self.observers: list = []
        if self.fleet_size == 1:
            self.observers += [GroundTruthScoring(), Table1Reference()]
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
        # numba's one-time set-up, and the kernels missing from its cache (the first run
        # after installation or an upgrade) compiled on every core at once: start-up like
        # an import, not the run's time.
        warm_kernel_cache()
        self._wall_start = time.perf_counter()
        spec = self.spec if seed is None else dataclasses.replace(self.spec, seed=seed)
        self.log_spec = spec
        self._worlds = lap_worlds(spec, world=self._world_override)
        base_world = self._worlds[0]
        path = build_spline(base_world.path)
        self.segments: tuple[PathSegment, ...] = path_segments(base_world, path)
        self._segment_keys = {segment.name: segment.index for segment in self.segments}
        self.log = RunLog(spec=spec, world=base_world, robot=self._robot_spec,
                          segments=self.segments)
        self.streams = RandomStreams(spec.seed)
        rates = spec.rates
        self._sim = sim = SimClient(gui=self.gui, time_step=1.0 / rates.physics_hz)
        self.world = SimWorld(sim, base_world)
        self.store = FleetMapStore() if spec.sharing and self.fleet_size > 1 else None
        self.fleet: list[Vehicle] = []
        for index, vehicle in enumerate(fleet_vehicles(spec)):
            robot = self._robot_spec if index == 0 and not spec.vehicles else \
                robot_preset(vehicle.robot, file=spec.source)
            self.fleet.append(Vehicle(self, index, vehicle.name, robot,
                                      vehicle_route(base_world, vehicle),
                                      store=self.store, start_time=vehicle.start_time))
        self.vehicles: Mapping[str, Vehicle] = MappingProxyType(
            {vehicle.name: vehicle for vehicle in self.fleet})
        if self.fleet_size == 1:
            self.fleet[0].log = self.log  # the run's log is the vehicle's
        else:
            self._attach_fleet_observers(spec)
        # A world without people costs no per-tick call (person_positions stays empty).
        self._people = People(self.world) if self.world.people else None
        # Control, localization and safety, in the order vehicles take them; each one's
        # next step is looked up once per firing, and a tick before the earliest does
        # no sensing or control at all.
        self._schedules = (Schedule(rates.control_hz, rates.physics_hz),
                           Schedule(rates.localization_hz, rates.physics_hz),
                           Schedule(rates.safety_hz, rates.physics_hz))
        self._due_steps = [schedule.next_due(0) for schedule in self._schedules]
        self._next_due = min(self._due_steps)
        self._step_count = 0
        self.person_positions: dict[str, np.ndarray | None] = {}
        self.layout_revision = 0
        self.done = False
        self._hooks = None
        self._apply_layout(self._worlds[0])
        for vehicle in self.fleet:
            vehicle.begin_lap(1)

    def _attach_fleet_observers(self, spec: ScenarioSpec) -> None:
        """Give every vehicle of a fleet its own scoring (and publishing) observers."""
        names = [segment.name for segment in self.segments]
        for vehicle in self.fleet:
            vehicle.add_observer(GroundTruthScoring())
            vehicle.add_observer(Table1Reference())
            if self.store is not None:
                vehicle.add_observer(
                    SegmentPublisher(self.store, vehicle.index, segment_names=names))

    def segment_key(self, name: str) -> int:
        """Return the fleet-wide index of segment ``name`` (its place in the world's path).

        Examples
        --------
        >>> with Testbench("pal1") as bench:
        ...     bench.reset()
        ...     [bench.segment_key(segment.name) for segment in bench.segments]
        [0, 1, 2]
        """
        return self._segment_keys[name]

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
        if self._sim is None or self.done:
            self._require_running()  # raises
        if self._people is not None:
            self._walk_people()
        self._sense_and_command()
        self._sim.step()
        self._after_physics()

    # The tick in named pieces (physics stepping and per-tick glue stay easy to find).
    def _walk_people(self) -> None:
        lead = self.fleet[0]
        self.person_positions = self._people.update(self._sim.sim_time,
                                                    lap_start=lead.lap_log.start_time)

    def _sense_and_command(self) -> None:
        self._step_count += 1
        n = self._step_count
        if n < self._next_due:
            # Nothing due: only a vehicle waiting for its start time looks at the clock.
            for vehicle in self.fleet:
                if vehicle.waiting:
                    vehicle.sense_and_command(False, False, False)
            return
        steps = self._due_steps
        due = (steps[0] == n, steps[1] == n, steps[2] == n)
        for index, schedule in enumerate(self._schedules):
            if due[index]:
                steps[index] = schedule.next_due(n)
        self._next_due = min(steps)
        for vehicle in self.fleet:
            vehicle.sense_and_command(*due)

    def _after_physics(self) -> None:
        for vehicle in self.fleet:
            if not vehicle.done:
                vehicle.contacts.check()
        for hook in self.observer_hooks("on_tick"):
            hook(self)
        for vehicle in self.fleet:
            vehicle.tick_observers()
        for vehicle in self.fleet:
            if vehicle.lap_over():
                self._end_lap(vehicle)

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
        >>> from scenarios.spec.load import load_scenario
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
    def lead(self) -> Vehicle:
        """Return the first vehicle: the one ``true_pose``, ``local_maps`` ... describe."""
        return self.fleet[0]

    @property
    def lap_log(self) -> LapLog:
        """Return the first vehicle's current lap log."""
        return self.fleet[0].lap_log

    @property
    def lap(self) -> int:
        """Return the current lap, counted from 1 (the last lap once the run is done)."""
        return self.lap_log.lap

    @property
    def time_step(self) -> float:
        """Return the physics time step (s)."""
        if self._sim is not None:  # the same quotient (reset); a progress bar asks per tick
            return self._sim.time_step
        return 1.0 / self.log.spec.rates.physics_hz

    @property
    def sim_time(self) -> float:
        """Return the simulated seconds since the run started."""
        return self._sim.sim_time if self._sim is not None else self.log.sim_time_s

    @property
    def true_pose(self) -> np.ndarray:
        """Return the simulator's true robot pose ``(x, y, theta)`` (for scoring only).

        With several vehicles, the first one's; ``bench.vehicles[name].true_pose`` is any
        vehicle's.

        Examples
        --------
        >>> with Testbench("warehouse_fleet") as bench:
        ...     bench.reset()
        ...     names = [name for name in bench.vehicles]
        ...     same = bool((bench.true_pose == bench.vehicles["lgv1"].true_pose).all())
        ...     names, bench.vehicles["lgv2"].segment.name, same
        (['lgv1', 'lgv2', 'lgv3'], 'north_west', True)
        """
        return self.fleet[0].true_pose

    @property
    def true_twist(self) -> np.ndarray:
        """Return the simulator's true ``(v_forward, v_left, omega)`` of the robot (m/s, rad/s)."""
        return self.fleet[0].true_twist

    @property
    def ekf_pose(self) -> np.ndarray:
        """Return the EKF's robot pose estimate ``(x, y, theta)``, world frame."""
        return self.fleet[0].ekf_pose

    @property
    def ekf_covariance(self) -> np.ndarray:
        """Return the EKF's ``(3, 3)`` pose covariance."""
        return self.fleet[0].ekf_covariance

    @property
    def local_maps(self) -> Mapping[str, LocalMap]:
        """Return the local map of every path segment by segment name (read-only mapping)."""
        return self.fleet[0].local_maps

    @property
    def zone(self) -> str:
        """Return the safety zone after the last safety scan: free, warning or protective."""
        return self.fleet[0].zone

    @property
    def speed_scale(self) -> float:
        """Return the speed factor the safety fields impose (1 free, 0 stopped)."""
        return self.fleet[0].speed_scale

    @property
    def policy(self) -> FieldPolicy:
        """Return the first vehicle's field policy (each vehicle has its own)."""
        return self.fleet[0].policy

    @property
    def segment(self) -> PathSegment:
        """Return the path segment the robot is on (by the follower's progress)."""
        return self.fleet[0].segment

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

    def observer_hooks(self, name: str) -> Any:
        """Return the bench observers' ``name`` hooks, or ``"wants_polylines"``; cached."""
        if self._hooks is None:
            self._hooks = hook_table(self.observers)
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

    def _end_lap(self, vehicle: Vehicle) -> None:
        """Close ``vehicle``'s lap; set up its next one (the first vehicle's brings the boxes)."""
        if vehicle.end_lap():
            lap = vehicle.lap_log.lap + 1
            if vehicle.index == 0:
                self._apply_layout(self._worlds[lap - 1])
            vehicle.begin_lap(lap)
            return
        if self.fleet_size > 1:
            x, y, yaw = PARKING
            vehicle.park((x - 3.0 * vehicle.index, y, yaw))
        if all(other.done for other in self.fleet):
            self._finish()

    def _finish(self) -> None:
        sim, log = self._sim, self.log
        self.done = True
        wall = time.perf_counter() - self._wall_start
        for vehicle in self.fleet:
            vehicle.log.engine_time_s = sim.engine_time_s
            vehicle.log.sim_time_s = sim.sim_time
            vehicle.log.wall_time_s = wall
        if self.fleet_size > 1:
            combine_logs(log, {vehicle.name: vehicle.log for vehicle in self.fleet}, self.store)
            log.engine_time_s, log.sim_time_s = sim.engine_time_s, sim.sim_time
            log.wall_time_s = wall
