"""Benchmark: one sim1 lap headless and watched in the GUI under a virtual display.

The goal: a lap with ``--gui`` under Xvfb (software rendering) within 5x the wall time of
the same lap headless, both measured here in one session (the machine's load moves both).
Reports the laps' wall times from ``metrics.json`` (the closed loop only) and the whole
commands' (start-up, world building, the window's opening included).

Before the GUI became a display of a headless physics server, every physics call waited
for the GUI's render thread and the lap took > 300 s against ~11 s headless.

Run: ``.venv/bin/python -m pytest -m bench -s benchmarks/test_bench_gui.py``
"""

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

GOAL_RATIO = 5.0
SCREEN = ["xvfb-run", "-a", "-s", "-screen 0 1280x800x24"]


def run_lap(out: Path, gui: bool) -> tuple[float, float]:
    """Run one sim1 lap; return its lap wall time (metrics.json) and the command's."""
    command = [str(Path(sys.executable).parent / "semistatic"), "run", "sim1", "--laps", "1",
               "--no-figures", "--out", str(out)]
    if gui:
        command = [*SCREEN, *command, "--gui"]
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, timeout=900, check=False)
    total = time.perf_counter() - started
    assert done.returncode == 0, done.stderr[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    return metrics["performance"]["wall_time_s"], total


@pytest.mark.bench
@pytest.mark.skipif(shutil.which("xvfb-run") is None,
                    reason="needs xvfb-run (apt-get install xvfb)")
def test_a_gui_lap_under_xvfb_within_5x_a_headless_lap(tmp_path):
    headless_lap, headless_total = run_lap(tmp_path / "headless", gui=False)
    gui_lap, gui_total = run_lap(tmp_path / "gui", gui=True)
    ratio = gui_lap / headless_lap
    print(
        f"\nsim1 lap: headless {headless_lap:.1f} s (command {headless_total:.1f} s), "
        f"--gui under Xvfb {gui_lap:.1f} s (command {gui_total:.1f} s): "
        f"lap ratio x{ratio:.2f}, command ratio x{gui_total / headless_total:.2f} "
        f"(goal <= x{GOAL_RATIO:.0f})"
    )
