"""Loading scenarios: the five bundled experiments, ``--set`` overrides, box moves per lap.

Every bad input is one :class:`SpecError` whose text is ``<file>: <key>: <what is wrong>``
(the CLI prints it after ``error:``), with a "did you mean" where a name was misspelt.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from robots.presets import get_preset
from scenarios.spec.layout import check_moves, lap_worlds, scenario_world, world_for_lap
from scenarios.spec.load import (
    OVERRIDE_FILE,
    bundled_scenarios,
    load_scenario,
    paper_scenarios,
    parse_override,
    scenario_from_toml,
)
from scenarios.spec.scenario import BoxMove, Noise, Rates, SafetySettings, ScenarioSpec
from semistatic.errors import SpecError
from semistatic.params import MapperParams
from worlds.checks import PIONEER_FOOTPRINT, layout_problems
from worlds.load import DATA_DIR as WORLD_DATA_DIR
from worlds.load import load_world

PAPER_SCENARIOS = {  # Table 1 rows of the paper and the world each one runs in
    "sim1": "sim1",
    "sim2": "sim2",
    "pal1": "pal1",
    "pal3a": "pal3",
    "pal3b": "pal3",
}
MOVE_DISTANCE = (0.3, 0.8)  # m a box is moved along its wall between laps
PARALLEL_TOLERANCE = math.radians(1.0)  # "along its wall": the move's direction vs the wall's


@pytest.fixture(params=paper_scenarios())
def name(request: pytest.FixtureRequest) -> str:
    return request.param


def write(folder: Path, text: str, filename: str = "scenario.toml") -> Path:
    path = folder / filename
    path.write_text(text)
    return path


def error_of(name_or_path, overrides=()) -> SpecError:
    with pytest.raises(SpecError) as caught:
        load_scenario(name_or_path, overrides=list(overrides))
    return caught.value


# --- the bundled scenarios ---------------------------------------------------------------


def test_bundled_scenarios_are_the_table_1_rows():
    assert paper_scenarios() == tuple(sorted(PAPER_SCENARIOS))
    assert bundled_scenarios() == tuple(sorted((*paper_scenarios(), "warehouse", "warehouse_fleet",
                                                "occlusion_hall", "warehouse_occlusion",
                                                "fault_blind_policy", "fault_short_field",
                                                "fault_slow_scanner")))


def test_bundled_scenario_loads_as_the_paper_ran_it(name):
    spec = load_scenario(name)
    assert spec.name == name
    assert spec.world == PAPER_SCENARIOS[name]
    assert spec.robot == "pioneer3dx"
    assert (spec.laps, spec.seed, spec.policy) == (5, 0, "conservative")
    assert spec.description
    assert spec.source.endswith(f"{name}.toml")
    assert spec.people == (("walker",) if name == "pal3b" else ())


def test_bundled_file_says_what_the_experiment_is(name):
    first_line = Path(load_scenario(name).source).read_text().splitlines()[0]
    assert first_line.startswith(f"# {name}: Table 1 row")


def test_boxes_move_go_and_come_between_laps(name):
    spec = load_scenario(name)
    assert [(move.lap, move.action) for move in spec.moves] == [
        (3, "move"),
        (4, "remove"),
        (5, "add"),
    ]
    worlds = lap_worlds(spec)
    assert len(worlds) == spec.laps
    names = [{box.name for box in world.boxes} for world in worlds]
    base = names[0]
    assert names[1] == names[2] == base
    assert worlds[2].boxes != worlds[1].boxes  # the moved box
    assert names[3] == base - {spec.moves[1].box}
    assert names[4] == names[3] | {spec.moves[2].box}
    assert spec.moves[2].box not in base


def test_moved_box_slides_0_3_to_0_8_m_along_its_wall(name):
    spec = load_scenario(name)
    world = load_world(spec.world)
    move = spec.moves[0]
    before = next(box for box in world.boxes if box.name == move.box)
    shift = np.subtract(move.pose[:2], before.pose[:2])
    assert MOVE_DISTANCE[0] <= np.linalg.norm(shift) <= MOVE_DISTANCE[1]
    assert move.pose[2] == before.pose[2]
    centre = np.asarray(before.pose[:2])
    nearest = min(
        world.walls,
        key=lambda wall: _distance_to_segment(centre, np.array(wall.start), np.array(wall.end)),
    )
    angle = abs(math.atan2(shift[1], shift[0]) - nearest.yaw) % math.pi
    assert min(angle, math.pi - angle) < PARALLEL_TOLERANCE


def _distance_to_segment(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    direction = end - start
    t = np.clip(np.dot(point - start, direction) / np.dot(direction, direction), 0.0, 1.0)
    return float(np.linalg.norm(point - (start + t * direction)))


def test_every_lap_layout_of_a_bundled_scenario_is_valid(name):
    # Bundled scenarios meet every check, whoever caused a problem: with the robot
    # preset's footprint (what the loader uses) and the centred one the worlds use.
    spec = load_scenario(name)
    footprints = {"preset": get_preset(spec.robot).footprint, "centred": PIONEER_FOOTPRINT}
    for lap, world in enumerate(lap_worlds(spec), start=1):
        for label, footprint in footprints.items():
            problems = [str(p) for p in layout_problems(world, footprint=footprint)]
            assert problems == [], f"lap {lap}, {label} footprint"


def test_pal3a_and_pal3b_differ_only_in_the_person():
    a, b = load_scenario("pal3a"), load_scenario("pal3b")
    assert b.people == ("walker",)
    same = dataclasses.replace(b, name=a.name, description=a.description, source=a.source)
    assert dataclasses.replace(same, people=()) == a
    assert [p.name for p in scenario_world(b).active_people] == ["walker"]
    assert scenario_world(a).active_people == ()


def test_loading_twice_gives_equal_specs(name):
    assert load_scenario(name) == load_scenario(name)


# --- --set overrides ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("override", "key", "value"),
    [
        ("laps=7", "laps", 7),
        ("seed=42", "seed", 42),
        ("policy=adaptive", "policy", "adaptive"),
        ('policy="adaptive"', "policy", "adaptive"),
        ("mapper.gate=0.15", "mapper.gate", 0.15),
        ("safety.slowdown=0.25", "safety.slowdown", 0.25),
        ("rates.safety_hz=25", "rates.safety_hz", 25.0),
        ('people=["walker"]', "people", ("walker",)),
    ],
)
def test_set_overrides_apply(override, key, value):
    spec = load_scenario("pal3a", overrides=[override])
    got = spec
    for part in key.split("."):
        got = getattr(got, part)
    assert got == value
    assert type(got) is type(value)
    unchanged = dataclasses.replace(load_scenario("pal3a"), moves=spec.moves)
    assert [
        f.name
        for f in dataclasses.fields(spec)
        if getattr(spec, f.name) != getattr(unchanged, f.name)
    ] == [key.split(".")[0]]


def test_set_fewer_laps_drops_the_moves_of_laps_that_never_run():
    assert len(load_scenario("sim1", overrides=["laps=4"]).moves) == 2
    spec = load_scenario("sim1", overrides=["laps=2"])
    assert (spec.laps, spec.moves) == (2, ())
    assert [len(world.boxes) for world in lap_worlds(spec)] == [3, 3]
    assert load_scenario("sim1", overrides=["laps=9"]).moves == load_scenario("sim1").moves


def test_later_overrides_win():
    assert load_scenario("sim1", overrides=["seed=1", "seed=2"]).seed == 2


@pytest.mark.parametrize(
    ("override", "key", "message"),
    [
        ("laps=-1", "laps", "must be >= 1 and <= 1000, got -1"),
        ("laps=2.5", "laps", "expected an integer, got a float 2.5"),
        ("seed=-3", "seed", "must be >= 0 and <= 9223372036854775807, got -3"),
        ("policy=fast", "policy", "must be one of conservative, adaptive"),
        ("mapper.gate=-0.1", "mapper.gate", "must be > 0"),
        ("safety.slowdown=1.5", "safety.slowdown", "must be > 0.0 and <= 1.0, got 1.5"),
        ("safety.slowdown=fast", "safety.slowdown", "expected a number"),
        ("lapz=3", "lapz", "unknown key (did you mean 'laps'?)"),
        ("safety.slowdwn=0.3", "safety.slowdwn", "unknown key (did you mean 'slowdown'?)"),
        ("mapper.gte=0.2", "mapper.gte", "unknown key (did you mean 'gate'?)"),
        ("moves=[]", "moves", "unknown key"),
        ("laps.x=1", "laps.x", "'laps' has no sub-keys"),
        ("safety=0.3", "safety", "expected safety.KEY=VALUE"),
        ("laps", "laps", "expected KEY=VALUE, e.g. mapper.gate=0.15"),
        ("=3", "=3", "expected KEY=VALUE"),
        ("mapper..gate=1", "mapper..gate=1", "expected KEY=VALUE"),
        ('people=["waker"]', "people[0]", "no person named 'waker' (did you mean 'walker'?)"),
        ("world=pal2", "world", "not a bundled world (did you mean 'pal3'?)"),
        ("robot=pioner3dx", "robot", "unknown robot preset 'pioner3dx' (did you mean"),
    ],
)
def test_bad_set_override_names_set_and_the_key(override, key, message):
    error = error_of("pal3a", [override])
    assert error.file == OVERRIDE_FILE
    assert error.key == key
    assert message in error.message
    assert str(error).startswith(f"--set: {key}: ")


def test_parse_override_reads_toml_values():
    assert parse_override(" safety.slowdown = 0.3 ") == (["safety", "slowdown"], 0.3)
    assert parse_override("people=[]") == (["people"], [])
    assert parse_override("description=two words") == (["description"], "two words")
    assert parse_override("description=a\tb") == (["description"], "a\tb")  # TOML whitespace


@pytest.mark.parametrize(
    ("text", "shown"),
    [
        ("seed=3\nlaps=7", "a line break ('\\n')"),  # TOML would read a second key
        ("seed=3\r\nlaps=7", "a line break ('\\r')"),
        ("seed=3\rlaps=7", "a line break ('\\r')"),
        ('description="a"\n[mapper]\ngate=0.3', "a line break ('\\n')"),
        ("policy=\x1b[31madaptive", "an unprintable character ('\\x1b')"),
    ],
    ids=["newline", "crlf", "cr", "table", "escape"],
)
def test_one_set_sets_one_key_on_one_line(text, shown):
    with pytest.raises(SpecError) as info:
        parse_override(text)
    assert (info.value.file, info.value.key) == (OVERRIDE_FILE, repr(text))
    assert info.value.message.startswith(f"holds {shown}; one --set sets one KEY=VALUE")
    # Nothing of it reaches the spec either: loading refuses it before any key is set.
    with pytest.raises(SpecError, match=r"^--set: "):
        load_scenario("sim1", overrides=[text])


def test_grid_and_vary_values_name_their_own_option():
    from scenarios.campaign.variations import parse_variation
    from scenarios.tuning.points import parse_grid

    with pytest.raises(SpecError) as grid:
        parse_grid("mapper.gate=0.1,0.2\nlaps=7")
    assert (grid.value.file, grid.value.key) == ("--grid", repr("mapper.gate=0.2\nlaps=7"))
    with pytest.raises(SpecError) as vary:
        parse_variation("mapper.gate=uniform(0.1, 0.\n2)")
    assert (vary.value.file, vary.value.key) == ("--vary", repr("mapper.gate=0.\n2"))


def test_a_set_value_nested_too_deep_is_refused_before_parsing():
    with pytest.raises(SpecError) as info:
        parse_override("people=" + "[" * 100_000 + "]" * 100_000)
    assert str(info.value) == ("--set: people: arrays and tables nest deeper than 64 levels "
                               "(at line 1); no input needs more than a few")
    assert parse_override("people=" + "[" * 64 + "]" * 64)[0] == ["people"]  # the limit holds


# --- bad files and names -------------------------------------------------------------------


GOOD = """\
world = "sim1"
laps = 5
"""


def test_a_minimal_file_gets_the_defaults(tmp_path):
    spec = load_scenario(write(tmp_path, GOOD))
    assert spec.name == "scenario"
    assert (spec.robot, spec.policy, spec.moves, spec.people) == (
        "pioneer3dx",
        "conservative",
        (),
        (),
    )


def test_missing_file_names_the_file(tmp_path):
    path = tmp_path / "nowhere.toml"
    error = error_of(path)
    assert (
        str(error)
        == f"{path}: <file>: no such file (bundled scenarios: "
        + ", ".join(bundled_scenarios())
        + ")"
    )


def test_unknown_scenario_name_suggests_one():
    error = error_of("pal3c")
    assert (error.file, error.key) == ("pal3c", "<file>")
    assert "not a bundled scenario (did you mean 'pal3b'?)" in error.message


def test_not_toml_names_the_line(tmp_path):
    path = write(tmp_path, 'world = "sim1"\nlaps = = 5\n')
    error = error_of(path)
    assert error.file == str(path)
    assert error.key == "line 2, column 8"
    assert error.message.startswith("not valid TOML")


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ('world = "sim1"\nlapz = 3\n', "lapz", "unknown key (did you mean 'laps'?)"),
        (GOOD + "[safety]\nslowdwn = 0.3\n", "safety.slowdwn", "did you mean 'slowdown'?"),
        (GOOD + "[mapper]\ngte = 0.3\n", "mapper.gte", "did you mean 'gate'?"),
        ('world = "sim1"\nlaps = -2\n', "laps", "must be >= 1 and <= 1000, got -2"),
        ('world = "sim1"\nlaps = 0\n', "laps", "must be >= 1"),
        (GOOD + 'policy = "fast"\n', "policy", "must be one of conservative, adaptive"),
        (GOOD + "seed = -1\n", "seed", "must be >= 0 and <= 9223372036854775807, got -1"),
        ("laps = 5\n", "world", "missing required key"),
        ('world = "sim11"\n', "world", "not a bundled world (did you mean 'sim1'?)"),
        (GOOD + 'robot = "pioner"\n', "robot", "(did you mean 'pioneer3dx'?)"),
        (GOOD + 'people = ["walker"]\n', "people[0]", "world 'sim1' has no person named"),
        (
            'world = "pal3"\npeople = ["walker", "wlaker"]\n',
            "people[1]",
            "no person named 'wlaker' (did you mean 'walker'?)",
        ),
    ],
)
def test_bad_file_names_file_and_key(tmp_path, text, key, message):
    path = write(tmp_path, text)
    error = error_of(path)
    assert (error.file, error.key) == (str(path), key)
    assert message in error.message
    assert str(error).startswith(f"{path}: {key}: ")


MOVE_OF_AISLE = """
[[moves]]
lap = {lap}
action = "move"
box = "{box}"
pose = [{x}, -0.98, 0.0]
"""


@pytest.mark.parametrize(
    ("moves", "key", "message"),
    [
        (
            MOVE_OF_AISLE.format(lap=3, box="carton_isle", x=3.5),
            "moves[0].box",
            "no box named 'carton_isle' in world 'sim1' before lap 3 "
            "(did you mean 'carton_aisle'?); "
            "boxes then: carton_aisle, pallet_turn, carton_north",
        ),
        (
            MOVE_OF_AISLE.format(lap=6, box="carton_aisle", x=3.5),
            "moves[0].lap",
            "lap 6 never runs with laps = 5",
        ),
        (MOVE_OF_AISLE.format(lap=1, box="carton_aisle", x=3.5), "moves[0].lap", "must be >= 2"),
        (
            '[[moves]]\nlap = 2\naction = "shift"\nbox = "carton_aisle"\n',
            "moves[0].action",
            "must be one of move, add, remove",
        ),
        (
            '[[moves]]\nlap = 2\naction = "move"\nbox = "carton_aisle"\n',
            "moves[0].pose",
            "'move' needs pose",
        ),
        (
            '[[moves]]\nlap = 2\naction = "add"\nbox = "carton"\npose = [1, 1, 0]\n',
            "moves[0].size",
            "'add' needs size",
        ),
        (
            '[[moves]]\nlap = 2\naction = "add"\nbox = "carton_aisle"\n'
            "pose = [5, -0.7, 0]\nsize = [0.5, 0.4, 0.5]\n",
            "moves[0].box",
            "a box named 'carton_aisle' already stands there before lap 2",
        ),
        (
            '[[moves]]\nlap = 2\naction = "remove"\nbox = "carton_aisle"\npose = [1, 1, 0]\n',
            "moves[0].pose",
            "'remove' takes no pose or size",
        ),
        (
            '[[moves]]\nlap = 2\naction = "remove"\nbox = "carton_aisle"\nsise = [1, 1, 1]\n',
            "moves[0].sise",
            "unknown key (did you mean 'size'?)",
        ),
        (
            # Removed before lap 3, so there is nothing to move before lap 4.
            '[[moves]]\nlap = 3\naction = "remove"\nbox = "carton_aisle"\n'
            + MOVE_OF_AISLE.format(lap=4, box="carton_aisle", x=3.5),
            "moves[1].box",
            "no box named 'carton_aisle' in world 'sim1' before lap 4",
        ),
        (
            # Listed out of lap order: indices stay the file's.
            MOVE_OF_AISLE.format(lap=4, box="carton_aisle", x=3.5)
            + '[[moves]]\nlap = 3\naction = "remove"\nbox = "carton_aisle"\n',
            "moves[0].box",
            "no box named 'carton_aisle' in world 'sim1' before lap 4",
        ),
        (
            '[[moves]]\nlap = 2\naction = "move"\nbox = "carton_aisle"\npose = [3.0, -0.3, 0]\n',
            "moves[0]",
            "before lap 2: box 'carton_aisle': overlaps a protective field",
        ),
        (
            MOVE_OF_AISLE.format(lap=2, box="carton_aisle", x=3.0).replace("-0.98", "4.0"),
            "moves[0]",
            "before lap 2: box 'carton_aisle': never enters a warning field",
        ),
        (
            '[[moves]]\nlap = 5\naction = "add"\nbox = "blocker"\npose = [7.5, 6.0, 0]\n'
            "size = [2.4, 0.3, 1.0]\n",
            "moves[0]",
            "before lap 5: path: ",
        ),
    ],
)
def test_bad_move_names_file_and_key(tmp_path, moves, key, message):
    path = write(tmp_path, GOOD + moves)
    error = error_of(path)
    assert (error.file, error.key) == (str(path), key)
    assert message in error.message


def test_set_world_keeps_the_file_moves_and_checks_them():
    error = error_of("sim1", ["world=sim2"])
    assert (error.key, error.file.endswith("sim1.toml")) == ("moves[0].box", True)
    assert "no box named 'carton_aisle' in world 'sim2'" in error.message


def test_layout_check_can_be_left_to_the_caller():
    spec = scenario_from_toml({"world": "nowhere"}, file="s.toml", check_layout=False)
    assert spec.world == "nowhere"
    with pytest.raises(SpecError, match=r"^s\.toml: world: not a bundled world"):
        scenario_from_toml({"world": "nowhere"}, file="s.toml")


def test_bad_moves_are_caught_even_when_set_laps_drops_them(tmp_path):
    path = write(tmp_path, GOOD + MOVE_OF_AISLE.format(lap=4, box="carton_isle", x=3.5))
    error = error_of(path, ["laps=2"])
    assert (error.file, error.key) == (str(path), "moves[0].box")


def test_valid_moves_in_a_user_file_load(tmp_path):
    moves = MOVE_OF_AISLE.format(lap=2, box="carton_aisle", x=3.8) + (
        '[[moves]]\nlap = 2\naction = "remove"\nbox = "carton_north"\n'
    )
    spec = load_scenario(write(tmp_path, GOOD + moves))
    boxes = {box.name: box.pose for box in lap_worlds(spec)[1].boxes}
    assert boxes == {"carton_aisle": (3.8, -0.98, 0.0), "pallet_turn": (6.8, -1.0, 0.35)}


# --- lap 1 is checked as it stands -------------------------------------------------------


@pytest.fixture
def flawed_world(tmp_path: Path) -> Path:
    """Return sim1 with carton_north on the path: the robot would stop in front of it."""
    text = (WORLD_DATA_DIR / "sim1.toml").read_text()
    assert "pose = [8.9, 3.8, 0.0]" in text
    path = tmp_path / "flawed.toml"
    path.write_text(text.replace("pose = [8.9, 3.8, 0.0]", "pose = [8.3, 3.8, 0.0]"))
    return path


def test_a_flawed_world_is_rejected_at_lap_1_in_its_own_file(tmp_path, flawed_world):
    assert layout_problems(load_world(flawed_world))
    text = 'world = "flawed.toml"\n' + MOVE_OF_AISLE.format(lap=2, box="carton_aisle", x=3.5)
    error = error_of(write(tmp_path, text))
    names = [box.name for box in load_world(flawed_world).boxes]
    assert (error.file, error.key) == (str(flawed_world), f"boxes[{names.index('carton_north')}]")
    assert error.message.startswith("lap 1: box 'carton_north': the swept robot footprint")


def _moved(old: str, new: str):
    """Return an edit of sim1's text that replaces ``old`` (which must be there) by ``new``."""

    def edit(text: str) -> str:
        assert old in text
        return text.replace(old, new, 1)

    return edit


