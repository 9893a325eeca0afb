"""Several vehicles in one Testbench: routes, streams, each other, people and shared maps."""

import dataclasses

import numpy as np
import pytest
import shapely

from scenarios import Testbench
from scenarios.spec.layout import scenario_world
from scenarios.spec.load import load_scenario
from scenarios.spec.routes import route_from
from scenarios.spec.scenario import VehicleSpec
from scenarios.spec.segments import path_segments
from semistatic.errors import SpecError
from sim.laser import LASER_IGNORE_GROUP, vehicle_laser_group
from worlds.checks import build_spline
from worlds.spec import PersonSpec


def test_a_rotated_route_is_the_same_loop_with_the_same_segments():
    world = scenario_world(load_scenario("warehouse"))
    rotated = route_from(world, "west")
    base = {s.name: s for s in path_segments(world)}
    for segment in path_segments(rotated, build_spline(rotated.path)):
        reference = base[segment.name]
        # Same frames and areas (a periodic spline through the same knots, started elsewhere).
        np.testing.assert_allclose(segment.origin, reference.origin, atol=1e-6)
        assert segment.end_s - segment.start_s == pytest.approx(
            reference.end_s - reference.start_s, abs=1e-6)
        difference = shapely.symmetric_difference(segment.safety_area_world,
                                                  reference.safety_area_world)
        assert difference.area < 1e-4 * reference.safety_area_world.area


def test_vehicle_keys_are_checked_with_the_file_and_key_named(tmp_path):
    path = tmp_path / "fleet.toml"
    path.write_text('world = "warehouse"\nrobot = "lgv"\n'
                    '[[vehicles]]\nname = "a"\n[[vehicles]]\nname = "b"\nstart_segment = "wst"\n')
    with pytest.raises(SpecError) as error:
        load_scenario(path)
    assert str(error.value).startswith(f"{path}: vehicles[1].start_segment: no segment 'wst'")
    assert "did you mean 'west'" in str(error.value)
    path.write_text('world = "warehouse"\n[[vehicles]]\nname = "a"\n[[vehicles]]\nname = "a"\n')
    with pytest.raises(SpecError, match=r"vehicles\[1\]\.name: vehicle 'a' is named twice"):
        load_scenario(path)


def test_a_laser_sees_every_vehicle_but_its_own():
    groups = [vehicle_laser_group(index) for index in range(3)]
    assert groups[0] == LASER_IGNORE_GROUP
    for index, group in enumerate(groups):
        mask = ~group  # the rays of vehicle ``index``
        assert not mask & group
        assert all(mask & other for k, other in enumerate(groups) if k != index)


def stand_then_leave(name, spot, away):
    """A person standing at ``spot`` for about 5 s, then walking to ``away`` (0.1 m/s)."""
    x, y = spot
    dx, dy = np.subtract(away, spot) / np.hypot(*np.subtract(away, spot)) * 0.1
    dither = [(x, y), (x + dx, y + dy)] * 3
    return PersonSpec(name, (*dither, (x, y), tuple(away)), speed=0.1, per_lap=False)


@pytest.mark.slow
def test_every_vehicle_stops_for_a_person_and_for_another_vehicle():
    """Three LGVs each meet a person in their lane; a fourth starts behind the first."""
    spec = load_scenario("warehouse_fleet", overrides=["laps=1"])
    people = (
        stand_then_leave("ann", (12.6, 2.8), (12.6, 4.1)),   # ahead of lgv1, south aisle
        stand_then_leave("bob", (17.4, 22.2), (17.4, 23.5)),  # ahead of lgv2, north aisle
        stand_then_leave("cem", (35.7, 8.1), (37.4, 8.1)),   # ahead of lgv3, east end
    )
    world = dataclasses.replace(scenario_world(spec), people=people)
    vehicles = (*spec.vehicles, VehicleSpec("lgv4", start_segment="south_start"))
    spec = dataclasses.replace(spec, people=("ann", "bob", "cem"), vehicles=vehicles)
    with Testbench(spec, world=world) as bench:
        bench.reset()
        start = {name: vehicle.follower.progress for name, vehicle in bench.vehicles.items()}
        stopped_for = {name: set() for name in bench.vehicles}
        while bench.sim_time < 25.0:
            bench.step()
            for name, vehicle in bench.vehicles.items():
                if vehicle.zone == "protective":
                    stopped_for[name].add(round(bench.sim_time))
        for name, vehicle in bench.vehicles.items():
            assert vehicle.supervisor.stops >= 1, name
            assert vehicle.contacts.collisions == 0, name
            # ... and it went on once the lane was clear.
            assert vehicle.follower.progress > start[name] + 3.0, name
        # lgv4 starts 3 m behind lgv1, which waits for ann: lgv4 waits behind lgv1.
        lgv1, lgv4 = bench.vehicles["lgv1"], bench.vehicles["lgv4"]
        assert stopped_for["lgv4"] & stopped_for["lgv1"]
        gap = np.hypot(*(lgv1.true_pose[:2] - lgv4.true_pose[:2]))
        assert gap > 1.0


