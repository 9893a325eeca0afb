"""`check` => `run`: what stops lap 1 from starting is refused by `check` with one line.

Each world below passed `check` before and then failed in `run` after PyBullet started
(issue 29): evenly spaced posts (the EKF cannot tell where it stands), a person standing
on the path start, two fleet vehicles starting on one segment. Each is now refused by
`check` (exit 2, one `error:` line naming the file and the key) and by `run` before
anything is written; a hand-made uneven layout still passes and its run starts.
"""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from scenarios.bench.testbench import Testbench
from scenarios.spec.load import load_scenario
from scenarios.spec.starts import check_starts
from semistatic.errors import MEMORY, SpecError
from tests.scenarios.tiny_world import TINY_SCENARIO, TINY_WORLD, write_tiny
from worlds.load import load_world
from worlds.spec import PersonSpec

_TINY_POSTS = TINY_WORLD[TINY_WORLD.index("posts = ["):TINY_WORLD.index("[path]")]


def _posts(points: list[tuple[float, float]]) -> str:
    rows = ", ".join(f"{{ x = {x}, y = {y} }}" for x, y in points)
    return f"posts = [{rows}]\n\n"


# Every 2 m on both walls, as docs/first-scenario.md's new user did: any three posts in
# view fit the layout 2 m further along too.
EVEN_POSTS = [(x, side) for x in (-2.0, 0.0, 2.0, 4.0, 6.0) for side in (-1.39, 1.39)]
# The same walls, the gaps varied by tens of centimetres: one place fits what is seen.
UNEVEN_POSTS = [(-2.0, -1.39), (-0.3, -1.39), (2.1, -1.39), (3.6, -1.39), (6.0, -1.39),
                (-1.2, 1.39), (1.0, 1.39), (2.7, 1.39), (5.3, 1.39)]

STANDER = """
[[people]]
name = "stander"
waypoints = [[0.1, 0.0]]
radius = 0.2
"""


