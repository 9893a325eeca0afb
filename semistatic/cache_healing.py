"""numba's on-disk kernel cache, made to recompile a damaged entry instead of crashing.

numba caches each ``@njit(cache=True)`` function in an index file (``*.nbi``: pickled
numba version, source stamp and signature -> data file name) and one data file per
signature (``*.nbc``: the pickled compile result). It trusts them: a truncated data file
raises ``UnpicklingError`` ("pickle data was truncated") from
``IndexDataCacheFile._load_data``, a garbled index ``UnpicklingError`` (or ``EOFError``,
``ValueError``...) from ``IndexDataCacheFile._load_index``, both through
``Cache.load_overload`` out of the kernel's first call, in every run until the file is
deleted by hand. A data file of another function copied over is worse: numba loads it
and runs the other function's machine code (a ``TypeError`` at best).

:class:`HealingCache` is numba's ``FunctionCache`` with a load that treats any of this as
a cache miss: the bad file is deleted with one line on stderr (``warning: <file>: ...;
deleted, <function> compiled again``), numba compiles the function as on a first run and
saves it afresh, and the results are those of a clean cache. :func:`heal_kernels` gives
the compiled functions of a package this cache; the ``semistatic`` and ``robots``
packages call it at the end of their import, before any kernel can run.

Why a load hook rather than checking the cache files ahead: a file is only known good
once numba's own loader has read it, so a check ahead would unpickle every data file a
second time on every start (~0.13 s for the mapper's ~90 files) or unpickle them in a new
place; the hook costs nothing on a healthy cache, reads nothing numba would not read, and
catches the failure where it happens, whichever kernel or helper is loaded and whenever.
It relies on numba's ``Cache`` internals (``_cache_file``, ``_impl``, ``_index_key``,
unchanged since numba 0.49), as :mod:`semistatic.kernel_cache` already does.

What it cannot catch: machine code damaged inside a data file that still unpickles and
links (numba keeps no checksum); that needs a byte-level fault, not a truncation.

Examples
--------
>>> from semistatic.frames import wrap_angle_compiled
>>> type(wrap_angle_compiled._cache).__name__  # given by the package's import
'HealingCache'
>>> heal_kernels("semistatic")  # the package's kernels have it already
0
"""

from __future__ import annotations

import os
import re
import sys

from numba.core import sigutils
from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher

from semistatic.errors import caused_by_interrupt

__all__ = ["HealingCache", "heal", "heal_kernels"]


def _reason(error: BaseException) -> str:
    """One line: the exception's type and message."""
    text = " ".join(str(error).split())
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


class HealingCache(FunctionCache):
    """numba's cache of one function; an unreadable or foreign entry is deleted and missed.

    Mirrors numba's ``Cache._load_overload`` and ``IndexDataCacheFile.load`` step by step
    so that each step's failure names its own file.

    Examples
    --------
    >>> import numba
    >>> square = numba.njit(lambda x: x * x)  # no source file: numba cannot cache it
    >>> heal(square)
    False
    """

    def index(self) -> dict:
        """Return the function's index (signature key -> data file name), as numba reads it.

        Empty when there is none, when it is obsolete (another numba version or another
        version of the source file: numba's own reading) and when it is unreadable or
        lists another function's data files, which is deleted then.
        """
        cache_file = self._cache_file
        try:
            overloads = cache_file._load_index()
        except Exception as error:
            if caused_by_interrupt(error):
                raise
            self._discard(cache_file._index_path, _reason(error))
            return {}
        # The data files an index names carry its function's file name base: any other
        # name means an index copied from another function (numba would load that
        # function's code for a signature of this one).
        own = re.compile(re.escape(self._impl.filename_base) + r"\.[0-9]+\.nbc")
        if not isinstance(overloads, dict) or not all(
            isinstance(name, str) and own.fullmatch(name) for name in overloads.values()
        ):
            self._discard(cache_file._index_path, "the index of another function")
            return {}
        return overloads

    def load_overload(self, sig: object, target_context: object) -> object:
        """Return the cached compile result for ``sig``, or ``None`` (numba then compiles)."""
        target_context.refresh()  # as numba's load does first
        if not self._enabled:
            return None
        key = self._index_key(sig, target_context.codegen())
        name = self.index().get(key)
        if name is None:
            return None
        path = self._cache_file._data_path(name)
        try:
            payload = self._cache_file._load_data(name)
        except FileNotFoundError:
            return None  # deleted since the index was read: numba's own behaviour
        except Exception as error:
            if caused_by_interrupt(error):
                raise
            self._discard(path, _reason(error))
            return None
        # payload: (library, fndesc, environment, signature, ...) (CompileResult._reduce).
        # A data file copied from another function, or from another signature of this
        # one, unpickles fine: it must describe this function and these argument types.
        py_func = self._py_func
        try:
            fndesc, signature = payload[1], payload[3]
            foreign = (fndesc.qualname != py_func.__qualname__
                       or fndesc.modname != py_func.__module__
                       or tuple(signature.args) != tuple(sigutils.normalize_signature(sig)[0]))
        except Exception:
            foreign = True  # not a compile result at all
        if foreign:
            self._discard(path, "the compiled code of another function or signature")
            return None
        try:
            return self._impl.rebuild(target_context, payload)
        except Exception as error:
            if caused_by_interrupt(error):
                raise
            self._discard(path, _reason(error))
            return None

    def _discard(self, path: str, reason: str) -> None:
        """Delete the bad cache file ``path`` and say so in one line on stderr.

        numba then saves the function afresh under the same names. A file that cannot be
        deleted would be read again by that save (a bad index) or by the next run: the
        cache is turned off for this function in this process instead.
        """
        function = f"{self._py_func.__module__}.{self._py_func.__qualname__}"
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass  # another process healed it first
        except OSError as error:
            self.disable()
            reason += f"; cannot delete it ({error.strerror}), not cached in this run"
        print(f"warning: {path}: bad numba cache file ({reason}); deleted, "
              f"{function} compiled again", file=sys.stderr, flush=True)


def heal(dispatcher: object) -> bool:
    """Give a compiled function a :class:`HealingCache`; return whether it needed one.

    Only functions numba caches on disk (``cache=True``) and not given one already.

    Examples
    --------
    >>> from semistatic.frames import wrap_angle_compiled
    >>> heal(wrap_angle_compiled)  # already has one
    False
    """
    if not isinstance(dispatcher, Dispatcher) or type(dispatcher._cache) is not FunctionCache:
        return False
    dispatcher._cache = HealingCache(dispatcher.py_func)
    return True


def heal_kernels(package: str) -> int:
    """Give every cached compiled function of the loaded modules of ``package`` a healing cache.

    Call it after the modules that define kernels are imported and before any of them
    runs (a kernel loaded from the cache before stays loaded). Returns how many functions
    got one.

    Examples
    --------
    >>> heal_kernels("robots")  # given at the end of the robots package's import
    0
    """
    healed = 0
    for name, module in list(sys.modules.items()):
        if name == package or name.startswith(package + "."):
            # getattr: sys.modules may hold None (an import known to fail) or proxies.
            for value in list(getattr(module, "__dict__", {}).values()):
                healed += heal(value)
    return healed