@pytest.mark.slow
def test_a_fleet_keeps_vehicles_out_of_its_maps_and_shares_them():
    spec = load_scenario("warehouse_fleet", overrides=["laps=2"])
    with Testbench(spec) as bench:
        log = bench.run()
    assert sorted(log.vehicles) == ["lgv1", "lgv2", "lgv3"]
    for name, vehicle in log.vehicles.items():
        for lap in vehicle.laps:
            assert lap.completed, (name, lap.lap)
            assert lap.collisions == 0, (name, lap.lap)
            assert lap.false_objects_from_vehicles == 0, (name, lap.lap)
            assert lap.false_objects_from_people == 0, (name, lap.lap)
        # Every vehicle published; what it sent is its part of the fleet's traffic.
        assert vehicle.sharing["messages"] > 0
    assert log.sharing["messages"] == sum(v.sharing["messages"] for v in log.vehicles.values())
    assert log.sharing["grid_bytes"] >= 10 * log.sharing["bytes"]
    assert len(log.laps) == 6


@pytest.mark.parametrize(("route", "problem"), [
    ('["south_west", "turn_southeast"]',   # skips south_east
     "route[1]: segment 'turn_southeast' does not follow 'south_west' (next on the path: "
     "'south_east')"),
    ('["south_east", "south_west"]',       # reversed
     "route[1]: segment 'south_west' does not follow 'south_east' (next on the path: "
     "'turn_southeast')"),
    ('["south_west", "sout_east"]', "route[1]: no segment 'sout_east' in world 'warehouse'"),
    ('["east", "turn_northeast", "east"]', "route[2]: segment 'east' is on the route twice"),
])
def test_a_route_that_does_not_follow_the_path_is_refused(tmp_path, route, problem):
    path = tmp_path / "fleet.toml"
    path.write_text(f'world = "warehouse"\nrobot = "lgv"\n[[vehicles]]\nname = "a"\n'
                    f'[[vehicles]]\nname = "b"\nroute = {route}\n')
    with pytest.raises(SpecError) as error:
        load_scenario(path)
    assert str(error.value).startswith(f"{path}: vehicles[1].{problem}")


def test_route_and_start_time_are_checked(tmp_path):
    path = tmp_path / "fleet.toml"
    path.write_text('world = "warehouse"\n[[vehicles]]\nname = "a"\nroute = ["east"]\n'
                    'start_segment = "east"\n')
    with pytest.raises(SpecError, match=r"vehicles\[0\]\.start_segment: give route .* not both"):
        load_scenario(path)
    path.write_text('world = "warehouse"\n[[vehicles]]\nname = "a"\nstart_time = -2.0\n')
    with pytest.raises(SpecError, match=r"vehicles\[0\]\.start_time: must be >= 0"):
        load_scenario(path)


@pytest.mark.slow
def test_a_vehicle_drives_its_sub_route_and_waits_for_its_start_time():
    spec = load_scenario("warehouse", overrides=["laps=1", "sharing=false"])
    spec = dataclasses.replace(spec, people=(), moves=(), vehicles=(
        VehicleSpec("lgv1", route=("turn_southwest", "south_start")),
        VehicleSpec("lgv2", route=("north_west",), start_time=4.0),
    ))
    world = scenario_world(spec)
    loop = shapely.LineString(build_spline(world.path).pose(np.linspace(0.0, 96.9, 2000))[:, :2])
    with Testbench(spec) as bench:
        bench.reset()
        lgv1, lgv2 = bench.vehicles["lgv1"], bench.vehicles["lgv2"]
        start = lgv2.true_pose.copy()
        moved_at = None
        while not bench.done:
            bench.step()
            if moved_at is None and np.hypot(*(lgv2.true_pose[:2] - start[:2])) > 0.01:
                moved_at = bench.sim_time
        log = bench.log
    # lgv2 stood still until its start time; its lap is timed from then.
    assert moved_at >= 4.0
    lap2 = log.vehicles["lgv2"].laps[0]
    assert lap2.start_time == pytest.approx(4.0, abs=0.01)
    assert lap2.completed
    # lgv1 drove the two segments' part of the loop, from (4.3, 5.5) to (10, 2.8).
    lap1 = log.vehicles["lgv1"].laps[0]
    poses = np.asarray(log.vehicles["lgv1"].true_poses)
    assert lap1.completed
    np.testing.assert_allclose(poses[0, :2], (4.3, 5.5), atol=0.1)
    np.testing.assert_allclose(poses[-1, :2], (10.0, 2.8), atol=0.3)
    assert max(loop.distance(shapely.Point(xy)) for xy in poses[:, :2]) < 0.15
    # Its segment maps are in the fleet's frames (a test above compares a rotated loop).
    assert [s.name for s in lgv1.segments] == ["turn_southwest", "south_start"]
    assert all(s.origin is bench.segments[bench.scene.segment_key(s.name)].origin
               for s in lgv1.segments)
