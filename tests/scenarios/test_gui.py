"""Watching a run: `--gui` under a virtual display, camera on the robot, items drawn."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios import Testbench
from scenarios.bench.gui import GuiView
from tests.scenarios.tiny_world import write_tiny

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
def test_run_gui_under_a_virtual_display(tmp_path):
    scenario = write_tiny(tmp_path)
    out = tmp_path / "out"
    command = [*SCREEN, str(Path(sys.executable).parent / "semistatic"), "run", str(scenario),
               "--gui", "--laps", "1", "--set", "lap_timeout=2", "--no-figures",
               "--out", str(out)]
    # Software rendering under Xvfb costs ~45 ms per physics step, so the lap is cut after
    # 2 simulated seconds: the run must end as any timed-out lap does (exit 1, one line,
    # metrics.json recording the failed lap), not crash in the GUI.
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 1, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    assert "run failed: lap 1: did not reach the end of the path" in done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["laps"] == 1
    assert metrics["safety"]["failed_laps"]


@pytest.mark.slow
@needs_xvfb
def test_the_camera_follows_the_robot_and_the_fields_scan_and_map_are_drawn(tmp_path):
    shot = tmp_path / "gui.png"
    command = [*SCREEN, sys.executable, "-m", "tests.scenarios.gui_capture", str(shot),
               "--scenario", "sim1", "--seconds", "6"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False,
                          cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    x, y, _ = report["true_pose"]
    target_x, target_y, _ = report["camera_target"]
    # Redrawn 4 times per simulated second at 0.4 m/s: the camera lags by < 0.1 m.
    assert abs(target_x - x) < 0.15
    assert abs(target_y - y) < 0.15
    assert report["items"]["fields"] == 8  # warning and protective, 4 edges each
    assert report["items"]["returns"] == 1
    assert report["items"]["maps"] >= 1
    # Each drawing shows on screen in its colour.
    assert all(count > 50 for count in report["pixels"].values()), report["pixels"]
    assert shot.stat().st_size > 20_000
