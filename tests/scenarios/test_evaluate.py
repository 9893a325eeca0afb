"""``semistatic evaluate`` on a synthetic CARMEN log: scores, the sweep outputs, bad input."""

import json

import pytest

from scenarios.cli import main
from tests.scenarios.test_replay import synthetic_log, write_carmen


@pytest.fixture
def log(tmp_path):
    path = tmp_path / "room.log.gz"
    write_carmen(synthetic_log(seed=4, noise=0.01), path)
    return path


def test_evaluate_prints_every_method_and_writes_the_sweep(capsys, tmp_path, log):
    out = tmp_path / "evaluation"
    assert main(["evaluate", str(log), "--every", "2", "--sweep", "0.01,0.03",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for method in ("paper", "default", "split-and-merge"):
        assert method in printed
    result = json.loads((out / "evaluation.json").read_text())
    curves = result["curves"]
    assert [point["epsilon_m"] for point in curves["default"]] == [0.01, 0.03]
    # a looser tolerance: fewer vertices, larger error; keeping 2-point clusters and
    # isolated readings, the default covers at least the rays the paper's pipeline covers
    tight, loose = curves["default"]
    assert loose["vertices_per_scan"] <= tight["vertices_per_scan"]
    assert loose["rmse_m"] >= tight["rmse_m"]
    for default, paper in zip(curves["default"], curves["paper"], strict=True):
        assert default["coverage"] >= paper["coverage"]
    assert (out / "figures" / "rmse_vertices.png").stat().st_size > 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--every", "0"], "<command line>: --every:"),
        (["--sweep", "0.01,x"], "<command line>: --sweep:"),
        (["--sweep", "0.0"], "<command line>: --sweep:"),
    ],
)
def test_evaluate_bad_options_exit_2_with_one_line(capsys, tmp_path, log, args, message):
    assert main(["evaluate", str(log), "--out", str(tmp_path / "x"), *args]) == 2
    error = capsys.readouterr().err
    assert error.startswith(f"error: {message}")
    assert error.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_evaluate_missing_log(capsys, tmp_path):
    assert main(["evaluate", str(tmp_path / "none.log")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_evaluate_shows_ples_published_figures_on_its_logs(capsys, tmp_path):
    log = tmp_path / "intel-corrected.log.gz"
    write_carmen(synthetic_log(seed=4, noise=0.01), log)
    out = tmp_path / "evaluation"
    assert main(["evaluate", str(log), "--sweep", "0.02", "--out", str(out)]) == 0
    assert "published (Schaefer et al. 2018)" in capsys.readouterr().out
    published = json.loads((out / "evaluation.json").read_text())["published"]
    assert published["log"] == "intel"
    assert published["ple_plus_rmse_m"][-1] == pytest.approx(0.0077)


def test_evaluate_has_no_published_figures_for_other_logs(capsys, tmp_path, log):
    out = tmp_path / "evaluation"
    assert main(["evaluate", str(log), "--sweep", "0.02", "--out", str(out)]) == 0
    assert "Schaefer" not in capsys.readouterr().out
    assert json.loads((out / "evaluation.json").read_text())["published"] is None
