"""``semistatic tune``: grid expansion, validation before any run, and real sweeps."""

import csv
import io
import json
import math

import pytest

from scenarios.cli import main
from scenarios.spec.load import load_scenario
from scenarios.tuning.metrics import METRICS, NEES_TARGET, TIMING_COLUMNS
from scenarios.tuning.points import MAX_POINTS, parse_grid, parse_grids, parse_seeds, sweep_points
from scenarios.tuning.run import PointResult, run_sweep
from scenarios.tuning.table import combine_seeds, format_ranking, rank, sweep_row, write_sweep
from semistatic.errors import SpecError
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import write_tiny

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
GATES = (0.08, 0.16)


def without_timing(row):
    return {key: value for key, value in row.items() if key not in TIMING_COLUMNS}


def without_performance(metrics):
    return {key: value for key, value in metrics.items() if key != "performance"}


# --------------------------------------------------------------------------------------
# Parsing and expansion


def test_grid_values_are_toml_typed_and_split_only_at_top_level_commas():
    assert parse_grid("mapper.miss_limit=3,5") == ("mapper.miss_limit", (3, 5))
    assert parse_grid("policy=conservative, adaptive") == ("policy", ("conservative", "adaptive"))
    assert parse_grid('people=["walker", "a,b"],[]') == ("people", (["walker", "a,b"], []))
    assert parse_grid("mapper.max_range=inf,8.0")[1] == (math.inf, 8.0)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("mapper.gate", "expected KEY=V1,V2"),
        ("=0.1,0.2", "expected KEY=V1,V2"),
        ("mapper.gate=", "empty grid"),
        ("mapper.gate=0.1,,0.2", "empty value"),
        ("mapper.gate=0.1,0.2,0.1", "appears twice"),
        ("seed=1,2", "--seeds"),
    ],
)
def test_bad_grid_text_is_refused(text, fragment):
    with pytest.raises(SpecError, match=fragment) as caught:
        parse_grid(text)
    assert caught.value.file == "--grid"


def test_a_key_in_two_grids_and_bad_seeds_are_refused():
    with pytest.raises(SpecError, match="given twice"):
        parse_grids(["mapper.gate=0.1", "mapper.gate=0.2"])
    for text in ("0,-1", "0,0", "", "1.5"):
        with pytest.raises(SpecError) as caught:
            parse_seeds(text)
        assert caught.value.file == "--seeds"


def test_points_are_the_cartesian_product_with_seeds_innermost():
    grids = {"mapper.gate": (0.1, 0.2), "policy": ("conservative", "adaptive")}
    points = sweep_points("sim1", grids, seeds=(5, 6), laps=2, overrides=["mapper.epsilon=0.04"])
    assert len(points) == 8
    assert [p.index for p in points] == list(range(8))
    expected = [(g, pol, s) for g in (0.1, 0.2) for pol in ("conservative", "adaptive")
                for s in (5, 6)]
    got = [(p.spec.mapper.gate, p.spec.policy, p.spec.seed) for p in points]
    assert got == expected
    assert all(p.spec.laps == 2 and p.spec.mapper.epsilon == 0.04 for p in points)
    assert dict(points[3].settings) == {"mapper.gate": 0.1, "policy": "adaptive"}
    assert points[3].label == "mapper.gate=0.1 policy=adaptive seed=6"
    for point in points:  # the same specs as the loader builds them one by one
        overrides = ["mapper.epsilon=0.04", "laps=2", f"mapper.gate={point.spec.mapper.gate}",
                     f"policy={point.spec.policy}", f"seed={point.seed}"]
        assert point.spec == load_scenario("sim1", overrides=overrides)


def test_every_distinct_layout_is_checked_not_only_the_first():
    # The second point changes the layout (who walks): its check must still run.
    with pytest.raises(SpecError, match="no person named 'ghost'") as caught:
        sweep_points("pal3b", {"people": ([], ["ghost"])})
    assert (caught.value.file, caught.value.key) == ("--grid", "people[0]")


