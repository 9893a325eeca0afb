"""``semistatic campaign``: variations drawn and checked, runs tabulated, resumed after a kill."""

import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from scenarios.campaign.journal import read_journal
from scenarios.campaign.plan import check_campaign, plan_campaign
from scenarios.campaign.table import flatten_metrics, read_campaign
from scenarios.campaign.variations import draw_samples, parse_variation, parse_variations
from scenarios.process.staging import write_result_marker
from semistatic.errors import SpecError
from tests.scenarios.cli_helpers import assert_one_error_line, kill_after_line, run_cli
from tests.scenarios.tiny_world import write_tiny

START_TIMEOUT_S = 240.0


@pytest.fixture
def tiny(tmp_path):
    return write_tiny(tmp_path)


# ------------------------------------------------------------------ variations
def test_uniform_draws_stay_in_their_range_and_repeat_with_the_seed():
    variation = parse_variation("mapper.gate=uniform(0.1, 0.3)")
    draws = [s["mapper.gate"] for s in draw_samples([variation], 2000, seed=7)]
    assert min(draws) >= 0.1
    assert max(draws) < 0.3
    # mean of U(0.1, 0.3) is 0.2, its standard error over 2000 draws 0.0013
    assert np.mean(draws) == pytest.approx(0.2, abs=0.006)
    assert draw_samples([variation], 5, seed=7) == draw_samples([variation], 5, seed=7)
    assert draw_samples([variation], 5, seed=7) != draw_samples([variation], 5, seed=8)


def test_normal_and_choice_draws_follow_their_distribution():
    normal, choice = parse_variations(["noise.range=normal(1.0, 0.2)",
                                       "policy=choice(adaptive, guarded)"])
    samples = draw_samples([normal, choice], 4000, seed=1)
    values = np.array([s["noise.range"] for s in samples])
    assert values.mean() == pytest.approx(1.0, abs=0.02)
    assert values.std() == pytest.approx(0.2, abs=0.01)
    picked = [s["policy"] for s in samples]
    assert set(picked) == {"adaptive", "guarded"}
    assert picked.count("adaptive") / len(picked) == pytest.approx(0.5, abs=0.03)


@pytest.mark.parametrize(("text", "fragment"), [
    ("mapper.gate=uniform(0.3, 0.1)", "reversed range"),
    ("mapper.gate=uniform(0.1, 0.1)", "empty range"),
    ("mapper.gate=normal(0.1, 0)", "standard deviation must be > 0"),
    ("mapper.gate=choice()", "choice() is empty"),
    ("mapper.gate=unifrom(0.1, 0.2)", "did you mean 'uniform'"),
    ("mapper.gate=0.1", "write KEY=uniform(LOW, HIGH)"),
    ("seed=uniform(0, 9)", "use --seeds"),
    ("world.boxes.crate=uniform(0, 1)", "world.boxes.NAME.FIELD"),
    ("world.walls.a.x=uniform(0, 1)", "world.boxes.NAME.FIELD"),
])
def test_malformed_variations_are_refused(text, fragment):
    with pytest.raises(SpecError, match="--vary") as raised:
        parse_variation(text)
    assert fragment in str(raised.value)


@pytest.mark.parametrize(("text", "fragment"), [
    ("mapper.gte=uniform(0.1, 0.2)", "did you mean 'gate'"),
    ("mapper.gate=uniform(-0.1, 0.2)", "mapper.gate: must be > 0"),
    ("world.boxes.crate.pose[0]=uniform(1, 2)", "no box 'crate'"),
    ("world.boxes.carton.psoe[0]=uniform(1, 2)", "did you mean 'pose'"),
    ("world.boxes.carton.pose[3]=uniform(1, 2)", "no element [3]"),
    ("world.boxes.carton.size[0]=uniform(-1, 2)", "size"),
])
def test_variations_the_scenario_cannot_take_are_refused_before_any_run(tiny, text, fragment):
    with pytest.raises(SpecError, match="--vary") as raised:
        check_campaign([str(tiny)], ["conservative"], [parse_variation(text)])
    assert fragment in str(raised.value)


