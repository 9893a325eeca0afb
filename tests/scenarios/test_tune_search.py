"""``semistatic tune --param``: parameters, bad input, Pareto front, resume after SIGKILL, Ray."""

import json
import re
import sqlite3
import subprocess
import sys
import threading
from types import SimpleNamespace

import optuna
import pytest

from scenarios.process.staging import write_result_marker
from scenarios.spec.load import load_scenario
from scenarios.tuning.metrics import TIMING_COLUMNS
from scenarios.tuning.params import parse_param, parse_params
from scenarios.tuning.run import PoolBackend, RayBackend
from scenarios.tuning.search import run_study
from scenarios.tuning.storage import GRACE_S, HEARTBEAT_S
from semistatic.errors import SpecError
from tests.scenarios.cli_helpers import assert_one_error_line, kill_after_line, run_cli
from tests.scenarios.tiny_world import write_tiny

KILL_AFTER = 3
TRIALS = 7
START_TIMEOUT_S = 180.0


# ------------------------------------------------------------------ parameters
@pytest.mark.parametrize(
    ("text", "distribution"),
    [
        ("mapper.gate=0.05:0.2", optuna.distributions.FloatDistribution(0.05, 0.2)),
        ("mapper.gate=0.01:0.1:log", optuna.distributions.FloatDistribution(0.01, 0.1, log=True)),
        ("mapper.outlier_k=2:6", optuna.distributions.IntDistribution(2, 6)),
        ("mapper.outlier_k=2,3,4", optuna.distributions.CategoricalDistribution((2, 3, 4))),
        ("policy=conservative,adaptive",
         optuna.distributions.CategoricalDistribution(("conservative", "adaptive"))),
    ],
)
def test_params_become_optuna_distributions(text, distribution):
    assert parse_param(text).distribution() == distribution


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("mapper.gate=0.2:0.1", "reversed range"),
        ("mapper.gate=0.1:0.1", "empty range"),
        ("mapper.gate=0:0.1:log", "log range needs LOW > 0"),
        ("mapper.gate=0.1:x", "not a number"),
        ("mapper.gate=0.1:0.2:cubic", "LOW:HIGH:log"),
        ("mapper.gate=", "KEY=LOW:HIGH"),
        ("mapper.gate=0.1,0.1", "appears twice"),
    ],
)
def test_bad_params_are_refused_with_the_key(text, fragment):
    with pytest.raises(SpecError, match=fragment) as error:
        parse_param(text)
    assert error.value.file == "--param"


def test_a_key_given_twice_is_refused():
    with pytest.raises(SpecError, match="given twice"):
        parse_params(["mapper.gate=0.1:0.2", "mapper.gate=0.3:0.4"])


def test_grid_values_cover_the_range_evenly():
    assert parse_param("mapper.gate=0.1:0.3").grid_values(3) == (0.1, 0.2, 0.3)
    assert parse_param("mapper.epsilon=0.001:0.1:log").grid_values(3) == (0.001, 0.01, 0.1)
    assert parse_param("mapper.outlier_k=1:8:log").grid_values(4) == (1, 2, 4, 8)


# ------------------------------------------------------------------ bad input, CLI
@pytest.fixture
def tiny(tmp_path):
    return write_tiny(tmp_path)


SEARCH = ["--laps", "1", "--objective", "f1", "--no-figures"]


@pytest.mark.parametrize(
    ("options", "fragments"),
    [
        (["--param", "mapper.gte=0.05:0.2"], ["--param: mapper.gte:", "did you mean 'gate'"]),
        (["--param", "mapper.gate=0.05:9"], ["--param: mapper.gate:", "<= 5.0"]),
        (["--param", "mapper.gate=0.2:0.05"], ["--param: mapper.gate:", "reversed range"]),
        (["--param", "mapper.gate=0.2:0.2"], ["--param: mapper.gate:", "empty range"]),
        (["--param", "mapper.gate=0.1:0.2", "--objective", "f2"], ["--objective: f2:"]),
        (["--param", "mapper.gate=0.1:0.2", "--sampler", "tpx"], ["--sampler: tpx:"]),
        (["--param", "mapper.gate=0.1:0.2", "--storage", "sqlite:////nonexistent/dir/s.db"],
         ["--storage: sqlite:////nonexistent/dir/s.db:", "cannot open"]),
        (["--param", "mapper.gate=0.1:0.2", "--storage", "nosuchdb://x"],
         ["--storage: nosuchdb://x:", "cannot open"]),
        (["--param", "mapper.gate=0.1:0.2", "--grid", "mapper.epsilon=0.03"], ["not both"]),
        (["--param", "mapper.gate=0.1:0.2", "--sampler", "grid", "--grid-points", "3",
          "--trials", "4"], ["--trials:", "grid's 3 points"]),
    ],
)
def test_bad_search_input_exits_2_with_one_line_and_keeps_the_results(
    tiny, tmp_path, capsys, options, fragments
):
    out = tmp_path / "out"
    out.mkdir()
    write_result_marker(out, "tune")  # an earlier result
    (out / "sweep.json").write_text("{}")
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    status, _, err = run_cli(capsys, "tune", tiny, *SEARCH, *options, "--out", out)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before


