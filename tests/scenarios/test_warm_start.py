"""Warm starts: a sample run from the saved mapping laps equals its full run, metric for metric."""

from __future__ import annotations

import dataclasses

import pytest

from scenarios.bench.observer import Observer
from scenarios.bench.testbench import Testbench
from scenarios.spec.load import load_scenario
from scenarios.tuning.run import run_point
from scenarios.tuning.warm import WarmStart
from tests.scenarios.tiny_world import write_crossing

# (trigger_distance m, speed m/s) of the lap-3 crosser: far ahead and gone (no stop), late
# and slow (a stop), late and fast (two stops for the person).
VARIATIONS = [(3.0, 1.5), (0.9, 0.6), (0.5, 1.4)]
BASE = (2.0, 1.0)


def without_timing(metrics):
    return {key: value for key, value in metrics.items() if key != "performance"}


@pytest.fixture(scope="module")
def crossing(tmp_path_factory):
    """The base scenario and a warm start of its lap 3 (laps 1-2 simulated once)."""
    folder = tmp_path_factory.mktemp("warm")
    distance, speed = BASE
    spec = load_scenario(write_crossing(folder, trigger_distance=distance, speed=speed))
    with WarmStart(spec, lap=3) as warm:
        yield folder, spec, warm


def varied(folder, spec, name, **crosser):
    """Return ``spec`` on a copy of its world whose crosser has other ``crosser`` fields."""
    path = write_crossing(folder, name=name, **crosser)
    return dataclasses.replace(spec, world=load_scenario(path).world)


@pytest.mark.slow
def test_warm_samples_equal_their_full_runs(crossing):
    folder, spec, warm = crossing
    stops, starts = [], []
    for index, (distance, speed) in enumerate(VARIATIONS):
        sample = varied(folder, spec, f"sample_{index}", trigger_distance=distance, speed=speed)
        assert warm.accepts(sample)
        full, error = run_point(sample)
        assert error is None
        assert without_timing(warm.run(sample)) == without_timing(full)
        stops.append(full["safety"]["stops_per_lap"])
        starts.append(warm.start_tick(sample))
    assert stops[0] == [0, 0, 0]
    # Stepping out at once (3 m ahead of a 3.1 m crossing) shares nothing of lap 3; the
    # later the trigger, the later the checkpoint a sample starts from.
    assert starts[0] == 0 < starts[1] < starts[2]
    assert all(lap_stops[2] > 0 for lap_stops in stops[1:])  # the person stops the robot
    # The state is restored each time: the first sample again gives the same metrics.
    again = varied(folder, spec, "sample_0", trigger_distance=3.0, speed=1.5)
    assert without_timing(warm.run(again))["safety"]["stops_per_lap"] == [0, 0, 0]


@pytest.mark.slow
def test_a_person_changed_before_stepping_out_starts_at_the_lap_start(crossing):
    # Remission changes what the scanner sees of the person standing behind the box from
    # the lap's first tick: no checkpoint inside lap 3 is that sample's.
    folder, spec, warm = crossing
    sample = varied(folder, spec, "shiny", trigger_distance=0.9, speed=0.6)
    world = folder / "shiny.toml"
    world.write_text(world.read_text().replace("radius = 0.2", "radius = 0.2\nremission = 0.9"))
    sample = dataclasses.replace(spec, world=load_scenario(world.with_name(
        "shiny_scenario.toml")).world)
    later = varied(folder, spec, "late", trigger_distance=0.9, speed=0.6)
    assert warm.start_tick(sample) == 0 < warm.start_tick(later)
    full, error = run_point(sample)
    assert error is None
    assert without_timing(warm.run(sample)) == without_timing(full)


@pytest.mark.slow
def test_warm_start_refuses_what_changes_the_shared_laps(crossing, tmp_path):
    folder, spec, warm = crossing
    world = (folder / "tiny_world.toml").read_text()
    moved = tmp_path / "moved.toml"
    moved.write_text(world.replace("pose = [2.6, -1.0, 0.0]", "pose = [2.5, -1.0, 0.0]"))
    early = tmp_path / "early.toml"
    early.write_text(world.replace("laps = [3]", "laps = [1, 3]"))
    assert not warm.accepts(dataclasses.replace(spec, world=str(moved)))
    assert not warm.accepts(dataclasses.replace(spec, world=str(early)))
    assert not warm.accepts(dataclasses.replace(spec, seed=spec.seed + 1))
    assert warm.differences(dataclasses.replace(spec, seed=4)) == ["seed: 4 instead of 3"]
    with pytest.raises(ValueError, match="person crosser acts before lap 3"):
        warm.run(dataclasses.replace(spec, world=str(early)))
    bigger = tmp_path / "bigger.toml"
    bigger.write_text(world.replace("radius = 0.2", "radius = 0.3"))
    assert warm.differences(dataclasses.replace(spec, world=str(bigger))) == [
        "person crosser's body (radius)"]


class PersonLaps(Observer):
    """Record in which laps the crosser stood in the scene."""

    def __init__(self):
        self.laps = set()

    def on_tick(self, vehicle):
        if vehicle.person_positions.get("crosser") is not None:
            self.laps.add(vehicle.lap)


@pytest.mark.slow
def test_a_person_of_lap_3_is_absent_from_laps_1_and_2(crossing):
    _, spec, _ = crossing
    seen = PersonLaps()
    with Testbench(spec) as bench:
        bench.add_observer(seen)
        log = bench.run()
    assert seen.laps == {3}
    at = log.safety_record.min_separation_at["person"]
    assert at["lap"] == 3


def test_lap_limits_are_checked():
    spec = load_scenario("pal1")
    for lap in (1, spec.laps + 1):  # lap 1 shares nothing; a lap that never runs
        with pytest.raises(ValueError, match=rf"lap must be in 2\.\.{spec.laps}"):
            WarmStart(spec, lap=lap)
