"""A damaged numba cache file is deleted and recompiled, not a crash (cache_healing.py)."""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from semistatic.cache_healing import HealingCache

ROOT = Path(__file__).resolve().parents[2]

# Two kernels of one module (robots.path: _cubic_rows calls _cubic_at, so both are
# cached, in one folder); the printed values are compared with a clean cache's.
_SCRIPT = """
import numpy as np
from robots.path import _cubic_at, _cubic_rows

breaks = np.array([0.0, 1.0, 2.0])
coefficients = np.arange(16.0).reshape(4, 2, 2) / 7.0
print(_cubic_rows(breaks, coefficients, np.linspace(-0.5, 2.5, 7)))
print(_cubic_at(breaks, coefficients, 1.25, 1))
"""


def _run(cache: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", _SCRIPT], capture_output=True, text=True, timeout=300,
        env={**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}, cwd=ROOT,
    )


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A private cache holding both kernels, and what the script prints with it."""
    cache = tmp_path_factory.mktemp("clean") / "numba"
    first = _run(cache)
    assert first.returncode == 0, first.stderr
    again = _run(cache)  # loaded from the cache now
    assert (again.returncode, again.stdout, again.stderr) == (0, first.stdout, "")
    return cache, first.stdout


def _file(cache: Path, pattern: str) -> Path:
    (path,) = cache.glob(f"*/{pattern}")
    return path


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 3])


def _garble(path: Path) -> None:
    # Seeded: a few random byte strings in a million unpickle to a foreign numba version,
    # which numba itself reads as an obsolete index (recompiled quietly).
    path.write_bytes(random.Random(0).randbytes(path.stat().st_size))


def _foreign_index(path: Path) -> None:
    (other,) = path.parent.glob("path._cubic_at-*.nbi")
    shutil.copyfile(other, path)


def _foreign_data(path: Path) -> None:
    (other,) = path.parent.glob("path._cubic_at-*.1.nbc")
    shutil.copyfile(other, path)


@pytest.mark.slow  # four cold compiles of two kernels in fresh interpreters: ~20 s
@pytest.mark.parametrize(("pattern", "damage", "reason"), [
    ("path._cubic_rows-*.1.nbc", _truncate, "UnpicklingError"),
    ("path._cubic_rows-*.nbi", _garble, ""),  # random bytes: whichever error pickle meets
    ("path._cubic_rows-*.nbi", _foreign_index, "the index of another function"),
    ("path._cubic_rows-*.1.nbc", _foreign_data, "the compiled code of another function"),
], ids=["truncated data", "garbled index", "foreign index", "foreign data"])
def test_a_damaged_cache_file_is_deleted_and_compiled_again(
        clean, tmp_path, pattern, damage, reason):
    cache = tmp_path / "numba"
    shutil.copytree(clean[0], cache)
    path = _file(cache, pattern)
    damage(path)
    healed = _run(cache)
    assert healed.returncode == 0, healed.stderr
    assert healed.stdout == clean[1]  # the results of a clean cache
    (line,) = healed.stderr.splitlines()  # one line
    assert line.startswith(f"warning: {path}: bad numba cache file (")
    assert reason in line
    assert line.endswith("deleted, robots.path._cubic_rows compiled again")
    again = _run(cache)  # saved afresh: loaded quietly
    assert (again.returncode, again.stdout, again.stderr) == (0, clean[1], "")


def test_every_cached_kernel_of_the_packages_gets_a_healing_cache():
    import robots
    import semistatic

    cached = [value for package in (semistatic, robots) for name, module in sys.modules.items()
              if name.startswith(package.__name__ + ".")
              for value in list(vars(module).values())
              if isinstance(value, numba.core.dispatcher.Dispatcher)
              and not isinstance(value._cache, numba.core.caching.NullCache)]
    assert len(cached) > 20
    assert all(isinstance(dispatcher._cache, HealingCache) for dispatcher in cached)


def test_an_interrupted_load_is_not_taken_for_a_damaged_file(monkeypatch, tmp_path, capsys):
    from semistatic.frames import wrap_angle_compiled

    cache = wrap_angle_compiled._cache
    index = tmp_path / "f.nbi"
    index.write_bytes(b"healthy")

    def interrupted():
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise SystemError("returned a result with an exception set") from interrupt

    monkeypatch.setattr(cache._cache_file, "_load_index", interrupted)
    monkeypatch.setattr(cache._cache_file, "_index_path", str(index))
    with pytest.raises(SystemError):
        cache.index()
    assert index.exists()
    assert capsys.readouterr().err == ""
