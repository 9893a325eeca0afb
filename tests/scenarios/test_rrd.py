"""Rerun recordings (``--rrd``), read back with Rerun's own reader, not ours.

The recordings are opened by ``rerun.server.Server`` (Rerun's catalog server, queried
through DataFusion); what they hold is checked against independent references: the
world file's field polygons, the supervisor's stop and slowdown counts in metrics.json,
the lap durations and the safety laser's rate, the palette of the local-map statuses.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from scenarios.logs.rrd import RerunRecorder
from semistatic.colours import STATUS_COLOURS, rgba8
from tests.scenarios import rerun_browser
from tests.scenarios.cli_helpers import assert_one_error_line, run_cli
from tests.scenarios.tiny_world import write_tiny

rr = pytest.importorskip("rerun", reason="the rerun extra is not installed")
pytest.importorskip("datafusion", reason="Rerun's reader needs rerun-sdk[catalog]")

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def read_rrd(path: Path) -> dict[str, list]:
    """Return every column of a recording (on ``sim_time``) as Python lists, by name."""
    with rr.server.Server(host="127.0.0.1", datasets={"run": [str(path)]}) as server:
        client = server.client()  # kept alive while the query runs
        table = client.get_dataset("run").reader(index="sim_time").to_arrow_table()
    return {name: table.column(name).to_pylist() for name in table.column_names}


def values(table: dict[str, list], column: str) -> list:
    """Return the non-null cells of ``column`` (rows where that entity was logged)."""
    return [cell for cell in table[column] if cell is not None]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """One lap of the tiny scenario with --rrd, and its metrics."""
    folder = tmp_path_factory.mktemp("rrd")
    scenario = write_tiny(folder)
    from scenarios.cli import main

    status = main(["run", str(scenario), "--laps", "1", "--no-figures", "--out",
                   str(folder / "out"), "--rrd", str(folder / "out" / "tiny.rrd")])
    assert status == 0
    metrics = json.loads((folder / "out" / "metrics.json").read_text())
    return folder, metrics, read_rrd(folder / "out" / "tiny.rrd")


def test_a_lap_logs_one_row_per_safety_scan(tiny_run):
    _, metrics, table = tiny_run
    duration = sum(metrics["safety"]["lap_time_s"])
    rate = 12.5  # the scenario's rates.safety_hz (the default)
    for column in ("/map/robot/laser/returns:Points2D:positions",
                   "/map/robot/true:Transform3D:translation",
                   "/map/robot/ekf:Transform3D:translation",
                   "/series/speed/robot:Scalars:scalars",
                   "/series/zone/robot:Scalars:scalars",
                   "/series/ekf_sigma_xy/robot:Scalars:scalars"):
        assert abs(len(values(table, column)) - duration * rate) <= 2, column


def test_the_world_and_the_vehicle_are_in_the_recording(tiny_run):
    _, _, table = tiny_run
    walls = values(table, "/map/walls:LineStrips2D:strips")[0]
    assert len(walls) == 4  # the tiny world's four walls
    posts = values(table, "/map/posts:Points2D:positions")[0]
    assert len(posts) == 11
    [carton] = values(table, "/map/boxes:LineStrips2D:labels")[0]
    assert carton == "carton"
    box = np.array(values(table, "/map/boxes:LineStrips2D:strips")[0][0])
    # The carton: 0.5 x 0.4 m centred at (2.6, -1.0), unrotated.
    np.testing.assert_allclose([box[:, 0].min(), box[:, 0].max(), box[:, 1].min(),
                                box[:, 1].max()], [2.35, 2.85, -1.2, -0.8])
    assert "/map/robot/true/footprint:LineStrips2D:strips" in table


def test_the_fields_are_the_world_files_polygons(tiny_run):
    _, _, table = tiny_run
    protective = np.array(values(table, "/map/robot/ekf/fields/protective:LineStrips2D:strips")
                          [0][0])
    warning = np.array(values(table, "/map/robot/ekf/fields/warning:LineStrips2D:strips")[0][0])
    # tiny_world.toml's corridor segment, closed.
    np.testing.assert_allclose(protective[:-1], [[0.18, -0.65], [0.78, -0.65], [0.78, 0.65],
                                                 [0.18, 0.65]])
    np.testing.assert_allclose(warning[:-1], [[0.18, -0.9], [1.4, -0.9], [1.4, 0.9],
                                              [0.18, 0.9]])
    np.testing.assert_allclose(protective[-1], protective[0])
    minimum = values(table, "/map/robot/ekf/fields/minimum:LineStrips2D:strips")
    assert minimum
    assert all(len(strips) == 1 for strips in minimum)


def test_zones_and_events_agree_with_the_supervisors_counts(tiny_run):
    _, metrics, table = tiny_run
    zones = [cell[0] for cell in values(table, "/series/zone/robot:Scalars:scalars")]
    assert set(zones) <= {0.0, 1.0, 2.0}
    events = [text for cell in values(table, "/events/robot:TextLog:text") for text in cell]
    stops = sum(text.startswith("protective stop") for text in events)
    slowdowns = sum(text.startswith("slowdown") for text in events)
    assert (stops, slowdowns) == (metrics["safety"]["stops"], metrics["safety"]["slowdowns"])
    assert metrics["safety"]["slowdowns"] > 0  # the carton reaches into the warning field
    assert (1.0 in zones) == (metrics["safety"]["slowdowns"] > 0)
    assert any(text.startswith("lap 1 completed") for text in events)


def test_map_polylines_carry_their_status_colours(tiny_run):
    _, _, table = tiny_run
    palette = {int.from_bytes(bytes(rgba8(colour)), "big") for colour in STATUS_COLOURS.values()}
    column = "/map/robot/local_map/corridor:LineStrips2D:colors"
    colours = [colour for cells in values(table, column) for colour in cells]
    assert colours
    assert set(colours) <= palette
    confirmed = int.from_bytes(bytes(rgba8(STATUS_COLOURS["confirmed"])), "big")
    assert confirmed in colours  # walls seen in many scans get confirmed within the lap


def test_recording_changes_nothing_in_the_metrics(tiny_run, capsys):
    folder, recorded, _ = tiny_run
    status, _, _ = run_cli(capsys, "run", folder / "tiny.toml", "--laps", "1", "--no-figures",
                           "--out", folder / "plain")
    assert status == 0
    plain = json.loads((folder / "plain" / "metrics.json").read_text())
    for metrics in (plain, recorded):
        metrics.pop("performance")
    assert plain == recorded


def test_a_bad_rrd_path_is_one_error_line_and_nothing_is_written(tmp_path, capsys):
    scenario = write_tiny(tmp_path)
    status, _, err = run_cli(capsys, "run", scenario, "--out", tmp_path / "out",
                             "--rrd", tmp_path / "run.txt")
    assert status == 2
    assert_one_error_line(err, "run.txt", "--rrd", ".rrd")
    (tmp_path / "old.rrd").write_text("mine")
    status, _, err = run_cli(capsys, "run", scenario, "--out", tmp_path / "out",
                             "--rrd", tmp_path / "old.rrd")
    assert status == 2
    assert_one_error_line(err, "old.rrd", "exists already")
    assert (tmp_path / "old.rrd").read_text() == "mine"
    assert not (tmp_path / "out").exists()


def test_an_unfinished_recording_leaves_nothing_behind(tmp_path):
    recorder = RerunRecorder(tmp_path / "run.rrd")
    assert recorder.close(finish=False) is None
    assert list(tmp_path.iterdir()) == []


def test_falsification_counterexamples_get_their_recordings(tmp_path):
    from scenarios.commands.falsify import record_counterexamples

    folder = tmp_path / "counterexamples"
    folder.mkdir()
    scenario = write_tiny(folder)  # as write_counterexamples names them
    (folder / "tiny_world.toml").rename(folder / "adaptive-0007.world.toml")
    (folder / "adaptive-0007.toml").write_text(scenario.read_text().replace(
        "laps = 2", "laps = 1").replace("tiny_world.toml", "adaptive-0007.world.toml"))
    scenario.unlink()
    line = record_counterexamples(tmp_path)
    assert "1 counterexample recordings" in line
    table = read_rrd(folder / "adaptive-0007.rrd")
    assert values(table, "/map/robot/laser/returns:Points2D:positions")


@pytest.mark.slow
def test_a_sim1_lap_recording_holds_its_entities_and_scans(tmp_path, capsys):
    from scenarios.spec.layout import scenario_world
    from scenarios.spec.load import load_scenario

    out = tmp_path / "sim1"
    status, stdout, _ = run_cli(capsys, "run", "sim1", "--laps", "1", "--no-figures",
                                "--out", out, "--rrd", out / "sim1.rrd")
    assert status == 0
    metrics = json.loads((out / "metrics.json").read_text())
    table = read_rrd(out / "sim1.rrd")
    scans = len(values(table, "/map/robot/laser/returns:Points2D:positions"))
    assert f"({scans} scans;" in stdout
    assert abs(scans - metrics["safety"]["lap_time_s"][0] * 12.5) <= 2
    entities = {name.split(":")[0] for name in table}
    for entity in ("/map/walls", "/map/posts", "/map/boxes", "/map/people", "/map/segments",
                   "/map/robot/true", "/map/robot/ekf", "/map/robot/trajectory/true",
                   "/map/robot/trajectory/ekf", "/map/robot/ekf/fields/warning",
                   "/map/robot/ekf/fields/protective", "/map/robot/ekf/fields/minimum",
                   "/events/robot", "/series/speed/robot", "/series/separation/robot"):
        assert entity in entities, entity
    mapped = {entity.split("/")[4] for entity in entities
              if entity.startswith("/map/robot/local_map/")}
    world = scenario_world(load_scenario("sim1"))
    assert mapped == {segment.name for segment in world.path.segments}


@pytest.mark.slow
def test_a_fleet_recording_holds_every_vehicle(tmp_path, capsys):
    from scenarios.spec.load import load_scenario

    spec = load_scenario("warehouse_fleet")
    out = tmp_path / "fleet"
    status, _, _ = run_cli(capsys, "run", "warehouse_fleet", "--laps", "1", "--no-figures",
                           "--out", out, "--rrd", tmp_path / "fleet.rrd")
    assert status == 0
    table = read_rrd(tmp_path / "fleet.rrd")
    names = [vehicle.name for vehicle in spec.vehicles]
    assert len(names) > 1
    for name in names:
        assert values(table, f"/map/{name}/laser/returns:Points2D:positions"), name
        assert values(table, f"/series/speed/{name}:Scalars:scalars"), name


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"no real logs in {DATA}")
def test_a_replayed_real_log_records_its_scans_and_maps(tmp_path, capsys):
    status, _, _ = run_cli(capsys, "replay", DATA / "intel-corrected.log.gz", "--every", "20",
                           "--no-figures",
                                "--out", tmp_path / "out", "--rrd", tmp_path / "intel.rrd")
    assert status == 0
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    table = read_rrd(tmp_path / "intel.rrd")
    assert len(values(table, "/map/log/laser/returns:Points2D:positions")) == metrics["scans"]
    maps = [name for name in table if name.startswith("/map/log/local_map/")
            and name.endswith(":strips")]
    assert maps


@pytest.mark.slow
@pytest.mark.skipif(rerun_browser.missing() is not None, reason=str(rerun_browser.missing()))
def test_the_web_viewer_draws_the_recording_in_headless_chromium(tiny_run, tmp_path):
    folder, _, _ = tiny_run
    with rerun_browser.served(None) as url:
        empty = rerun_browser.screenshot(url, tmp_path / "empty.png", seconds=15)
    with rerun_browser.served(folder / "out" / "tiny.rrd") as url:
        drawn = rerun_browser.screenshot(url, tmp_path / "run.png", seconds=90)
    # The fields and the laser returns in their colours: absent from an empty viewer.
    for name in ("warning", "protective", "returns"):
        assert drawn[name] > 10 * max(empty[name], 10), (name, drawn, empty)


def test_viewer_streams_to_a_listening_viewer_and_refuses_an_absent_one(tmp_path, capsys):
    import os
    import signal
    import socket
    import subprocess
    import sys
    import time

    scenario = write_tiny(tmp_path)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    status, _, err = run_cli(capsys, "run", scenario, "--laps", "1", "--out", tmp_path / "a",
                             "--viewer", url)
    assert status == 2
    assert_one_error_line(err, "--viewer", "no Rerun viewer listens", url)
    assert not (tmp_path / "a").exists()
    # Rerun's own gRPC server stands in for a viewer (a session of its own: the launcher's
    # child serves).
    server = subprocess.Popen([str(Path(sys.executable).with_name("rerun")), "--serve-grpc",
                               "--bind", "127.0.0.1", "--port", str(port)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True, env={**os.environ, "HOME": str(tmp_path)})
    try:
        for _ in range(100):
            with socket.socket() as probe:
                if probe.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.1)
        status, out, _ = run_cli(capsys, "run", scenario, "--laps", "1", "--no-figures",
                                 "--out", tmp_path / "b", "--viewer", url)
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=10)
    assert status == 0
    assert f"scans to the Rerun viewer at {url}" in out


def test_a_recording_inside_out_is_replaced_with_the_result(tmp_path, capsys):
    scenario = write_tiny(tmp_path)
    out = tmp_path / "out"
    for _ in range(2):  # the second run replaces the first result, recording included
        status, _, _ = run_cli(capsys, "run", scenario, "--laps", "1", "--no-figures",
                               "--out", out, "--rrd", out / "run.rrd")
        assert status == 0
    assert (out / "run.rrd").stat().st_size > 0
    assert not [path for path in tmp_path.rglob("*.partial")]
