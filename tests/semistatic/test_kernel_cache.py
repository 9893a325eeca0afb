"""The parallel compilation of a cold kernel cache (semistatic/kernel_cache.py)."""

from __future__ import annotations

import itertools
import sys
from pathlib import Path
from types import SimpleNamespace

import numba
import pytest

from semistatic import kernel_cache
from semistatic.kernel_cache import Kernel, load_kernels, parse_type, publish, shares, type_text


def test_every_recorded_kernel_is_a_compiled_function_with_parsable_arguments():
    kernels = load_kernels()
    assert kernels
    for kernel in kernels:
        dispatcher = kernel.dispatcher()
        assert isinstance(dispatcher, numba.core.registry.CPUDispatcher), kernel.function
        assert dispatcher.py_func.__qualname__ == kernel.function.rpartition(".")[2]
        for text in kernel.arguments:
            assert type_text(parse_type(text)) == text
    # One signature per function: two processes never save two signatures of one function.
    assert len({kernel.function for kernel in kernels}) == len(kernels)


def test_types_parse_to_what_numba_infers_from_arguments():
    import numpy as np

    frozen = np.zeros(3)
    frozen.flags.writeable = False
    assert parse_type("readonly array(float64, 1)") == numba.typeof(frozen)
    assert parse_type("array(int64, 2)") == numba.typeof(np.zeros((2, 2), dtype=np.int64))
    assert parse_type("bool") == numba.typeof(True)
    with pytest.raises(ValueError, match="unknown argument type"):
        parse_type("array(float32, 1)")
    with pytest.raises(ValueError, match="C-contiguous"):
        type_text(numba.typeof(np.zeros((3, 3))[:, 0]))


def test_shares_split_like_the_best_of_all_splits_within_the_largest_kernel():
    kernels = [Kernel(f"m{n}.kernel", (), seconds)
               for n, seconds in enumerate([5.0, 3.5, 3.0, 2.0, 1.0, 0.5, 0.5])]
    split = shares(kernels, 2)
    assert sorted(k.function for share in split for k in share) == sorted(
        k.function for k in kernels)
    longest = max(sum(k.seconds for k in share) for share in split)
    best = min(
        max(sum(k.seconds for k, side in zip(kernels, sides, strict=True) if side == s)
            for s in (0, 1))
        for sides in itertools.product((0, 1), repeat=len(kernels))
    )
    assert best <= longest <= best + max(k.seconds for k in kernels)
    assert shares(kernels, 2) == split  # deterministic


def _files(folder: Path, names: dict[str, str]) -> None:
    for name, text in names.items():
        (folder / name).write_text(text)


def test_publish_adds_only_functions_that_numba_has_no_file_of(tmp_path):
    worker, cache = tmp_path / "worker", tmp_path / "cache"
    worker.mkdir()
    cache.mkdir()
    _files(worker, {
        "merge._a-10.py311.nbi": "index a", "merge._a-10.py311.1.nbc": "code a",
        "merge._b-20.py311.nbi": "index b", "merge._b-20.py311.1.nbc": "code b",
        "merge._c-30.py311.nbi": "index c", "merge._c-30.py311.1.nbc": "code c",
        "merge._c-30.py311.2.nbc": "code c2",
    })
    # numba wrote b's index already, and c's second data file (its own signature).
    _files(cache, {"merge._b-20.py311.nbi": "numba index b",
                   "merge._c-30.py311.2.nbc": "numba code c"})
    assert publish(worker, cache) == 1
    found = {path.name: path.read_text() for path in cache.iterdir()}
    assert found == {
        "merge._a-10.py311.nbi": "index a", "merge._a-10.py311.1.nbc": "code a",
        "merge._b-20.py311.nbi": "numba index b", "merge._c-30.py311.2.nbc": "numba code c",
    }
    assert publish(worker, cache) == 0  # a second worker: everything is there


def test_publish_never_leaves_an_index_without_its_data(tmp_path, monkeypatch):
    worker, cache = tmp_path / "worker", tmp_path / "cache"
    worker.mkdir()
    _files(worker, {"f-1.py311.nbi": "index", "f-1.py311.1.nbc": "code"})
    real_link = kernel_cache.os.link

    def racing_link(source, target):  # another process saves the data file first
        if Path(target).name.endswith(".nbc"):
            Path(target).write_text("theirs")
        real_link(source, target)

    monkeypatch.setattr(kernel_cache.os, "link", racing_link)
    assert publish(worker, cache) == 0
    assert {path.name: path.read_text() for path in cache.iterdir()} == {
        "f-1.py311.1.nbc": "theirs"}


def test_switch_off_or_one_cpu_compiles_nothing_here(monkeypatch):
    def no_process(*args, **kwargs):
        raise AssertionError("no worker may start")

    monkeypatch.setattr(kernel_cache, "start_worker", no_process)
    monkeypatch.setattr(kernel_cache, "uncached", list)
    monkeypatch.setattr(kernel_cache, "compile_kernels", no_process)
    monkeypatch.setenv(kernel_cache.SWITCH, "0")
    assert kernel_cache.warm_kernel_cache(workers=1) is False
    monkeypatch.setenv(kernel_cache.SWITCH, "1")
    monkeypatch.setattr(kernel_cache.os, "cpu_count", lambda: 1)
    assert kernel_cache.warm_kernel_cache() is False


