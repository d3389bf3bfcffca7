"""The numba conventions every compiled kernel of footsim follows: :func:`compiled` (the
decorator) and :func:`typed_entry` (a kernel's entry point for fixed argument types).

Kernels replace pure-Python code and do the same float operations in the same order (no
fast-math, so no contraction into fused multiply-adds), so their results are bit-identical to
that code; the tests keep the Python code as the reference and check the kernels against it.

Compiled code is cached on disk (``cache=True``: ``NUMBA_CACHE_DIR`` if set, else next to the
kernel's source file, else numba's user-wide cache directory; without any writable one, each
process compiles again, with a warning).  A process without a cache compiles on first use
(seconds, see ``docs/BENCHMARKS.md``).  ``NUMBA_DISABLE_JIT=1`` runs the kernels as plain Python.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
from numba import njit

F = TypeVar("F", bound=Callable[..., Any])

_uncached: list[str] = []


def compiled(func: F) -> F:
    """``njit(cache=True)``; without the on-disk cache (a warning, compiled once per process) where
    numba finds no writable cache directory: a read-only install, no writable home directory and
    no ``NUMBA_CACHE_DIR``."""
    try:
        return cast(F, njit(cache=True)(func))  # a numba Dispatcher: called like func
    except RuntimeError as err:  # numba: "cannot cache function ...: no locator available ..."
        if not _uncached:
            warnings.warn(
                f"footsim.compiled: {err}; compiling without a cache "
                "(set NUMBA_CACHE_DIR to a writable directory to keep the compiled code)",
                RuntimeWarning,
                stacklevel=2,
            )
        _uncached.append(func.__name__)
        return cast(F, njit(func))


def typed_entry(kernel: Callable[..., Any], *example: Any) -> Callable[..., Any]:
    """``kernel``'s compiled code for exactly the argument types of ``example``, callable without
    numba's per-call type resolution: about 0.5 µs less a call in a tight loop, and more where a
    physics step has left the caches cold.  For per-tick loops whose argument types never change
    (the caller guarantees that; other types are not checked).  Getting it costs ~0.1 ms (numba's
    compile lock), so get it once, not per double step.  The kernel itself where numba offers no
    entry point (``NUMBA_DISABLE_JIT=1``)."""
    compile_for = getattr(kernel, "compile", None)
    if compile_for is None:
        return kernel
    entry = compile_for(tuple(numba.typeof(a) for a in example))
    return entry if callable(entry) else kernel
