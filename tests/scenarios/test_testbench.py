"""The Testbench: life cycle, tick-by-tick equals run(), observers, worlds and policies in code."""

import dataclasses

import numpy as np
import pytest
import shapely

from robots.safety import FieldSet
from scenarios import FieldPolicy, Observer, Testbench, bundled_scenarios
from scenarios.bench.policies import FieldReadings, FieldView, counted_occupancy
from scenarios.bench.runner import run_scenario
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario
from semistatic.errors import MEMORY
from tests.scenarios.tiny_world import write_tiny
from worlds.spec import BoxSpec, PathSpec, PostSpec, SegmentSpec, WallSpec, WorldSpec


def without_performance(metrics):
    kept = {key: value for key, value in metrics.items() if key != "performance"}
    if "vehicles" in kept:  # a fleet: every vehicle's figures, its timings aside
        kept["vehicles"] = {name: without_performance(vehicle)
                            for name, vehicle in kept["vehicles"].items()}
    return kept


def assert_same_run(first, second):
    assert without_performance(summarize(first)) == without_performance(summarize(second))
    assert first.vehicles.keys() == second.vehicles.keys()
    for name, vehicle in first.vehicles.items():
        assert vehicle.maps_after_lap == second.vehicles[name].maps_after_lap
    assert first.maps_after_lap == second.maps_after_lap
    assert first.table1_distances == second.table1_distances
    for name in ("stamps", "true_poses", "estimated_poses", "covariances"):
        np.testing.assert_array_equal(np.array(getattr(first, name)),
                                      np.array(getattr(second, name)))
    for key, values in first.ekf_history.items():
        np.testing.assert_array_equal(values, second.ekf_history[key])


@pytest.fixture(scope="module")
def tiny_spec(tmp_path_factory):
    return load_scenario(write_tiny(tmp_path_factory.mktemp("tiny")))


@pytest.fixture(scope="module")
def tiny_log(tiny_spec):
    return run_scenario(tiny_spec)


class Counter(Observer):
    """Counts every hook call and checks what the bench shows at each."""

    def __init__(self):
        self.calls = {"on_tick": 0, "on_scan": 0, "on_lap_start": [], "on_lap_end": []}
        self.zones = set()

    def on_tick(self, bench):
        self.calls["on_tick"] += 1
        self.zones.add(bench.zone)

    def on_scan(self, bench, record):
        self.calls["on_scan"] += 1
        assert record.lap == bench.lap
        assert record.segment in bench.local_maps

    def on_lap_start(self, bench, lap):
        self.calls["on_lap_start"].append(lap)
        # Re-localised at the start: the EKF agrees with the truth to a few cm.
        assert np.abs(bench.ekf_pose[:2] - bench.true_pose[:2]).max() < 0.05

    def on_lap_end(self, bench, lap_log):
        self.calls["on_lap_end"].append(lap_log.lap)


@pytest.mark.slow
def test_stepping_tick_by_tick_gives_the_log_of_run(tiny_spec, tiny_log):
    counter = Counter()
    with Testbench(tiny_spec) as bench:
        bench.add_observer(counter)
        bench.reset()
        ticks = 0
        while not bench.done:
            bench.step()
            ticks += 1
        assert_same_run(bench.log, tiny_log)
        with pytest.raises(RuntimeError, match="reset"):
            bench.step()
    assert counter.calls["on_tick"] == ticks
    assert counter.calls["on_scan"] == sum(lap.safety_scans for lap in tiny_log.laps)
    assert counter.calls["on_lap_start"] == counter.calls["on_lap_end"] == [1, 2]
    # The carton reaches into the warning field: the bench showed the slowdown.
    assert counter.zones == {"free", "warning"}


@pytest.mark.slow
def test_run_lap_returns_each_lap_and_state_is_readable_between(tiny_spec, tiny_log):
    with Testbench(tiny_spec) as bench:
        bench.reset()
        first = bench.run_lap()
        assert (first.lap, bench.lap) == (1, 2)
        assert first == tiny_log.laps[0]
        # After lap 1 the local map of the only segment holds the carton and the walls.
        assert len(bench.local_maps["corridor"]) >= 1
        assert bench.ekf_covariance.shape == (3, 3)
        assert bench.sim_time > first.duration_s
        second = bench.run_lap()
        assert second == tiny_log.laps[1]
        assert bench.done
        assert_same_run(bench.run(), tiny_log)