def _finished(database):
    with sqlite3.connect(database) as connection:
        return connection.execute(
            "SELECT number, state, datetime_complete FROM trials ORDER BY number"
        ).fetchall()


@pytest.mark.slow
def test_search_writes_the_pareto_front_and_refuses_another_search_on_its_study(
    tiny, tmp_path, capsys
):
    out = tmp_path / "out"
    options = ["--laps", "1", "--param", "mapper.gate=0.05:0.3", "--param",
               "mapper.outlier_k=2,3,4", "--objective", "rmse_xy_m", "--objective",
               "total_lap_time_s", "--sampler", "random", "--trials", "3", "--jobs", "2"]
    status, stdout, _ = run_cli(capsys, "tune", tiny, *options, "--out", out)
    assert status == 0, stdout
    study = json.loads((out / "study.json").read_text())
    assert len(study["trials"]) == 3
    assert (out / "figures" / "pareto.png").exists()
    assert "--set mapper.gate=" in stdout
    means = {row["trial"]: row["mean"] for row in study["trials"]}

    def dominates(a, b):
        return all(a[k] <= b[k] for k in a) and any(a[k] < b[k] for k in a)

    front = {row["trial"] for row in study["pareto_front"]}
    expected = {n for n in means if not any(dominates(means[m], means[n]) for m in means)}
    assert front == expected
    sweep = json.loads((out / "sweep.json").read_text())
    assert len(sweep["points"]) == 3
    assert all(point["metrics"] for point in sweep["points"])

    before = _finished(out / "study.db")
    status, _, err = run_cli(capsys, "tune", tiny, *options[:-6], "--trials", "3",
                             "--out", out)
    assert status == 2
    assert_one_error_line(err, "--storage: tune-tiny:", "another search")
    assert _finished(out / "study.db") == before


# ------------------------------------------------------------------ resume after SIGKILL
def _search_command(scenario, out):
    return [sys.executable, "-m", "scenarios", "tune", str(scenario), "--laps", "1",
            "--param", "mapper.gate=0.05:0.3", "--objective", "f1", "--trials", str(TRIALS),
            "--no-figures", "--out", str(out)]


@pytest.mark.slow
def test_a_search_killed_after_three_trials_resumes_without_rerunning_them(tiny, tmp_path):
    out = tmp_path / "out"
    command = _search_command(tiny, out)
    kill_after_line(command, tmp_path, f"{KILL_AFTER}/{TRIALS} trials done", START_TIMEOUT_S)
    killed = _finished(out / "study.db")
    complete_before = [row for row in killed if row[1] == "COMPLETE"]
    assert len(complete_before) >= KILL_AFTER

    resumed = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True,
                             timeout=START_TIMEOUT_S, check=False)
    assert resumed.returncode == 0, resumed.stderr
    remaining = TRIALS - len(complete_before)
    done_lines = [line for line in resumed.stderr.splitlines() if "trials done" in line]
    assert len(done_lines) == remaining
    assert done_lines[-1].startswith(f"tune tune-tiny: {remaining}/{remaining} trials done")
    after = _finished(out / "study.db")
    complete_after = [row for row in after if row[1] == "COMPLETE"]
    assert len(complete_after) == TRIALS
    # The trials finished before the kill were kept as they were, not run again.
    assert set(complete_before) <= set(complete_after)
    # A trial the kill interrupted was failed once and retried with its values.
    interrupted = [row for row in after if row[1] == "FAIL"]
    assert len(after) == TRIALS + len(interrupted)
    study = json.loads((out / "study.json").read_text())
    assert len(study["trials"]) == TRIALS
    retried = [row for row in study["trials"] if row["retried_from"] is not None]
    assert {row["retried_from"] for row in retried} == {row[0] for row in interrupted}


# ------------------------------------------------------------------ Ray against the pool
def _without_timing(metrics):
    metrics = json.loads(json.dumps(metrics))
    performance = metrics.pop("performance")
    assert performance["wall_time_s"] >= 0
    return metrics


@pytest.mark.slow
def test_ray_tasks_give_the_pool_results(tiny):
    specs = [load_scenario(tiny, overrides=["laps=1", f"mapper.gate={gate}"])
             for gate in (0.06, 0.2)]
    results = {}
    for name, backend in (("pool", PoolBackend(2)), ("ray", RayBackend(2))):
        with backend:
            for index, spec in enumerate(specs):
                backend.submit(index, [spec], None)
            done = []
            while len(done) < len(specs):
                done += backend.finished(timeout=1.0)
        results[name] = {key: [_without_timing(m) for m, _ in outcomes]
                         for key, outcomes in done}
    assert results["ray"] == results["pool"]
    assert TIMING_COLUMNS == ("wall_time_s",)


