"""The numba conventions every compiled kernel of footsim follows: :func:`compiled` (the
decorator), :func:`typed_entry` (a kernel's entry point for fixed argument types) and
:func:`pack` (a kernel's arguments held by one object, for per-tick calls).

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
from numba.core import types
from numba.experimental import structref
from numba.extending import overload

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


# -- packed arguments -----------------------------------------------------------------------------


@structref.register
class PackedType(types.StructRef):
    """numba's type of a :class:`Packed`: one field, ``args``, typed as the packed tuple."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


class Packed(structref.StructRefProxy):
    """A tuple of arguments held by one compiled object (:func:`pack`); compiled code reads it as
    ``packed.args``."""

    __slots__ = ()


structref.define_boxing(PackedType, Packed)


class _PythonPacked:
    """:func:`pack`'s object under ``NUMBA_DISABLE_JIT=1``: the tuple as its attribute ``args``."""

    __slots__ = ("args",)
    _numba_type_ = None  # no compiled code to type (typed_entry gives the kernel itself)

    def __init__(self, args: tuple):
        self.args = args


def _packed(args):
    return _PythonPacked(args)


@overload(_packed)
def _packed_compiled(args):
    packed_type = PackedType([("args", args)])

    def new(args):
        packed = structref.new(packed_type)
        packed.args = args
        return packed

    return new


@compiled
def _pack(args):
    return _packed(args)


def pack(args: tuple) -> Any:
    """``args`` (a tuple of a kernel's arguments: arrays, numbers, None, tuples of them) held by one
    compiled object, read in compiled code as ``packed.args`` (e.g. ``kernel(k, *packed.args)``).

    A compiled call unboxes each array argument: numba wraps it in a new reference (an allocation,
    freed at return) and reads its shape and strides, ~0.1–0.3 µs per array, more when a physics
    step has left the caches cold.  A kernel called at every control tick with some twenty arrays
    that do not change between ticks takes them packed once instead: one argument to unbox per
    call.  The arrays are the same objects (their buffers, not copies); the pack keeps them alive.
    ``numba.typeof(packed)`` is ``packed._numba_type_`` (cheaper: no type dispatch), the key for
    :func:`typed_entry`."""
    return _pack(args)
