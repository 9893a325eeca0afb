"""The standard's test pieces: who can see them (check), what the vehicles do (closed loop)."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from robots.presets import LGV, PIONEER3DX
from scenarios.bench.safety_record import SafetyRecord, merged_record
from scenarios.results.pieces import PIECE_X, piece_corridor, piece_trial
from scenarios.spec.field_sizing import stop_model
from scenarios.spec.pieces import check_piece_sightings, piece_sightings
from scenarios.spec.scenario import SafetySettings, ScenarioSpec, VehicleSpec
from semistatic.errors import SpecError
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import TINY_SCENARIO, write_tiny
from worlds.load import load_world
from worlds.spec import TestPieceSpec

LYING_Z_TOP = 0.2  # the lying piece's top: its 200 mm diameter
PIONEER_SCAN_Z, LGV_SCAN_Z = 0.35, 0.15  # the presets' safety-laser scan planes

# Both pieces on the tiny world's path (y = 0), clear of its carton.
PIECES = """
[[test_pieces]]
name = "person_lying"
kind = "lying"
pose = [3.0, 0.0, 1.5707963267948966]

[[test_pieces]]
name = "leg"
kind = "upright"
pose = [2.0, 0.0, 0.0]
"""


def with_pieces(folder, pieces: str = PIECES, scenario: str = TINY_SCENARIO):
    path = write_tiny(folder, scenario=scenario)
    world = folder / "tiny_world.toml"
    world.write_text(world.read_text() + pieces)
    return path


def pieces_world():
    return dataclasses.replace(load_world("sim1"), test_pieces=(
        TestPieceSpec("person_lying", "lying", (3.0, 0.0, math.pi / 2)),
        TestPieceSpec("leg", "upright", (5.0, 0.0, 0.0))))


# ----------------------------------------------------------------------- who sees what
def test_the_lgvs_low_scanner_sees_both_pieces_the_pioneers_only_the_upright_one():
    assert PIONEER3DX.safety_laser.z == PIONEER_SCAN_Z  # the premise of this test
    assert LGV.safety_laser.z == LGV_SCAN_Z
    world = pieces_world()
    seen = {(s.robot, s.piece): s.seen for robot in ("pioneer3dx", "lgv")
            for s in piece_sightings(ScenarioSpec("s", world="sim1", robot=robot), world)}
    # 0.35 m over a 0.2 m top: no; 0.35 m under a 0.4 m top: yes; 0.15 m under both: yes.
    assert seen == {("pioneer3dx", "person_lying"): False, ("pioneer3dx", "leg"): True,
                    ("lgv", "person_lying"): True, ("lgv", "leg"): True}


def test_a_piece_a_vehicle_cannot_see_is_an_error_unless_the_scenario_studies_it():
    world = pieces_world()
    spec = ScenarioSpec("s", world="sim1")
    with pytest.raises(SpecError) as caught:
        check_piece_sightings(spec, world)
    error = caught.value
    assert (error.file, error.key) == (world.source, "test_pieces[0]")
    for fragment in ("'person_lying'", "0.2 m", "0.35 m", "pioneer3dx",
                     "safety.unseen_test_pieces = true"):
        assert fragment in error.message
    studied = dataclasses.replace(spec, safety=SafetySettings(unseen_test_pieces=True))
    assert [s.seen for s in check_piece_sightings(studied, world)] == [False, True]


def test_every_vehicle_of_a_fleet_is_checked():
    world = pieces_world()
    fleet = ScenarioSpec("f", world="sim1", robot="lgv", vehicles=(
        VehicleSpec("low", robot="lgv"), VehicleSpec("high", robot="pioneer3dx")))
    blind = [(s.vehicle, s.piece) for s in piece_sightings(fleet, world) if not s.seen]
    assert blind == [("high", "person_lying")]
    with pytest.raises(SpecError, match="vehicle 'high'"):
        check_piece_sightings(fleet, world)


def test_check_refuses_the_pioneer_with_a_lying_piece_in_one_error_line(capsys, tmp_path):
    scenario = with_pieces(tmp_path)
    status, out, err = run_cli(capsys, "check", scenario)
    assert status == 2
    assert out == ""
    assert_one_error_line(err, "tiny_world.toml: test_pieces[0]:", "'person_lying'",
                          "vehicle 'robot' (pioneer3dx, safety laser at 0.35 m)",
                          "safety.unseen_test_pieces = true")


def test_check_reports_each_piece_against_each_vehicle(capsys, tmp_path):
    scenario = with_pieces(tmp_path)
    status, out, err = run_cli(capsys, "check", scenario,
                               "--set", "safety.unseen_test_pieces=true")
    assert status == 0, err
    assert "2 test pieces" in out
    rows = {line.split()[0]: line.split() for line in out.splitlines()
            if line.strip().startswith(("person_lying ", "leg "))}
    assert rows["person_lying"][:6] == ["person_lying", "lying", "0.200", "robot",
                                        "pioneer3dx", "0.350"]
    assert "NO: scans over it (studied)" in " ".join(rows["person_lying"])
    assert rows["leg"][:7] == ["leg", "upright", "0.400", "robot", "pioneer3dx", "0.350",
                               "yes"]


def test_a_world_without_pieces_checks_as_before(capsys, tmp_path):
    status, out, err = run_cli(capsys, "check", write_tiny(tmp_path))
    assert status == 0, err
    assert "test piece" not in out


# ------------------------------------------------------------------------ the record
def test_the_safety_record_keeps_the_separation_to_test_pieces():
    record = SafetyRecord()
    record.note_separation("test_piece", 0.4, t=1.0, lap=1, where=(2.9, 0.0), name="leg")
    record.note_separation("test_piece", 0.3, t=2.0, lap=1, where=(2.9, 0.0), name="leg")
    metrics = merged_record([record, SafetyRecord()]).as_metrics()
    assert metrics["min_separation_m"] == {"person": None, "box": None, "vehicle": None,
                                           "test_piece": 0.3}
    assert metrics["min_separation_at"]["test_piece"]["object"] == "leg"


@pytest.mark.slow
def test_a_run_past_a_piece_reports_its_separation_and_sighting(capsys, tmp_path):
    # An upright piece beside the tiny path, outside the fields: the Pioneer drives past.
    # Its footprint is 0.381 m wide, centred on the path: 1.0 - 0.035 - 0.1905 m apart.
    beside = '\n[[test_pieces]]\nname = "leg"\nkind = "upright"\npose = [2.0, 1.0, 0.0]\n'
    scenario = with_pieces(tmp_path, beside)
    out = tmp_path / "out"
    status, _, err = run_cli(capsys, "run", scenario, "--laps", 1, "--no-figures",
                             "--out", out)
    assert status == 0, err
    safety = json.loads((out / "metrics.json").read_text())["safety"]
    assert safety["min_separation_m"]["test_piece"] == pytest.approx(1.0 - 0.035 - 0.1905,
                                                                      abs=0.02)
    assert safety["test_pieces"] == [{"piece": "leg", "kind": "upright", "top_m": 0.4,
                                      "vehicle": "robot", "robot": "pioneer3dx",
                                      "scan_height_m": 0.35, "seen": True}]
    assert not [item for item in safety["infractions"] if item["kind"] == "contact"]


# ------------------------------------------------------------------ the closed loop
def field_length(robot, speed) -> float:
    """How far the trial corridor's protective field reaches ahead of the vehicle's front."""
    protective = piece_corridor(robot, speed, "upright").path.segments[0].protective
    return max(x for x, _ in protective) - max(x for x, _ in robot.footprint)


def stop_bounds(robot, speed) -> tuple[float, float]:
    """The least and the most the vehicle travels after a piece enters its protective field.

    At least its braking distance v^2 / 2a; at most the worst case of the stop model's
    closed form, v T + v^2 / 2a, with T the scanner's response time plus the command's
    latency and period (the scenario's rates), a the braking deceleration.
    """
    model = stop_model(ScenarioSpec("t", world="test_piece", robot=robot.name), robot)
    braking = speed**2 / (2.0 * model.deceleration)
    return braking, speed * model.reaction_time + braking


def first_stop(trial) -> dict:
    assert trial.stops, f"no protective stop: {trial}"
    return trial.stops[0]


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["upright", "lying"])
def test_the_lgv_stops_short_of_either_piece(kind):
    speed = 1.0
    trial = piece_trial(LGV, speed, kind)
    assert trial.seen
    assert not trial.contact, trial
    assert trial.infractions == (), trial
    # The S300 at 0.15 m reads the lying piece's near surface sqrt(r^2 - (0.15 - r)^2)
    # before its axis, 0.0134 m behind its footprint's edge: it enters the field later.
    r = 0.1 if kind == "lying" else 0.035
    hidden = r - math.sqrt(r**2 - (LGV_SCAN_Z - r) ** 2) if kind == "lying" else 0.0
    least, most = stop_bounds(LGV, speed)
    length = field_length(LGV, speed)
    assert length - most - hidden - 0.01 <= trial.gap <= length - least - hidden + 0.01, trial
    stop = first_stop(trial)
    assert stop["object"] == f"test_piece {kind}"
    assert stop["speed"] == pytest.approx(speed, abs=0.02)
    assert stop["distance_to_object_m"] == pytest.approx(trial.gap, abs=0.005)
    assert trial.min_separation == pytest.approx(trial.gap, abs=0.005)


@pytest.mark.slow
def test_the_pioneer_stops_short_of_the_upright_piece_and_keeps_seeing_it():
    speed = 0.2
    trial = piece_trial(PIONEER3DX, speed, "upright")
    assert trial.seen
    assert not trial.contact, trial
    assert trial.infractions == (), trial
    least, most = stop_bounds(PIONEER3DX, speed)
    length = field_length(PIONEER3DX, speed)
    assert length - most - 0.01 <= trial.gap <= length - least + 0.01, trial
    # Standing, the piece is still beyond the LMS100's 0.5 m blind zone (else it would
    # vanish, the field clear and the vehicle drive on: see the next tests).
    front = max(x for x, _ in PIONEER3DX.footprint)
    mount = PIONEER3DX.safety_laser
    assert trial.gap + front - mount.x >= mount.laser.range_min
    assert first_stop(trial)["object"] == "test_piece upright"


@pytest.mark.slow
def test_the_pioneer_cannot_see_the_lying_piece_and_its_contact_is_reported():
    trial = piece_trial(PIONEER3DX, 0.2, "lying")
    # The LMS100 scans at 0.35 m, over the 0.2 m piece: check says so, the run shows it.
    assert not trial.seen
    assert trial.stops == ()
    assert trial.contact
    assert [detail.split(",")[0] for kind, detail in trial.infractions if kind == "contact"] \
        == ["test_piece lying"]
    assert trial.gap < 0.01


@pytest.mark.slow
def test_a_pioneer_too_fast_for_its_blind_zone_loses_the_upright_piece_and_touches_it():
    # The field reaches the LMS100's blind zone plus Z_G (0.1 m) and no further: at
    # 0.6 m/s braking alone (0.18 m) carries the piece into the blind zone before the
    # vehicle stands; it sees nothing, drives on, and the contact is reported.
    speed = 0.6
    least, _ = stop_bounds(PIONEER3DX, speed)
    front = max(x for x, _ in PIONEER3DX.footprint)
    mount = PIONEER3DX.safety_laser
    assert field_length(PIONEER3DX, speed) - least + front - mount.x < mount.laser.range_min
    trial = piece_trial(PIONEER3DX, speed, "upright")
    assert trial.seen
    assert trial.contact, trial
    assert first_stop(trial)["object"] == "test_piece upright"
    assert ("contact", "test_piece upright") in {
        (kind, detail.split(",")[0]) for kind, detail in trial.infractions}


def test_the_trial_corridor_puts_the_piece_across_the_path():
    world = piece_corridor(LGV, 1.0, "lying")
    (piece,) = world.test_pieces
    assert piece.pose[:2] == (PIECE_X, 0.0)
    x0, y0, x1, y1 = piece.footprint().bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((0.2, 0.6))  # its 0.6 m axis across the path
    assert world.people == ()