def test_without_seeds_every_point_keeps_the_file_seed(tmp_path):
    scenario = write_tiny(tmp_path)
    points = sweep_points(scenario, {"mapper.gate": GATES})
    assert [p.seed for p in points] == [3, 3]
    assert [p.spec.laps for p in points] == [2, 2]


def test_too_many_points_are_refused_before_any_scenario_loads():
    many = {"mapper.gate": [0.05 + 0.01 * i for i in range(17)],
            "mapper.epsilon": [0.01 + 0.002 * i for i in range(16)]}
    with pytest.raises(SpecError, match=f"272 points .* exceed the limit of {MAX_POINTS}"):
        # The scenario does not exist: the cap must fire first, without loading anything.
        sweep_points("no/such/scenario.toml", many)
    with pytest.raises(SpecError, match="4 points"):
        sweep_points("sim1", {"mapper.gate": (0.1, 0.2)}, seeds=(0, 1), max_points=3)


# --------------------------------------------------------------------------------------
# The command line refuses bad input: exit 2, one line, nothing written


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--grid", "mapper.gte=0.1,0.2"], ["--grid", "mapper.gte", "did you mean 'gate'"]),
        (["--grid", "polcy=adaptive"], ["--grid", "polcy", "did you mean 'policy'"]),
        (["--grid", "mapper.gate="], ["--grid", "mapper.gate", "empty grid"]),
        (["--grid", "mapper.gate=0.1,,0.2"], ["--grid", "empty value"]),
        (["--grid", "mapper.gate=0.1", "--grid", "mapper.gate=0.2"], ["given twice"]),
        (["--grid", "mapper.gate=0.1,0.1"], ["appears twice"]),
        # The bad value is the second point's: every point is validated before a run.
        (["--grid", "mapper.gate=0.1,-0.1"], ["--grid", "mapper.gate", "must be > 0"]),
        (["--grid", "policy=conservative,greedy"], ["--grid", "policy", "conservative"]),
        (["--grid", "mapper.gate=0.1", "--set", "mapper.gate=0.2"], ["also given as --set"]),
        (["--grid", "mapper.gate=0.1", "--set", "mapper.gte=0.2"], ["--set", "'gate'"]),
        (["--grid", "seed=1,2"], ["--grid", "--seeds"]),
        (["--grid", "mapper.gate=0.1", "--seeds", "0,x"], ["--seeds", "'x'"]),
        (["--grid", "laps=1,2", "--laps", "1"], ["--grid", "laps", "--laps"]),
        (["--grid", "mapper.gate=0.1", "--laps", "0"], ["--laps", "laps", "must be >= 1"]),
        (["--grid", "mapper.gate=0.1", "--jobs", "0"], ["--jobs", "must be >= 1"]),
        (["--grid", "mapper.gate=0.1", "--sort", "recal"], ["--sort", "'recall'"]),
        ([], ["nothing to sweep"]),
        (["--grid", "mapper.gate=" + ",".join(f"0.{i:02d}" for i in range(10, 27)),
          "--grid", "mapper.epsilon=" + ",".join(f"0.0{i:02d}" for i in range(10, 26))],
         ["272 points", "17 x 16", "limit of 256"]),
    ],
)
def test_bad_tune_input_exits_2_and_writes_nothing(capsys, tmp_path, args, fragments):
    out = tmp_path / "out"
    status, stdout, err = run_cli(capsys, "tune", "sim1", *args, "--out", out)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert stdout == ""
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_a_missing_scenario_exits_2(capsys, tmp_path):
    status, _, err = run_cli(capsys, "tune", "sim3", "--grid", "mapper.gate=0.1",
                             "--out", tmp_path / "out")
    assert status == 2
    assert_one_error_line(err, "sim3", "did you mean 'sim2'")
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------------------
# Ranking and outputs, on hand-made metrics


