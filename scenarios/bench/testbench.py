"""The closed loop as an object: PyBullet physics, the UGV's stack and the polyline mapper.

One physics tick (docs/design.md, the closed loop); observers are called where marked::

    people walk ------------------------------------------------------------------------
    wheel encoders -> odometry increment --------------------------------> EKF predict
    top laser scan -> reflective posts -> landmarks ----------------------> EKF update
    safety laser scan -+-> field policy -> warning/protective fields -> speed scale
                       +-> polyline mapper (EKF pose) -> local map of the current segment
                       +-> on_scan(vehicle, record)
    EKF pose + spline path -> chained-form follower (u1, u2) * speed scale -> wheel motors
    physics step, contacts -> on_tick(vehicle)
    lap over? -> on_lap_end(vehicle, lap_log); next lap's boxes; re-localise -> on_lap_start

Sensors and control run at their own rates on the physics clock. Each lap starts with the
robot carried back to the start (it re-localises) and the boxes changed as the scenario
says, "while the robot is not observing". The tick does what the robot does; ground
truth is read only by observers (scoring, Table 1, recording, progress).

With ``[[vehicles]]`` a fleet shares the :class:`~scenarios.bench.scene.Scene`; each
:class:`~scenarios.bench.vehicle.Vehicle` (``bench.vehicles``) runs the tick above with its
own stack, laps and scoring. The bench is its first vehicle's
:class:`~scenarios.bench.observer.VehicleView` (:mod:`scenarios.bench.lead_view`); a
vehicle done parks outside.
numba compiles the mapper's kernels on first use; :func:`semistatic.kernel_cache.
warm_kernel_cache` compiles them ahead on every core (the CLI does; ``reset`` does not).

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

import numpy as np

from robots.presets import UGVSpec
from scenarios.bench.fleet import PARKING
from scenarios.bench.gui import GuiView
from scenarios.bench.lead_view import LeadVehicleView
from scenarios.bench.observer import Observer, require_observer
from scenarios.bench.policies import FieldPolicy
from scenarios.bench.records import LapLog, RunLog, combine_logs
from scenarios.bench.safety_record import SafetyRecorder
from scenarios.bench.saved_state import SavedStates
from scenarios.bench.scene import Scene
from scenarios.bench.scoring import GroundTruthScoring, Table1Reference
from scenarios.bench.sharing import SegmentPublisher
from scenarios.bench.vehicle import Vehicle
from scenarios.spec.clock import SensorClock
from scenarios.spec.layout import lap_worlds, robot_preset
from scenarios.spec.load import load_scenario
from scenarios.spec.preflight import check_scenario
from scenarios.spec.routes import fleet_vehicles, vehicle_route
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment, path_segments
from semistatic.fleet import FleetMapStore
from sim.client import SimClient, emptied_or_new
from sim.random_streams import RandomStreams
from sim.uncopyable import Uncopyable
from sim.world_builder import SimWorld
from worlds.checks import build_spline
from worlds.spec import BoxSpec, WorldSpec

__all__ = ["Testbench"]


class Testbench(Uncopyable, SavedStates, LeadVehicleView):
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

    Notes
    -----
    Life cycle: :meth:`reset` builds the simulation and starts lap 1; :meth:`step`
    advances one physics tick; :meth:`run_lap` and :meth:`run` advance to the end of the
    lap or of the run; :meth:`close` (or leaving a ``with`` block) frees PyBullet. Between
    laps the robot is carried back to the start and the next lap's box moves applied;
    :meth:`move_box`, :meth:`add_box` and :meth:`remove_box` change the boxes at any
    moment. Observers added before :meth:`reset` see lap 1 start; the bench hands them
    itself (:class:`~scenarios.bench.observer.Observer`).

    A bench is used by one thread at a time; benches in different threads are safe. A
    :meth:`reset` reuses the bench's PyBullet server: memory stays flat over thousands of
    resets. Copying or pickling a bench raises ``TypeError`` and leaves it untouched:
    :meth:`save_state` / :meth:`restore_state` are its snapshots.

    Examples
    --------
    >>> with Testbench("pal1") as bench:
    ...     bench.reset()
    ...     lap = bench.run_lap()
    ...     lap.lap, lap.completed, bench.lap, sorted(bench.local_maps)
    (1, True, 2, ['east', 'niches', 'side_corridor'])
    """

    __test__ = False  # a name starting with "Test" is not a test class
    copy_advice = ("it drives a PyBullet server; take a snapshot with save_state() and go "
                   "back with restore_state(), or build another Testbench(bench.spec)")

    def __init__(
        self,
        scenario: ScenarioSpec | str,
        *,
        world: WorldSpec | None = None,
        robot: UGVSpec | str | None = None,
        policy: str | FieldPolicy | None = None,
        gui: bool = False,
    ) -> None:
        loaded = not isinstance(scenario, ScenarioSpec)
        spec = load_scenario(scenario) if loaded else scenario
        if policy is not None:
            spec = dataclasses.replace(spec, policy=policy)
        self._spec = spec
        self.gui = bool(gui)
        self._world_override = world
        self._robot_spec = robot_preset(spec.robot if robot is None else robot, file=spec.source)
        if not loaded or world is not None or robot is not None:  # load_scenario checked
            check_scenario(spec, world=world, robot=None if robot is None else self._robot_spec)
        self.fleet_size = len(fleet_vehicles(spec))
        # The bench's observers follow its first vehicle and receive the bench; each
        # vehicle's scoring observers are its own (attached at reset).
        self.observers: list[Observer] = [GuiView()] if self.gui else []
        self.log: RunLog | None = None
        self.scene: Scene | None = None
        self._sim: SimClient | None = None
        self.done = False

    # ------------------------------------------------------------------ life cycle
    def add_observer(self, observer: Observer) -> None:
        """Call ``observer``'s hooks with this bench (its first vehicle's view) from now on.

        An observer whose ``every_vehicle`` is true is called for every vehicle of the
        fleet instead, each time with that vehicle's view. Added before :meth:`reset`, it
        sees lap 1 start; a reset keeps it.

        Examples
        --------
        >>> bench = Testbench("pal1")
        >>> bench.add_observer(Observer())   # overrides nothing: never called
        >>> len(bench.observers)
        1
        >>> bench.add_observer(object())  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        TypeError: observer <object ...> is no scenarios.Observer: subclass it and override \
the hooks you need (on_lap_start, on_scan, on_tick, on_lap_end)
        """
        self.observers.append(require_observer(observer))
        if self.scene is not None:
            self._attach(observer)

    def _attach(self, observer: Observer) -> None:
        """Hand ``observer`` the bench (its first vehicle), or each vehicle if it asks."""
        if observer.every_vehicle:
            for vehicle in self.fleet:
                vehicle.add_observer(observer, view=vehicle)
        else:
            self.fleet[0].add_observer(observer, view=self)

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
        self._wall_start = time.perf_counter()
        spec = self._spec if seed is None else dataclasses.replace(self._spec, seed=seed)
        self._worlds = lap_worlds(spec, world=self._world_override)
        base_world = self._worlds[0]
        segments = path_segments(base_world, build_spline(base_world.path))
        self.log = RunLog(spec=spec, world=base_world, robot=self._robot_spec, segments=segments)
        rates = spec.rates
        # The last run's server, emptied (its meshes kept: memory stays flat over resets)
        self._sim = sim = emptied_or_new(self._sim, gui=self.gui, time_step=1.0 / rates.physics_hz)
        store = FleetMapStore() if spec.sharing and self.fleet_size > 1 else None
        self.scene = scene = Scene(spec, sim, SimWorld(sim, base_world), segments,
                                   RandomStreams(spec.seed), store)
        for index, vehicle in enumerate(fleet_vehicles(spec)):
            robot = self._robot_spec if index == 0 and not spec.vehicles else \
                robot_preset(vehicle.robot, file=spec.source)
            scene.fleet.append(Vehicle(scene, index, vehicle.name, robot,
                                       vehicle_route(base_world, vehicle),
                                       store=store, start_time=vehicle.start_time))
        self.fleet: list[Vehicle] = scene.fleet
        self.vehicles: Mapping[str, Vehicle] = MappingProxyType({v.name: v for v in self.fleet})
        if self.fleet_size == 1:
            self.fleet[0].log = self.log  # the run's log is the vehicle's
        names = [segment.name for segment in segments]
        for vehicle in self.fleet:  # each vehicle's own scoring
            vehicle.add_observer(GroundTruthScoring())
            vehicle.add_observer(Table1Reference())
            vehicle.add_observer(SafetyRecorder(vehicle.fields.model))
            if spec.sharing:  # alone, a vehicle publishes to a store of its own
                vehicle.add_observer(SegmentPublisher(store, vehicle.index, segment_names=names))
        for observer in self.observers:
            self._attach(observer)
        scene.add_people()
        self._clock = SensorClock(rates)
        self.done = False
        scene.apply_layout(self._worlds[0])
        for vehicle in self.fleet:
            vehicle.begin_lap(1)

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
        self.scene.walk_people(self.fleet[0].lap_log.start_time, self.fleet[0].lap_log.lap)
        self._sense_and_command()
        self._sim.step()
        self._after_physics()

    # The tick in named pieces (physics stepping and per-tick glue stay easy to find).
    def _sense_and_command(self) -> None:
        due = self._clock.tick()
        if due is None:
            # Nothing due: only a vehicle waiting for its start time looks at the clock.
            for vehicle in self.fleet:
                if vehicle.waiting:
                    vehicle.sense_and_command(False, False, False)
            return
        for vehicle in self.fleet:
            vehicle.sense_and_command(*due)

    def _after_physics(self) -> None:
        for vehicle in self.fleet:
            if not vehicle.done:
                vehicle.contacts.check()
        for vehicle in self.fleet:
            vehicle.observers.emit("on_tick")
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

    # ------------------------------------------------------------------ the view
    # The bench is the VehicleView of its first vehicle (LeadVehicleView); besides:
    @property
    def spec(self) -> ScenarioSpec:
        """Return the scenario: of the run once reset (its seed applied), else as given."""
        return self._spec if self.log is None else self.log.spec

    @property
    def segments(self) -> tuple[PathSegment, ...]:
        """Return the world path's segments."""
        return self.log.segments

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
        return self.scene.streams.generator(name)

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
        ...     bench.move_box("carton_west", (2.5, -1.0, 0.0))
        ...     bench.add_box(BoxSpec("crate", (0.4, 0.4, 0.5), (6.0, 0.9, 0.0)))
        ...     bench.remove_box("trolley_niche")
        ...     [(box.name, box.pose) for box in bench.world.boxes]
        [('carton_west', (2.5, -1.0, 0.0)), ('crate_corridor', (6.9, 1.15, 0.3)), \
('crate', (6.0, 0.9, 0.0))]
        """
        self._require_running()
        self.scene.move_box(name, pose)

    def add_box(self, box: BoxSpec) -> None:
        """Put a new semi-static box into the world now."""
        self._require_running()
        self.scene.add_box(box)

    def remove_box(self, name: str) -> None:
        """Take semi-static box ``name`` out of the world now."""
        self._require_running()
        self.scene.remove_box(name)

    # ------------------------------------------------------------------ pieces
    def _require_running(self) -> None:
        if self._sim is None:
            raise RuntimeError("Testbench: call reset() first (or the bench was closed)")
        if self.done:
            raise RuntimeError("Testbench: every lap has run; call reset() to start over")

    def _end_lap(self, vehicle: Vehicle) -> None:
        """Close ``vehicle``'s lap; set up its next one (the first vehicle's brings the boxes)."""
        if vehicle.end_lap():
            lap = vehicle.lap_log.lap + 1
            if vehicle.index == 0:
                self.scene.apply_layout(self._worlds[lap - 1])
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
            combine_logs(log, {vehicle.name: vehicle.log for vehicle in self.fleet},
                         self.scene.store)
            log.engine_time_s, log.sim_time_s = sim.engine_time_s, sim.sim_time
            log.wall_time_s = wall