@pytest.mark.slow  # two more runs of the tiny world
def test_reset_with_a_seed_starts_over_with_other_noise(tiny_spec, tiny_log):
    with Testbench(tiny_spec) as bench:
        bench.reset(seed=tiny_spec.seed + 1)
        other = bench.run()
        assert other.spec.seed == tiny_spec.seed + 1
        assert other.estimated_poses[5].tolist() != tiny_log.estimated_poses[5].tolist()
        bench.reset()
        assert_same_run(bench.run(), tiny_log)


def test_a_bench_must_be_reset_before_stepping(tiny_spec):
    bench = Testbench(tiny_spec)
    with pytest.raises(RuntimeError, match="reset"):
        bench.step()


def code_world() -> WorldSpec:
    """The tiny world of the TOML test files, built in code."""
    walls = (
        WallSpec((-2.5, -1.5), (6.5, -1.5)), WallSpec((-2.5, 1.5), (6.5, 1.5)),
        WallSpec((-2.5, -1.5), (-2.5, 1.5)), WallSpec((6.5, -1.5), (6.5, 1.5)),
    )
    posts = tuple(PostSpec(x, -1.39) for x in (-2.0, 0.0, 2.0, 4.0, 6.0)) + tuple(
        PostSpec(x, 1.39) for x in (-1.0, 1.0, 3.0, 5.0)
    ) + (PostSpec(-2.39, 0.3), PostSpec(6.39, -0.3))
    segment = SegmentSpec(
        "corridor", 0, 2,
        warning=((0.18, -0.9), (1.4, -0.9), (1.4, 0.9), (0.18, 0.9)),
        protective=((0.18, -0.65), (0.78, -0.65), (0.78, 0.65), (0.18, 0.65)),
    )
    path = PathSpec(((0.0, 0.0), (1.75, 0.0), (3.5, 0.0)), (segment,), speed=0.4)
    return WorldSpec(name="tiny", walls=walls, posts=posts,
                     boxes=(BoxSpec("carton", (0.5, 0.4, 0.6), (2.6, -1.0, 0.0)),),
                     people=(), path=path)


@pytest.mark.slow  # another run of the tiny world, to the last bit
def test_a_world_built_in_code_runs_like_its_file(tiny_spec, tiny_log):
    with Testbench(tiny_spec, world=code_world()) as bench:
        log = bench.run()
    assert log.world.source == MEMORY  # not read from a file
    # Same walls, posts, box and path as the file: the same run to the last bit.
    assert_same_run(log, tiny_log)


def test_a_box_pushed_mid_lap_is_mapped_where_it_now_stands(tiny_spec):
    with Testbench(dataclasses.replace(tiny_spec, laps=1), world=code_world()) as bench:
        bench.reset()
        while bench.sim_time < 1.0:
            bench.step()
        # Before the robot reaches it, the carton is pushed 40 cm along the wall.
        bench.move_box("carton", (3.0, -1.0, 0.0))
        log = bench.run()
    truth = log.truth_after_lap[0]["carton"]
    assert (truth[:, 0].min(), truth[:, 0].max()) == pytest.approx((2.75, 3.25))
    assert truth[:, 1].max() == pytest.approx(-0.8)
    assert log.laps[0].detection["f1"] == 1.0


class IgnoreWarning(FieldPolicy):
    """A policy that counts no reading for the warning field."""

    name = "ignore-warning"

    def counted_readings(self, view):
        return FieldReadings(warning=np.zeros(len(view.points), dtype=bool))


class IgnoreEverything(FieldPolicy):
    """A policy that tries to count no reading at all: the protective floor must hold."""

    name = "ignore-everything"

    def counted_readings(self, view):
        nothing = np.zeros(len(view.points), dtype=bool)
        return FieldReadings(warning=nothing, protective=nothing)


def test_a_policy_that_ignores_the_warning_field_never_slows_down(tiny_spec, tiny_log):
    with Testbench(tiny_spec, policy=IgnoreWarning()) as bench:
        metrics = summarize(bench.run())
    assert summarize(tiny_log)["safety"]["slowdowns"] >= tiny_spec.laps
    assert metrics["safety"]["slowdowns"] == 0
    assert metrics["safety"]["collisions"] == 0
    assert metrics["policy"] == "ignore-warning"
    assert metrics["safety"]["lap_time_s"][0] < summarize(tiny_log)["safety"]["lap_time_s"][0]


def test_a_scenario_takes_a_policy_object_and_rejects_other_objects(tiny_spec):
    spec = dataclasses.replace(tiny_spec, policy=IgnoreWarning())
    assert Testbench(spec).spec.policy.name == "ignore-warning"
    with pytest.raises(ValueError, match="no field policy"):
        Testbench(tiny_spec, policy=object()).reset()


