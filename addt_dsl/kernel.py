"""Compiled kernels: a loop over the batch's runs and actors, written once in plain Python
and compiled by numba the first time it is called.

Per-call numpy costs ~1-5 us whatever the array's size, so a step made of numpy calls is
bound by their count, not by the work (docs/twin.md, Batches). A kernel is one call per
phase over the whole batch. The same source runs interpreted as `kernel.py_func` (tests
check the compiled form gives its bits), so there is one definition of each computation.

The settings keep IEEE semantics, so a kernel gives the bits of the Python it was written
from, except a NaN's sign and payload (`bits`): no fast-math (no reassociation, no fused
multiply-add), numpy's error model (x / 0.0 is inf or nan as in numpy, not
ZeroDivisionError). numba calls the C library for `math.sin`, `math.exp`, `math.pow` and
the like, as CPython does, with two exceptions: `x ** 2` and
`x ** 2.0` become `x * x` (CPython's is the C library's `pow`, ~0.1 % of doubles differ):
write `pow(x, 2.0)` with this module's `pow` where the Python it replaces wrote `x ** 2`;
and `math.hypot` is the C library's where CPython has its own: use this module's `hypot`
(CPython's) or `c_hypot` (the C library's, as numpy's `np.hypot`), each the same compiled and
interpreted.

The module also holds what keeps a trace the same on another machine: the C library's
`exp`, `log`, `log2`, `atan`, `tan`, `atan2`, `pow` over arrays (`Libm.over`, where numpy's
ufuncs take AVX-512 code with other bits) and `matmul` in one summation order (where BLAS's
kernel, picked by the CPU, decides the order and the fused multiply-adds).

numba is imported at a kernel's first call, not at import (its import costs ~0.2-0.4 s that
a compile-only command should not pay). Compiled code is cached on disk, so a process pays
the compile (~0.3-1 s a kernel) only the first time for a version of the code: in a folder
per code fingerprint (`cache_dir`). numba's own cache checks only the kernel's own source
file, and a kernel has its callees' code and the constants it reads from other modules
compiled in: changed there, its cached code would be stale.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import shutil
import sys
import time
import types
from collections.abc import Callable
from pathlib import Path

OPTIONS = {"cache": True, "error_model": "numpy", "fastmath": False, "nogil": True}
_interpreting = False  # `interpreted()`: every kernel call runs its Python
_bound: list[Kernel] = []  # the compiled kernels (their calls go to the dispatcher but while interpreted)


@contextlib.contextmanager
def interpreted():
    """Within: kernels called from Python run their Python source, callees included (tests
    compare it with the compiled code's bits)."""
    global _interpreting
    before, _interpreting = _interpreting, True
    if not before:
        for k in _bound:
            k._unbind()
    try:
        yield
    finally:
        _interpreting = before
        if not before:
            for k in _bound:
                k._bind()


class Libm:
    """A C library function a kernel calls by a name of its own, so the compiler cannot
    rewrite it: LLVM turns `pow(x, 2.0)` into `x * x`, which the C library's `pow` is not
    (they differ in ~0.1 % of doubles), and CPython's `x ** 2.0` is the C library's."""

    def __init__(self, name: str, python: Callable, arity: int):
        self.name, self.python, self.arity = name, python, arity
        self._external = None

    def __call__(self, *args):
        return self.python(*args)

    def external(self):
        if self._external is None:
            import ctypes
            import ctypes.util

            import llvmlite.binding as llvm
            from numba import types as nt

            lib = ctypes.CDLL(ctypes.util.find_library("m") or ctypes.util.find_library("c"))
            symbol = "addt_libm_" + self.name
            llvm.add_symbol(symbol, ctypes.cast(getattr(lib, self.name), ctypes.c_void_p).value)
            self._external = nt.ExternalFunction(symbol, nt.float64(*[nt.float64] * self.arity))
        return self._external

    def over(self, *args):
        """The function elementwise over arrays (float64, broadcast as numpy does; a float64
        scalar where every argument is a scalar): numpy's ufunc of the same name with the C
        library's bits on every machine (one compiled call)."""
        import numpy as np

        first = args[0]
        if type(first) is np.ndarray and first.dtype == np.float64 and first.flags.c_contiguous and first.ndim \
                and all(type(a) is np.ndarray and a.dtype == np.float64 and a.shape == first.shape
                        and a.flags.c_contiguous for a in args[1:]):
            arrays = args  # (already what broadcasting would give: the common case, ~4 us less)
        else:
            arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in args))
        shape = arrays[0].shape
        flat = [a.reshape(-1) if a.flags.c_contiguous else np.ascontiguousarray(a).reshape(-1) for a in arrays]
        if _numba_loaded():
            out = np.empty(arrays[0].size)
            _OVER[self.name](*flat, out)
        else:  # (the same function value by value: a compile-only process does not load numba)
            out = np.fromiter(map(self.python, *(f.tolist() for f in flat)), np.float64, arrays[0].size)
        return out.reshape(shape) if shape else out[0]