def _posts_kept(count: int):
    """Return an edit of sim1's text that keeps only its first ``count`` posts."""

    def edit(text: str) -> str:
        block = re.search(r"^posts = \[\n(.*?)^\]", text, flags=re.S | re.M)
        posts = re.findall(r"\{[^}]*\}", block[1])
        return text.replace(block[0], "posts = [" + ", ".join(posts[:count]) + "]")

    return edit


@pytest.mark.parametrize(
    ("edit", "key", "fragment"),
    [
        pytest.param(_moved("pose = [3.0, -0.98, 0.0]", "pose = [3.0, -1.45, 0.0]"),
                     "boxes[0]", "box 'carton_aisle': overlaps walls[0]", id="box-in-wall"),
        pytest.param(_moved("pose = [3.0, -0.98, 0.0]", "pose = [1.0, 0.0, 0.0]"),
                     "boxes[0]", "box 'carton_aisle': the swept robot footprint overlaps it",
                     id="box-on-start"),
        pytest.param(_posts_kept(2), "posts", "see fewer than 3 posts", id="two-posts"),
        pytest.param(_posts_kept(0), "posts", "see fewer than 3 posts, the worst 0", id="no-posts"),
    ],
)
def test_lap_1_problems_are_errors_of_the_world_file(tmp_path, edit, key, fragment):
    text = (WORLD_DATA_DIR / "sim1.toml").read_text()
    world_file = tmp_path / "edited.toml"
    world_file.write_text(edit(text))
    error = error_of(write(tmp_path, 'world = "edited.toml"\n'))
    assert (error.file, error.key) == (str(world_file), key)
    assert error.message.startswith("lap 1: ")
    assert fragment in error.message