def _write(folder: Path, world: str, scenario: str = TINY_SCENARIO) -> Path:
    (folder / "tiny_world.toml").write_text(world)
    path = folder / "tiny.toml"
    path.write_text(scenario)
    return path


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    return subprocess.run([sys.executable, "-m", "scenarios", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600, check=False)


def _one_error_line(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    return lines[0]


def _even(folder: Path) -> Path:
    return _write(folder, TINY_WORLD.replace(_TINY_POSTS, _posts(EVEN_POSTS)))


def _stander(folder: Path) -> Path:
    return _write(folder, TINY_WORLD + STANDER,
                  TINY_SCENARIO.replace("laps = 2", 'laps = 2\npeople = ["stander"]'))


def _two_on_one_segment(folder: Path) -> Path:
    path = folder / "fleet.toml"
    path.write_text('world = "warehouse"\nrobot = "lgv"\nlaps = 1\n\n'
                    '[[vehicles]]\nname = "a"\n\n[[vehicles]]\nname = "b"\n')
    return path


CASES = [
    (_even, "tiny_world.toml: posts: lap 1: vehicle 'robot' at its start (0.00, 0.00) "
            "cannot localise: the posts it sees", "fit the post layout in"),
    (_stander, "tiny_world.toml: people[0]: person 'stander'",
     "on vehicle 'robot' at its start (0.00, 0.00)"),
    (_two_on_one_segment, "fleet.toml: vehicles[1].start_segment: vehicle 'b' starts on "
                          "segment 'south_west' like vehicles[0] 'a'", "start_segment of its own"),
]


@pytest.mark.parametrize(("write", "key", "fix"), CASES, ids=["even", "stander", "fleet"])
def test_check_refuses_what_cannot_start(tmp_path, write, key, fix):
    scenario = write(tmp_path)
    line = _one_error_line(_cli("check", str(scenario), cwd=tmp_path))
    assert line.startswith("error: ")
    assert key in line
    assert fix in line


@pytest.mark.parametrize(("write", "key", "fix"), CASES, ids=["even", "stander", "fleet"])
def test_load_refuses_what_cannot_start(tmp_path, write, key, fix):
    with pytest.raises(SpecError) as caught:
        load_scenario(write(tmp_path))
    assert key in str(caught.value)
    assert fix in str(caught.value)


def test_run_refuses_before_writing(tmp_path):
    """`run` gets the same pass: exit 2, one line, no PyBullet, nothing written."""
    scenario = _even(tmp_path)
    out = tmp_path / "out"
    before = sorted(path.name for path in tmp_path.iterdir())
    line = _one_error_line(_cli("run", str(scenario), "--laps", "1", "--out", str(out),
                                cwd=tmp_path))
    assert "posts: lap 1:" in line
    assert sorted(path.name for path in tmp_path.iterdir()) == before


def test_even_posts_ambiguous_where_uneven_are_not(tmp_path):
    """The hand-made positive case: the same corridor, gaps varied, passes the check."""
    world = TINY_WORLD.replace(_TINY_POSTS, _posts(UNEVEN_POSTS))
    spec = load_scenario(_write(tmp_path, world))
    assert spec.laps == 2


def test_bundled_and_tiny_scenarios_pass(tmp_path):
    """Every bundled scenario and the tiny world start: the checks refuse no good layout."""
    load_scenario(write_tiny(tmp_path))
    for name in ("pal1", "pal3a", "pal3b", "sim1", "sim2", "warehouse", "warehouse_fleet"):
        load_scenario(name)


def test_world_in_code_gets_the_layout_checks():
    """A WorldSpec handed to Testbench gets the checks a file gets, named <memory>."""
    world = load_world("sim1")
    into_wall = dataclasses.replace(world.boxes[0], pose=(3.0, -1.5, 0.0))
    built = dataclasses.replace(world, boxes=(into_wall, *world.boxes[1:]), source=MEMORY)
    with pytest.raises(SpecError) as caught:
        Testbench("sim1", world=built)
    assert str(caught.value).startswith("<memory>: boxes[0]: lap 1: box 'carton_aisle': "
                                        "overlaps walls[0]")


def test_spec_in_code_gets_the_start_checks(tmp_path):
    """A ScenarioSpec built in code (a second vehicle on lgv1's segment) is refused."""
    spec = load_scenario("warehouse_fleet")
    on_lgv1 = dataclasses.replace(spec.vehicles[1], start_segment="")
    with pytest.raises(SpecError, match=r"vehicles\[1\]\.start_segment: vehicle 'lgv2'"):
        Testbench(dataclasses.replace(spec, vehicles=(spec.vehicles[0], on_lgv1)))


@pytest.mark.slow
def test_uneven_run_starts(tmp_path):
    """The positive case runs: lap 1 starts from a triangulated pose near the truth."""
    world = TINY_WORLD.replace(_TINY_POSTS, _posts(UNEVEN_POSTS))
    with Testbench(str(_write(tmp_path, world))) as bench:
        bench.reset()
        assert bench.lap == 1
        assert abs(bench.ekf_pose - bench.true_pose).max() < 0.05


@pytest.fixture(scope="module")
def tiny_spec(tmp_path_factory):
    return load_scenario(write_tiny(tmp_path_factory.mktemp("tiny")))


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(x=st.floats(-1.0, 1.0), y=st.floats(-0.8, 0.8), radius=st.floats(0.1, 0.4))
def test_a_standing_person_is_refused_exactly_when_on_the_start_footprint(
        tiny_spec, x, y, radius):
    """Against the closed form: a disc meets the Pioneer's rectangle at the start pose
    (0, 0, heading 0; base_link on the wheel axle: x from -0.2725 m behind to 0.1825 m
    ahead, +-0.1905 m across) when the rectangle's nearest point is within the radius."""
    rear, front, half_width = -0.2725, 0.1825, 0.1905
    gap = math.hypot(max(rear - x, 0.0, x - front), max(abs(y) - half_width, 0.0))
    assume(abs(gap - radius) > 1e-6)
    world = load_world(tiny_spec.world)
    person = PersonSpec("stander", waypoints=((x, y),), radius=radius)
    world = dataclasses.replace(world, people=(person,)).enable_people("stander")
    if gap < radius:
        with pytest.raises(SpecError, match=r"people\[0\]: person 'stander'"):
            check_starts(tiny_spec, world)
    else:
        check_starts(tiny_spec, world)
