"""The observer contract: what an experiment adds to a run without touching the robot's tick.

An :class:`Observer` is called at four points of the closed loop (dm_control's hooks are
the model). Each hook does nothing by default; a subclass overrides the ones it needs:

- ``on_lap_start(vehicle, lap)``: the vehicle stands re-localised at its start, the lap's
  boxes are in place;
- ``on_scan(vehicle, record)``: after each safety-laser scan was used by the safety
  fields and the local map (``record`` is a :class:`~scenarios.bench.records.ScanRecord`);
- ``on_tick(vehicle)``: after each physics step;
- ``on_lap_end(vehicle, lap_log)``: the lap is over (``lap_log`` is a
  :class:`~scenarios.bench.records.LapLog` that the observer may complete).

The first argument of every hook is a :class:`VehicleView`: the read-only view of the
running vehicle the observer watches. An observer added with
:meth:`Testbench.add_observer <scenarios.bench.testbench.Testbench.add_observer>` receives
the Testbench itself (the view of its first vehicle, which also lets a script move boxes),
or, when it sets ``every_vehicle = True`` (a recording of the whole fleet), each vehicle
of the fleet in turn; one added for a fleet vehicle receives that vehicle; a recording's
replay hands its own view to the scoring observers. Observers read; they must not drive the robot.

``on_scan`` records carry the segment's whole map (``record.polylines`` with their
``polyline_status``) and the fields the scan was judged against (``record.fields``) only
when an observer of the vehicle sets ``wants_polylines = True``: building them costs at
every scan.

Examples
--------
>>> class CountScans(Observer):
...     def __init__(self):
...         self.scans = 0
...     def on_scan(self, vehicle, record):
...         self.scans += 1
>>> observers = ObserverSet()
>>> counter = CountScans()
>>> observers.add(counter, view=None)
>>> observers.emit("on_scan", None)
>>> observers.emit("on_tick")    # not overridden: never called
>>> counter.scans, observers.wants_polylines
(1, False)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from robots.presets import UGVSpec
from scenarios.bench.records import LapLog, RunLog, ScanRecord
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment
from semistatic.local_map import LocalMap

__all__ = [
    "HOOKS",
    "Observer",
    "ObserverSet",
    "ProgressReporter",
    "ScanCallback",
    "VehicleView",
    "require_observer",
]

HOOKS = ("on_lap_start", "on_scan", "on_tick", "on_lap_end")
"""The points of the closed loop where observers are called (module docstring)."""


class VehicleView(Protocol):
    """The read-only view of a running vehicle that observers receive.

    Provided by :class:`~scenarios.bench.testbench.Testbench` (its first vehicle),
    :class:`~scenarios.bench.vehicle.Vehicle` (any vehicle of a fleet) and a recording's
    replay (:mod:`scenarios.logs.recording`). Poses are ``(x, y, theta)`` in the world
    frame (m, rad); the ``true_*`` figures are the simulator's ground truth, for scoring
    only.

    Attributes
    ----------
    name : str
        The vehicle's name.
    spec : ScenarioSpec
        The scenario of the run (with the run's seed).
    world
        The world as it stands now: ``world.boxes`` are the semi-static boxes where they
        are (:class:`~worlds.spec.BoxSpec`), ``world.walls``, ``world.posts``.
    segments : tuple of PathSegment
        The path segments (the fleet's frames).
    segment : PathSegment
        The segment the vehicle is on.
    lap : int
        The current lap, from 1.
    lap_log : LapLog
        The current lap's log.
    log : RunLog
        The vehicle's run log so far.
    fleet_size : int
        How many vehicles drive in the world (1 for a single robot).
    sim_time : float
        Simulated seconds since the run started.
    time_step : float
        The physics time step (s).
    true_pose, true_twist : numpy.ndarray
        True pose, and true ``(v_forward, v_left, omega)`` (m/s, rad/s).
    ekf_pose, ekf_covariance : numpy.ndarray
        The EKF's pose estimate and its ``(3, 3)`` covariance.
    local_maps : Mapping[str, LocalMap]
        Each segment's local map by name (read-only mapping).
    zone : str
        The safety zone after the last safety scan: ``free``, ``warning`` or ``protective``.
    speed_scale : float
        The speed factor the safety fields impose (1 free, 0 stopped).
    person_positions : Mapping[str, numpy.ndarray or None]
        Where each person stands now (``None``: not in the scene).
    robot : UGVSpec
        The vehicle's preset (footprint, lasers, wheels).
    layout_revision : int
        Changes whenever a box is moved, added or removed.

    Examples
    --------
    >>> from scenarios.bench.testbench import Testbench
    >>> def describe(vehicle: VehicleView) -> str:
    ...     return f"{vehicle.name} lap {vehicle.lap} in {vehicle.segment.name}"
    >>> with Testbench("pal1") as bench:
    ...     bench.reset()
    ...     describe(bench), describe(bench.vehicles["robot"])
    ('robot lap 1 in niches', 'robot lap 1 in niches')
    """

    name: str
    spec: ScenarioSpec
    world: Any
    segments: tuple[PathSegment, ...]
    segment: PathSegment
    lap: int
    lap_log: LapLog
    log: RunLog
    fleet_size: int
    sim_time: float
    time_step: float
    true_pose: np.ndarray
    true_twist: np.ndarray
    ekf_pose: np.ndarray
    ekf_covariance: np.ndarray
    local_maps: Mapping[str, LocalMap]
    zone: str
    speed_scale: float
    person_positions: Mapping[str, np.ndarray | None]
    robot: UGVSpec
    layout_revision: int

    def vehicle_outlines(self) -> list[np.ndarray]:
        """Return the true ``(N, 2)`` footprints of the fleet's vehicles (for scoring)."""
        ...


class Observer:
    """Base class of observers: four hooks that do nothing until overridden.

    Examples
    --------
    >>> class LapTimes(Observer):
    ...     def __init__(self):
    ...         self.times = []
    ...     def on_lap_end(self, vehicle, lap_log):
    ...         self.times.append(lap_log.duration_s)
    >>> LapTimes().times, Observer.wants_polylines
    ([], False)
    """

    wants_polylines: bool = False
    """Whether ``on_scan`` reads ``record.polylines`` and ``record.fields`` (built per scan)."""

    every_vehicle: bool = False
    """Whether a Testbench calls the hooks for every vehicle of its fleet (each its view)."""

    def on_lap_start(self, vehicle: VehicleView, lap: int) -> None:
        """Prepare for lap ``lap``: the vehicle stands re-localised at its start."""

    def on_scan(self, vehicle: VehicleView, record: ScanRecord) -> None:
        """Read a safety scan after the fields and the local map used it."""

    def on_tick(self, vehicle: VehicleView) -> None:
        """Read the state after a physics step."""

    def on_lap_end(self, vehicle: VehicleView, lap_log: LapLog) -> None:
        """Read (or complete) ``lap_log``: the lap is over."""


class ObserverSet:
    """The observers of one vehicle, each with the view it is handed, in the order added.

    :meth:`emit` calls only the hooks a subclass overrides, so the per-tick path never
    calls a no-op (a physics step is ~20 us).

    Examples
    --------
    >>> ObserverSet().emit("on_tick")
    >>> ObserverSet().add(object(), view=None)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    TypeError: observer <object ...> is no scenarios.Observer: subclass it and override \
the hooks you need (on_lap_start, on_scan, on_tick, on_lap_end)
    """

    def __init__(self) -> None:
        self._calls: dict[str, list[tuple[Callable, Any]]] = {hook: [] for hook in HOOKS}
        self.wants_polylines = False

    def add(self, observer: Observer, view: Any) -> None:
        """Call ``observer``'s overridden hooks with ``view`` from now on."""
        require_observer(observer)
        for hook in HOOKS:
            if getattr(type(observer), hook) is not getattr(Observer, hook):
                self._calls[hook].append((getattr(observer, hook), view))
        self.wants_polylines |= bool(observer.wants_polylines)

    def emit(self, hook: str, *args) -> None:
        """Call every observer's ``hook`` with its view and ``args``."""
        for method, view in self._calls[hook]:
            method(view, *args)


def require_observer(observer: object) -> Observer:
    """Return ``observer``, or raise ``TypeError`` unless it is an :class:`Observer`.

    Examples
    --------
    >>> require_observer(Observer()).wants_polylines
    False
    >>> class Careless(Observer):
    ...     wants_polylines = "yes"
    >>> require_observer(Careless())
    Traceback (most recent call last):
    ...
    TypeError: observer Careless.wants_polylines is str 'yes'; expected True or False
    """
    if not isinstance(observer, Observer):
        raise TypeError(
            f"observer {observer!r} is no scenarios.Observer: subclass it and override "
            f"the hooks you need ({', '.join(HOOKS)})"
        )
    label = f"observer {type(observer).__name__}"
    for flag in ("wants_polylines", "every_vehicle"):
        value = getattr(observer, flag)
        if not isinstance(value, bool | np.bool_):
            raise TypeError(f"{label}.{flag} is {type(value).__name__} {value!r}; expected "
                            "True or False")
    for hook in HOOKS:
        if not callable(getattr(observer, hook)):
            raise TypeError(f"{label}.{hook} is {type(getattr(observer, hook)).__name__}, not "
                            f"a method; expected def {hook}(self, vehicle, ...)")
    return observer


class ProgressReporter(Observer):
    """Call ``advance(seconds)`` with the simulated time of every physics step (a progress bar).

    Examples
    --------
    >>> seen = []
    >>> ProgressReporter(seen.append).advance is not None
    True
    """

    def __init__(self, advance: Callable[[float], None]) -> None:
        self.advance = advance

    def on_tick(self, vehicle: VehicleView) -> None:
        """Report one physics step."""
        self.advance(vehicle.time_step)


class ScanCallback(Observer):
    """Call ``callback(record)`` with every scan's :class:`~scenarios.bench.records.ScanRecord`.

    ``wants_polylines`` says whether the callback reads the records' map polylines (a ROS
    bag's markers do).

    Examples
    --------
    >>> records = []
    >>> ScanCallback(records.append).callback == records.append
    True
    """

    def __init__(self, callback: Callable[[ScanRecord], None], *,
                 wants_polylines: bool = True) -> None:
        self.callback = callback
        self.wants_polylines = wants_polylines

    def on_scan(self, vehicle: VehicleView, record: ScanRecord) -> None:
        """Pass the record on."""
        self.callback(record)
