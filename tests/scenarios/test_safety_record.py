"""Safety figures against hand-computed cases: a person, a stop, a contact never hidden."""

import dataclasses

import numpy as np
import pytest

from robots.presets import PIONEER3DX
from scenarios import Testbench
from scenarios.bench.safety_record import SafetyRecord, merged_record
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario
from tests.scenarios.tiny_world import TINY_WORLD, write_tiny
from worlds.spec import BoxSpec

HALF_WIDTH = 0.381 / 2   # the Pioneer's footprint
PERSON = """
[[people]]
name = "bystander"
waypoints = [[1.8, 1.0]]
radius = 0.25
"""


@pytest.fixture(scope="module")
def bystander_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bystander")
    path = write_tiny(folder)
    (folder / "tiny_world.toml").write_text(TINY_WORLD.replace("[path]", PERSON + "\n[path]"))
    spec = load_scenario(str(path), overrides=["laps=1"])
    with Testbench(spec) as bench:
        log = bench.run()
    return summarize(log)["safety"]


def test_the_least_separation_from_a_standing_person_is_computed_by_hand(bystander_run):
    # The robot drives along y = 0 past a person standing at y = 1.0: body edge at 0.75,
    # footprint side at 0.19 m; the EKF keeps the robot within a centimetre of the path.
    expected = 1.0 - 0.25 - HALF_WIDTH
    assert bystander_run["min_separation_m"]["person"] == pytest.approx(expected, abs=0.015)
    at = bystander_run["min_separation_at"]["person"]
    assert at["object"] == "bystander"
    assert at["x"] == pytest.approx(1.8, abs=1e-6)
    # Nobody near a box or another vehicle: the box 0.5 m off the path, no fleet.
    assert bystander_run["min_separation_m"]["vehicle"] is None
    assert bystander_run["infractions"] == []


def test_zone_times_add_up_to_the_lap(bystander_run):
    zones = bystander_run["time_in_zone_s"]
    # Each safety scan stands for one 80 ms period: the lap, within a period or two.
    assert sum(zones.values()) == pytest.approx(bystander_run["lap_time_s"][0], abs=0.17)
    assert zones["warning"] == pytest.approx(sum(bystander_run["slowed_time_s"]))
    assert zones["protective"] == pytest.approx(sum(bystander_run["stopped_time_s"]))


def test_a_stop_from_a_known_speed_brakes_the_followers_ramp(tmp_path):
    spec = load_scenario(str(write_tiny(tmp_path)), overrides=["laps=1"])
    with Testbench(spec) as bench:
        bench.reset(seed=0)
        while bench.true_pose[0] < 0.5:  # at full speed, the carton not yet in a field
            bench.step()
        x = float(bench.true_pose[0])
        # A crate 0.9 m ahead, in the protective field: the robot stops before it.
        bench.add_box(BoxSpec("crate", (0.3, 0.3, 0.5), (x + 0.9, 0.0, 0.0)))
        for _ in range(2 * 240):
            bench.step()
        stops = bench.fleet[0].log.safety_record.protective_stops
        front_at_rest = float(bench.true_pose[0]) + 0.1825
    (stop,) = stops
    assert stop["speed"] == pytest.approx(0.4, abs=0.01)
    # From the scan that trips the field: the follower's ramp from 0.4 m/s, 20 ms steps of
    # 0.02 m/s (hand sum: 0.02 * (0.38 + 0.36 + ... + 0.02) = 0.076 m), no latency (the
    # 12.5 Hz scans fall on 50 Hz control steps).
    assert stop["travelled_m"] == pytest.approx(0.076, abs=0.01)
    assert stop["object"] == "box crate"
    # At rest: from the bumper to the crate's near face, by the true poses.
    assert stop["distance_to_object_m"] == pytest.approx(x + 0.9 - 0.15 - front_at_rest,
                                                         abs=0.005)


def test_a_contact_is_an_infraction(tmp_path):
    spec = load_scenario(str(write_tiny(tmp_path)), overrides=["laps=1"])
    with Testbench(spec) as bench:
        bench.reset()
        while bench.sim_time < 1.0:
            bench.step()
        x, y, heading = bench.true_pose
        front = max(vertex[0] for vertex in PIONEER3DX.footprint)
        reach = front + 0.15 - 0.02
        pose = (x + reach * np.cos(heading), y + reach * np.sin(heading), heading)
        bench.add_box(BoxSpec("crate", (0.3, 0.3, 0.5), tuple(float(v) for v in pose)))
        for _ in range(24):
            bench.step()
        infractions = bench.fleet[0].log.safety_record.infractions
    contacts = [item for item in infractions if item["kind"] == "contact"]
    assert len(contacts) == 1
    assert "box crate" in contacts[0]["detail"]
    assert contacts[0]["t"] == pytest.approx(1.0, abs=0.05)


def test_a_fleet_record_keeps_the_least_of_its_vehicles():
    a, b = SafetyRecord(), SafetyRecord()
    a.note_separation("box", 0.4, t=1.0, lap=1, where=(0.0, 0.0), name="crate")
    b.note_separation("box", 0.3, t=2.0, lap=1, where=(1.0, 0.0), name="pallet")
    a.infraction("contact", t=3.0, vehicle="a", lap=1, where=(0.0, 0.0), detail="wall")
    merged = merged_record([a, b])
    assert merged.min_separation["box"] == 0.3
    assert merged.min_separation_at["box"]["object"] == "pallet"
    assert len(merged.infractions) == 1
    assert dataclasses.asdict(merged)["min_ttc_s"] is None
