"""Watching a run: `--gui` under a virtual display, top-down view, items, legend, status."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios import Testbench
from scenarios.bench.gui import LEGEND, GuiView, world_bounds
from tests.scenarios.tiny_world import write_tiny
from worlds.load import load_world

ROOT = Path(__file__).resolve().parents[2]
NO_DISPLAY = shutil.which("xvfb-run") is None or shutil.which("xwd") is None
needs_xvfb = pytest.mark.skipif(
    NO_DISPLAY,
    reason="needs a virtual X display: xvfb-run and xwd (apt-get install xvfb x11-apps)",
)
SCREEN = ["xvfb-run", "-a", "-s", "-screen 0 1024x768x24"]


def test_headless_runs_draw_nothing(tmp_path):
    bench = Testbench(write_tiny(tmp_path))
    assert not any(isinstance(observer, GuiView) for observer in bench.observers)
    with Testbench(write_tiny(tmp_path), gui=False) as bench:
        view = GuiView()
        bench.add_observer(view)
        bench.reset()
        for _ in range(100):
            bench.step()
        assert not view.view.active
        assert view.view.items == {}


@pytest.mark.slow
@needs_xvfb
def test_run_gui_under_a_virtual_display_with_the_results_of_a_headless_run(tmp_path):
    scenario = write_tiny(tmp_path)
    out = tmp_path / "out"
    run = [str(Path(sys.executable).parent / "semistatic"), "run", str(scenario), "--laps", "1",
           "--set", "lap_timeout=2", "--no-figures", "--out"]
    command = [*SCREEN, *run, str(out), "--gui"]
    # The lap is cut after 2 simulated seconds: the run must end as any timed-out lap
    # does (exit 1, one line, metrics.json recording the failed lap), not crash in the GUI.
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 1, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    assert "run failed: lap 1: did not reach the end of the path" in done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["laps"] == 1
    assert metrics["safety"]["failed_laps"]
    # The physics runs headless either way; the window only shows it.
    subprocess.run([*run, str(tmp_path / "headless")], capture_output=True, timeout=300,
                   check=False)
    headless = json.loads((tmp_path / "headless" / "metrics.json").read_text())
    del metrics["performance"], headless["performance"]
    assert metrics == headless


@pytest.mark.slow
@needs_xvfb
def test_the_view_is_top_down_on_the_world_with_fields_scan_map_legend_and_status(tmp_path):
    shot = tmp_path / "gui.png"
    command = [*SCREEN, sys.executable, "-m", "tests.scenarios.gui_capture", str(shot),
               "--scenario", "sim1", "--seconds", "6"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False,
                          cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    # Straight down (PyBullet's camera has no 'up' at exactly -90) with +y up on screen,
    # aimed inside the world, which stands still: the robot moved, the camera did not.
    assert report["camera_pitch"] == pytest.approx(-89.9, abs=0.01)
    assert report["camera_yaw"] == 0.0
    x_min, y_min, x_max, y_max = world_bounds(load_world("sim1"))
    target_x, target_y, _ = report["camera_target"]
    assert x_min < target_x < x_max + 0.3 * (x_max - x_min)
    assert y_min < target_y < y_max
    # Fields, returns and map as dots in one item (one GUI command per redraw).
    assert report["items"]["scene"] == 1
    assert report["items"]["legend"] == report["items"]["legend text"] == len(LEGEND)
    assert report["items"]["status"] == 1
    # Each drawing shows in the world's part of the screen in its colour (the legend's
    # samples are not counted), the status line in the top tenth.
    assert all(count > 50 for count in report["pixels"].values()), report["pixels"]
    assert report["status_text_pixels"] > 200
    assert shot.stat().st_size > 20_000
