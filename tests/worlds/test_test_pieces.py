"""Test pieces in world files: loaded with the standard's sizes, bad ones one clear error."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from tests.spec_errors import raises_spec_error
from worlds import BoxSpec, SpecError, TestPieceSpec, bundled_worlds, load_world
from worlds.checks import layout_problems, overlapping_solids, piece_scan_margins

CORRIDOR = """\
walls = [
    { start = [0.0, -1.2], end = [6.0, -1.2] },
    { start = [0.0, 1.2], end = [6.0, 1.2] },
]

[path]
knots = [[0.5, 0.0], [5.5, 0.0]]

[[path.segments]]
name = "only"
start_knot = 0
end_knot = 1
warning = [[0.25, -0.5], [1.4, -0.5], [1.4, 0.5], [0.25, 0.5]]
protective = [[0.25, -0.3], [0.6, -0.3], [0.6, 0.3], [0.25, 0.3]]
"""

LYING = """
[[test_pieces]]
name = "person_lying"
kind = "lying"
pose = [3.0, 0.0, 1.5707963267948966]
"""

UPRIGHT = """
[[test_pieces]]
name = "leg"
kind = "upright"
pose = [4.0, 0.0, 0.0]
remission = 0.05
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "pieces.toml"
    path.write_text(text)
    return path


def load_error(path: Path) -> SpecError:
    with pytest.raises(SpecError) as info:
        load_world(path)
    error = info.value
    assert str(error) == f"{path}: {error.key}: {error.message}"  # one line, file and key
    assert "\n" not in str(error)
    return error


def test_pieces_load_with_the_standards_sizes(tmp_path):
    world = load_world(write(tmp_path, CORRIDOR + LYING + UPRIGHT))
    lying, upright = world.test_pieces
    # Test piece 1: 200 mm across, 600 mm long; test piece 2: 70 mm across, 400 mm high.
    assert (lying.name, lying.kind, lying.diameter, lying.length) == (
        "person_lying", "lying", 0.2, 0.6)
    assert (upright.name, upright.kind, upright.diameter, upright.length) == (
        "leg", "upright", 0.07, 0.4)
    assert (lying.top, upright.top) == (0.2, 0.4)
    assert upright.remission == 0.05
    assert lying.pose == (3.0, 0.0, math.pi / 2)


def test_the_dimensions_are_parameters(tmp_path):
    sized = 'kind = "lying"\ndiameter = 0.3\nlength = 1.0'
    text = CORRIDOR + LYING.replace('kind = "lying"', sized)
    (piece,) = load_world(write(tmp_path, text)).test_pieces
    assert (piece.diameter, piece.length, piece.top) == (0.3, 1.0, 0.3)


def test_a_lying_piece_lies_across_its_yaw():
    # Axis along y (yaw 90 deg): 0.2 m deep along x, 0.6 m wide along y, centred at (3, 0).
    piece = TestPieceSpec("p", "lying", (3.0, 0.0, math.pi / 2))
    x0, y0, x1, y1 = piece.footprint().bounds
    assert (x0, y0, x1, y1) == pytest.approx((2.9, -0.3, 3.1, 0.3), abs=1e-12)
    assert piece.footprint().area == pytest.approx(0.2 * 0.6, abs=1e-12)


def test_an_upright_piece_stands_on_a_disc():
    piece = TestPieceSpec("p", "upright", (1.0, 2.0, 0.7))
    assert piece.footprint().area == pytest.approx(math.pi * 0.035**2, rel=1e-3)
    assert piece.footprint().centroid.coords[0] == pytest.approx((1.0, 2.0))


def test_worlds_without_pieces_load_unchanged():
    for name in bundled_worlds():
        assert load_world(name).test_pieces == ()


