"""Compiled kernels: a loop over the batch's runs and actors, written once in plain Python
and compiled by numba the first time it is called.

Per-call numpy costs ~1-5 us whatever the array's size, so a step made of numpy calls is
bound by their count, not by the work (docs/twin.md, Batches). A kernel is one call per
phase over the whole batch. The same source runs interpreted as `kernel.py_func` (tests
check the compiled form gives its bits), so there is one definition of each computation.

The settings keep IEEE semantics, so a kernel gives the bits of the Python it was written
from: no fast-math (no reassociation, no fused multiply-add), numpy's error model (x / 0.0
is inf or nan as in numpy, not ZeroDivisionError). numba calls the C library for `math.sin`,
`math.exp`, `**` and the like, as CPython does; `math.hypot` is numba's own (it differs from
CPython's in the last bit): write `math.sqrt(x * x + y * y)` where that is meant, and
`hypot` (below: CPython's algorithm) where `math.hypot` was.

numba is imported at a kernel's first call, not at import (its import costs ~0.2-0.4 s that
a compile-only command should not pay). Compiled code is cached on disk (numba's `cache`:
beside the source, or numba's per-user cache directory where that is read-only), so a
process pays the compile (~0.3-1 s a kernel) only the first time on a machine.
"""

from __future__ import annotations

import functools
import math
import types
from typing import Callable

OPTIONS = {"cache": True, "error_model": "numpy", "fastmath": False, "nogil": True}


class Kernel:
    """A function compiled on first call (`numba.njit` with `OPTIONS`); `py_func` is the
    Python it was written as."""

    def __init__(self, fn: Callable):
        self.py_func = fn
        self._compiled: Callable | None = None
        functools.update_wrapper(self, fn)

    def __call__(self, *args):
        compiled = self._compiled
        if compiled is None:
            compiled = self.dispatcher()
        return compiled(*args)

    def compile(self) -> Callable:
        import numba

        fn = self.py_func
        callees = {name: fn.__globals__[name].dispatcher() for name in fn.__code__.co_names
                   if isinstance(fn.__globals__.get(name), Kernel)}
        if callees:  # numba types dispatchers, not this class: the kernels it calls, compiled
            fn = types.FunctionType(fn.__code__, {**fn.__globals__, **callees}, fn.__name__, fn.__defaults__,
                                    fn.__closure__)
            fn.__qualname__, fn.__module__ = self.py_func.__qualname__, self.py_func.__module__
        return numba.njit(**OPTIONS)(fn)

    def dispatcher(self) -> Callable:
        """The compiled function (compiling it now if it is not yet)."""
        if self._compiled is None:
            self._compiled = self.compile()
        return self._compiled

    def __reduce__(self):  # pickles by name (as the module-level function it is)
        return self.__qualname__


def kernel(fn: Callable) -> Kernel:
    """Mark a module-level function as a compiled kernel. A kernel may call other kernels by
    their module-level names (compiled, they are compiled in)."""
    return Kernel(fn)


@kernel
def hypot(x, y):
    """`math.hypot(x, y)` of CPython 3.11, bit for bit (its `vector_norm` of two floats:
    scaled by a power of two, squared exactly by Veltkamp-Dekker splitting, summed with
    their rounding errors, one Newton correction of the square root)."""
    x, y = abs(x), abs(y)
    most = x if x > y else y
    if math.isinf(x) or math.isinf(y):
        return math.inf
    if math.isnan(x) or math.isnan(y):
        return math.nan
    if most == 0.0:
        return 0.0
    e = math.frexp(most)[1]
    if e < -1023:  # (subnormal) 2 ** -e would overflow: divided by the larger
        csum, frac = 1.0, 0.0
        for v in (x, y):
            v = v / most
            v = v * v
            old = csum
            csum += v
            frac += (old - csum) + v
        return most * math.sqrt(csum - 1.0 + frac)
    scale = math.ldexp(1.0, -e)
    csum, frac1, frac2, frac3 = 1.0, 0.0, 0.0, 0.0
    for v in (x, y):
        v *= scale
        t = v * 134217729.0  # 2 ** 27 + 1
        hi = t - (t - v)
        lo = v - hi
        v = hi * hi
        old = csum
        csum += v
        frac1 += (old - csum) + v
        v = 2.0 * hi * lo
        old = csum
        csum += v
        frac2 += (old - csum) + v
        frac3 += lo * lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2 + frac3))
    t = h * 134217729.0
    hi = t - (t - h)
    lo = h - hi
    v = -hi * hi
    old = csum
    csum += v
    frac1 += (old - csum) + v
    v = -2.0 * hi * lo
    old = csum
    csum += v
    frac2 += (old - csum) + v
    v = -lo * lo
    old = csum
    csum += v
    frac3 += (old - csum) + v
    v = csum - 1.0 + (frac1 + frac2 + frac3)
    return (h + v / (2.0 * h)) / scale