def fake_metrics(avg, f1, nees=3.0, stops=0):
    return {
        "table1_cm": {"mean": {"avg": avg, "max": None if avg is None else 2 * avg},
                      "polylines": 0 if avg is None else 4},
        "detection": {"f1": f1, "precision": f1, "recall": f1},
        "safety": {"collisions": 0, "stops": stops, "total_time_s": 30.0, "laps_completed": 2},
        "localization": {"rmse_xy_m": 0.01, "nees_mean": nees},
        "performance": {"wall_time_s": 1.5},
    }


def test_rank_puts_the_best_first_missing_values_and_failures_last():
    rows = [{"id": 0, "table1_mean_avg_cm": 3.0, "f1": 0.5, "nees_mean": 6.0},
            {"id": 1, "table1_mean_avg_cm": None, "f1": 0.9, "nees_mean": 2.5},
            {"id": 2, "table1_mean_avg_cm": 2.0, "f1": 0.7, "nees_mean": 3.2},
            {"id": 3, "table1_mean_avg_cm": 1.0, "f1": 1.0, "nees_mean": 3.0, "failed": 1},
            {"id": 4, "table1_mean_avg_cm": 3.0, "f1": 0.5, "nees_mean": 1.0}]
    ids = {metric: [row["id"] for row in rank(rows, metric)]
           for metric in ("table1_mean_avg_cm", "f1", "nees_mean")}
    assert ids["table1_mean_avg_cm"] == [2, 0, 4, 1, 3]  # ties keep the grid order
    assert ids["f1"] == [1, 2, 0, 4, 3]
    assert NEES_TARGET == 3.0
    assert ids["nees_mean"] == [2, 1, 4, 0, 3]  # |3.2-3| < |2.5-3| < |1-3| < |6-3|
    with pytest.raises(ValueError, match="unknown metric"):
        rank(rows, "speed")


def test_seed_means_ignore_missing_values_and_count_failures():
    points = sweep_points("sim1", {"mapper.gate": (0.1, 0.2)}, seeds=(0, 1, 2))
    results = [
        PointResult(points[0], fake_metrics(2.0, 0.5)),
        PointResult(points[1], fake_metrics(None, 1.0)),
        PointResult(points[2], fake_metrics(4.0, 0.0)),
        PointResult(points[3], fake_metrics(1.0, 1.0)),
        PointResult(points[4], error="RuntimeError: lost"),
        PointResult(points[5], fake_metrics(3.0, 0.5, stops=3)),
    ]
    first, second = combine_seeds(results)
    assert first["settings"] == {"mapper.gate": 0.1}
    assert first["seeds"] == [0, 1, 2]
    assert first["table1_mean_avg_cm"] == 3.0
    assert first["f1"] == 0.5
    assert first["failed"] == 0
    assert second["table1_mean_avg_cm"] == 2.0
    assert second["stops"] == 1.5
    assert second["failed"] == 1
    # The better mean loses to a combination whose runs all finished.
    assert [row["settings"]["mapper.gate"] for row in rank([first, second])] == [0.1, 0.2]
    assert sweep_row(results[4])["error"] == "RuntimeError: lost"
    assert sweep_row(results[4])["f1"] is None
    # Worst seed and spread, by hand: Table 1 of gate 0.1 is 2.0, -, 4.0; F1 0.5, 1.0, 0.0.
    assert first["worst"]["table1_mean_avg_cm"] == 4.0
    assert first["spread"]["table1_mean_avg_cm"] == 2.0
    assert first["worst"]["f1"] == 0.0  # higher is better: the worst is the lowest
    assert first["spread"]["f1"] == 1.0
    assert second["worst"]["table1_mean_avg_cm"] == 3.0  # the failed seed has no value


