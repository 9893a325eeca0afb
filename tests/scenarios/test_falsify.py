"""semistatic falsify: objectives, coverage, samplers, bad input, replay and resume."""

import hashlib
import json
import subprocess
import sys

import numpy as np
import optuna
import pyarrow.parquet as pq
import pytest

from scenarios.campaign.table import flatten_metrics
from scenarios.campaign.variations import parse_variations
from scenarios.cli import main
from scenarios.falsify.objectives import Objective, parse_objectives
from scenarios.falsify.report import bin_edges, bin_of, coverage
from scenarios.falsify.search import SAMPLERS, FalsifyConfig
from semistatic.errors import SpecError
from tests.scenarios.cli_helpers import assert_one_error_line, kill_after_line, run_cli
from tests.scenarios.tiny_world import write_crossing, write_tiny

START_TIMEOUT_S = 240.0
BOX_X = "world.boxes.carton.pose[0]=uniform(1.5, 3.0)"
SLOWDOWN = "safety.slowdown=uniform(0.3, 1.0)"


@pytest.fixture
def tiny(tmp_path):
    return write_tiny(tmp_path)


def _search(tiny, out, *extra):
    return ["falsify", str(tiny), "--laps", "1", "--vary", BOX_X, "--vary", SLOWDOWN,
            "--objective", "safety.min_separation_m.box", "--no-figures", "--out", str(out),
            *map(str, extra)]


# ------------------------------------------------------------------ objectives and coverage
def test_a_separation_is_violated_at_contact_and_a_count_at_its_threshold():
    separation = parse_objectives([], [])[0]
    assert separation.metric == "safety.min_separation_m.person"
    assert [separation.violated(v) for v in (0.0, 1e-4, None)] == [True, False, False]
    collisions = parse_objectives(["safety.collisions"], [])[0]
    assert collisions.direction == "maximize"
    assert [collisions.violated(v) for v in (0, 1, 3)] == [False, True, True]
    ttc = parse_objectives(["safety.min_ttc_s"], [0.5])[0]
    assert ttc.violated(0.5)
    assert not ttc.violated(0.51)


def test_an_objective_reads_its_column_of_the_flattened_metrics():
    metrics = {"safety": {"min_separation_m": {"person": 0.31, "box": None}}}
    assert Objective("safety.min_separation_m.person", "higher", 0.0).value(metrics) == 0.31
    assert Objective("safety.min_separation_m.box", "higher", 0.0).value(metrics) is None


def test_bins_split_a_range_evenly_and_the_upper_end_falls_in_the_last():
    edges = bin_edges((0.3, 3.0), 3)
    np.testing.assert_allclose(edges, [0.3, 1.2, 2.1, 3.0])
    assert [bin_of(v, edges) for v in (0.3, 1.19, 1.2, 2.99, 3.0)] == [0, 0, 1, 2, 2]


def test_coverage_counts_samples_and_violations_per_bin_and_cell():
    config = FalsifyConfig("pal1", "adaptive", parse_variations(
        ["mapper.gate=uniform(0, 1)", "policy=choice(adaptive, guarded)"]),
        parse_objectives([], []), budget=4, seed=0)
    rows = [{"status": "ok", "vary.mapper.gate": g, "vary.policy": p, "violation": v}
            for g, p, v in ((0.1, "adaptive", True), (0.2, "adaptive", False),
                            (0.9, "guarded", True), (0.95, "guarded", True))]
    rows.append({"status": "rejected", "vary.mapper.gate": 0.5, "vary.policy": "guarded",
                 "violation": None})
    cover = coverage(rows, config, 2, ["mapper.gate", "policy"])
    gate = cover["keys"]["mapper.gate"]
    assert gate["samples"] == [2, 2]
    assert gate["violation_rate"] == [0.5, 1.0]
    assert cover["keys"]["policy"]["bins"] == ["adaptive", "guarded"]
    assert (cover["cells"], cover["cells_sampled"]) == (4, 2)
    # rows: policy bins, columns: gate bins (the failure-region grid)
    assert cover["pair"]["samples"] == [[2, 0], [0, 2]]
    assert cover["pair"]["violation_rate"] == [[0.5, None], [None, 1.0]]


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_every_sampler_stays_in_the_box_and_repeats_with_its_seed(sampler):
    variations = parse_variations(["mapper.gate=uniform(0.05, 0.2)",
                                   "mapper.epsilon=uniform(0.01, 0.05)"])

    def proposals():
        config = FalsifyConfig("pal1", "adaptive", variations, parse_objectives([], []),
                               budget=12, seed=0, sampler=sampler, sampler_seed=3)
        study = optuna.create_study(sampler=config.sampler_object(),
                                    directions=config.directions())
        drawn = []
        for _ in range(12):
            trial = study.ask(config.distributions())
            gate, epsilon = trial.params["mapper.gate"], trial.params["mapper.epsilon"]
            drawn.append((gate, epsilon))
            study.tell(trial, [(gate - 0.12) ** 2 + (epsilon - 0.02) ** 2])
        return drawn

    first = proposals()
    assert first == proposals()
    gates, epsilons = np.array(first).T
    assert np.all((gates >= 0.05) & (gates <= 0.2))
    assert np.all((epsilons >= 0.01) & (epsilons <= 0.05))
    assert len(set(first)) == len(first)