class Kernel:
    """A function compiled on first call (`numba.njit` with `OPTIONS`); `py_func` is the
    Python it was written as.

    Each kernel is the one instance of a class of its own: once compiled, that class's
    `__call__` is the dispatcher itself (a call costs the dispatcher's own ~0.3-1 us, not a
    Python frame more), and `interpreted()` puts this class's `__call__` back meanwhile."""

    def __new__(cls, fn: Callable):
        return object.__new__(type(cls)(cls.__name__, (cls,), {"__module__": cls.__module__}))

    def __init__(self, fn: Callable):
        self.py_func = fn
        self._compiled: Callable | None = None
        self._compiling = False
        functools.update_wrapper(self, fn)

    def __call__(self, *args):
        if _interpreting:
            return self.py_func(*args)
        compiled = self._compiled
        if compiled is None:
            compiled = self.dispatcher()
        return compiled(*args)

    def _bind(self) -> None:
        """Calls go straight to the compiled dispatcher (while nothing is interpreted)."""
        type(self).__call__ = staticmethod(self._compiled)

    def _unbind(self) -> None:
        if "__call__" in type(self).__dict__:
            del type(self).__call__

    def compile(self) -> Callable:
        import numba

        fn = self.py_func
        callees = {name: fn.__globals__[name].dispatcher() for name in fn.__code__.co_names
                   if isinstance(fn.__globals__.get(name), Kernel)}
        callees.update({name: fn.__globals__[name].external() for name in fn.__code__.co_names
                        if isinstance(fn.__globals__.get(name), Libm)})
        if any(d is None for d in callees.values()):
            raise TypeError(f"kernel {fn.__qualname__} calls itself (write the recursion as a loop)")
        if callees:  # numba types dispatchers, not these classes: the kernels it calls, compiled
            fn = types.FunctionType(fn.__code__, {**fn.__globals__, **callees}, fn.__name__, fn.__defaults__,
                                    fn.__closure__)
            fn.__qualname__, fn.__module__ = self.py_func.__qualname__, self.py_func.__module__
        from numba.core import config

        before, config.CACHE_DIR = config.CACHE_DIR, cache_dir()  # (read as the dispatcher is made)
        try:
            return numba.njit(**OPTIONS)(fn)
        finally:
            config.CACHE_DIR = before

    def dispatcher(self) -> Callable | None:
        """The compiled function (compiling it now if it is not yet); None while it compiles."""
        if self._compiled is None:
            if self._compiling:
                return None
            self._compiling = True
            try:
                self._compiled = self.compile()
            finally:
                self._compiling = False
            _bound.append(self)
            if not _interpreting:
                self._bind()
        return self._compiled

    def __reduce__(self):  # pickles by name (as the module-level function it is)
        return self.__qualname__


@functools.cache
def cache_dir() -> str:
    """The folder of this code's compiled kernels: `<base>/kernels/<code fingerprint>`, base
    `$NUMBA_CACHE_DIR`, else the package's `__pycache__` where writable, else
    `~/.cache/addt-dsl`. Made on first use; folders of other versions not used for a day are
    removed then."""
    from addt_dsl.fingerprint import code_fingerprint

    if os.environ.get("NUMBA_CACHE_DIR"):
        base = Path(os.environ["NUMBA_CACHE_DIR"])
    elif os.access(Path(__file__).parent, os.W_OK):
        base = Path(__file__).parent / "__pycache__"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "addt-dsl"
    root = base / "kernels"
    here = root / code_fingerprint()
    if not here.is_dir():
        here.mkdir(parents=True, exist_ok=True)
        for old in root.iterdir():
            if old != here and old.is_dir() and time.time() - old.stat().st_mtime > 86400.0:
                shutil.rmtree(old, ignore_errors=True)
    return str(here)


def _numba_loaded() -> bool:
    """Whether this process has imported numba (a kernel has run): helpers that would call a
    kernel for a few values compute them in numpy or Python until then, the same bits."""
    return "numba" in sys.modules