def test_the_best_worst_case_can_differ_from_the_best_mean(tmp_path):
    points = sweep_points("sim1", {"mapper.gate": (0.1, 0.2)}, seeds=(0, 1))
    values = (1.0, 5.0, 3.2, 3.2)  # gate 0.1: mean 3.0, worst 5.0; gate 0.2: 3.2 and 3.2
    results = [PointResult(point, fake_metrics(value, 1.0))
               for point, value in zip(points, values, strict=True)]
    summary = write_sweep(results, tmp_path / "sweep", figures=False)
    assert summary["best"]["settings"] == {"mapper.gate": 0.1}
    assert summary["best_worst_case"]["settings"] == {"mapper.gate": 0.2}
    text = format_ranking(summary, tmp_path / "sweep", figures=False)
    assert text.splitlines()[1].split()[-2:] == ["worst", "spread"]
    assert text.splitlines()[2].split()[-2:] == ["5", "4"]
    assert "best worst case: mapper.gate=0.2 (3.2 at worst, mean 3.2)" in text


def test_written_sweep_has_one_row_per_point_and_ranks_seed_means(tmp_path):
    restriction = "mapper.hausdorff_restriction"
    points = sweep_points("sim1", {restriction: ("vertex", "projection")}, seeds=(0, 1))
    results = [PointResult(points[0], fake_metrics(3.0, 0.8, nees=5.0)),
               PointResult(points[1], fake_metrics(None, 0.9)),
               PointResult(points[2], fake_metrics(2.0, 0.6)),
               PointResult(points[3], error="RuntimeError: robot lost")]
    out = tmp_path / "sweep"
    summary = write_sweep(results, out, sort="f1")
    rows = list(csv.DictReader(io.StringIO((out / "sweep.csv").read_text())))
    assert [row[restriction] for row in rows] == ["vertex", "vertex", "projection", "projection"]
    assert [row["seed"] for row in rows] == ["0", "1", "0", "1"]
    assert rows[1]["table1_mean_avg_cm"] == ""
    assert rows[3]["error"] == "RuntimeError: robot lost"
    assert list(rows[0]) == ["point", restriction, "scenario", "seed", *METRICS, "error"]
    data = json.loads((out / "sweep.json").read_text())
    assert data["grid"] == {restriction: ["vertex", "projection"]}
    assert data["seeds"] == [0, 1]
    assert data["points"][0]["metrics"]["localization"]["nees_mean"] == 5.0
    assert data["points"][3]["metrics"] is None
    assert data["best"]["settings"] == {restriction: "vertex"}  # F1 0.85, all runs finished
    assert summary["best"]["f1"] == 0.85
    assert (out / "figures" / "sweep.png").read_bytes()[:8] == PNG_SIGNATURE
    text = format_ranking(summary, out)
    assert f"best by F1: {restriction}=vertex (0.85, mean of 2 seeds)" in text
    assert "point 3 failed: RuntimeError: robot lost" in text


@pytest.mark.parametrize(
    "grids",
    [
        {},
        {"mapper.gate": (0.1, 0.2), "policy": ("conservative", "adaptive")},
        {"mapper.gate": (0.1, 0.2), "policy": ("conservative",), "mapper.epsilon": (0.03,)},
    ],
)
def test_every_grid_shape_draws_a_figure(tmp_path, grids):
    points = sweep_points("sim1", grids, seeds=(0, 1))
    results = [PointResult(p, fake_metrics(1.0 + p.index, 0.5 if p.index else None))
               for p in points]
    write_sweep(results, tmp_path / "out")
    assert (tmp_path / "out" / "figures" / "sweep.png").read_bytes()[:8] == PNG_SIGNATURE


def test_runs_that_raise_are_recorded_and_the_exit_status_says_so(
    capsys, tmp_path, monkeypatch
):
    def broken_run(spec, **_):
        raise RuntimeError(f"no triangulation with gate {spec.mapper.gate}")

    monkeypatch.setattr("scenarios.bench.runner.run_scenario", broken_run)
    scenario = write_tiny(tmp_path)
    out = tmp_path / "out"
    status, stdout, _ = run_cli(capsys, "tune", scenario, "--grid", "mapper.gate=0.1,0.2",
                                "--out", out, "--no-figures")
    assert status == 1
    assert "point 1 failed: RuntimeError: no triangulation with gate 0.2" in stdout
    assert "best: none" in stdout
    data = json.loads((out / "sweep.json").read_text())
    assert [p["error"] for p in data["points"]] == [
        "RuntimeError: no triangulation with gate 0.1",
        "RuntimeError: no triangulation with gate 0.2",
    ]
    assert not (out / "figures").exists()


