"""Run a scenario in one call: every lap of a :class:`~scenarios.bench.testbench.Testbench`.

Two maps are fed by the same scans:

- the paper's Table 1 experiment (:class:`~scenarios.bench.scoring.Table1Reference`): lap 1
  builds a reference map per segment; later laps only associate against it and record
  the restricted Hausdorff distances;
- the operating system of Sec. 4: one :class:`~semistatic.local_map.LocalMap` per
  segment, updated every scan with the life cycle, whose known objects drive the
  ``adaptive`` field policy.

The log types live in :mod:`scenarios.bench.records`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from scenarios.bench.observer import Observer, ProgressReporter, ScanCallback
from scenarios.bench.records import RunLog, ScanRecord
from scenarios.bench.testbench import Testbench
from scenarios.spec.scenario import ScenarioSpec
from worlds.spec import WorldSpec

__all__ = ["run_scenario"]


def run_scenario(
    spec: ScenarioSpec,
    *,
    gui: bool = False,
    progress: Callable[[float], None] | None = None,
    on_scan: Callable[[ScanRecord], None] | None = None,
    observers: Sequence[Observer] = (),
    world: WorldSpec | None = None,
) -> RunLog:
    """Run every lap of ``spec`` in a fresh PyBullet world and return the log.

    ``progress``, when given, is called with the simulated seconds advanced (for a
    progress bar). ``on_scan``, when given, is called once per safety-laser scan, after
    the local map update, with a :class:`ScanRecord` (its map polylines and fields
    included). ``observers`` are added to the bench after those (e.g. a
    :class:`~scenarios.logs.bag.BagRecorder` for a ROS 2 bag or a
    :class:`~scenarios.logs.recording.ScanRecorder`). ``world``, the scenario's world as
    loaded already (:func:`scenarios.spec.layout.scenario_world`), spares reading its file
    again: a command's runs all use the world it loaded at the start, whatever happens to
    the file meanwhile. Same spec (and seed) -> identical log and records, except the
    timing figures.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> log = run_scenario(load_scenario("pal1", overrides=["laps=1"]))
    >>> len(log.laps), log.laps[0].collisions
    (1, 0)
    """
    with Testbench(spec, gui=gui, world=world) as bench:
        if progress is not None:
            bench.add_observer(ProgressReporter(progress))
        if on_scan is not None:
            bench.add_observer(ScanCallback(on_scan))
        for observer in observers:
            bench.add_observer(observer)
        return bench.run()
