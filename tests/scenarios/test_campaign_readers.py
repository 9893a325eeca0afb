"""A campaign's tables open in pandas and DuckDB without this project (nothing imported from it).

The campaign runs as a command, in a subprocess; the checks use only the readers.
"""

import json
import subprocess
import sys

import duckdb
import pandas as pd
import pytest


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    out = tmp_path_factory.mktemp("readers") / "campaign"
    done = subprocess.run(
        [sys.executable, "-m", "scenarios", "campaign", "pal1", "--laps", "2",
         "--seeds", "0:1", "--policy", "conservative,adaptive", "--no-figures",
         "--jobs", "2", "--out", str(out)],
        capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.slow
def test_pandas_reads_one_row_per_run_with_flattened_metrics(campaign):
    runs = pd.read_parquet(campaign / "runs.parquet")
    assert len(runs) == 4
    assert sorted(zip(runs["policy"], runs["seed"], strict=True)) == [
        ("adaptive", 0), ("adaptive", 1), ("conservative", 0), ("conservative", 1)]
    assert (runs["status"] == "ok").all()
    assert runs["detection.f1"].between(0.0, 1.0).all()
    assert runs["safety.collisions"].dtype.kind == "i"
    assert runs["safety.total_time_s"].gt(0.0).all()
    # The CSV holds the same table.
    csv = pd.read_csv(campaign / "runs.csv")
    assert list(csv.columns) == list(runs.columns)
    pd.testing.assert_series_equal(csv["safety.total_time_s"], runs["safety.total_time_s"])
    # Each run's scenario digest is in the manifest.
    manifest = json.loads((campaign / "manifest.json").read_text())
    assert set(manifest["runs"]) == set(runs["run"])
    assert set(runs["digest"]) == {entry["digest"] for entry in manifest["runs"].values()}


@pytest.mark.slow
def test_duckdb_queries_the_parquet_file(campaign):
    query = f"""
        SELECT policy, count(*) AS runs, avg("safety.total_time_s") AS mean_time
        FROM read_parquet('{campaign / "runs.parquet"}') GROUP BY policy ORDER BY policy
    """
    rows = duckdb.sql(query).fetchall()
    assert [(policy, runs) for policy, runs, _ in rows] == [("adaptive", 2), ("conservative", 2)]
    times = pd.read_parquet(campaign / "runs.parquet").groupby("policy")["safety.total_time_s"]
    for policy, _, mean_time in rows:
        assert mean_time == pytest.approx(times.mean()[policy])