def test_an_interruption_stops_the_workers_at_once(monkeypatch):
    class Worker:
        killed = joined = False

        def __init__(self, *args, **kwargs):
            workers.append(self)

        def kill(self):
            self.killed = True

        def join(self, timeout=None):
            self.joined = True

        def is_alive(self):
            return not self.killed

    def interrupted(kernels):
        raise KeyboardInterrupt

    workers: list[Worker] = []
    monkeypatch.setenv(kernel_cache.SWITCH, "1")
    monkeypatch.setattr(kernel_cache, "start_worker", Worker)
    monkeypatch.setattr(kernel_cache, "uncached", list)
    monkeypatch.setattr(kernel_cache, "compile_kernels", interrupted)
    with pytest.raises(KeyboardInterrupt):
        kernel_cache.warm_kernel_cache(workers=2)
    assert len(workers) == 2
    assert all(worker.killed and worker.joined for worker in workers)


def test_a_kernel_that_cannot_be_compiled_is_left_to_lazy_compilation():
    kernel_cache.compile_kernels([
        Kernel("semistatic.frames.no_such_kernel", ("float64",), 0.1),
        Kernel("semistatic.frames.wrap_angle_compiled", ("complex128",), 0.1),
    ])


_PROBE = """
import numba


@numba.njit(cache=True)
def twice(x):
    return {factor} * x


@numba.njit(cache=True)
def helper(x):
    return x + 1.0
"""


def test_a_kernel_is_uncached_until_compiled_and_again_once_its_source_changes(
        tmp_path, monkeypatch):
    import importlib
    import os

    source = tmp_path / "cache_probe_module.py"
    source.write_text(_PROBE.format(factor="2.0"))
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("cache_probe_module")
    folder = Path(module.twice.stats.cache_path)
    try:
        kernel = Kernel("cache_probe_module.twice", ("float64",), 0.1)
        assert kernel_cache.uncached([kernel]) == [kernel]  # never compiled
        assert module.twice(1.5) == 3.0  # compiled and saved
        assert module.helper(1.0) == 2.0
        assert kernel_cache.uncached([kernel]) == []
        assert kernel_cache.remove_obsolete([kernel]) == 0  # current files stay
        assert len(list(folder.glob("cache_probe_module.*.nb?"))) == 4  # index + data each
        # An upgrade: the module's source changes, a new process loads the new version.
        source.write_text(_PROBE.format(factor="3.0"))
        stat = source.stat()  # a new time too: numba hashes a file again when it changes
        os.utime(source, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
        module = importlib.reload(module)
        assert kernel_cache.uncached([kernel]) == [kernel]
        assert kernel_cache.remove_obsolete([kernel]) == 4  # the helper's files too
        assert not list(folder.glob("cache_probe_module.*.nb?"))
        assert module.twice(1.5) == 4.5
    finally:
        sys.modules.pop("cache_probe_module", None)


def test_no_worker_is_forked_beside_other_threads_or_in_a_daemonic_process(monkeypatch):
    def no_process(*args, **kwargs):
        raise AssertionError("no worker may start")

    monkeypatch.setenv(kernel_cache.SWITCH, "1")
    monkeypatch.setattr(kernel_cache, "start_worker", no_process)
    monkeypatch.setattr(kernel_cache, "uncached", list)
    monkeypatch.setattr(kernel_cache, "compile_kernels", no_process)
    monkeypatch.setattr(kernel_cache.threading, "active_count", lambda: 2)
    assert kernel_cache.warm_kernel_cache(workers=1) is False
    monkeypatch.setattr(kernel_cache.threading, "active_count", lambda: 1)
    monkeypatch.setattr(kernel_cache.multiprocessing, "current_process",
                        lambda: SimpleNamespace(daemon=True))
    assert kernel_cache.warm_kernel_cache(workers=1) is False


# Two cheap kernels of two modules: one share each, this process's and a forked worker's.
_FORK_SCRIPT = """
import os, sys
from semistatic import kernel_cache
from semistatic.kernel_cache import Kernel

kernels = [
    Kernel("semistatic.polyline._run_boxes", ("array(float64, 2)", "array(int64, 1)"), 1.0),
    Kernel("robots.ekf._stacked_pairs", ("array(float64, 2)", "array(float64, 3)",
           "array(float64, 2)", "array(float64, 3)", "array(int64, 1)", "array(int64, 1)"), 1.0),
]
kernel_cache.load_kernels = lambda path=None: kernels
print(kernel_cache.warm_kernel_cache(workers=1))
print(len(kernel_cache.uncached(kernels)))
print(sorted(len(kernel.dispatcher().overloads) for kernel in kernels))
"""


def test_a_forked_worker_compiles_its_share_into_the_cache(tmp_path):
    import os
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-c", _FORK_SCRIPT], capture_output=True, text=True, check=True,
        env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), kernel_cache.SWITCH: "1"},
        cwd=Path(__file__).resolve().parents[2],
    )
    started, cold, overloads = result.stdout.split("\n")[:3]
    assert started == "True"
    assert cold == "0"  # both kernels are in numba's cache now
    assert overloads == "[0, 1]"  # one compiled here, the other only by the worker