def test_an_unknown_robot_preset_names_the_key(tiny_spec):
    with pytest.raises(Exception, match="robot: unknown robot preset 'pioner3dx'"):
        Testbench(tiny_spec, robot="pioner3dx")


def test_no_policy_can_ignore_what_stands_in_the_minimum_field():
    fields = FieldSet([(0.2, -0.5), (1.5, -0.5), (1.5, 0.5), (0.2, 0.5)],
                      [(0.2, -0.3), (0.7, -0.3), (0.7, 0.3), (0.2, 0.3)])
    # A minimum field (robot frame) reaching from behind the footprint to 0.25 m ahead,
    # narrower than the protective field: x in [-0.3, 0.25], |y| <= 0.2.
    envelope = shapely.box(-0.3, -0.2, 0.25, 0.2)
    rng = np.random.default_rng(5)
    points = rng.uniform([-0.5, -0.6], [1.6, 0.6], size=(600, 2))
    counted = IgnoreEverything().counted_readings(
        FieldView(points, None, envelope, np.zeros(3), None, None)
    )
    state = counted_occupancy(points, fields, envelope, counted, min_points=3)
    # Hand-counted references from the boxes' bounds.
    in_envelope = (np.abs(points[:, 1]) <= 0.2) & (points[:, 0] >= -0.3) & (points[:, 0] <= 0.25)
    in_protective = (points[:, 0] >= 0.2) & (points[:, 0] <= 0.7) & (np.abs(points[:, 1]) <= 0.3)
    in_warning = (points[:, 0] >= 0.2) & (points[:, 0] <= 1.5) & (np.abs(points[:, 1]) <= 0.5)
    assert state.warning_count == state.protective_count == np.count_nonzero(in_envelope) > 3
    assert state.zone == "protective"
    plain = counted_occupancy(points, fields, envelope, None, min_points=3)
    assert plain.protective_count == np.count_nonzero(in_protective | in_envelope)
    assert plain.warning_count == np.count_nonzero(in_warning | in_envelope)


def test_a_policy_sees_a_read_only_copy_of_the_readings():
    points = np.array([[1.0, 0.0], [2.0, 0.5]])
    view = FieldView(points, None, shapely.Polygon(), np.zeros(3), None, None)
    with pytest.raises(ValueError, match="read-only"):
        view.points[0, 0] = 9.0
    view.points.flags.writeable = True  # its own copy: writing it changes nothing else
    view.points[:] = 100.0
    assert points[0, 0] == 1.0


class NothingCounts(FieldPolicy):
    """Answers "no reading counts" for both fields, at every scan."""

    name = "nothing-counts"

    def counted_readings(self, view):
        nothing = np.zeros(len(view.points), dtype=bool)
        return FieldReadings(warning=nothing, protective=nothing)


class ReadingEditor(FieldPolicy):
    """Moves every reading it is shown out of the fields, then lets them all count."""

    name = "reading-editor"

    def counted_readings(self, view):
        view.points.flags.writeable = True
        view.points[:] = 100.0
        return None


@pytest.mark.slow
@pytest.mark.parametrize("policy", [IgnoreWarning(), NothingCounts(), ReadingEditor()],
                         ids=lambda policy: policy.name)