def test_relative_world_path_resolves_next_to_the_scenario(tmp_path, flawed_world):
    other = tmp_path / "elsewhere"
    other.mkdir()
    error = error_of(write(other, 'world = "flawed.toml"\n'))
    assert (error.file, error.key) == (str(other / "scenario.toml"), "world")
    assert error.message.startswith(f"{other / 'flawed.toml'}: no such file")


# --- world_for_lap and check_moves on their own --------------------------------------------


def test_world_for_lap_applies_moves_in_lap_order():
    world = load_world("sim1")
    moves = [
        BoxMove(lap=4, action="move", box="carton_aisle", pose=(4.0, -0.66, 0.0)),
        BoxMove(lap=3, action="move", box="carton_aisle", pose=(3.5, -0.66, 0.0)),
        BoxMove(lap=3, action="move", box="carton_aisle", pose=(3.6, -0.66, 0.0), size=(1, 1, 1)),
    ]
    assert world_for_lap(world, moves, 1) is world
    assert world_for_lap(world, moves, 2) is world
    lap3 = world_for_lap(world, moves, 3).boxes[0]
    assert (lap3.pose, lap3.size) == ((3.6, -0.66, 0.0), (1.0, 1.0, 1.0))
    assert world_for_lap(world, moves, 4).boxes[0].pose == (4.0, -0.66, 0.0)
    assert world_for_lap(world, moves, 99).boxes[0].pose == (4.0, -0.66, 0.0)