def test_a_low_discrepancy_sampler_covers_the_box_more_evenly_than_random_draws():
    # Star discrepancy of 64 points in the unit square (scipy's, an independent measure).
    from scipy.stats import qmc

    def points(sampler):
        config = FalsifyConfig("pal1", "adaptive", parse_variations(
            ["mapper.gate=uniform(0, 1)", "mapper.epsilon=uniform(0, 1)"]),
            parse_objectives([], []), budget=64, seed=0, sampler=sampler)
        study = optuna.create_study(sampler=config.sampler_object())
        drawn = []
        for _ in range(64):
            trial = study.ask(config.distributions())
            drawn.append([trial.params["mapper.gate"], trial.params["mapper.epsilon"]])
            study.tell(trial, 0.0)
        return np.array(drawn)

    random = qmc.discrepancy(points("random"))
    assert qmc.discrepancy(points("halton")) < random / 2
    assert qmc.discrepancy(points("sobol")) < random / 2


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(("arguments", "fragments"), [
    (["--vary", "world.boxes.cartn.pose[1]=uniform(-1, -0.6)"],
     ["--vary:", "no box 'cartn'", "carton"]),
    (["--vary", "safety.slowdwn=uniform(0.3, 1.0)"], ["--vary:", "slowdwn", "slowdown"]),
    (["--vary", "safety.slowdown=uniform(1.0, 0.3)"], ["--vary:", "reversed range"]),
    (["--vary", SLOWDOWN, "--objective", "safety.min_separation"],
     ["--objective:", "not a metric"]),
    (["--vary", SLOWDOWN, "--threshold", "-0.1"], ["--threshold:", "never be reached"]),
    (["--vary", SLOWDOWN, "--sampler", "anneal"], ["--sampler:", "unknown sampler"]),
    (["--vary", "safety.slowdown=normal(0.5, 0.1)"], ["--vary:", "explores a box"]),
    ([], ["--vary:", "nothing to search"]),
])
def test_bad_input_exits_2_with_one_line_and_leaves_an_existing_study_alone(
        tiny, tmp_path, capsys, arguments, fragments):
    out = tmp_path / "search"
    out.mkdir()
    (out / "study.db").write_bytes(b"the study of an earlier search")
    (out / "falsify.json").write_text('{"kind": "falsify", "definition": {}}')
    before = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in out.iterdir()}
    status, _, err = run_cli(capsys, "falsify", tiny, "--laps", "1", "--out", out, *arguments)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in out.iterdir()} == before


def test_a_cmaes_pareto_search_is_refused():
    with pytest.raises(SpecError, match="CMA-ES searches one objective"):
        FalsifyConfig("pal1", "adaptive", (), parse_objectives(
            ["safety.min_separation_m.person", "safety.collisions"], []),
            budget=2, seed=0, sampler="cmaes")


# ------------------------------------------------------------------ searches that run
COUNTEREXAMPLES = 20


