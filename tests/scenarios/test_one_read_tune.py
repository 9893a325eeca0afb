"""One read of the inputs for ``tune`` and ``campaign``: every run uses the scenario and
world as loaded at the start (the specs carry the world to the workers), whatever happens
to the files meanwhile."""

import csv
import dataclasses

import pytest

import scenarios.campaign.execute as execute
from scenarios.campaign.plan import plan_campaign
from scenarios.campaign.variations import parse_variations
from scenarios.falsify.objectives import parse_objectives
from scenarios.falsify.search import FalsifyConfig
from scenarios.spec.layout import lap_worlds, with_loaded_world
from scenarios.spec.load import load_scenario
from scenarios.tuning.params import parse_params
from scenarios.tuning.points import sweep_points
from scenarios.tuning.run import run_sweep
from scenarios.tuning.search import SearchConfig
from semistatic.errors import SpecError
from tests.scenarios.cli_helpers import run_cli
from tests.scenarios.tiny_world import TINY_WORLD, write_tiny
from worlds.load import load_world

# The tiny world with its carton 5 cm further from the path: another layout, still valid.
MOVED_WORLD = TINY_WORLD.replace("pose = [2.6, -1.0, 0.0]", "pose = [2.6, -1.05, 0.0]")


def test_moved_world_is_another_layout():
    assert MOVED_WORLD != TINY_WORLD


def test_a_replaced_world_value_never_uses_the_stale_world(tmp_path):
    spec = load_scenario(write_tiny(tmp_path))
    assert spec.loaded_world[1].name == "tiny"
    other = dataclasses.replace(spec, world="pal1")
    assert lap_worlds(other)[0] == load_world("pal1")  # read for its own world value
    plain = dataclasses.replace(spec, loaded_world=None)
    assert spec == plain
    assert hash(spec) == hash(plain)
    assert repr(spec) == repr(plain)


def test_the_loaded_world_is_no_key_of_a_file_or_of_set(tmp_path):
    scenario = write_tiny(tmp_path)
    with pytest.raises(SpecError, match="loaded_world: unknown key"):
        load_scenario(scenario, overrides=["loaded_world=1"])
    scenario.write_text(scenario.read_text().replace("laps = 2", "laps = 2\nloaded_world = 1"))
    with pytest.raises(SpecError, match="loaded_world: unknown key"):
        load_scenario(scenario)
    with pytest.raises(SpecError, match="loaded_world: must be"):
        dataclasses.replace(load_scenario("pal1"), loaded_world=("pal1", "not a world"))


def test_sweep_and_search_points_keep_the_files_as_read_at_the_start(tmp_path):
    scenario = write_tiny(tmp_path)
    original = lap_worlds(load_scenario(scenario))  # the reference, read from the file
    points = sweep_points(scenario, {"mapper.gate": [0.1, 0.2]}, laps=2)
    config = SearchConfig(str(scenario), parse_params(["mapper.gate=0.05:0.2"]), trials=2)
    config.validate()  # reads the scenario and its world, once
    (tmp_path / "tiny_world.toml").write_text(MOVED_WORLD)
    assert lap_worlds(load_scenario(scenario)) != original  # the file did change
    (tmp_path / "tiny_world.toml").unlink()
    scenario.unlink()
    assert [lap_worlds(point.spec) for point in points] == [original, original]
    [trial] = config.points({"mapper.gate": 0.15})  # no file left to read
    assert trial.spec.mapper.gate == 0.15
    assert lap_worlds(trial.spec) == original


def test_falsification_samples_keep_the_files_as_read_at_the_start(tmp_path):
    scenario = write_tiny(tmp_path)
    original = lap_worlds(load_scenario(scenario))
    config = FalsifyConfig(str(scenario), "conservative",
                           parse_variations(["mapper.gate=uniform(0.05, 0.2)"]),
                           parse_objectives([], []), budget=2, seed=0)
    [first] = config.points({"mapper.gate": 0.1})  # the first plan reads the files
    (tmp_path / "tiny_world.toml").write_text(MOVED_WORLD)
    assert lap_worlds(load_scenario(scenario)) != original  # the file did change
    (tmp_path / "tiny_world.toml").unlink()
    scenario.unlink()
    [later] = config.points({"mapper.gate": 0.15})  # no file left to read
    assert later.spec.mapper.gate == 0.15
    assert lap_worlds(later.spec) == lap_worlds(first.spec) == original
    assert lap_worlds(config.base_spec()) == original


def figures(metrics):
    """What a run measured: everything but its timings."""
    return {key: value for key, value in metrics.items() if key != "performance"}


@pytest.mark.slow  # six one-lap runs of the tiny world, two in worker processes
@pytest.mark.parametrize("jobs", [1, 2])
def test_tune_grid_runs_use_the_world_read_at_the_start(tmp_path, jobs):
    scenario = write_tiny(tmp_path)
    grid = {"mapper.gate": [0.1, 0.2]}
    expected = [figures(result.metrics) for result in run_sweep(
        sweep_points(scenario, grid, laps=1), jobs=1)]
    points = sweep_points(scenario, grid, laps=1)
    (tmp_path / "tiny_world.toml").unlink()  # a run that read it again would fail
    scenario.unlink()
    results = run_sweep(points, jobs=jobs)
    assert [result.error for result in results] == [None, None]
    assert [figures(result.metrics) for result in results] == expected


def metric_rows(out):
    with (out / "runs.csv").open() as handle:
        return [{key: value for key, value in row.items() if not key.startswith("performance")}
                for row in csv.DictReader(handle)]


@pytest.mark.slow  # four one-lap runs of the tiny world
def test_campaign_runs_use_the_world_read_at_the_start(tmp_path, monkeypatch, capsys):
    scenario = write_tiny(tmp_path)
    options = ["--seeds", "0:1", "--laps", "1", "--no-figures"]
    status, _, err = run_cli(capsys, "campaign", scenario, *options, "--out", tmp_path / "a")
    assert status == 0, err
    assert all(run.spec.loaded_world is not None for run in plan_campaign(
        [str(scenario)], ["conservative"], [0], (), [{}], laps=1, worlds_dir=None))
    real_run_pending = execute.run_pending

    def rewrite_then_run(*args, **kwargs):  # the plan is built and its digests written
        (tmp_path / "tiny_world.toml").unlink()  # a run that read it again would fail
        scenario.unlink()
        return real_run_pending(*args, **kwargs)

    monkeypatch.setattr(execute, "run_pending", rewrite_then_run)
    status, _, err = run_cli(capsys, "campaign", scenario, *options, "--out", tmp_path / "b")
    assert status == 0, err
    assert not scenario.exists()
    assert metric_rows(tmp_path / "b") == metric_rows(tmp_path / "a")


def test_with_loaded_world_attaches_the_given_world():
    spec = load_scenario("pal1")
    world = dataclasses.replace(load_world("pal1"), description="given")
    assert with_loaded_world(spec, world).loaded_world == ("pal1", world)