# --------------------------------------------------------------------------------------
# Real closed-loop sweeps of the tiny scenario


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    """Two gates x two laps of the tiny scenario: through the CLI with two workers, and
    directly in this process. Same seeds, so the metrics must be identical."""
    folder = tmp_path_factory.mktemp("tune")
    scenario = write_tiny(folder)
    out = folder / "out"
    status = main(["tune", str(scenario), "--grid", "mapper.gate=" + ",".join(map(str, GATES)),
                   "--laps", "2", "--jobs", "2", "--out", str(out)])
    points = sweep_points(scenario, {"mapper.gate": GATES}, laps=2)
    finished = []
    direct = run_sweep(points, jobs=1, on_result=finished.append)
    return {"status": status, "out": out, "direct": direct, "finished": finished}


@pytest.mark.slow
def test_sweep_writes_its_outputs(tiny_sweep):
    assert tiny_sweep["status"] == 0
    out = tiny_sweep["out"]
    rows = list(csv.DictReader(io.StringIO((out / "sweep.csv").read_text())))
    assert [float(row["mapper.gate"]) for row in rows] == list(GATES)
    assert all(row["seed"] == "3" and row["error"] == "" for row in rows)
    assert all(row["laps_completed"] == "2" for row in rows)
    # Two laps: the second revisits the first one's reference map, so Table 1 has values.
    assert all(float(row["table1_mean_avg_cm"]) > 0 for row in rows)
    assert all(int(row["table1_polylines"]) >= 1 for row in rows)
    assert all(0 <= float(row["f1"]) <= 1 for row in rows)
    data = json.loads((out / "sweep.json").read_text())
    assert data["scenario"] == "tiny"
    assert data["laps"] == 2
    assert [p["metrics"]["table1_cm"]["mean"]["avg"] for p in data["points"]] == [
        float(row["table1_mean_avg_cm"]) for row in rows
    ]
    ranked = [row["table1_mean_avg_cm"] for row in data["ranking"]]
    assert ranked == sorted(ranked)
    assert data["best"] == data["ranking"][0]
    png = out / "figures" / "sweep.png"
    assert png.read_bytes()[:8] == PNG_SIGNATURE
    assert png.stat().st_size > 20_000


@pytest.mark.slow
def test_sweep_prints_the_ranked_table_and_best_point(tiny_sweep):
    data = json.loads((tiny_sweep["out"] / "sweep.json").read_text())
    text = format_ranking(data, tiny_sweep["out"])
    best = data["best"]["settings"]["mapper.gate"]
    assert f"best by Table 1 mean avg (cm): mapper.gate={best} " in text
    assert text.splitlines()[2].split()[:2] == ["1", str(best)]


@pytest.mark.slow
def test_results_do_not_depend_on_the_number_of_workers(tiny_sweep):
    direct = tiny_sweep["direct"]
    assert [r.point.index for r in direct] == [0, 1]
    assert sorted(r.point.index for r in tiny_sweep["finished"]) == [0, 1]
    assert not any(r.failed for r in direct)
    data = json.loads((tiny_sweep["out"] / "sweep.json").read_text())
    for result, written in zip(direct, data["points"], strict=True):
        row = {key: value for key, value in written.items() if key in sweep_row(result)}
        assert without_timing(row) == without_timing(sweep_row(result))
        assert without_performance(written["metrics"]) == without_performance(result.metrics)
    # The two gates really ran differently (the sweep is not one run written twice).
    assert direct[0].metrics["table1_cm"] != direct[1].metrics["table1_cm"]
