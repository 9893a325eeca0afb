"""Experiments: scenario files, the closed-loop runner, metrics, figures, replay and the CLI.

Examples
--------
>>> from scenarios import bundled_scenarios, load_scenario
>>> bundled_scenarios()
('pal1', 'pal3a', 'pal3b', 'sim1', 'sim2', 'warehouse', 'warehouse_fleet')
>>> load_scenario("pal3b").people
('walker',)
"""

from scenarios.bench.testbench import Testbench
from scenarios.spec.layout import lap_worlds, scenario_world, world_for_lap
from scenarios.spec.load import bundled_scenarios, load_scenario
from scenarios.spec.scenario import ScenarioSpec

__all__ = [
    "ScenarioSpec",
    "Testbench",
    "bundled_scenarios",
    "lap_worlds",
    "load_scenario",
    "scenario_world",
    "world_for_lap",
]
