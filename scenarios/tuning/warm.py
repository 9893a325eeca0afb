"""Warm starts: run many variations of a scenario's last laps from one saved state.

A falsification search runs many samples of one scenario that differ only in what
happens from some lap on (e.g. when a person limited to ``laps = [3]`` steps into the
lane); the laps before it, the paper's mapping laps, are the same in every sample.
:class:`WarmStart` simulates those laps once, keeps the bench's state in memory
(:meth:`Testbench.save_state <scenarios.bench.saved_state.SavedStates.save_state>`) and runs
each sample from it: the metrics are exactly those of a full run of the sample
(:func:`scenarios.tuning.run.run_point`), ``performance`` aside (timing; a warm
sample's wall and engine times count the shared laps as measured once).

The samples share more than those laps: until its trigger fires, a person a vehicle
triggers stands at its first waypoint whatever its walk. So the warm start also runs
lap ``lap`` once with every such person held (:meth:`PersonTriggers.hold
<scenarios.bench.triggers.PersonTriggers.hold>`), saving a checkpoint every
:data:`CHECKPOINT_S` simulated seconds and the vehicle's progress at every tick; a sample
starts from the last checkpoint before its own first trigger fires
(:meth:`WarmStart.start_tick`). A person changed in what shows before that (first
waypoint, remission, laps, a time trigger) starts the sample at the lap's start.

A sample may differ from the base scenario only in people whose ``laps`` all come at or
after the warm-start lap, in anything but their bodies (``radius``, ``height``,
``enabled``): those people were parked below the floor during the shared laps, in the
sample's full run as in the base run. Anything else (a box, the seed, a threshold, a
person of the shared laps) would have changed the shared laps: :meth:`WarmStart.accepts`
says no and :meth:`WarmStart.run` raises ``ValueError`` naming it.

Examples
--------
>>> import dataclasses
>>> from scenarios.spec.load import load_scenario
>>> spec = load_scenario("pal1", overrides=["laps=2"])
>>> with WarmStart(spec, lap=2) as warm:
...     refused = warm.differences(dataclasses.replace(spec, seed=1))
...     metrics = warm.run(spec)
>>> refused, metrics["laps"], metrics["safety"]["laps_completed"]
(['seed: 1 instead of 0'], 2, 2)
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from scenarios.bench.saved_state import BenchState
from scenarios.bench.testbench import Testbench
from scenarios.bench.triggers import PersonTriggers
from scenarios.results.outputs import summarize
from scenarios.spec.layout import lap_worlds
from scenarios.spec.routes import fleet_vehicles
from scenarios.spec.scenario import LOADER_FIELDS, ScenarioSpec
from worlds.spec import PersonSpec, WorldSpec

__all__ = ["BODY_FIELDS", "CHECKPOINT_S", "WarmStart", "WarmStarts"]

CHECKPOINT_S = 0.5
"""Simulated seconds between the checkpoints of the warm-start lap: a sample replays at
most this much of the base run before its own people act (each checkpoint costs a copy
of the bench's state, about what 0.1 s of simulation costs)."""

BODY_FIELDS = ("name", "enabled", "radius", "height")
"""A person's fields that make its body: built once, the same in every warm sample."""

_SCENARIO_LABELS = ("name", *LOADER_FIELDS)
"""Scenario fields that only label a run: a sample may rename itself."""


class WarmStart:
    """A scenario's shared laps simulated once, to run variations of its later laps from.

    Parameters
    ----------
    spec
        The base scenario (its seed applied): laps ``1 .. lap - 1`` are simulated now.
    lap
        The first lap in which samples may differ (2 or more, at most ``spec.laps``).

    Notes
    -----
    The checkpoints live in one PyBullet server of this process until :meth:`close` (or
    the end of a ``with`` block); every :meth:`run` restores one, so many samples in a row
    use no more memory than one. Building the warm start costs laps ``1 .. lap`` and a
    state copy per checkpoint. Single-vehicle scenarios whose boxes are the same from
    ``lap`` on (moves, not additions or removals) only: PyBullet restores only the bodies
    it saved.
    """

    def __init__(self, spec: ScenarioSpec, lap: int) -> None:
        if not 2 <= lap <= spec.laps:
            raise ValueError(f"WarmStart: lap must be in 2..{spec.laps} (the laps of "
                             f"{spec.name}; lap 1 shares nothing), got {lap}")
        if len(fleet_vehicles(spec)) > 1:
            raise ValueError(f"WarmStart: {spec.name} drives a fleet; warm starts serve "
                             "single-vehicle scenarios")
        worlds = lap_worlds(spec)
        names = [[box.name for box in world.boxes] for world in worlds[lap - 1:]]
        if any(later != names[0] for later in names):
            raise ValueError(f"WarmStart: {spec.name} adds or removes boxes after lap {lap}; "
                             "a saved state holds the bodies of its lap only")
        self.spec, self.lap = spec, int(lap)
        self._worlds = worlds
        self._bench = bench = Testbench(spec)
        bench.reset()
        while bench.lap < lap:
            bench.step()
        self._checkpoints: dict[int, BenchState] = {0: bench.save_state()}  # by tick
        self._progress = np.empty(0)
        triggers = bench.scene.triggers
        if triggers is not None:
            self._fired_at_lap_start = dict(triggers.fired)
            self._hold_through_lap(triggers)

    def differences(self, spec: ScenarioSpec) -> list[str]:
        """Return what keeps ``spec`` from running warm (empty: :meth:`run` accepts it).

        The scenarios are compared field by field (``name`` and ``source`` only label a
        run), their worlds lap by lap, the people person by person.
        """
        found = []
        for field in dataclasses.fields(ScenarioSpec):
            name = field.name
            if name in (*_SCENARIO_LABELS, "world"):
                continue
            ours, theirs = getattr(self.spec, name), getattr(spec, name)
            if ours != theirs:
                found.append(f"{name}: {theirs!r} instead of {ours!r}")
        if found:
            return found
        worlds = lap_worlds(spec)
        for lap, (ours, theirs) in enumerate(zip(self._worlds, worlds, strict=True), start=1):
            found += [f"world of lap {lap}: {name} differ" for name in _world_fields(ours, theirs)]
        # Box moves change boxes only: every lap's world has the same people.
        return found + self._people_differences(self._worlds[0].people, worlds[0].people)

    def accepts(self, spec: ScenarioSpec) -> bool:
        """Return whether ``spec`` differs from the base only in people of lap ``lap`` on."""
        return not self.differences(spec)

    def run(self, spec: ScenarioSpec) -> dict[str, Any]:
        """Run ``spec`` from the saved state; return its ``metrics.json`` content.

        The metrics are those of ``run_point(spec)`` (apart from ``performance``); a run
        that raises raises here. ``ValueError`` names what keeps ``spec`` from running warm.
        """
        if self._bench.sim is None:
            raise RuntimeError("WarmStart: closed; its saved state went with it")
        found = self.differences(spec)
        if found:
            raise ValueError(f"WarmStart: {spec.name} differs from {self.spec.name} in "
                             f"more than the people of lap {self.lap} on: {'; '.join(found)}")
        bench = self._bench
        bench.restore_state(self._checkpoints[self.start_tick(spec)])
        bench.replace_people(spec)
        return summarize(bench.run())

    def start_tick(self, spec: ScenarioSpec) -> int:
        """Return the tick of lap ``lap`` (0: its start) :meth:`run` starts ``spec`` from.

        The tick of the last checkpoint before ``spec``'s run leaves the base run's: when
        one of its people's triggers fires (found on the base run's recorded progress),
        or at once when a person differs before that (first waypoint, body, remission,
        laps, a time trigger). ``spec`` must be accepted (:meth:`differences`).
        """
        if len(self._checkpoints) == 1:
            return 0
        ours = {person.name: person for person in self._worlds[0].people}
        theirs = lap_worlds(spec)[0].people
        if any(_before_firing(ours[person.name]) != _before_firing(person)
               for person in theirs):
            return 0
        triggers = PersonTriggers(theirs, self._bench.fleet)
        triggers.fired.update({name: self._fired_at_lap_start.get(name)
                               for name in triggers.watched})
        fires = [tick for tick in triggers.fire_ticks(self._progress, self.lap).values()
                 if tick is not None]
        diverges = min(fires, default=len(self._progress))
        return max(tick for tick in self._checkpoints if tick <= diverges)

    def close(self) -> None:
        """Free the saved state and the PyBullet server; safe to call twice."""
        if self._bench.sim is not None:
            for state in self._checkpoints.values():
                self._bench.release_state(state)
            self._bench.close()

    def __enter__(self) -> WarmStart:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # ------------------------------------------------------------------ pieces
    def _hold_through_lap(self, triggers: PersonTriggers) -> None:
        """Run lap ``lap`` with every triggered person held, saving checkpoints on the way.

        Until its trigger fires, a triggered person stands at its first waypoint in every
        variation of its walk, as a held one does the whole lap: the base run's ticks up
        to there are the sample's. The vehicle's progress at every tick is kept to find
        that tick for each sample (:meth:`PersonTriggers.fire_ticks`).
        """
        bench = self._bench
        vehicle = bench.fleet[0]
        triggers.hold(triggers.watched)
        progress: list[float] = []
        saved_at = bench.sim_time
        while not bench.done and bench.lap == self.lap:
            if bench.sim_time - saved_at >= CHECKPOINT_S - 1e-9:
                self._checkpoints[len(progress)] = bench.save_state()
                saved_at = bench.sim_time
            idle = vehicle.done or vehicle.waiting
            progress.append(math.nan if idle else vehicle.follower.progress)
            bench.step()
        self._progress = np.array(progress)

    def _people_differences(self, ours: tuple[PersonSpec, ...],
                            theirs: tuple[PersonSpec, ...]) -> list[str]:
        our_names = [person.name for person in ours]
        their_names = [person.name for person in theirs]
        if our_names != their_names:
            return [f"people {their_names} instead of {our_names}"]
        found = []
        for before, after in zip(ours, theirs, strict=True):
            if before != after:
                found += self._person_differences(before, after)
        return found

    def _person_differences(self, before: PersonSpec, after: PersonSpec) -> list[str]:
        found = []
        for person in (before, after):
            if not person.laps or person.laps[0] < self.lap:
                laps = list(person.laps) or "every lap"
                found.append(f"person {person.name} acts before lap {self.lap} (laps = {laps})")
                break
        body = [key for key in BODY_FIELDS if getattr(before, key) != getattr(after, key)]
        if body:
            found.append(f"person {before.name}'s body ({', '.join(body)})")
        return found


_AFTER_FIRING = ("trigger", "trigger_distance", "meet_at", "speed", "start_time", "dwell",
                 "loop")
"""A triggered person's fields that matter only once its trigger fired (so do its
waypoints after the first): before that, it stands at its first waypoint."""


def _before_firing(person: PersonSpec) -> tuple:
    """Return what a person is before its trigger fires (a time trigger: all of it)."""
    if person.trigger == "time":
        return (person,)
    return (person.waypoints[0], *(getattr(person, field.name)
                                   for field in dataclasses.fields(PersonSpec)
                                   if field.name not in (*_AFTER_FIRING, "waypoints")))


def _world_fields(ours: WorldSpec, theirs: WorldSpec) -> list[str]:
    """Return the names of the fields, people and source aside, in which two worlds differ."""
    return [field.name for field in dataclasses.fields(WorldSpec)
            if field.name not in ("people", "source")
            and getattr(ours, field.name) != getattr(theirs, field.name)]


@dataclasses.dataclass(frozen=True)
class WarmStarts:
    """Points that differ from ``base`` only in people acting from lap ``lap`` on.

    Passed where a point's recordings go, it makes a worker simulate ``base``'s first
    ``lap - 1`` laps once (:class:`WarmStart`, kept for the
    worker's later points) and run each point from there: the metrics are a full run's.
    A point the warm start does not accept runs in full.
    """

    base: ScenarioSpec
    lap: int

    def run(self, spec: ScenarioSpec) -> dict[str, Any]:
        """Return the metrics of ``spec``, from this worker's warm start when it accepts it."""
        warm = _warm_start(self.base, self.lap)
        if warm.accepts(spec):
            return warm.run(spec)
        from scenarios.bench.runner import run_scenario

        return summarize(run_scenario(spec))


_WARM: dict[tuple[ScenarioSpec, int], WarmStart] = {}
"""This process's warm start (one at a time: it holds a PyBullet server)."""


def _warm_start(base: ScenarioSpec, lap: int) -> WarmStart:
    if (base, lap) not in _WARM:
        for earlier in _WARM.values():
            earlier.close()
        _WARM.clear()
        _WARM[(base, lap)] = WarmStart(base, lap)
    return _WARM[(base, lap)]
