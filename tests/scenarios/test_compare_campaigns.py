"""``semistatic compare`` on real campaigns: no false alarm across seed sets, a worse
threshold flagged with exit status 1, JUnit a reader that is not ours understands.

Three pal1 campaigns of 12 seeds, 2 laps: the baseline (seeds 0-11), the same code on
seeds 12-23 (unpaired: different seeds), and the baseline's seeds with the Douglas-Peucker
tolerance tripled (``mapper.epsilon`` 0.03 -> 0.09 m: coarser polylines, a worse Table 1).
"""

import json
import shutil

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from junitparser import Failure, JUnitXml, Skipped

from tests.scenarios.cli_helpers import assert_one_error_line, run_cli

CAMPAIGN = ("pal1", "--laps", "2", "--jobs", "2", "--no-figures")


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory):
    folder = tmp_path_factory.mktemp("compare")
    plans = {"baseline": ["--seeds", "0:11"], "other_seeds": ["--seeds", "12:23"],
             "coarse": ["--seeds", "0:11", "--set", "mapper.epsilon=0.09"]}
    for name, options in plans.items():
        from scenarios.cli import main

        assert main(["campaign", *CAMPAIGN, *options, "--out", str(folder / name)]) == 0
    return {name: folder / name for name in plans}


@pytest.mark.slow
def test_the_same_code_on_other_seeds_is_no_significant_change(campaigns, capsys):
    capsys.readouterr()
    status, out, _ = run_cli(capsys, "compare", campaigns["baseline"], campaigns["other_seeds"])
    assert status == 0, out
    assert "**No regression.**" in out
    verdicts = {line.split("|")[1].strip(): line.split("|")[3].strip()
                for line in out.splitlines()
                if line.startswith("| ") and ("| lower |" in line or "| higher |" in line)}
    assert verdicts  # the table was found
    assert set(verdicts.values()) <= {"no significant change", "not measured"}, verdicts
    assert verdicts["table1_cm.mean.avg"] == "no significant change"


@pytest.mark.slow
def test_a_tripled_epsilon_is_a_table1_regression_with_exit_status_1(campaigns, capsys,
                                                                      tmp_path):
    capsys.readouterr()
    junit = tmp_path / "compare.xml"
    status, out, _ = run_cli(capsys, "compare", campaigns["baseline"], campaigns["coarse"],
                             "--junit", junit)
    assert status == 1
    assert "**Regressions: " in out
    regressed = out.split("**Regressions: ")[1].split("**")[0].split(", ")
    # Coarser polylines lie farther from the walls they stand for: a Table 1 column (over
    # 12 pal1 seeds, the spread of the distances first: +0.43 cm, p 0.0005 before the
    # adjustment) and nothing else.
    assert regressed
    assert all(name.startswith("table1_cm.") for name in regressed), regressed
    suite = next(iter(JUnitXml.fromfile(str(junit))))
    cases = {case.name: [type(result) for result in case.result] for case in suite}
    assert all(cases[name] == [Failure] for name in regressed)
    assert cases["detection.f1"] == []  # a passing test case
    assert "safety.min_separation_m.person" in cases  # every judged metric is a test case
    assert cases["safety.min_separation_m.person"] == [Skipped]  # pal1 has no person
    assert suite.failures == len(regressed)


def _edited_copy(source, target, *, scenario=None, format_=None):
    """Copy campaign ``source`` to ``target``, renaming its scenario or its format."""
    shutil.copytree(source, target)
    if scenario is not None:
        table = pq.read_table(target / "runs.parquet")
        column = pa.array([scenario] * table.num_rows)
        table = table.set_column(table.column_names.index("scenario"), "scenario", column)
        pq.write_table(table, target / "runs.parquet")
    if format_ is not None:
        manifest = json.loads((target / "manifest.json").read_text())
        (target / "manifest.json").write_text(json.dumps({**manifest, "format": format_}))
    return target


@pytest.mark.slow
@pytest.mark.parametrize(("edit", "fragments"), [
    ({"scenario": "pal3a"}, ("candidate: groups:", "different scenario / policy groups",
                             "only in", "pal3a / conservative")),
    ({"format_": 99}, ("format", "mismatched versions of the result format")),
    (None, ("CANDIDATE", "no such directory")),
])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(campaigns, capsys, tmp_path, edit,
                                                          fragments):
    candidate = tmp_path / "candidate"
    if edit is not None:
        _edited_copy(campaigns["baseline"], candidate, **edit)
    junit = tmp_path / "compare.xml"
    capsys.readouterr()
    status, out, err = run_cli(capsys, "compare", campaigns["baseline"], candidate,
                               "--junit", junit)
    assert status == 2
    assert out == ""
    assert_one_error_line(err, *fragments)
    assert not junit.exists()