def kernel(fn: Callable) -> Kernel:
    """Mark a module-level function as a compiled kernel. A kernel may call other kernels by
    their module-level names (compiled, they are compiled in)."""
    return Kernel(fn)


@functools.cache
def _libm(name: str, arity: int = 2):
    import ctypes
    import ctypes.util

    fn = getattr(ctypes.CDLL(ctypes.util.find_library("m") or ctypes.util.find_library("c")), name)
    fn.restype, fn.argtypes = ctypes.c_double, (ctypes.c_double,) * arity
    return fn


def _c_pow(x, y) -> float:
    """The C library's pow: CPython's `x ** y` where that is a float (CPython calls pow),
    pow's own answer where CPython raises (an overflow, 0 ** -1) or gives a complex number
    (a negative base to a fractional power: nan)."""
    try:
        r = float(x) ** float(y)
    except (OverflowError, ZeroDivisionError):
        return _libm("pow")(x, y)
    return r if r.__class__ is float else math.nan


def _c_math(name: str, python: Callable) -> Callable:
    """The C library's `name` of one float as CPython's `math` function gives it (CPython
    calls the C library), and the C library's own answer where CPython raises instead
    (log(0) -inf, log(-1) nan, exp(1000) inf, tan(inf) nan)."""

    def c(x) -> float:
        try:
            return python(x)
        except (OverflowError, ValueError):
            return _libm(name, 1)(x)

    c.__name__ = c.__qualname__ = f"c_{name}"
    return c


pow = Libm("pow", _c_pow, 2)
"""x ** y [-]: the C library's pow, compiled and interpreted alike (CPython's float power
where that gives a float)."""

# The C library's transcendental functions, for kernels (by these names, not `math.exp`: the
# compiler may not rewrite or vectorise them) and, through `Libm.over`, over arrays: numpy's
# own `exp`, `log`, `log2`, `arctan`, `tan`, `arctan2` (and `power`) take SIMD code on a
# machine with AVX-512 whose bits differ from the C library's (in ~1-8 % of doubles), so a
# trace computed with them would depend on the machine it ran on. `sin`, `cos`, `sqrt` and
# `hypot` give the C library's bits in numpy on every machine.
exp = Libm("exp", _c_math("exp", math.exp), 1)
log = Libm("log", _c_math("log", math.log), 1)
log2 = Libm("log2", _c_math("log2", math.log2), 1)
atan = Libm("atan", _c_math("atan", math.atan), 1)
tan = Libm("tan", _c_math("tan", math.tan), 1)
atan2 = Libm("atan2", math.atan2, 2)  # (CPython's never raises: the C library's throughout)
c_hypot = Libm("hypot", lambda x, y: _libm("hypot")(x, y), 2)
"""The C library's hypot (numpy's `np.hypot`), for kernels that compute what numpy did;
`hypot` below is CPython's `math.hypot`, which is not the C library's."""


@kernel
def _over_exp(x, out):
    for i in range(x.shape[0]):
        out[i] = exp(x[i])


@kernel
def _over_log(x, out):
    for i in range(x.shape[0]):
        out[i] = log(x[i])


@kernel
def _over_log2(x, out):
    for i in range(x.shape[0]):
        out[i] = log2(x[i])


@kernel
def _over_atan(x, out):
    for i in range(x.shape[0]):
        out[i] = atan(x[i])


@kernel
def _over_tan(x, out):
    for i in range(x.shape[0]):
        out[i] = tan(x[i])


@kernel
def _over_atan2(y, x, out):
    for i in range(x.shape[0]):
        out[i] = atan2(y[i], x[i])


@kernel
def _over_pow(x, y, out):
    for i in range(x.shape[0]):
        out[i] = pow(x[i], y[i])