def test_a_box_pushed_into_a_wall_rejects_its_sample_and_the_others_run(tiny, tmp_path):
    # The corridor's wall is at y = -1.5 and the carton 0.4 m deep: y <= -1.3 touches it.
    variation = parse_variation("world.boxes.carton.pose[1]=choice(-1.0, -1.45)")
    samples = [{variation.key: -1.0}, {variation.key: -1.45}]
    runs = plan_campaign([str(tiny)], ["conservative"], [0, 1], [variation], samples,
                         worlds_dir=tmp_path / "worlds")
    assert [run.status for run in runs] == ["ok", "ok", "rejected", "rejected"]
    assert "overlaps walls[0]" in runs[2].reason
    assert runs[2].reason.startswith("worlds/tiny_world-")
    # The run's world is a plain world file with the drawn pose: `semistatic run` repeats it.
    world = runs[0].spec.world
    with open(world) as text:
        assert "pose = [2.6, -1.0, 0.0]" in text.read()


def test_flattened_metrics_count_infractions_by_kind_and_keep_scalars():
    metrics = {"scenario": "s", "seed": 1,
               "safety": {"collisions": 2, "min_separation_m": {"person": None, "box": 0.3},
                          "infractions": [{"kind": "contact"}, {"kind": "contact"},
                                          {"kind": "near_miss"}],
                          "protective_stops": [{"speed": 1.0}], "lap_time_s": [3.0, 4.0]}}
    flat = flatten_metrics(metrics)
    assert flat == {
        "safety.collisions": 2, "safety.min_separation_m.person": None,
        "safety.min_separation_m.box": 0.3, "safety.infractions.contact": 2,
        "safety.infractions.near_miss": 1,
        "safety.infractions.person_in_protective_while_moving": 0,
        "safety.infractions.unnecessary_stop": 0, "safety.protective_stops.count": 1,
    }


# ------------------------------------------------------------------ the command
@pytest.mark.parametrize(("option", "fragment"), [
    (["--vary", "mapper.gte=uniform(0.1, 0.2)"], "--vary: mapper.gte: unknown key"),
    (["--vary", "mapper.gate=uniform(0.2, 0.2)"], "--vary: mapper.gate: empty range"),
    (["--seeds", "5:2"], "--seeds: seed: reversed range 5:2"),
    (["--policy", "fastest"], "--policy: policy:"),
    (["--samples", "3"], "--samples: samples: nothing to sample"),
    (["--jobs", "0"], "--jobs: jobs: must be >= 1"),
])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(tiny, tmp_path, capsys, option,
                                                            fragment):
    out = tmp_path / "campaign"
    status, _stdout, err = run_cli(capsys, "campaign", tiny, "--seeds", "0:1", *option,
                                  "--out", out)
    assert status == 2
    assert_one_error_line(err, fragment)
    assert not out.exists()


def test_another_campaign_in_the_out_directory_is_refused(tiny, tmp_path, capsys):
    out = tmp_path / "campaign"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps({"kind": "semistatic-campaign",
                                                   "definition": {"seeds": [7]}}))
    # A manifest without our marker is a file of the user's, however it reads.
    status, _, err = run_cli(capsys, "campaign", tiny, "--seeds", "0:1", "--out", out)
    assert status == 2
    assert_one_error_line(err, "holds files of yours")
    write_result_marker(out, "campaign")
    status, _, err = run_cli(capsys, "campaign", tiny, "--seeds", "0:1", "--out", out)
    assert status == 2
    assert_one_error_line(err, "holds another campaign")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.md").write_text("my notes")
    status, _, err = run_cli(capsys, "campaign", tiny, "--out", tmp_path / "mine")
    assert status == 2
    assert_one_error_line(err, "holds files of yours")
    assert (tmp_path / "mine" / "notes.md").read_text() == "my notes"


