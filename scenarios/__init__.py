"""Experiments: scenario files, the closed loop, results, recorded data, tuning and the CLI.

The wings, lowest first: :mod:`scenarios.process` (worker pools, progress, staged
outputs), :mod:`scenarios.spec` (scenario data), :mod:`scenarios.bench` (the closed loop),
:mod:`scenarios.results` (metrics, outputs, Table 1, figures), :mod:`scenarios.logs` (real
logs, recordings, bags), :mod:`scenarios.tuning` (sweeps, searches, warm starts),
:mod:`scenarios.campaign` (many seeds and variations, comparisons) and
:mod:`scenarios.falsify` (searching for failures); each imports only those before it.
What a script needs is importable from here.

Examples
--------
>>> from scenarios import bundled_scenarios, load_scenario
>>> bundled_scenarios()  # doctest: +NORMALIZE_WHITESPACE
('fault_blind_policy', 'fault_short_field', 'fault_slow_scanner', 'occlusion_hall', 'pal1',
 'pal3a', 'pal3b', 'sim1', 'sim2', 'warehouse', 'warehouse_fleet', 'warehouse_occlusion')
>>> load_scenario("pal3b").people
('walker',)
"""

from scenarios.bench.observer import Observer, VehicleView
from scenarios.bench.policies import FieldPolicy, FieldReadings, FieldView
from scenarios.bench.runner import run_scenario
from scenarios.bench.testbench import Testbench
from scenarios.spec.layout import lap_worlds, scenario_world, world_for_lap
from scenarios.spec.load import bundled_scenarios, load_scenario
from scenarios.spec.scenario import ScenarioSpec

__all__ = [
    "FieldPolicy",
    "FieldReadings",
    "FieldView",
    "Observer",
    "ScenarioSpec",
    "Testbench",
    "VehicleView",
    "bundled_scenarios",
    "lap_worlds",
    "load_scenario",
    "run_scenario",
    "scenario_world",
    "world_for_lap",
]
