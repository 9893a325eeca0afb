"""One read of the inputs per command: every run of ``run --compare`` (and its recording)
uses the world as loaded at the start, whatever happens to its file meanwhile."""

import dataclasses
import json

import pytest

import scenarios.bench.runner as runner
from scenarios.logs.recording import spec_fingerprint
from scenarios.results.outputs import summarize
from scenarios.spec.load import load_scenario
from tests.scenarios.cli_helpers import run_cli
from tests.scenarios.tiny_world import write_tiny


def figures(summary):
    """What a run measured: everything but its timings."""
    return {key: value for key, value in summary.items() if key != "performance"}


@pytest.mark.slow  # six one-lap runs of the tiny world
def test_compare_runs_use_the_world_loaded_at_the_start_when_its_file_goes(
        tmp_path, monkeypatch, capsys):
    scenario = write_tiny(tmp_path)
    world_file = tmp_path / "tiny_world.toml"
    spec = load_scenario(scenario, overrides=["laps=1"])
    policies = ["conservative", "adaptive", "guarded"]
    assert spec.policy == policies[0]
    fingerprint = spec_fingerprint(spec)  # reads the world file, still there
    expected = {policy: figures(summarize(runner.run_scenario(
        dataclasses.replace(spec, policy=policy)))) for policy in policies}

    seen = {}
    real_run = runner.run_scenario

    def run_then_delete_the_world(spec, **options):
        log = real_run(spec, **options)
        seen[spec.policy] = figures(summarize(log))
        world_file.unlink(missing_ok=True)  # gone before the next policy's run starts
        return log

    monkeypatch.setattr(runner, "run_scenario", run_then_delete_the_world)
    status, _, err = run_cli(capsys, "run", scenario, "--laps", "1", "--compare",
                             "--no-figures", "--out", tmp_path / "out",
                             "--record", tmp_path / "recording")
    assert status == 0, err
    assert not world_file.exists()
    assert list(seen) == policies
    assert seen == expected
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert {"adaptive", "guarded"} <= metrics["policy_comparison"].keys()
    manifest = json.loads((tmp_path / "recording" / "manifest.json").read_text())
    assert manifest["fingerprint"] == fingerprint
