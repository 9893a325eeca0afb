"""Call every compiled kernel once and print the seconds it took (the start-up cost).

Run in a fresh process: with an empty ``NUMBA_CACHE_DIR`` it measures compilation (the
first run after installation: :func:`semistatic.kernel_cache.warm_kernel_cache` first, as
a run starts, then the calls), with the cache filled by that run it measures loading the
cached machine code (every later run). ``benchmarks/test_bench_goals.py`` runs it both
ways; by hand::

    NUMBA_CACHE_DIR=$(mktemp -d) .venv/bin/python -m benchmarks.kernel_warmup

``--record`` (empty cache, ``SEMISTATIC_PARALLEL_COMPILE=0``) writes the kernels the calls
compiled, with their argument types and compile seconds, to
``semistatic/kernel_signatures.toml``; ``--check`` prints the differences to that file.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

# Imports first: they are start-up cost too, but not the kernels'.
from benchmarks.test_bench_mapper import hall
from robots.ekf import EKFLocalizer, EKFParams
from robots.landmarks import LandmarkObservation, detect_landmarks
from robots.path import SplinePath
from semistatic.association import associate, sort_ccw
from semistatic.hausdorff import hausdorff, restrict, restricted_hausdorff
from semistatic.kernel_cache import (
    SIGNATURES_FILE,
    SWITCH,
    Kernel,
    load_kernels,
    type_text,
    warm_kernel_cache,
)
from semistatic.mapper import PolylineMap
from semistatic.merge import project_onto
from semistatic.polyline import Polyline
from semistatic.types import Scan
from tests.semistatic.synthetic import cast_scan


def warm_up() -> float:
    """Run each kernel once (as the closed loop calls them); return the seconds taken."""
    rng = np.random.default_rng(0)
    segments = hall()
    scans = [cast_scan(segments, np.zeros(3), noise=0.01, rng=rng, stamp=0.1 * k) for k in range(3)]
    path = SplinePath([(0.0, 0.0), (2.0, 0.0), (3.0, 1.0)])
    start = time.perf_counter()
    warm_kernel_cache()
    mapper = PolylineMap()
    for scan in scans:
        mapper.update(scan, np.zeros(3))
    wall, part = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]]), [[1.0, 0.1], [3.0, 0.1]]
    hausdorff(wall, part)
    restrict(wall, part, mode="projection")
    restricted_hausdorff(wall, part, mode="projection")
    project_onto(part, Polyline(wall))  # as join does it: a polyline's read-only vertices
    sort_ccw([wall, part], (0.0, 0.0, 0.0))
    associate([part], [wall], 0.12, viewpoint=(0.0, 0.0, 0.0))
    # Two scan polylines near two map polylines: the gate leaves more than one path, so
    # association ranks the pairs by tangent similarity (one kernel call for all of them).
    up = np.array([0.0, 0.02])
    associate([np.asarray(part), np.add(part, up)], [wall, np.add(wall, 2.0 * up)], 0.12,
              viewpoint=(0.0, 0.0, 0.0))
    angles = np.radians(np.arange(-10.0, 10.5, 0.5))
    ranges = np.full(angles.size, 12.0)
    intensities = np.full(angles.size, 0.2)
    ranges[20], intensities[20] = 7.96, 0.95
    detect_landmarks(Scan(ranges=ranges, angle_min=angles[0], angle_increment=0.5 * np.pi / 180,
                          intensities=intensities))
    ekf = EKFLocalizer([[4.0, 0.0], [0.0, 4.0]], EKFParams(range_bias_sigma=0.01))
    ekf.initialize([0.0, 0.0, 0.0], np.diag([0.01, 0.01, 0.001]), stamp=0.0)
    ekf.update([LandmarkObservation(4.0, 0.0, np.diag([1e-4, 1e-6]), [0])], stamp=0.1)
    path.project((1.0, 0.1), s_hint=0.9, window=1.0)  # the follower's projection
    path.frame(0.9)  # and its reference
    return time.perf_counter() - start


def compiled_kernels() -> tuple[list[Kernel], float]:
    """Run :func:`warm_up` and return the kernels it compiled from Python, and its seconds.

    Each kernel's seconds include the compilation of the functions it calls that were
    not compiled before (numba's compile events, outermost ones only).
    """
    from numba.core import event

    found: list[Kernel] = []
    started: list[float] = []

    class Outermost(event.Listener):
        def on_start(self, item: event.Event) -> None:
            started.append(time.perf_counter())

        def on_end(self, item: event.Event) -> None:
            seconds = time.perf_counter() - started.pop()
            dispatcher = item.data["dispatcher"]
            if not started and not dispatcher.py_func.__module__.startswith("numba"):
                function = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
                arguments = tuple(type_text(argument) for argument in item.data["args"])
                found.append(Kernel(function, arguments, round(seconds, 2)))

    with event.install_listener("numba:compile", Outermost()):
        seconds = warm_up()
    return found, seconds


def _signature_file(kernels: list[Kernel]) -> str:
    lines = ["# The kernels a first `semistatic run` compiles (semistatic/kernel_cache.py).",
             "# Written by `python -m benchmarks.kernel_warmup --record`: do not edit.", ""]
    for kernel in kernels:
        arguments = ", ".join(f'"{text}"' for text in kernel.arguments)
        lines += ["[[kernel]]", f'function = "{kernel.function}"',
                  f"arguments = [{arguments}]", f"seconds = {kernel.seconds}", ""]
    return "\n".join(lines)


def _unrecorded(found: list[Kernel]) -> list[str]:
    recorded = {(kernel.function, kernel.arguments) for kernel in load_kernels()}
    compiled = {(kernel.function, kernel.arguments) for kernel in found}
    return ([f"not recorded: {item}" for item in sorted(compiled - recorded)]
            + [f"not compiled: {item}" for item in sorted(recorded - compiled)])


if __name__ == "__main__":
    if sys.argv[1:] in (["--record"], ["--check"]):
        os.environ[SWITCH] = "0"  # every kernel compiled here, in this process
    if sys.argv[1:] == ["--record"]:
        kernels, _ = compiled_kernels()
        SIGNATURES_FILE.write_text(_signature_file(kernels))
        print(f"{len(kernels)} kernels written to {SIGNATURES_FILE}")
    elif sys.argv[1:] == ["--check"]:
        print("\n".join(_unrecorded(compiled_kernels()[0])) or "same")
    else:
        print(f"{warm_up():.3f}")
