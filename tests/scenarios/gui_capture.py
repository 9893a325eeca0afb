"""Run a scenario in PyBullet's GUI, screenshot the window and report what was drawn.

Run under a (virtual) display, from the repository root::

    xvfb-run -a -s "-screen 0 1024x768x24" python -m tests.scenarios.gui_capture OUT.png \\
        [--scenario sim1] [--seconds 12]

Prints one JSON line: the robot's true pose, the camera (target, pitch, yaw, distance),
the debug items drawn, the count of pixels of each drawing colour in the screenshot, and
of text-coloured pixels in the status area (the top tenth of the window). The screenshot is the
X root window (``xwd``), decoded here: PyBullet's own camera image leaves debug items out.
"""

from __future__ import annotations

import argparse
import json
import struct
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from matplotlib.image import imsave

from scenarios import Testbench, load_scenario
from scenarios.bench.gui import GuiView
from semistatic.colours import TEXT_COLOUR

# Drawing colours as 8-bit RGB, as the GUI renders them (scenarios.bench.gui).
COLOURS = {"warning": (255, 153, 0), "protective": (229, 0, 0), "returns": (191, 0, 191),
           "confirmed": (0, 165, 0)}
TEXT_RGB = tuple(round(255 * c) for c in TEXT_COLOUR)


GUI_SETTLE_S = 1.0
"""Wall seconds to wait before the screenshot."""


def read_xwd(path: Path) -> np.ndarray:
    """Return the ``(H, W, 3)`` RGB pixels of an X window dump (ZPixmap, 24 or 32 bits)."""
    data = path.read_bytes()
    header = struct.unpack(">25I", data[:100])
    header_size, width, height = header[0], header[4], header[5]
    bits_per_pixel, bytes_per_line, colours = header[11], header[12], header[19]
    start = header_size + 12 * colours
    rows = np.frombuffer(data, np.uint8, bytes_per_line * height, start)
    step = bits_per_pixel // 8
    pixels = rows.reshape(height, bytes_per_line)[:, : width * step].reshape(height, width, step)
    return pixels[:, :, [2, 1, 0]].copy()  # stored B, G, R (least significant byte first)


def colour_counts(rgb: np.ndarray, tolerance: int = 40) -> dict[str, int]:
    """Count the pixels near each drawing colour."""
    return {
        name: count_near(rgb, colour, tolerance) for name, colour in COLOURS.items()
    }


def count_near(rgb: np.ndarray, colour: tuple[int, int, int], tolerance: int = 40) -> int:
    """Count the pixels of ``rgb`` within ``tolerance`` of ``colour`` in every channel."""
    return int(np.count_nonzero(np.abs(rgb.astype(int) - colour).max(axis=2) <= tolerance))


def main(argv: list[str] | None = None) -> int:
    """Run, capture and print the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--scenario", default="sim1")
    parser.add_argument("--seconds", type=float, default=12.0)
    args = parser.parse_args(argv)
    spec = load_scenario(args.scenario, overrides=["laps=1"])
    with Testbench(spec, gui=True) as bench:
        bench.reset()
        while bench.sim_time < args.seconds:
            bench.step()
        observer = next(o for o in bench.observers if isinstance(o, GuiView))
        observer.draw(bench)  # the last redraw may lag: its wall-time budget (DRAW_SHARE)
        view = observer.view
        time.sleep(GUI_SETTLE_S)  # the GUI renders on its own thread: let it show the last draw
        camera = bench.sim.display.getDebugVisualizerCamera()
        width, height = camera[0], camera[1]
        with tempfile.TemporaryDirectory() as folder:
            dump = Path(folder) / "screen.xwd"
            subprocess.run(["xwd", "-root", "-silent", "-out", str(dump)], check=True)
            rgb = read_xwd(dump)[:height, :width]
        imsave(args.out, rgb)
        report = {
            "true_pose": bench.true_pose.round(3).tolist(),
            "camera_target": [round(v, 3) for v in camera[11]],
            "camera_pitch": round(camera[9], 2),
            "camera_yaw": round(camera[8], 2),
            "camera_distance": round(camera[10], 2),
            "items": {name: len(ids) for name, ids in view.items.items()},
            # the world's part: the legend's colour samples stand right of it
            "pixels": colour_counts(rgb[:, : 3 * width // 4]),
            "status_text_pixels": count_near(rgb[: height // 10], TEXT_RGB, 60),
        }
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