# ------------------------------------------------------------------ robust thresholds
@pytest.mark.slow
def test_a_trial_spans_every_recorded_scenario_and_ranks_by_mean_and_worst_case(
    tmp_path, capsys
):
    from scenarios.bench.runner import run_scenario
    from scenarios.logs.recording import ScanRecorder
    from scenarios.results.outputs import summarize
    from tests.scenarios.tiny_world import TINY_SCENARIO

    first = write_tiny(tmp_path)
    second = tmp_path / "noisy.toml"  # the same world and seed, three times the range noise
    second.write_text(TINY_SCENARIO + "\n[noise]\nrange = 3.0\n")
    recordings = []
    for scenario in (first, second):
        spec = load_scenario(scenario, overrides=["laps=1"])
        recorder = ScanRecorder()
        metrics = summarize(run_scenario(spec, observers=(recorder,)))
        recordings += ["--recording", tmp_path / f"rec-{spec.name}"]
        recorder.write(recordings[-1], spec, metrics)
    out = tmp_path / "out"
    status, stdout, _ = run_cli(
        capsys, "tune", f"{first},{second}", *recordings, "--param", "mapper.epsilon=0.01:0.06",
        "--objective", "rmse_xy_m", "--sampler", "random",
        "--trials", "3", "--no-figures", "--out", out,
    )
    assert status == 0, stdout
    study = json.loads((out / "study.json").read_text())
    sweep = json.loads((out / "sweep.json").read_text())
    # Every trial ran both scenarios (replayed: the recorded seed 3 of each).
    assert [point["scenario"] for point in sweep["points"]] == ["tiny", "noisy"] * 3
    assert all(point["metrics"]["replayed_from"] for point in sweep["points"])
    for row in study["trials"]:
        assert row["runs"] == ["tiny seed=3", "noisy seed=3"]
        assert row["seeds"] == [3, 3]
    # Mean, worst case and spread over the two runs, from the runs' own metrics.
    values = [point["rmse_xy_m"] for point in sweep["points"]]
    pairs = [values[k:k + 2] for k in range(0, len(values), 2)]
    for row, (a, b) in zip(study["trials"], pairs, strict=True):
        assert a != b  # the noisier scenario localises differently
        assert row["mean"]["rmse_xy_m"] == pytest.approx((a + b) / 2, abs=1e-6)  # 6 decimals
        assert row["worst"]["rmse_xy_m"] == max(a, b)
        assert row["spread"]["rmse_xy_m"] == pytest.approx(abs(a - b), abs=1e-6)
    worst = [row["worst"]["rmse_xy_m"] for row in study["trials"]]
    ranked = {row["trial"]: row["worst"]["rmse_xy_m"] for row in study["trials"]}
    assert [ranked[n] for n in study["ranking_by_worst"]] == sorted(worst)
    assert re.search(r"rmse_xy_m mean +worst +spread", stdout), stdout
    assert "mean over 2 run(s): tiny seed=3, noisy seed=3" in stdout


class _Square:
    """A search of one key, objective x squared (the protocol ``run_study`` takes)."""

    trials = 3
    objectives = ("value",)

    def distributions(self):
        return {"x": optuna.distributions.FloatDistribution(0.0, 1.0)}

    def points(self, values):
        return [SimpleNamespace(spec=values["x"], seed=0, run="square")]

    def objective_values(self, metrics):
        return {"mean": {"value": metrics[0]["value"]}}


class _AtOnce:
    """A backend that runs each point as it is submitted."""

    capacity = 1

    def __init__(self):
        self.done = []

    def submit(self, key, specs, recordings):
        self.done.append((key, [({"value": spec * spec}, None) for spec in specs]))

    def finished(self, timeout):
        done, self.done = self.done, []
        return done


def test_a_trial_left_running_without_a_heartbeat_is_retried_not_waited_for(tmp_path):
    # A driver killed between asking a trial and its first heartbeat leaves it RUNNING
    # with no heartbeat; Optuna never takes such a trial for stale on its own.
    url = f"sqlite:///{tmp_path / 'study.db'}"
    storage = optuna.storages.RDBStorage(
        url, heartbeat_interval=HEARTBEAT_S, grace_period=GRACE_S,
        heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback())
    study = optuna.create_study(storage=storage, sampler=optuna.samplers.RandomSampler(seed=1))
    orphan = study.ask({"x": optuna.distributions.FloatDistribution(0.0, 1.0)})
    # In a daemon thread, so that a search that waits for the orphan forever fails the
    # test (after ten times the grace period) instead of hanging the suite.
    ran = []
    search = threading.Thread(daemon=True, target=lambda: ran.append(
        run_study(study, storage, _Square(), _AtOnce())))
    search.start()
    search.join(timeout=10 * GRACE_S)
    assert ran == [3], "the search waited for the orphaned trial"
    states = [trial.state for trial in study.get_trials()]
    assert states.count(optuna.trial.TrialState.COMPLETE) == 3
    assert study.get_trials()[orphan.number].state == optuna.trial.TrialState.FAIL
    retried = [trial for trial in study.get_trials()
               if trial.system_attrs.get("failed_trial") == orphan.number]
    assert [trial.params for trial in retried] == [orphan.params]