def test_no_policy_can_configure_away_the_stop_for_the_person_in_pal3b(policy):
    spec = load_scenario("pal3b", overrides=["laps=1", "seed=0"])
    with Testbench(spec, policy=policy) as bench:
        metrics = summarize(bench.run())
    safety = metrics["safety"]
    # The worker stands in the minimum field: whatever the policy, the robot stops.
    assert safety["stops_per_lap"][0] >= 1
    assert safety["collisions"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("minimum_field", ["fixed", "standard"])
def test_the_old_fixed_minimum_field_lets_the_lgv_reach_the_worker_at_1_m_s(minimum_field):
    # The warehouse LGV drives the south aisle at 1.0 m/s, where it stops within 0.65 m
    # (robots.stopping); a policy that counts nothing leaves only the minimum field. The
    # old fixed one (the first 0.15 m of the protective field) sees the worker too late,
    # and the testbench reports the contact; the standard one stops in time.
    spec = load_scenario("warehouse", overrides=[
        "laps=1", "seed=0", f"safety.minimum_field={minimum_field}"])
    with Testbench(spec, policy=NothingCounts()) as bench:
        record = bench.run().safety_record
    contacts = [item for item in record.infractions if item["kind"] == "contact"]
    if minimum_field == "fixed":
        assert contacts, "the contact with the worker went unreported"
        assert "worker" in contacts[0]["detail"]
    else:
        assert contacts == []
        assert record.min_separation["person"] > 0.0


class WrongAnswer(FieldPolicy):
    def __init__(self, answer):
        self.answer = answer
        self.name = "wrong-answer"

    def counted_readings(self, view):
        return self.answer(len(view.points))


@pytest.mark.parametrize(("answer", "message"), [
    (lambda n: (None, None), "returned a tuple; expected FieldReadings"),
    (lambda n: FieldReadings(warning=np.ones(n + 1, dtype=bool)), r"a boolean numpy array"),
    (lambda n: FieldReadings(protective=np.ones(n, dtype=int)), "int64 array"),
    (lambda n: FieldReadings(warning=[True] * n), "returned warning = a list"),
])
def test_a_policy_answering_something_else_than_masks_is_named(tiny_spec, answer, message):
    with Testbench(tiny_spec, policy=WrongAnswer(answer)) as bench:
        bench.reset(seed=0)
        named = r"policy WrongAnswer \('wrong-answer'\)\.counted_readings"
        with pytest.raises(TypeError, match=f"{named}.*{message}"):
            bench.run_lap()


@pytest.mark.slow
@pytest.mark.parametrize("name", bundled_scenarios())
def test_every_bundled_scenario_repeats_itself_exactly(name):
    spec = load_scenario(name, overrides=["laps=2"])
    assert_same_run(run_scenario(spec), run_scenario(spec))


class RandomPusher(Observer):
    """Draws from its own stream every tick, as a script moving boxes at random would."""

    def __init__(self):
        self.draws = 0

    def on_lap_start(self, bench, lap):
        self.rng = bench.random_stream(f"pusher/lap{lap}")

    def on_tick(self, bench):
        self.rng.standard_normal(16)
        self.draws += 16


@pytest.mark.slow  # another run of the tiny world, to the last bit
def test_a_script_drawing_random_numbers_leaves_the_robots_noise_alone(tiny_spec, tiny_log):
    pusher = RandomPusher()
    with Testbench(tiny_spec) as bench:
        bench.add_observer(pusher)
        assert_same_run(bench.run(), tiny_log)
    assert pusher.draws > 10_000


@pytest.mark.slow
def test_a_closed_route_is_driven_lap_after_lap_without_a_return_to_the_start():
    spec = load_scenario("warehouse", overrides=["laps=2"])
    log = run_scenario(spec)
    first, second = log.laps
    assert first.completed
    assert second.completed
    assert second.start_time == pytest.approx(first.start_time + first.duration_s)
    true = np.asarray(log.true_poses)
    estimated = np.asarray(log.estimated_poses)
    # Control ticks are 20 ms apart at <= 1 m/s: no pose (true or EKF) jumps anywhere,
    # the lap change included, and the EKF tracks across it.
    assert np.max(np.linalg.norm(np.diff(true[:, :2], axis=0), axis=1)) < 0.03
    assert np.max(np.linalg.norm(np.diff(estimated[:, :2], axis=0), axis=1)) < 0.03
    assert np.max(np.linalg.norm(true[:, :2] - estimated[:, :2], axis=1)) < 0.02
    # Each lap is one loop: it ends where it began (within the follower's goal tolerance).
    boundary = second.first_tick
    assert np.linalg.norm(true[boundary, :2] - true[0, :2]) < 0.2
    assert [lap.stops for lap in log.laps] == [1, 1]  # the worker, on every lap
    assert sum(lap.collisions for lap in log.laps) == 0


def test_a_box_that_appears_against_the_robot_is_caught_as_a_collision_at_once(tiny_spec):
    # The closed loop checks contacts after every physics step: a box teleported into the
    # robot's front mid-lap is one collision, recorded on the very next step.
    with Testbench(dataclasses.replace(tiny_spec, laps=1)) as bench:
        bench.reset()
        while bench.sim_time < 1.0:
            bench.step()
        x, y, heading = bench.true_pose
        front = max(vertex[0] for vertex in bench.fleet[0].robot.footprint)
        reach = front + 0.15 - 0.02  # the 0.3 m crate overlaps the front by 2 cm
        pose = (x + reach * np.cos(heading), y + reach * np.sin(heading), heading)
        bench.add_box(BoxSpec("crate", (0.3, 0.3, 0.5), tuple(float(v) for v in pose)))
        appeared = bench.sim_time
        for _ in range(48):
            bench.step()
        events = bench.fleet[0].contacts.events
    assert len(events) == 1
    assert events[0].name == "crate"
    assert events[0].time == pytest.approx(appeared + bench.time_step)
