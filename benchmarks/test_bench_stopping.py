"""Stopping distances of both presets at five speeds: measured against the model.

Writes the table and figure of the docs' safety page (``docs/safety/stopping.md`` and
``docs/safety/stopping_distances.png``): each preset driven at 0.2 ... 1.0 m/s down a
straight corridor, a box put into its protective field right after a safety scan (the
worst moment), the distance travelled to standstill beside
:meth:`robots.stopping.StopModel.distance`.

Run: ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_stopping.py``
"""

from pathlib import Path

import pytest
from matplotlib.figure import Figure

from robots.presets import LGV, PIONEER3DX
from scenarios.results.stopping import measure_stop
from scenarios.spec.field_sizing import stop_model
from scenarios.spec.scenario import ScenarioSpec

DOCS = Path(__file__).resolve().parents[1] / "docs" / "safety"
SPEEDS = (0.2, 0.4, 0.6, 0.8, 1.0)


@pytest.mark.bench
def test_stopping_distances_table_and_figure():
    rows, curves = [], {}
    for robot in (PIONEER3DX, LGV):
        model = stop_model(ScenarioSpec(name="x", world="x", robot=robot.name), robot)
        stops = [measure_stop(robot, speed) for speed in SPEEDS]
        curves[robot.name] = (model, stops)
        rows += [f"| {robot.name} | {stop.speed:.1f} | {stop.predicted:.3f} | "
                 f"{stop.measured:.3f} | {1000 * stop.error:+.1f} | "
                 f"{100 * stop.error / stop.predicted:+.1f} % |" for stop in stops]
    table = "\n".join([
        "| preset | speed (m/s) | model (m) | measured (m) | error (mm) | error |",
        "|---|---:|---:|---:|---:|---:|", *rows])
    print("\n" + table)
    DOCS.mkdir(parents=True, exist_ok=True)
    (DOCS / "stopping.md").write_text(table + "\n")
    figure = Figure(figsize=(6.5, 4.0), layout="constrained")
    axes = figure.subplots()
    for (name, (model, stops)), colour in zip(curves.items(), ("tab:blue", "tab:orange"),
                                              strict=True):
        speeds = [0.01 * k for k in range(0, 101)]
        axes.plot(speeds, [model.distance(v) for v in speeds], color=colour,
                  label=f"{name}: model")
        axes.plot([s.speed for s in stops], [s.measured for s in stops], "o", color=colour,
                  label=f"{name}: measured")
    axes.set_xlabel("speed when the protective field triggers (m/s)")
    axes.set_ylabel("stopping distance (m)")
    axes.set_title("Stopping distance: model and closed-loop measurement")
    axes.grid(True, alpha=0.3)
    axes.legend()
    figure.savefig(DOCS / "stopping_distances.png", dpi=120)
    for _, (_, stops) in curves.items():
        assert all(abs(stop.error) <= max(0.05 * stop.predicted, 0.02) for stop in stops)
