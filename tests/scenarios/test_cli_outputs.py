"""Output directories are replaced as a whole; a lap that cannot complete is a failed run."""

from __future__ import annotations

import json

import pytest

from scenarios.process.staging import read_result_marker
from tests.scenarios.cli_helpers import run_cli
from tests.scenarios.tiny_world import TINY_SCENARIO, write_tiny


@pytest.mark.slow
def test_a_reused_output_directory_holds_only_the_newest_run(capsys, tmp_path):
    scenario = write_tiny(tmp_path)
    out = tmp_path / "out"
    # A staging directory left by a killed run (its process id no longer exists).
    stale = tmp_path / ".out.staging-999999999-abc"
    stale.mkdir()
    (stale / "metrics.json").write_text("{}")

    status, _, err = run_cli(capsys, "run", scenario, "--laps", 2, "--out", out)
    assert status == 0, err
    assert (out / "maps" / "lap_02.geojson").exists()
    assert any((out / "figures").iterdir())
    assert not stale.exists()

    status, stdout, err = run_cli(capsys, "run", scenario, "--laps", 1, "--no-figures",
                                  "--out", out)
    assert status == 0, err
    assert json.loads((out / "metrics.json").read_text())["laps"] == 1
    assert sorted(path.name for path in (out / "maps").iterdir()) == ["lap_01.geojson"]
    assert not (out / "figures").exists()
    assert read_result_marker(out)["command"] == "run"
    assert "Table 1 needs at least 2 laps" in stdout
    assert "None" not in stdout
    assert [path.name for path in tmp_path.iterdir() if path.name.startswith(".")] == []


def test_a_lap_that_times_out_fails_the_run_and_is_recorded(capsys, tmp_path):
    scenario = write_tiny(tmp_path, scenario="lap_timeout = 2.0\n" + TINY_SCENARIO)
    out = tmp_path / "out"
    status, stdout, err = run_cli(capsys, "run", scenario, "--laps", 1, "--no-figures",
                                  "--out", out)
    assert status == 1
    failure = [line for line in err.splitlines() if line.startswith("run failed")]
    assert len(failure) == 1
    assert "lap 1: did not reach the end of the path within lap_timeout = 2 s" in failure[0]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["safety"]["laps_completed"] == 0
    assert [lap["lap"] for lap in metrics["safety"]["failed_laps"]] == [1]
    assert "detection: not scored" in stdout
    assert "precision" not in stdout


@pytest.mark.slow
def test_compare_runs_every_bundled_policy_and_reports_their_safety(capsys, tmp_path):
    scenario = write_tiny(tmp_path)
    out = tmp_path / "out"
    status, stdout, err = run_cli(capsys, "run", scenario, "--laps", 1, "--compare",
                                  "--no-figures", "--out", out)
    assert status == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    compared = metrics["policy_comparison"]
    assert [p for p in ("conservative", "adaptive", "guarded") if p in compared] == [
        "conservative", "adaptive", "guarded"]
    for policy in ("conservative", "adaptive", "guarded"):
        run = compared[policy]
        total = sum(run["lap_time_s"])
        # Saved against the conservative run, by hand from the lap times written.
        base = sum(compared["conservative"]["lap_time_s"])
        assert abs(run["saved_percent"] - 100 * (base - total) / base) < 0.01
        assert set(run["min_separation_m"]) == {"person", "box", "vehicle", "test_piece"}
    assert compared["conservative"] == {
        key: metrics["safety"][key] for key in ("lap_time_s", "stops", "slowdowns",
                                                "stops_per_lap", "min_separation_m",
                                                "min_ttc_s")
    } | {"infractions": {}, "saved_percent": 0.0}
    assert compared["total_time_saved_percent"] == compared["adaptive"]["saved_percent"]
    assert "guarded fields save" in stdout
    assert "adaptive fields save" in stdout
