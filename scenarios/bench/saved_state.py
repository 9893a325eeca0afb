"""Saving a running Testbench's state in memory and going back to it (warm starts).

:class:`SavedStates` gives :class:`~scenarios.bench.testbench.Testbench` its
``save_state``, ``restore_state``, ``release_state`` and ``replace_people``: a search that
runs many variations of a scenario's last laps simulates the laps they share once, saves,
and starts each variation from there (:mod:`scenarios.tuning.warm`). A restored run
continues exactly as the saved one would have: PyBullet restores the bodies' poses,
velocities and contacts, a deep copy the rest (stacks, logs, observers, random streams).

Examples
--------
>>> from scenarios.bench.testbench import Testbench
>>> with Testbench("pal1") as bench:
...     bench.reset()
...     state = bench.save_state()
...     lap = bench.run_lap().duration_s
...     bench.restore_state(state)
...     again = bench.run_lap().duration_s
...     bench.release_state(state)
>>> lap == again
True
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from types import MappingProxyType

from scenarios.spec.layout import lap_worlds
from scenarios.spec.scenario import ScenarioSpec
from sim.client import PhysicsState

__all__ = ["BenchState", "SavedStates"]

NOT_COPIED = ("_sim", "vehicles")
"""Bench attributes a saved state leaves out: the physics client (PyBullet saves its state)
and the read-only view of the fleet (rebuilt from the fleet; a mapping proxy cannot be copied)."""


@dataclass(frozen=True, eq=False)
class BenchState:
    """A running bench's state kept in memory (:meth:`Testbench.save_state`).

    ``physics`` is PyBullet's in-memory state with the clock, ``python`` a deep copy of
    the bench's own state (every vehicle's stack, logs, observers, people, random
    streams), ``bodies`` the ids of the bodies the physics state expects and ``wall_s``
    the wall time the run had taken when it was saved.
    """

    physics: PhysicsState
    python: dict
    bodies: tuple[int, ...]
    wall_s: float



class SavedStates:
    """The state methods of :class:`~scenarios.bench.testbench.Testbench` (its base class).

    They read and write the bench's own attributes; in a module of their own only to keep
    ``testbench.py`` short.
    """

    def save_state(self) -> BenchState:
        """Keep the run's whole state in memory, to go back to with :meth:`restore_state`.

        The physics (PyBullet's ``saveState``) and a deep copy of everything else: the
        vehicles' stacks (EKF, odometry, follower, maps, supervisor), logs, observers,
        people and triggers, the clock and the random streams. ``copy.deepcopy`` of a
        bench itself is refused with a ``TypeError`` before anything is copied (two
        benches would step one physics server);
        :meth:`release_state` frees the physics part.

        Examples
        --------
        >>> from scenarios.bench.testbench import Testbench
        >>> from scenarios.spec.load import load_scenario
        >>> with Testbench(load_scenario("pal1", overrides=["laps=1"])) as bench:
        ...     bench.reset()
        ...     for _ in range(480):
        ...         bench.step()
        ...     state = bench.save_state()
        ...     first = bench.run().laps[0].duration_s
        ...     bench.restore_state(state)
        ...     again = bench.run().laps[0].duration_s
        ...     bench.release_state(state)
        >>> first == again
        True
        """
        self._require_running()
        sim = self._sim
        bullet = sim.bullet
        bodies = tuple(bullet.getBodyUniqueId(i) for i in range(bullet.getNumBodies()))
        python = copy.deepcopy({key: value for key, value in vars(self).items()
                                if key not in NOT_COPIED}, self._shared_in_copies())
        return BenchState(sim.save_state(), python, bodies,
                          time.perf_counter() - self._wall_start)

    def restore_state(self, state: BenchState) -> None:
        """Go back to ``state`` (:meth:`save_state`); the state stays for later restores.

        The wall time of the run counts the time before the save and since this restore.
        Raises ``RuntimeError`` when the world's bodies changed since the save (a box
        added or removed): PyBullet restores only the same bodies.
        """
        if self._sim is None:
            raise RuntimeError("Testbench: the bench was closed; its saved states went with it")
        sim = self._sim
        bullet = sim.bullet
        bodies = tuple(bullet.getBodyUniqueId(i) for i in range(bullet.getNumBodies()))
        if bodies != state.bodies:
            raise RuntimeError(
                f"Testbench: the world holds bodies {list(bodies)}, the saved state "
                f"{list(state.bodies)}: restore before boxes are added or removed")
        sim.restore_state(state.physics)
        vars(self).update(copy.deepcopy(state.python, self._shared_in_copies()))
        self.vehicles = MappingProxyType({vehicle.name: vehicle for vehicle in self.fleet})
        self._wall_start = time.perf_counter() - state.wall_s
        for vehicle in self.fleet:
            # PyBullet's state leaves out the motors' targets: send the saved ones again.
            vehicle.body.set_wheel_speeds(*vehicle.body.wheel_targets)

    def release_state(self, state: BenchState) -> None:
        """Free the physics memory of ``state``; it cannot be restored any more."""
        if self._sim is not None:
            self._sim.remove_state(state.physics)

    def _shared_in_copies(self) -> dict[int, object]:
        # A deepcopy memo: copies keep this bench (observers' view) and its physics client
        # and display (which refuse copies: sim.client.Uncopyable).
        sim = self._sim
        shared = {id(self): self, id(sim): sim, id(sim.bullet): sim.bullet}
        if sim.display is not None:
            shared[id(sim.display)] = sim.display
        return shared

    def replace_people(self, scenario: ScenarioSpec) -> None:
        """Go on with ``scenario``, whose world's people differ from the running one's.

        Everything else of ``scenario`` must be the running scenario's (its seed too):
        the bench does not check. The people keep their bodies (same names, ``enabled``,
        ``radius`` and ``height``); their walks, triggers and remissions are the new
        ones from the next tick (:meth:`Scene.replace_people
        <scenarios.bench.scene.Scene.replace_people>`); the run log reads ``scenario``.
        """
        self._require_running()
        worlds = lap_worlds(scenario, world=self._world_override)
        self.scene.replace_people(worlds[0].people)
        self._spec = self.scene.spec = scenario
        self._worlds = worlds
        for log in {id(log): log for log in (self.log, *(v.log for v in self.fleet))}.values():
            log.spec = scenario
        self.log.world = worlds[0]
