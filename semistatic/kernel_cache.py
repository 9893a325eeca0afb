"""Compile the numba kernels missing from the cache on every core before a run.

The kernels compile on first use and are cached on disk (``@njit(cache=True)``), so the
first run after installation compiles them all, one after the other on one core, and so
does the first run after an upgrade or an edit changed their source files (numba stamps
its cache files with a hash of their source file). When kernels are missing from
the cache, :func:`warm_kernel_cache` compiles them in parallel instead: this process
compiles one share of them, ``os.cpu_count() - 1`` worker processes the others, each
worker into a private cache directory that it then publishes into numba's cache without
replacing any file there (:func:`publish`; obsolete files of a changed source file are
deleted first, :func:`remove_obsolete`). The run that follows loads those kernels from
the cache. The machine code is the same whichever process compiles it: results do not
change.

Workers are forked: a fork starts in milliseconds with numba set up and the kernels'
modules imported, where a fresh interpreter would spend ~1.5 s of the wait importing
them. Where no worker can be forked (see :func:`_may_fork`), the kernels compile lazily,
one after the other.

Why private directories: numba writes each cache file to a temporary name and renames it
(atomic), but a function's index (signature -> data file) is read, extended and written
back, so two processes saving *different* signatures of one function at the same time can
both give theirs the same data file: one of them would later load the other's code.

Which kernels, with which argument types, is recorded in ``kernel_signatures.toml``
beside this module by ``python -m benchmarks.kernel_warmup --record`` (the signatures a
first ``semistatic run`` compiles; a slow test checks the file against a fresh compile).
A kernel missing from it, a worker that fails or a cache that cannot be written leaves
the kernel to numba's lazy compilation, as without this module.
``SEMISTATIC_PARALLEL_COMPILE=0`` turns it off.

Examples
--------
>>> [type_text(parse_type(text)) for text in ("float64", "readonly array(float64, 1)")]
['float64', 'readonly array(float64, 1)']
>>> [[kernel.function for kernel in share] for share in shares([
...     Kernel("m.a", (), 3.0), Kernel("n.b", (), 2.0), Kernel("o.c", (), 2.0)], 2)]
[['m.a'], ['n.b', 'o.c']]
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing
import os
import re
import shutil
import sys
import tempfile
import threading
import tomllib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from semistatic.cache_healing import HealingCache, heal
from semistatic.frames import wrap_angle_compiled

__all__ = [
    "SIGNATURES_FILE",
    "SWITCH",
    "Kernel",
    "compile_kernels",
    "load_kernels",
    "parse_type",
    "publish",
    "remove_obsolete",
    "shares",
    "start_worker",
    "type_text",
    "uncached",
    "warm_kernel_cache",
]

SIGNATURES_FILE = Path(__file__).with_name("kernel_signatures.toml")
"""The kernels a first run compiles: function, argument types, compile seconds."""

SWITCH = "SEMISTATIC_PARALLEL_COMPILE"
"""Environment variable: ``0`` compiles lazily in the run, one kernel after the other."""

WORKER_TIMEOUT_S = 120.0
"""A worker still compiling after this long is stopped (its kernels compile lazily)."""

WORKER_START_S = 0.1
"""What a worker's share costs the run beyond compiling it (forking, publishing, loading
its kernels back from the cache): its share is that much smaller (measured, 2 cores)."""

_SCALARS = ("bool", "float64", "int64")
_ARRAY = re.compile(r"(readonly )?array\((bool|float64|int64), ([1-9])\)")


@dataclass(frozen=True)
class Kernel:
    """A compiled function and one signature: ``module.qualname``, argument types, cost.

    Examples
    --------
    >>> Kernel("semistatic.frames.wrap_angle_compiled", ("float64",), 0.05).module
    'semistatic.frames'
    """

    function: str
    arguments: tuple[str, ...]
    seconds: float

    @property
    def module(self) -> str:
        """The module that defines the function."""
        return self.function.rpartition(".")[0]

    def dispatcher(self) -> object:
        """Return the compiled function the record names (imported by its name).

        Examples
        --------
        >>> kernel = Kernel("semistatic.frames.wrap_angle_compiled", ("float64",), 0.05)
        >>> kernel.dispatcher().py_func.__name__
        'wrap_angle_compiled'
        """
        module = importlib.import_module(self.module)
        return getattr(module, self.function.rpartition(".")[2])


def parse_type(text: str) -> object:
    """Return the numba type ``text`` names (:func:`type_text`'s format, C-contiguous arrays).

    Examples
    --------
    >>> parse_type("array(int64, 2)")
    Array(int64, 2, 'C', False, aligned=True)
    """
    from numba import types

    if text in _SCALARS:
        return getattr(types, "boolean" if text == "bool" else text)
    match = _ARRAY.fullmatch(text)
    if match is None:
        raise ValueError(f"{SIGNATURES_FILE.name}: unknown argument type {text!r}")
    readonly, dtype, ndim = match.groups()
    return types.Array(parse_type(dtype), int(ndim), "C", readonly=bool(readonly))


def type_text(numba_type: object) -> str:
    """Return the text :func:`parse_type` reads back as ``numba_type``.

    Examples
    --------
    >>> import numpy as np, numba
    >>> type_text(numba.typeof(np.zeros((2, 2), dtype=bool)))
    'array(bool, 2)'
    """
    text = str(numba_type)
    if text in _SCALARS:
        return text
    if getattr(numba_type, "layout", None) != "C" or not numba_type.aligned:
        raise ValueError(f"no text for {numba_type!r}: only C-contiguous aligned arrays")
    readonly = "" if numba_type.mutable else "readonly "
    return f"{readonly}array({numba_type.dtype}, {numba_type.ndim})"


def load_kernels(path: Path = SIGNATURES_FILE) -> list[Kernel]:
    """Return the kernels recorded in ``path`` (empty if the file is missing).

    Examples
    --------
    >>> any(kernel.function.endswith("._merge_all") for kernel in load_kernels())
    True
    """
    if not path.exists():
        return []
    table = tomllib.loads(path.read_text())
    return [Kernel(row["function"], tuple(row["arguments"]), float(row["seconds"]))
            for row in table.get("kernel", [])]


def shares(kernels: Sequence[Kernel], count: int, head_start: float = 0.0) -> list[list[Kernel]]:
    """Split ``kernels`` into ``count`` shares of about equal compile time.

    The kernels of one module stay together (they call the same helpers, which every
    process that needs them compiles again); modules go longest first to the share with
    the least so far (ties to the lower share). Share 0 is this process's; the others
    start ``head_start`` seconds behind it (a worker's start-up).

    Examples
    --------
    >>> [[k.function for k in share] for share in shares(
    ...     [Kernel("m.a", (), 4.0), Kernel("n.b", (), 3.0), Kernel("n.c", (), 2.0)], 2, 1.0)]
    [['n.b', 'n.c'], ['m.a']]
    """
    modules: dict[str, list[Kernel]] = {}
    for kernel in kernels:
        modules.setdefault(kernel.module, []).append(kernel)
    loads = [0.0] + [head_start] * (count - 1)
    split: list[list[Kernel]] = [[] for _ in range(count)]
    for name in sorted(modules, key=lambda name: (-sum(k.seconds for k in modules[name]), name)):
        least = loads.index(min(loads))
        split[least] += modules[name]
        loads[least] += sum(kernel.seconds for kernel in modules[name])
    return split


def _index_state(dispatcher: object) -> str:
    """Return ``"current"``, ``"obsolete"`` or ``"missing"``: numba's cache index of a function.

    numba's own reading of the index: an index written for another version of the
    source file (or of numba) loads as empty, and numba compiles the function again.
    A function numba does not cache reads ``"current"`` (nothing to compile ahead). An
    unreadable index is deleted and reads ``"missing"`` (:mod:`semistatic.cache_healing`).
    """
    heal(dispatcher)  # a kernel of a module its package's import did not heal
    cache = dispatcher._cache
    if not isinstance(cache, HealingCache) or cache.index():
        return "current"
    cache_file = cache._cache_file
    return "obsolete" if os.path.exists(cache_file._index_path) else "missing"


def uncached(kernels: Iterable[Kernel]) -> list[Kernel]:
    """Return the ``kernels`` numba's cache cannot load (a first run, or source changed since).

    Examples
    --------
    >>> uncached([])
    []
    """
    return [kernel for kernel in kernels if _index_state(kernel.dispatcher()) != "current"]


def remove_obsolete(kernels: Iterable[Kernel]) -> int:
    """Delete numba's cache files of every source file with an obsolete kernel index.

    numba stamps every cache file of a source file with a hash of that file, so when one
    kernel's index is obsolete all of them are: numba would overwrite them on its next
    save. Removed first, they leave the names free for :func:`publish`, which
    never replaces a file. Returns how many files went.

    Examples
    --------
    >>> remove_obsolete([])
    0
    """
    removed = 0
    done: set[tuple[str, str]] = set()
    for kernel in kernels:
        dispatcher = kernel.dispatcher()
        source = (dispatcher.stats.cache_path,
                  Path(dispatcher.py_func.__code__.co_filename).stem)
        if source in done or _index_state(dispatcher) != "obsolete":
            continue
        done.add(source)
        folder, stem = source
        for path in Path(folder).glob(f"{stem}.*"):
            if path.suffix in (".nbi", ".nbc"):
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
                    removed += 1
    return removed


def _link_new(source: Path, target: Path) -> bool:
    """Put a copy of ``source`` at ``target`` unless a file is there; return whether it did."""
    staged = target.with_name(f"{target.name}.{os.getpid()}.staged")
    shutil.copyfile(source, staged)
    try:
        os.link(staged, target)  # atomic, and fails rather than replace a file
    except FileExistsError:
        return False
    finally:
        staged.unlink()
    return True


def publish(private: Path, public: Path) -> int:
    """Add a worker's cache files of one source directory to numba's; return functions added.

    A function is added only where numba's cache has none of its files: its data files
    first, then its index, each linked in under its name only while that name is free,
    so no file of another process is ever replaced and an index published here names only
    data published with it. Anything else stays for numba to compile lazily.

    Examples
    --------
    >>> with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
    ...     for name in ("f-1.py311.nbi", "f-1.py311.1.nbc", "g-9.py311.nbi"):
    ...         _ = (Path(a) / name).write_text("worker")
    ...     _ = (Path(b) / "g-9.py311.nbi").write_text("numba")
    ...     added = publish(Path(a), Path(b))
    ...     names = sorted(path.name for path in Path(b).iterdir())
    ...     added, names, (Path(b) / "g-9.py311.nbi").read_text()
    (1, ['f-1.py311.1.nbc', 'f-1.py311.nbi', 'g-9.py311.nbi'], 'numba')
    """
    public.mkdir(parents=True, exist_ok=True)
    existing = {path.name for path in public.iterdir()}
    added = 0
    for index in sorted(private.glob("*.nbi")):
        base = index.name.removesuffix(".nbi")
        data = sorted(path for path in private.iterdir()
                      if path.name.startswith(base + ".") and path.name.endswith(".nbc"))
        if any(name.startswith(base + ".") for name in existing):
            continue
        if all(_link_new(path, public / path.name) for path in data) and _link_new(
            index, public / index.name
        ):
            added += 1
    return added


def compile_kernels(kernels: Iterable[Kernel]) -> None:
    """Compile each kernel for its recorded argument types, in this process.

    Examples
    --------
    >>> compile_kernels([Kernel("semistatic.frames.wrap_angle_compiled", ("float64",), 0.05),
    ...                  Kernel("semistatic.frames.no_such_kernel", ("float64",), 0.05)])
    """
    for kernel in kernels:
        # Any failure (a kernel renamed or retyped since the file was recorded) leaves
        # that kernel to lazy compilation, where a real error shows itself.
        with contextlib.suppress(Exception):
            kernel.dispatcher().compile(tuple(parse_type(text) for text in kernel.arguments))


def _redirect_caches(folder: str) -> None:
    """Make every compiled function loaded in this process cache into ``folder`` from now on.

    numba picks a function's cache directory when the function is defined (from
    ``numba.config.CACHE_DIR``); a forked worker inherits the parent's choice, numba's
    own cache, which it must not write to.
    """
    import numba
    from numba.core.caching import FunctionCache
    from numba.core.dispatcher import Dispatcher

    numba.config.CACHE_DIR = folder
    for module in list(sys.modules.values()):
        # getattr: sys.modules may hold None (an import known to fail) or proxies.
        for value in list(getattr(module, "__dict__", {}).values()):
            if isinstance(value, Dispatcher) and isinstance(value._cache, FunctionCache):
                value.enable_caching()


def _worker(kernels: list[Kernel], folders: dict[str, str], private: str) -> None:
    """Compile ``kernels`` into the cache directory ``private``, then publish it.

    Runs in a forked worker. ``folders`` maps each kernel module to its directory in
    numba's cache. Any failure leaves the kernels to lazy compilation.
    """
    try:
        _redirect_caches(private)
        compile_kernels(kernels)
        done: set[tuple[str, str]] = set()
        for kernel in kernels:
            folder = kernel.dispatcher().stats.cache_path
            pair = (folder, folders[kernel.module])
            if pair not in done and os.path.isdir(folder):
                done.add(pair)
                publish(Path(folder), Path(pair[1]))
    except BaseException:
        # Quietly (no traceback from the fork): the run compiles what is missing itself.
        os._exit(1)


def _may_fork() -> bool:
    """Return whether this process may fork compile workers.

    Not where the platform cannot fork, not in a daemonic process (a pool's worker may
    have no children; its pool already uses the other cores) and not beside other Python
    threads (a lock one of them holds at the fork would stay held in the worker).
    """
    return ("fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon
            and threading.active_count() == 1)


def start_worker(kernels: list[Kernel], folders: dict[str, str],
                 private: Path) -> multiprocessing.Process:
    """Fork a process that compiles ``kernels`` into ``private`` and publishes them.

    ``folders`` maps each kernel's module to its directory in numba's cache; any failure
    leaves the kernels to lazy compilation.

    Examples
    --------
    >>> with tempfile.TemporaryDirectory() as private:
    ...     worker = start_worker([], {}, Path(private))
    ...     worker.join()
    >>> worker.exitcode
    0
    """
    process = multiprocessing.get_context("fork").Process(
        target=_worker, args=(kernels, folders, str(private)), daemon=True)
    process.start()
    return process


def warm_kernel_cache(workers: int | None = None) -> bool:
    """Set numba up, then compile the recorded kernels the cache cannot load, in parallel.

    numba sets up its compiler and type registries on a process's first compiled call
    (~0.1 s with cached kernels, ~0.25 s without): done here first, before a run's clock
    starts and before any worker is forked (the workers inherit it). Returns whether
    kernels were compiled: not (``False``) when the cache can load every recorded kernel,
    with fewer than two CPUs, where no worker can be forked or with
    ``SEMISTATIC_PARALLEL_COMPILE=0``. ``workers``: how many worker processes (default
    ``os.cpu_count() - 1``).

    Examples
    --------
    >>> warm_kernel_cache(workers=0)  # no worker: nothing to share the compilation with
    False
    """
    wrap_angle_compiled(0.0)  # numba's set-up: any compiled call does it
    count = (os.cpu_count() or 1) if workers is None else workers + 1
    kernels = load_kernels()
    if (os.environ.get(SWITCH, "1") == "0" or count < 2 or not kernels
            or not _may_fork()):
        return False
    try:
        kernels = uncached(kernels)
        if not kernels:
            return False
        folders = {kernel.module: kernel.dispatcher().stats.cache_path for kernel in kernels}
        remove_obsolete(kernels)
    except (OSError, ImportError, AttributeError):
        return False  # a cache numba cannot locate, or a kernel renamed: compile lazily
    with tempfile.TemporaryDirectory(prefix="semistatic-kernels-") as scratch:
        started = []
        split = shares(kernels, count, WORKER_START_S)
        for share in range(1, count):
            if split[share]:
                with contextlib.suppress(OSError):
                    started.append(start_worker(split[share], folders,
                                                Path(scratch) / str(share)))
        try:
            compile_kernels(split[0])
        except BaseException:
            # Interrupted (Ctrl-C reaches a worker only from a terminal): stop the workers
            # now rather than wait for them. A worker stopped while publishing leaves no
            # file half-written (each is linked in whole).
            for process in started:
                process.kill()
            raise
        finally:
            for process in started:
                process.join(timeout=WORKER_TIMEOUT_S)
                if process.is_alive():
                    process.kill()
                    process.join()
    return True