@pytest.mark.parametrize("lap", [0, -1, 1.5, True])
def test_world_for_lap_counts_laps_from_1(lap):
    with pytest.raises(ValueError, match="lap counts from 1"):
        world_for_lap(load_world("sim1"), [], lap)


@pytest.mark.parametrize(
    ("build", "text", "key"),
    [
        (lambda: ScenarioSpec(name="s", world="sim1", laps=0), "laps = 0", "laps"),
        (lambda: ScenarioSpec(name="s", world="sim1", seed=-1), "seed = -1", "seed"),
        (lambda: ScenarioSpec(name="s", world="sim1", lap_timeout=1e9), "lap_timeout = 1e9",
         "lap_timeout"),
        (lambda: ScenarioSpec(name="../up", world="sim1"), 'name = "../up"', "name"),
        (lambda: Rates(safety_hz=float("nan")), "[rates]\nsafety_hz = nan", "rates.safety_hz"),
        (lambda: Rates(control_hz=300.0), "[rates]\ncontrol_hz = 300.0", "rates.control_hz"),
        (lambda: Noise(range=-1.0), "[noise]\nrange = -1.0", "noise.range"),
        (lambda: SafetySettings(slowdown=0), "[safety]\nslowdown = 0", "safety.slowdown"),
        (lambda: SafetySettings(min_points=2.5), "[safety]\nmin_points = 2.5",
         "safety.min_points"),
        (lambda: BoxMove(lap=2, action="move", box="carton_aisle", pose=(3.5, -0.66, 0.0),
                         size=(0.6, -0.5, 0.6)),
         '[[moves]]\nlap = 2\naction = "move"\nbox = "carton_aisle"\npose = [3.5, -0.66, 0.0]'
         "\nsize = [0.6, -0.5, 0.6]", "moves[0].size"),
        (lambda: BoxMove(lap=2, action="move", box="carton_aisle", pose=(3.5, 1e7, 0.0)),
         '[[moves]]\nlap = 2\naction = "move"\nbox = "carton_aisle"\npose = [3.5, 1e7, 0.0]',
         "moves[0].pose"),
        (lambda: MapperParams(gate=-0.1), "[mapper]\ngate = -0.1", "mapper.gate"),
        (lambda: MapperParams(epsilon=2.0), "[mapper]\nepsilon = 2.0", "mapper.epsilon"),
        (lambda: MapperParams(min_points=1), "[mapper]\nmin_points = 1", "mapper.min_points"),
        (lambda: MapperParams(max_range=-1.0), "[mapper]\nmax_range = -1.0",
         "mapper.max_range"),
        (lambda: MapperParams(vertex_placement="snapped"),
         '[mapper]\nvertex_placement = "snapped"', "mapper.vertex_placement"),
    ],
)
def test_spec_built_in_code_fails_as_the_file_would(tmp_path, build, text, key):
    with pytest.raises(SpecError) as in_code:
        build()
    path = tmp_path / "scenario.toml"
    top, _, tables = text.partition("[")
    path.write_text(f'world = "sim1"\n{top}\n' + (f"[{tables}\n" if tables else ""))
    with pytest.raises(SpecError) as from_file:
        load_scenario(path)
    assert in_code.value.file == "<memory>"
    assert from_file.value.file == str(path)
    assert from_file.value.key == key
    assert key.endswith(in_code.value.key)
    assert in_code.value.message == from_file.value.message


