"""Recordings: ``run --record`` and ``tune --recording`` against full re-simulation."""

import json

import numpy as np
import pytest

from scenarios.bench.runner import run_scenario
from scenarios.logs.recording import (
    FORMAT_VERSION,
    ScanRecorder,
    motion_changes,
    read_recording,
)
from scenarios.logs.recording_replay import replay_recording
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario
from semistatic.errors import SpecError
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli

RECORDED = ["laps=2", "mapper.gate=0.12"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """pal1, 2 laps, recorded: (recording directory, the run's metrics, the run's log).

    A closed-loop run of a bundled scenario: the tests that use it are slow.
    """
    spec = load_scenario("pal1", overrides=RECORDED)
    recorder = ScanRecorder()
    log = run_scenario(spec, observers=(recorder,))
    metrics = summarize(log)
    path = tmp_path_factory.mktemp("recording") / "pal1"
    recorder.write(path, spec, metrics)
    return path, metrics, log


def mapper_results(metrics):
    return metrics["table1_cm"], metrics["detection"]


@pytest.mark.slow
def test_recording_holds_every_safety_scan_in_float64(recorded):
    path, metrics, log = recorded
    recording = read_recording(path)
    arrays = recording.arrays
    assert len(arrays["lap"]) == len(log.mapper_seconds) == metrics["performance"]["safety_scans"]
    assert arrays["ranges"].dtype == np.float64
    assert sorted(set(arrays["lap"].tolist())) == [1, 2]
    assert recording.manifest["scenario"] == "pal1"
    assert recording.manifest["format_version"] == FORMAT_VERSION


@pytest.mark.slow
def test_replay_at_other_thresholds_equals_full_resimulation(recorded):
    path, recorded_metrics, _ = recorded
    recording = read_recording(path)
    spec = load_scenario("pal1", overrides=["laps=2", "mapper.gate=0.05"])
    replayed = replay_recording(recording, spec)
    simulated = summarize(run_scenario(spec))
    assert mapper_results(replayed) == mapper_results(simulated)
    # The point differs from the recorded one, so the equality says something.
    assert replayed["table1_cm"] != recorded_metrics["table1_cm"]
    assert replayed["safety"] == simulated["safety"]


@pytest.mark.slow
def test_replay_at_the_recorded_thresholds_gives_the_recorded_metrics(recorded):
    path, metrics, _ = recorded
    replayed = replay_recording(read_recording(path), load_scenario("pal1", overrides=RECORDED))
    assert mapper_results(replayed) == mapper_results(metrics)


def test_motion_changes_name_the_field():
    base = load_scenario("pal1")
    assert motion_changes(base, load_scenario("pal1", overrides=["mapper.gate=0.3"])) == ()
    assert motion_changes(base, load_scenario("pal1", overrides=["rates.safety_hz=25"])) == (
        "rates",
    )
    adaptive = load_scenario("pal1", overrides=["policy=adaptive"])
    changed = load_scenario("pal1", overrides=["policy=adaptive", "mapper.gate=0.3"])
    assert motion_changes(adaptive, changed) == ("mapper",)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("options", "fragments"),
    [
        (["--grid", "policy=adaptive"], ["--recording: policy:", "motion"]),
        (["--grid", "noise.range=2"], ["--recording: noise:", "re-simulate"]),
        (["--grid", "mapper.gate=0.1", "--seeds", "3"], ["--recording: seed:", "seed 3"]),
        (["--grid", "mapper.gate=0.1", "--laps", "3"], ["--recording: laps", "2 laps"]),
        (["--grid", "mapper.gte=0.1"], ["--grid: mapper.gte:", "did you mean 'gate'"]),
        (["--param", "noise.range=1:2", "--trials", "2"], ["--recording: noise:", "motion"]),
        (["--param", "policy=conservative,adaptive"], ["--recording: policy:", "motion"]),
    ],
)
def test_tune_refuses_what_a_recording_cannot_replay(recorded, tmp_path, capsys, options,
                                                     fragments):
    path, _, _ = recorded
    out = tmp_path / "tune"
    out.mkdir()
    (out / "keep.txt").write_text("old")
    status, _, err = run_cli(capsys, "tune", "pal1", "--recording", path, *options,
                             "--out", out)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert (out / "keep.txt").read_text() == "old"


@pytest.mark.slow
def test_tune_refuses_another_scenario_and_other_versions(recorded, tmp_path, capsys):
    path, _, _ = recorded
    status, _, err = run_cli(capsys, "tune", "sim1", "--recording", path,
                             "--grid", "mapper.gate=0.1", "--out", tmp_path / "a")
    assert status == 2
    assert_one_error_line(err, "--recording: scenario:", "'pal1', not 'sim1'")
    old = tmp_path / "old"
    old.mkdir()
    manifest = json.loads((path / "manifest.json").read_text())
    manifest["format_version"] = FORMAT_VERSION + 1
    (old / "manifest.json").write_text(json.dumps(manifest))
    status, _, err = run_cli(capsys, "tune", "pal1", "--recording", old,
                             "--grid", "mapper.gate=0.1", "--out", tmp_path / "b")
    assert status == 2
    assert_one_error_line(err, "--recording: format_version:", "record it again")
    assert not (tmp_path / "a").exists()
    assert not (tmp_path / "b").exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scenarios", "options", "fragments"),
    [
        ("pal1,sim1", ["--param", "mapper.gate=0.1:0.2"],
         ["--recording: scenario:", "'pal1', not 'sim1'", "record sim1"]),
        ("pal1,pal1", ["--param", "mapper.gate=0.1:0.2"], ["scenario: pal1,pal1:", "twice"]),
        ("pal1,", ["--param", "mapper.gate=0.1:0.2"], ["scenario: pal1,:", "empty name"]),
        ("pal1,sim1", ["--grid", "mapper.gate=0.1"], ["scenario: pal1,sim1:", "--param"]),
    ],
)
def test_several_scenarios_need_a_search_and_a_recording_each(recorded, tmp_path, capsys,
                                                               scenarios, options, fragments):
    path, _, _ = recorded
    out = tmp_path / "tune"
    status, _, err = run_cli(capsys, "tune", scenarios, "--recording", path, *options,
                             "--out", out)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert not out.exists()


@pytest.mark.slow
def test_tune_from_a_recording_ranks_replayed_points(recorded, tmp_path, capsys):
    path, metrics, _ = recorded
    out = tmp_path / "tune"
    status, stdout, _ = run_cli(capsys, "tune", "pal1", "--recording", path, "--grid",
                                "mapper.gate=0.12,0.2", "--no-figures", "--out", out)
    assert status == 0, stdout
    sweep = json.loads((out / "sweep.json").read_text())
    first = sweep["points"][0]["metrics"]
    assert mapper_results(first) == mapper_results(metrics)
    assert first["replayed_from"] == str(path)


def test_read_recording_refuses_a_directory_without_manifest(tmp_path):
    with pytest.raises(SpecError, match="not a recording"):
        read_recording(tmp_path)


def test_run_record_refuses_an_existing_directory(tmp_path, capsys):
    existing = tmp_path / "recording"
    existing.mkdir()
    status, _, err = run_cli(capsys, "run", "pal1", "--laps", "1", "--record", existing,
                             "--out", tmp_path / "out")
    assert status == 2
    assert_one_error_line(err, "--record:", "exists already")
    assert not (tmp_path / "out").exists()
