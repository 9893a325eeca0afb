"""One PyBullet physics server, bound once, with fixed stepping and engine-time accounting.

``SimClient`` owns a ``pybullet_utils.bullet_client.BulletClient``: every PyBullet call
in this project goes through ``sim.bullet`` (never the module-global ``pybullet`` API
with its implicit client 0), so several simulations can live side by side in one
process - the determinism tests run two of them.

With ``gui=True`` the physics still runs in a headless ``DIRECT`` server and a second,
GUI server (``sim.display``) only shows it (:class:`sim.debug_view.DebugView` copies the
bodies there a few times per simulated second). PyBullet's own GUI server answers every
command through a hand-over between the caller, its physics thread and its render thread:
under a software-rendered virtual display each hand-over waited for a frame (10-45 ms
measured, against ~0.02 ms in ``DIRECT``), and the closed loop makes ~650 calls per
simulated second: a sim1 lap took > 300 s instead of ~11 s. Keeping the physics
``DIRECT`` also keeps a watched run's results identical to a headless one.

Time is fixed-step: ``step(n)`` advances the simulation by ``n * time_step`` seconds and
``sim_time`` counts them. The wall time spent inside PyBullet is accumulated in
``engine_time_s``: stepping always, and other calls when made inside
``with sim.engine_timer():`` or timed inline by their callers (the ray casts, and the
closed loop's per-tick calls: contact points, the robot's base and wheel states, its
motor commands, the people's moves). A run's report compares it to the total wall time
to show that the engine, not our Python, dominates.

Examples
--------
>>> with SimClient() as sim:
...     sim.step(240)
...     round(sim.sim_time, 6), sim.engine_time_s > 0.0
(1.0, True)
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import TracebackType

_LIBC = ctypes.CDLL(None)


@contextmanager
def quiet_stdout() -> Iterator[None]:
    """Silence what PyBullet's C library prints straight to file descriptors 1 and 2.

    It writes its build time on import and ``argv[0]=`` on every connection, which would
    clutter the command line's output and any stdout a caller parses. Python exceptions
    are unaffected: they are raised, not printed, inside this block.
    """
    for stream in (sys.stdout, sys.stderr):
        if stream is not None and not stream.closed:  # None: started with it closed
            stream.flush()
    for descriptor in (1, 2):
        try:
            os.fstat(descriptor)
        except OSError:
            # Started with it closed: the next file opened would get its number and
            # receive what the C library prints. Hold it with /dev/null for good.
            held = os.open(os.devnull, os.O_WRONLY)
            if held != descriptor:
                os.dup2(held, descriptor)
                os.close(held)
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        _LIBC.fflush(None)  # C stdio buffers what it printed: flush it into /dev/null
        for descriptor, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, descriptor)
            os.close(copy)


with quiet_stdout():
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

__all__ = ["DEFAULT_TIME_STEP", "GRAVITY", "PhysicsState", "SimClient"]

DEFAULT_TIME_STEP = 1.0 / 240.0
"""PyBullet's native step (s); its contact and solver defaults are tuned for it."""

GRAVITY = 9.81
"""Standard gravity, m/s^2, pointing down -z."""

# Projected Gauss-Seidel iterations per step. PyBullet's default (50) keeps the wheel
# contacts converged at 240 Hz; fewer iterations let the velocity motors creep.
_SOLVER_ITERATIONS = 50


def _open_display() -> BulletClient:
    """Open PyBullet's GUI window, set up to cost the least per frame.

    The side panels and their camera previews (each a render of its own), and shadows
    (a second pass over the scene) are off: each adds work to every frame, done by the
    CPU under software rendering (Mesa llvmpipe in a virtual display), and a frame is
    what the GUI makes a command wait for.
    """
    with quiet_stdout():
        display = BulletClient(connection_mode=pybullet.GUI)
    # Rendering itself is off too, until DebugView.show() renders a frame: the render
    # thread would redraw the unchanged scene without pause, taking a core.
    for flag in (pybullet.COV_ENABLE_RENDERING, pybullet.COV_ENABLE_GUI,
                 pybullet.COV_ENABLE_SHADOWS,
                 pybullet.COV_ENABLE_RGB_BUFFER_PREVIEW, pybullet.COV_ENABLE_DEPTH_BUFFER_PREVIEW,
                 pybullet.COV_ENABLE_SEGMENTATION_MARK_PREVIEW):
        display.configureDebugVisualizer(flag, 0)
    return display


