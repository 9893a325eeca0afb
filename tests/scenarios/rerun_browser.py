"""Open a Rerun recording in the Rerun web viewer in headless Chromium and screenshot it.

Used by the real-browser test and to make the screenshot in the docs::

    python -m tests.scenarios.rerun_browser RUN.rrd OUT.png [--seconds 40]

``rerun --web-viewer`` serves the viewer (WebAssembly) and the recording on 127.0.0.1;
Playwright drives Debian's Chromium (``/usr/bin/chromium``, software WebGL through
SwiftShader) to the viewer's page and takes screenshots until the drawing colours stop
changing. Analytics stay off: the viewer runs with a configuration directory of its own.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from matplotlib.image import imread

from semistatic.colours import FIELD_COLOURS, RETURNS_COLOUR

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
RERUN = Path(sys.executable).with_name("rerun")
COLOURS = {"warning": FIELD_COLOURS["warning"], "protective": FIELD_COLOURS["protective"],
           "returns": RETURNS_COLOUR}
"""The drawing colours counted in a screenshot (8-bit, within a tolerance). Not the walls'
dark grey: the viewer's own panels have it, drawn or not."""

MIN_DRAWN = 100
"""Protective-field and return pixels that say the scene is drawn: the viewer's own panels
have none (its orange software-rendering notice passes for the warning field's colour)."""


def missing() -> str | None:
    """Return why the browser test cannot run here, or ``None``."""
    if not Path(CHROMIUM).exists():
        return "no Chromium: apt-get install chromium (Debian's package; .ci/run installs it)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "no playwright: pip install -e '.[test]'"
    if not RERUN.exists():
        return f"no rerun command beside {sys.executable}: pip install 'semistatic[rerun]'"
    return None


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextlib.contextmanager
def served(rrd: Path | None) -> Iterator[str]:
    """Serve the web viewer (with ``rrd`` loaded, or empty) on 127.0.0.1; yield its URL."""
    web, grpc = _free_port(), _free_port()
    with tempfile.TemporaryDirectory() as config:
        env = {**os.environ, "XDG_CONFIG_HOME": config, "HOME": config}
        subprocess.run([str(RERUN), "analytics", "disable"], env=env, check=True,
                       capture_output=True)
        command = [str(RERUN), "--web-viewer", "--bind", "127.0.0.1", "--web-viewer-port",
                   str(web), "--port", str(grpc), "--hide-welcome-screen"]
        # A session of its own: `rerun` is a launcher whose child serves; both must go.
        server = subprocess.Popen([*command, *([str(rrd)] if rrd else [])], env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  start_new_session=True)
        try:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                with socket.socket() as probe:
                    if probe.connect_ex(("127.0.0.1", web)) == 0:
                        break
                time.sleep(0.2)
            source = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
            yield f"http://127.0.0.1:{web}/?url={source}"
        finally:
            os.killpg(server.pid, signal.SIGTERM)
            try:
                server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(server.pid, signal.SIGKILL)
                server.wait()


def colour_counts(png: Path, tolerance: int = 30) -> dict[str, int]:
    """Count the pixels of ``png`` near each of :data:`COLOURS`."""
    rgb = (imread(png)[:, :, :3] * 255).astype(int)
    return {name: int(np.count_nonzero(
        np.abs(rgb - np.array(colour) * 255).max(axis=2) <= tolerance))
        for name, colour in COLOURS.items()}


def screenshot(url: str, out: Path, *, seconds: float = 60.0,
               size: tuple[int, int] = (1400, 850)) -> dict[str, int]:
    """Screenshot ``url`` into ``out`` once the drawing stops changing; return its counts.

    Screenshots every 3 s until two in a row count the same drawing pixels with the scene
    drawn (:data:`MIN_DRAWN`), or ``seconds`` have passed (an empty viewer draws nothing:
    it waits them out).
    Only the scene's colours count: the viewer's loading screen holds still for as long
    as a slow machine takes to load it, and must not pass for the drawn scene.
    """
    from playwright.sync_api import sync_playwright

    with sync_playwright() as driver:
        browser = driver.chromium.launch(
            executable_path=CHROMIUM,
            args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
        try:
            page = browser.new_page(viewport={"width": size[0], "height": size[1]})
            page.goto(url)
            deadline, last = time.monotonic() + seconds, None
            while True:
                time.sleep(3.0)
                page.screenshot(path=str(out))
                counts = colour_counts(out)
                drawn = counts["protective"] + counts["returns"] >= MIN_DRAWN
                if (drawn and counts == last) or time.monotonic() > deadline:
                    return counts
                last = counts
        finally:
            browser.close()


def main(argv: list[str] | None = None) -> int:
    """Screenshot a recording in the web viewer; print the colour counts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rrd", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args(argv)
    reason = missing()
    if reason:
        print(f"error: {reason}", file=sys.stderr)
        return 2
    with served(args.rrd) as url:
        print(screenshot(url, args.out, seconds=args.seconds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