def test_check_moves_blames_the_move_that_broke_the_layout():
    good = BoxMove(lap=2, action="move", box="carton_aisle", pose=(3.5, -0.98, 0.0))
    bad = BoxMove(lap=2, action="move", box="pallet_turn", pose=(6.8, -0.2, 0.35))
    world = load_world("sim1")
    check_moves(world, [good], footprint=PIONEER_FOOTPRINT)
    with pytest.raises(SpecError) as caught:
        check_moves(world, [good, bad], footprint=PIONEER_FOOTPRINT, file="f.toml")
    assert caught.value.key == "moves[1]"
    assert "box 'pallet_turn'" in caught.value.message


# --- mapper thresholds from the safety laser's noise -------------------------------------


def test_mapper_noise_thresholds_follow_the_safety_laser_unless_set(tmp_path):
    # the lgv's safety laser is the S300 (3 cm): 2.5 x 3 cm tolerance, 3 cm breakpoint
    # noise; the pioneer's LMS100 (1.2 cm) keeps the library defaults, 3 cm and 1.2 cm
    s300 = get_preset("lgv").safety_laser.laser.range_sigma
    lms100 = get_preset("pioneer3dx").safety_laser.laser.range_sigma
    assert (s300, lms100) == (0.03, 0.012)
    warehouse = load_scenario("warehouse").mapper
    assert warehouse.epsilon == pytest.approx(0.075)
    assert warehouse.breakpoint_sigma_r == pytest.approx(0.03)
    assert warehouse.vertex_placement == "fitted"
    for name in paper_scenarios():
        mapper = load_scenario(name).mapper
        assert (mapper.epsilon, mapper.breakpoint_sigma_r) == (0.03, 0.012)
    # the scenario's noise scale scales the laser's noise, hence the thresholds
    path = write(tmp_path, 'world = "sim1"\n[noise]\nrange = 2.0\n')
    scaled = load_scenario(path).mapper
    assert (scaled.epsilon, scaled.breakpoint_sigma_r) == pytest.approx((0.06, 0.024))
    # a file's [mapper] keys and --set win over the laser's
    path = write(tmp_path, 'world = "warehouse"\nrobot = "lgv"\n[mapper]\nepsilon = 0.04\n')
    mapper = load_scenario(path).mapper
    assert (mapper.epsilon, mapper.breakpoint_sigma_r) == pytest.approx((0.04, 0.03))
    mapper = load_scenario(path, overrides=["mapper.breakpoint_sigma_r=0.02"]).mapper
    assert (mapper.epsilon, mapper.breakpoint_sigma_r) == pytest.approx((0.04, 0.02))
    # a noiseless laser keeps the defaults (a tolerance must stay above zero)
    path = write(tmp_path, 'world = "sim1"\n[noise]\nrange = 0.0\n')
    assert load_scenario(path).mapper == MapperParams()