@pytest.mark.slow
def test_twenty_counterexamples_replay_with_identical_metrics(tiny, tmp_path, capsys):
    out = tmp_path / "search"
    status, _stdout, err = run_cli(capsys, *_search(tiny, out, "--budget", COUNTEREXAMPLES,
                                                   "--k-worst", COUNTEREXAMPLES,
                                                   "--sampler", "halton", "--jobs", "2"))
    assert status == 0, err
    summary = json.loads((out / "summary.json").read_text())
    files = [entry["file"] for entry in summary["counterexamples"]]
    assert len(files) == COUNTEREXAMPLES
    rows = {row["sample"]: row for row in pq.read_table(out / "runs.parquet").to_pylist()}
    assert len(rows) == COUNTEREXAMPLES
    assert all(row["status"] == "ok" for row in rows.values())
    for entry in summary["counterexamples"]:
        replay = tmp_path / f"replay-{entry['sample']}"
        assert main(["run", str(out / entry["file"]), "--out", str(replay)]) == 0
        capsys.readouterr()
        replayed = flatten_metrics(json.loads((replay / "metrics.json").read_text()))
        sampled = rows[entry["sample"]]
        compared = [key for key in replayed if not key.startswith("performance.")]
        assert len(compared) > 40
        assert {k: replayed[k] for k in compared} == {k: sampled[k] for k in compared}, entry
        assert entry["objectives"]["safety.min_separation_m.box"] == \
            replayed["safety.min_separation_m.box"]


KILL_AFTER = 4
BUDGET = 10


@pytest.mark.slow
def test_a_search_killed_mid_way_resumes_losing_and_repeating_no_sample(tiny, tmp_path):
    out = tmp_path / "search"
    command = [sys.executable, "-m", "scenarios", *_search(tiny, out, "--budget", BUDGET,
                                                          "--sampler", "random", "--jobs", "2")]
    kill_after_line(command, tmp_path, f"{KILL_AFTER}/{BUDGET} samples done", START_TIMEOUT_S)
    storage = f"sqlite:///{out / 'study.db'}"
    [name] = optuna.study.get_all_study_names(storage)
    done = optuna.load_study(study_name=name, storage=storage).get_trials(
        states=[optuna.trial.TrialState.COMPLETE])
    before = {trial.number: (trial.params, trial.values) for trial in done}
    assert KILL_AFTER <= len(before) < BUDGET

    resumed = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True,
                             timeout=START_TIMEOUT_S, check=False)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(before)} samples finished earlier" in resumed.stdout
    rows = pq.read_table(out / "runs.parquet").to_pylist()
    assert len(rows) == BUDGET
    drawn = [(row["vary.world.boxes.carton.pose[0]"], row["vary.safety.slowdown"])
             for row in rows]
    assert len(set(drawn)) == BUDGET  # no sample twice
    by_number = {row["sample"]: row for row in rows}
    for number, (params, values) in before.items():  # every earlier sample kept as it was
        row = by_number[number]
        assert row["vary.safety.slowdown"] == params["safety.slowdown"]
        assert row["objective.safety.min_separation_m.box"] == values[0]


# ------------------------------------------------------------------ warm starts
CROSSER = ["world.people.crosser.trigger_distance=uniform(0.5, 3.0)",
           "world.people.crosser.speed=uniform(0.5, 1.5)"]


def test_a_search_of_the_last_laps_people_starts_warm_and_nothing_else_does(tmp_path):
    scenario = str(write_crossing(tmp_path))

    def lap(*texts):
        return FalsifyConfig(scenario, "conservative", parse_variations(texts),
                             parse_objectives([], []), budget=1, seed=3).warm_lap()

    assert lap(*CROSSER) == 3
    assert lap(CROSSER[0], "world.boxes.carton.pose[0]=uniform(2.4, 2.8)") is None
    assert lap("world.people.crosser.radius=uniform(0.15, 0.25)") is None
    assert lap("safety.slowdown=uniform(0.3, 0.6)") is None


@pytest.mark.slow
def test_a_warm_started_search_gives_the_samples_of_full_runs(tmp_path, capsys):
    scenario = write_crossing(tmp_path)
    tables = {}
    for mode in ("warm", "full"):
        arguments = ["falsify", scenario, "--budget", 6, "--jobs", 2, "--sampler", "halton",
                     "--no-figures", "--out", tmp_path / mode,
                     *(a for text in CROSSER for a in ("--vary", text))]
        status, out, err = run_cli(capsys, *arguments, *(["--no-warm-start"] if mode == "full"
                                                          else []))
        assert status == 0, err
        assert ("warm start" in out) == (mode == "warm")
        table = pq.read_table(tmp_path / mode / "runs.parquet")
        timing = [name for name in table.column_names if name.startswith("performance.")]
        tables[mode] = table.drop(timing).to_pylist()
    assert len(tables["warm"]) == 6
    assert tables["warm"] == tables["full"]
    assert any(row["safety.stops"] for row in tables["warm"])  # the crosser made it stop