@pytest.mark.parametrize(
    ("old", "new", "key", "fragment"),
    [
        pytest.param('kind = "lying"', 'kind = "lieing"', "test_pieces[0].kind",
                     "must be one of lying, upright, got 'lieing' (did you mean 'lying'?)",
                     id="bad-kind"),
        pytest.param('kind = "lying"', 'kind = "lying"\ndiameter = 0.0', "test_pieces[0].diameter",
                     "must be > 0.0 and <= 2.0, got 0.0", id="zero-diameter"),
        pytest.param('kind = "lying"', 'kind = "lying"\ndiameter = -0.2',
                     "test_pieces[0].diameter", "must be > 0.0 and <= 2.0, got -0.2",
                     id="negative-diameter"),
        pytest.param('kind = "lying"', 'kind = "lying"\nlength = 0', "test_pieces[0].length",
                     "must be > 0.0 and <= 5.0, got 0.0", id="zero-length"),
        pytest.param('kind = "lying"\n', "", "test_pieces[0].kind", "missing required key",
                     id="no-kind"),
        pytest.param("pose = [3.0, 0.0, 1.5707963267948966]", "pose = [3.0, 0.0]",
                     "test_pieces[0].pose", "expected a list of 3 numbers", id="short-pose"),
        pytest.param('kind = "lying"', 'kind = "lying"\nheight = 0.4', "test_pieces[0].height",
                     "unknown key", id="unknown-key"),
    ],
)
def test_a_bad_piece_is_one_error_naming_its_key(tmp_path, old, new, key, fragment):
    text = CORRIDOR + LYING
    assert text.count(old) == 1
    error = load_error(write(tmp_path, text.replace(old, new)))
    assert error.key == key
    assert fragment in error.message


def test_piece_names_are_unique_and_not_a_box_or_persons(tmp_path):
    twice = CORRIDOR + LYING + LYING
    error = load_error(write(tmp_path, twice))
    assert (error.key, error.message) == (
        "test_pieces[1].name", "duplicate name 'person_lying' (also test_pieces[0])")
    clash = CORRIDOR + '\n[[boxes]]\nname = "leg"\nsize = [0.3, 0.3, 0.3]\npose = [2, 1, 0]\n' \
        + UPRIGHT
    error = load_error(write(tmp_path, clash))
    assert error.key == "test_pieces[0].name"
    assert "'leg' is also the name of one of the boxes" in error.message


def test_a_piece_built_in_code_fails_like_a_file():
    with raises_spec_error("kind", r"must be one of lying, upright, got 'flat'"):
        TestPieceSpec("p", "flat", (0.0, 0.0, 0.0))
    with raises_spec_error("diameter", r"must be > 0.0 and <= 2.0, got -0.07"):
        TestPieceSpec("p", "upright", (0.0, 0.0, 0.0), diameter=-0.07)


def test_scan_margins_are_the_top_less_the_scan_height():
    world = load_world("sim1")
    pieces = (TestPieceSpec("lying", "lying", (3.0, 0.0, 0.0)),
              TestPieceSpec("upright", "upright", (5.0, 0.0, 0.0)))
    world = dataclasses.replace(world, test_pieces=pieces)
    # The LGV's S300 at 0.15 m cuts both; the Pioneer's LMS100 at 0.35 m only the 0.4 m one.
    assert piece_scan_margins(world, 0.15) == pytest.approx({"lying": 0.05, "upright": 0.25})
    assert piece_scan_margins(world, 0.35) == pytest.approx({"lying": -0.15, "upright": 0.05})
    assert [piece.cut_by(h) for piece in pieces for h in (0.15, 0.2, 0.35)] == [
        True, False, False, True, True, True]


def test_pieces_on_the_path_are_no_layout_problem_but_a_piece_in_a_wall_is():
    world = load_world("sim1")
    on_path = TestPieceSpec("leg", "upright", (3.0, 0.0, 0.0))  # sim1's first aisle, y = 0
    assert layout_problems(dataclasses.replace(world, test_pieces=(on_path,))) == []
    wall = world.walls[0]
    in_wall = TestPieceSpec("flat", "lying", (*wall.start, 0.0))
    assert ("test piece 'flat'", "walls[0]") in overlapping_solids(
        dataclasses.replace(world, test_pieces=(in_wall,)))


def test_a_piece_under_a_box_overlaps_it():
    world = load_world("sim1")
    box: BoxSpec = world.boxes[0]
    under = TestPieceSpec("flat", "lying", box.pose)
    pairs = overlapping_solids(dataclasses.replace(world, test_pieces=(under,)))
    assert (f"box {box.name!r}", "test piece 'flat'") in pairs