@pytest.mark.slow
def test_a_campaign_tabulates_every_run_with_statistics(tiny, tmp_path, capsys):
    out = tmp_path / "campaign"
    status, stdout, _ = run_cli(
        capsys, "campaign", tiny, "--seeds", "0:2", "--policy", "conservative,adaptive",
        "--vary", "world.boxes.carton.pose[1]=choice(-1.0, -1.45)", "--samples", "2",
        "--variation-seed", "3", "--laps", "2", "--jobs", "2", "--out", out)
    assert status == 0
    result = read_campaign(out)
    rows = result.rows
    assert len(rows) == 2 * 2 * 3
    assert {row["run"] for row in rows} == set(result.manifest["runs"])
    by_status = {kind: [r for r in rows if r["status"] == kind] for kind in ("ok", "rejected")}
    assert len(by_status["ok"]) + len(by_status["rejected"]) == len(rows)
    for row in by_status["ok"]:
        assert row["vary.world.boxes.carton.pose[1]"] == -1.0
        assert row["detection.f1"] is not None
        assert row["reason"] is None
    for row in by_status["rejected"]:
        assert row["vary.world.boxes.carton.pose[1]"] == -1.45
        assert "overlaps" in row["reason"]
        assert row["detection.f1"] is None
    # The statistics are those of the table's own numbers (an independent recomputation).
    summary = json.loads((out / "summary.json").read_text())
    for group in summary["groups"]:
        values = [r["safety.total_time_s"] for r in by_status["ok"]
                  if (r["scenario"], r["policy"]) == (group["scenario"], group["policy"])]
        if values:
            figure = group["metrics"]["safety.total_time_s"]
            assert figure["mean"] == pytest.approx(np.mean(values))
            assert figure["max"] == pytest.approx(max(values))
            low, high = figure["ci95"]
            assert low - 1e-9 <= figure["mean"] <= high + 1e-9
    assert (out / "figures" / "campaign_distributions.png").stat().st_size > 10_000
    # The same command again runs nothing and writes the same table.
    before = pq.read_table(out / "runs.parquet")
    status, stdout, _ = run_cli(
        capsys, "campaign", tiny, "--seeds", "0:2", "--policy", "conservative,adaptive",
        "--vary", "world.boxes.carton.pose[1]=choice(-1.0, -1.45)", "--samples", "2",
        "--variation-seed", "3", "--laps", "2", "--jobs", "2", "--out", out)
    assert status == 0
    assert f"{len(by_status['ok'])} runs finished earlier" in stdout
    after = pq.read_table(out / "runs.parquet")
    assert after.drop(["performance.wall_time_s"]).equals(before.drop(["performance.wall_time_s"]))


# ------------------------------------------------------------------ SIGKILL, then resume
KILL_AFTER = 10
RUNS = 14


@pytest.mark.slow
def test_a_campaign_killed_after_ten_runs_resumes_with_every_run_exactly_once(tiny, tmp_path):
    out = tmp_path / "campaign"
    command = [sys.executable, "-m", "scenarios", "campaign", str(tiny), "--laps", "1",
               "--seeds", f"0:{RUNS - 1}", "--jobs", "2", "--no-figures", "--out", str(out)]
    kill_after_line(command, tmp_path, f"{KILL_AFTER}/{RUNS} runs done", START_TIMEOUT_S)
    before = read_journal(out / "runs.jsonl")
    assert KILL_AFTER <= len(before) < RUNS
    assert not (out / "runs.parquet").exists()

    resumed = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True,
                             timeout=START_TIMEOUT_S, check=False)
    assert resumed.returncode == 0, resumed.stderr
    remaining = RUNS - len(before)
    assert f"{len(before)} runs finished earlier" in resumed.stdout
    done_lines = [line for line in resumed.stderr.splitlines() if "runs done" in line]
    assert len(done_lines) == remaining
    lines = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()
             if line.strip()]
    recorded = [line["run"] for line in lines]
    assert len(recorded) == len(set(recorded)) == RUNS
    table = pq.read_table(out / "runs.parquet").to_pylist()
    assert sorted(row["seed"] for row in table) == list(range(RUNS))
    # The runs finished before the kill are kept as they were.
    for row in table:
        if row["run"] in before:
            assert row["detection.f1"] == before[row["run"]][0]["detection"]["f1"]


# ------------------------------------------------------------------ unreadable campaigns
@pytest.mark.parametrize(("manifest", "parquet", "fragment"), [
    ('{"kind": "semistatic-campaign", "format": 1}', b"PAR1 not a parquet file",
     "runs.parquet: unreadable"),
    ("{not json", None, "manifest.json: unreadable"),
    ('{"kind": "semistatic-sweep"}', None, "not the manifest of a campaign"),
    (None, None, "manifest.json: missing"),
])
def test_an_unreadable_baseline_exits_2_with_one_line_and_writes_nothing(
        tmp_path, capsys, manifest, parquet, fragment):
    baseline = tmp_path / "baseline"
    baseline.mkdir()
    if manifest is not None:
        (baseline / "manifest.json").write_text(manifest)
    (baseline / "runs.parquet").write_bytes(parquet or b"")
    junit = tmp_path / "compare.xml"
    status, out, err = run_cli(capsys, "compare", baseline, tmp_path, "--junit", junit)
    assert status == 2
    assert out == ""
    assert_one_error_line(err, "BASELINE", fragment)
    assert not junit.exists()