@dataclass(frozen=True)
class PhysicsState:
    """A physics state kept in the server's memory (:meth:`SimClient.save_state`).

    ``state_id`` is PyBullet's handle; ``steps`` and ``engine_time_s`` are the client's
    clock and engine time when it was saved.
    """

    state_id: int
    steps: int
    engine_time_s: float


class SimClient:
    """A PyBullet physics server with fixed time step, gravity and deterministic settings.

    Parameters
    ----------
    gui
        Also open PyBullet's GUI window as ``display``, a second server that only shows
        the scene; the physics always runs in the headless ``DIRECT`` server.
    time_step
        Fixed physics step in seconds (default 1/240 s).
    gravity
        Magnitude of gravity along -z, m/s^2.

    Attributes
    ----------
    bullet
        The bound ``BulletClient``: call PyBullet functions on it.
    time_step
        The fixed step, seconds.
    engine_time_s
        Wall time spent inside PyBullet (stepping and timed calls), seconds.
    display
        The GUI server's ``BulletClient`` when ``gui=True``, else ``None``.

    Examples
    --------
    >>> sim = SimClient(time_step=0.01)
    >>> sim.step(3)
    >>> round(sim.sim_time, 6), sim.steps
    (0.03, 3)
    >>> with sim.engine_timer():
    ...     hits = sim.bullet.rayTestBatch([[0, 0, 1]], [[0, 0, -1]])
    >>> hits[0][0]  # nothing to hit in an empty world
    -1
    >>> sim.close()
    >>> sim.closed
    True
    """

    def __init__(
        self, *, gui: bool = False, time_step: float = DEFAULT_TIME_STEP, gravity: float = GRAVITY
    ) -> None:
        if not (time_step > 0.0 and time_step <= 0.1):
            raise ValueError(
                f"SimClient: time_step must be in (0, 0.1] s (got {time_step}); "
                "PyBullet's contacts are tuned for 1/240 s"
            )
        if not gravity >= 0.0:
            raise ValueError(
                f"SimClient: gravity is a magnitude along -z, must be >= 0 (got {gravity})"
            )
        self.gui = bool(gui)
        self.time_step = float(time_step)
        self.engine_time_s = 0.0
        self._steps = 0
        self._closed = False
        # The display first: PyBullet answers getDebugVisualizerCamera (all zeros
        # otherwise) only for a GUI that is the process's client 0.
        self.display: BulletClient | None = _open_display() if self.gui else None
        with quiet_stdout():
            self.bullet = BulletClient(connection_mode=pybullet.DIRECT)
        self.bullet.setGravity(0.0, 0.0, -float(gravity))
        # Fixed stepping with no sub-steps, and overlapping pairs processed in a fixed
        # order: with the same calls in the same order two servers give identical states.
        self.bullet.setPhysicsEngineParameter(
            fixedTimeStep=self.time_step,
            numSubSteps=0,
            numSolverIterations=_SOLVER_ITERATIONS,
            deterministicOverlappingPairs=1,
        )
        self.bullet.setRealTimeSimulation(0)
        # BulletClient builds a new partial on every attribute access (~1 us): bind the
        # per-step call once.
        self._step_simulation = self.bullet.stepSimulation

    @property
    def client_id(self) -> int:
        """Return the PyBullet physics client id of this server."""
        return int(self.bullet._client)

    @property
    def steps(self) -> int:
        """Return how many physics steps were taken."""
        return self._steps

    @property
    def sim_time(self) -> float:
        """Return the simulated time in seconds (``steps * time_step``)."""
        return self._steps * self.time_step

    @property
    def closed(self) -> bool:
        """Return whether the server was disconnected."""
        return self._closed

    def step(self, n: int = 1) -> None:
        """Advance the simulation by ``n`` fixed steps, timing the engine.

        Examples
        --------
        >>> with SimClient() as sim:
        ...     sim.step(0)
        ...     sim.steps
        0
        """
        if n < 0:
            raise ValueError(f"SimClient.step: n must be >= 0 (got {n})")
        self._require_open()
        step_simulation = self._step_simulation
        start = time.perf_counter()
        for _ in range(n):
            step_simulation()
        self.engine_time_s += time.perf_counter() - start
        self._steps += n

    @contextmanager
    def engine_timer(self) -> Iterator[None]:
        """Count the wall time of the enclosed block as engine time.

        Wrap heavy PyBullet calls (``rayTestBatch``, ``getContactPoints``) in it; keep
        our own numpy work outside.

        Examples
        --------
        >>> with SimClient() as sim:
        ...     before = sim.engine_time_s
        ...     with sim.engine_timer():
        ...         _ = sim.bullet.getNumBodies()
        ...     sim.engine_time_s > before
        True
        """
        start = time.perf_counter()
        try:
            yield
        finally:
            self.engine_time_s += time.perf_counter() - start

    def save_state(self) -> PhysicsState:
        """Keep the bodies' poses, velocities and contacts, and the clock, in memory.

        :meth:`restore_state` goes back to it (as often as wanted) while the world holds
        the same bodies; :meth:`remove_state` frees it. Motor targets are not part of it
        (PyBullet's ``saveState``): whoever set them sets them again.

        Examples
        --------
        >>> with SimClient() as sim:
        ...     ball = sim.bullet.createMultiBody(
        ...         baseMass=1.0, basePosition=[0.0, 0.0, 1.0],
        ...         baseCollisionShapeIndex=sim.bullet.createCollisionShape(
        ...             sim.bullet.GEOM_SPHERE, radius=0.1))
        ...     state = sim.save_state()
        ...     sim.step(100)
        ...     fallen = sim.bullet.getBasePositionAndOrientation(ball)[0]
        ...     sim.restore_state(state)
        ...     again = sim.bullet.getBasePositionAndOrientation(ball)[0]
        ...     sim.step(100)
        ...     sim.remove_state(state)
        ...     again, sim.bullet.getBasePositionAndOrientation(ball)[0] == fallen, sim.steps
        ((0.0, 0.0, 1.0), True, 100)
        """
        self._require_open()
        return PhysicsState(int(self.bullet.saveState()), self._steps, self.engine_time_s)

    def restore_state(self, state: PhysicsState) -> None:
        """Go back to ``state`` (:meth:`save_state`): bodies, contacts, clock, engine time."""
        self._require_open()
        self.bullet.restoreState(stateId=state.state_id)
        self._steps = state.steps
        self.engine_time_s = state.engine_time_s

    def remove_state(self, state: PhysicsState) -> None:
        """Free the memory of ``state``; it cannot be restored any more."""
        self._require_open()
        self.bullet.removeState(state.state_id)

    def close(self) -> None:
        """Disconnect the physics server; calling it again does nothing."""
        if not self._closed:
            self._closed = True
            self.bullet.disconnect()
            if self.display is not None:
                with quiet_stdout():  # the GUI prints its threads' shutdown
                    self.display.disconnect()

    def _require_open(self) -> None:
        if self._closed:
            raise RuntimeError("SimClient is closed; create a new one")

    def __enter__(self) -> SimClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        mode = "DIRECT+GUI" if self.gui else "DIRECT"
        state = "closed" if self._closed else f"t={self.sim_time:.3f}s"
        return f"SimClient({mode}, dt={self.time_step:.6g}s, {state})"