def matmul(a, b):
    """`a @ b` (np.matmul's shapes for a 1-D or 2-D `b`; `a` of any number of dimensions, a
    stack of rows), each element summed from the first product on, in one order, without
    fused multiply-adds: numpy's `@` calls BLAS, whose kernel (picked by the CPU: Haswell,
    SkylakeX, Zen...) decides the order and the fusing, so its last bits depend on the machine."""
    import numpy as np

    a, b = np.ascontiguousarray(a, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64)
    if a.ndim < 1 or b.ndim not in (1, 2):
        raise ValueError(f"matmul takes an array of rows and a 1-D or 2-D one, not {a.ndim}-D and {b.ndim}-D")
    k = a.shape[-1]
    if b.shape[0] != k:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not align")
    a2 = a.reshape(a.size // k if k else math.prod(a.shape[:-1]), k)
    b2 = b if b.ndim == 2 else b.reshape(k, 1)
    if _numba_loaded():
        out = np.empty((a2.shape[0], b2.shape[1]))
        _matmul(a2, b2, out)
    else:  # the kernel's order, a column at a time (a compile-only process does not load numba)
        out = a2[:, :1] * b2[:1, :] if k else np.zeros((a2.shape[0], b2.shape[1]))
        for q in range(1, k):
            out = out + a2[:, q:q + 1] * b2[q:q + 1, :]
    if b.ndim == 1:
        return out[0, 0] if a.ndim == 1 else out.reshape(a.shape[:-1])
    return out.reshape(a.shape[:-1] + b.shape[1:])


@kernel
def _matmul(a, b, out):
    n, k = a.shape
    m = b.shape[1]
    for i in range(n):
        for j in range(m):
            acc = a[i, 0] * b[0, j] if k else 0.0
            for q in range(1, k):
                acc += a[i, q] * b[q, j]
            out[i, j] = acc


matmul_into = _matmul
"""`matmul` of a 2-D `a` and `b` into `out` (rows of a by columns of b), in its order: for a
kernel, which calls it by this name (matmul itself is Python)."""


_OVER = {"exp": _over_exp, "log": _over_log, "log2": _over_log2, "atan": _over_atan, "tan": _over_tan,
         "atan2": _over_atan2, "pow": _over_pow}

@kernel
def maximum(a, b):
    """`np.maximum` of two floats: a NaN either side gives NaN; of equals, a."""
    if math.isnan(a) or math.isnan(b):
        return math.nan
    return a if a >= b else b


@kernel
def minimum(a, b):
    """`np.minimum` of two floats: a NaN either side gives NaN; of equals, a."""
    if math.isnan(a) or math.isnan(b):
        return math.nan
    return a if a <= b else b


@kernel
def bisect_right(a, x, hi):
    """`bisect.bisect_right(a, x, 0, hi)`: where x goes after its equals in the sorted
    a[:hi], by the comparisons Python's `bisect` makes (a NaN x goes first)."""
    lo = 0
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@kernel
def bisect_left(a, x, hi):
    """`bisect.bisect_left(a, x, 0, hi)`: where x goes before its equals in the sorted a[:hi]."""
    lo = 0
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


_SPLIT = 134217729.0  # 2**27 + 1: Veltkamp's splitter for doubles


@kernel
def hypot(x, y):
    """sqrt(x*x + y*y) [same unit as x, y] with CPython 3.11's `math.hypot` bits (its
    vector_norm of two floats: scaled by a power of two, squared exactly by Veltkamp-Dekker
    splitting, summed with the rounding errors of each term, one Newton correction of the
    root; where the scale would overflow, divided by the larger instead). numba's
    `math.hypot` is the C library's, which differs in the last bit: kernels call this one."""
    x, y = abs(x), abs(y)
    if math.isinf(x) or math.isinf(y):
        return math.inf
    if math.isnan(x) or math.isnan(y):
        return math.nan
    big = x if x > y else y
    if big == 0.0:
        return 0.0
    e = math.frexp(big)[1]
    if e < -1023:  # (subnormal) 2 ** -e would overflow
        csum, frac = 1.0, 0.0
        for v in (x, y):
            v = v / big
            v = v * v
            old = csum
            csum += v
            frac += (old - csum) + v
        return big * math.sqrt(csum - 1.0 + frac)
    scale = math.ldexp(1.0, -e)
    csum, frac1, frac2, frac3 = 1.0, 0.0, 0.0, 0.0
    for v in (x, y):
        v *= scale  # lossless
        t = v * _SPLIT
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
    t = h * _SPLIT
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
    return (h + v / (2.0 * h)) / scale  # differential correction


_NAN_BITS = 0x7FF8000000000000


def bits(values) -> list[int]:
    """The float64 bit patterns of `values` (a number or any array-like), every NaN as one
    pattern: what "the same bits" means between a kernel and its Python. Compiled code keeps
    every bit of every number, -0.0 and subnormals included, but LLVM may swap the operands
    of + and *, and which operand's NaN an operation passes on decides the NaN's sign and
    payload (the Python gives +nan where the kernel gives -nan). A NaN's sign and payload
    carry no value; the same compiled code gives the same NaN in every run."""
    import numpy as np

    a = np.asarray(values, dtype=np.float64).reshape(-1)
    return np.where(np.isnan(a), _NAN_BITS, a.view(np.int64)).tolist()
