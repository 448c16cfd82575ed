"""`addt_dsl.kernel`: a compiled kernel gives the bits of its Python source (`py_func`),
with numpy's error model, kernels calling kernels, and pickling by name."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import OPTIONS, Kernel, bits, interpreted, kernel
from addt_dsl.kernel import pow as kpow


@kernel
def _mix(a, b):
    return math.sin(a) * b + math.exp(-abs(b)) + abs(a) ** b - math.atan2(a, b) + math.sqrt(a * a + b * b)


@kernel
def _loop(x, y, out):
    for i in range(x.size):
        out[i] = _mix(x[i], y[i]) / (x[i] - y[i])  # inf or nan where equal, as numpy's


floats = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([0.0, -0.0, 1e-300])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(floats, floats), min_size=1, max_size=40))
def test_compiled_gives_its_python_bits(pairs):
    x = np.array([p[0] for p in pairs])
    y = np.array([p[1] for p in pairs])
    got, want = np.empty(len(x)), np.empty(len(x))
    with np.errstate(all="ignore"):
        _loop(x, y, got)
        _loop.py_func(x, y, want)
    assert bits(got) == bits(want)


def test_settings_keep_ieee_semantics():
    assert OPTIONS["fastmath"] is False and OPTIONS["error_model"] == "numpy"
    out = np.empty(1)
    _loop(np.array([1.0]), np.array([1.0]), out)  # a division by zero: no exception
    assert math.isinf(out[0])


def test_callee_compiled_in_and_pickled_by_name():
    assert isinstance(_loop, Kernel) and _loop.__name__ == "_loop"
    assert pickle.loads(pickle.dumps(_loop)) is _loop
    _loop(np.array([2.0]), np.array([0.5]), np.empty(1))
    assert _mix._compiled is not None  # compiled as the caller's callee


any_float = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)


@settings(max_examples=400, deadline=None)
@given(any_float, any_float)
def test_hypot_is_pythons(x, y):
    from addt_dsl.kernel import hypot

    want = math.hypot(x, y)
    for got in (hypot(x, y), hypot.py_func(x, y)):
        assert (got == want and math.copysign(1.0, got) == math.copysign(1.0, want)) or \
            (math.isnan(got) and math.isnan(want))


def test_hypot_edges():
    from addt_dsl.kernel import hypot

    for x, y in [(3.0, 4.0), (1e308, 1e308), (5e-324, 5e-324), (1e-310, 3e-312), (-0.0, 0.0),
                 (math.inf, math.nan), (math.nan, -math.inf), (0.1, 0.7),
                 (2.582449101461543e-309, 3.44863960473017e-310)]:  # 3.11 divides subnormals by the larger
        want = math.hypot(x, y)
        assert hypot(x, y) == want or (math.isnan(want) and math.isnan(hypot(x, y)))


def test_hypot_over_many_scales_is_pythons():
    """Bit for bit over magnitudes from subnormal to huge, each against each (subnormal
    pairs take 3.11's division by the larger)."""
    from addt_dsl.kernel import hypot

    rng = np.random.default_rng(7)
    n = 5000
    scales = [rng.normal(size=n) * 100.0, np.exp(rng.uniform(-745.0, 709.0, n)) * rng.choice([-1.0, 1.0], n),
              np.round(rng.uniform(-50.0, 50.0, n), 2), np.exp(rng.uniform(-745.0, -700.0, n))]
    for a in scales:
        for b in scales:
            want = np.fromiter(map(math.hypot, a.tolist(), b.tolist()), float, n)
            got = np.fromiter(map(hypot, a.tolist(), b.tolist()), float, n)
            assert got.view(np.int64).tolist() == want.view(np.int64).tolist()


@kernel
def _powers(x, out):
    for i in range(x.size):
        out[0, i] = kpow(x[i], 2.0)  # (numba's x ** 2.0 would be x * x)
        out[1, i] = kpow(x[i], 4.0)
        out[2, i] = kpow(x[i], 0.5)


def test_pow_is_pythons_where_numba_would_multiply():
    rng = np.random.default_rng(0)
    x = rng.normal(size=20000) * np.exp(rng.normal(size=20000) * 20)
    out = np.empty((3, x.size))
    _powers(x, out)
    values = x.tolist()
    for row, y in zip(out, (2.0, 4.0, 0.5)):
        want = np.array([v ** y if v >= 0.0 or y != 0.5 else math.nan for v in values])
        assert np.array_equal(row, want, equal_nan=True)
    # the same inputs as x * x: some differ, so the test would catch the rewrite
    assert (out[0] != x * x).any()


def test_cache_folder_per_code_version(tmp_path, monkeypatch):
    """Compiled kernels are kept per code fingerprint (numba would check the kernel's own file
    only: a changed callee elsewhere would leave it stale); old versions' folders go after a day."""
    import os
    from pathlib import Path

    from addt_dsl.fingerprint import code_fingerprint
    from addt_dsl.kernel import cache_dir

    assert Path(cache_dir()).name == code_fingerprint()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    for old, age in ((tmp_path / "kernels" / "old", 2 * 86400), (tmp_path / "kernels" / "recent", 3600)):
        old.mkdir(parents=True)
        os.utime(old, (os.stat(old).st_atime, os.stat(old).st_mtime - age))
    here = Path(cache_dir.__wrapped__())
    assert here == tmp_path / "kernels" / code_fingerprint() and here.is_dir()
    assert sorted(p.name for p in (tmp_path / "kernels").iterdir()) == sorted([code_fingerprint(), "recent"])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-10, 10), max_size=12),
       st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([0.0, 1.0]), st.integers(0, 12))
def test_bisects_are_pythons(values, x, hi):
    """The kernels' bisections give `bisect`'s answers, a NaN x included (compiled and not)."""
    import bisect

    from addt_dsl.kernel import bisect_left, bisect_right

    a = np.array(sorted(values) + [0.0])  # (a slot past the sorted part, as the callers' tables have)
    hi = min(hi, len(values))
    for mine, python in ((bisect_right, bisect.bisect_right), (bisect_left, bisect.bisect_left)):
        want = python(a.tolist(), x, 0, hi)
        assert mine(a, x, hi) == want
        with interpreted():
            assert mine(a, x, hi) == want


def test_bits_tell_every_number_apart_and_every_nan_alike():
    neg_nan = -np.float64("nan")
    payload = np.array([0x7FF0000000000001], dtype=np.int64).view(np.float64)[0]
    assert bits([math.nan]) == bits([neg_nan]) == bits([payload]) == bits(math.nan)
    assert bits([0.0]) != bits([-0.0])
    assert bits([5e-324]) != bits([0.0])
    assert bits([math.inf]) != bits([math.nan]) != bits([-math.inf])
    assert bits([[1.0, 2.0], [3.0, math.nan]]) == bits([1.0, 2.0, 3.0, math.nan])
    assert bits([1.0]) == [np.float64(1.0).view(np.int64).item()]


def test_a_nan_the_kernel_passes_on_may_differ_in_sign_only():
    """A separation with an infinite term: inf * 0 makes a NaN whose sign depends on the
    operand order LLVM chose (compiled -nan, Python +nan on x86-64); `bits` calls them one."""
    from addt_dsl.runtime.world import separation

    args = (0.0, 0.0, 0.0, 1.0, 0.0, math.inf, 0.0, 0.0, 0.0, 0.0)
    compiled, python = separation(*args), separation.py_func(*args)
    assert math.isnan(compiled) and math.isnan(python)
    assert bits([compiled]) == bits([python])


@kernel
def _pow(x, y):
    return kpow(x, y)


@settings(max_examples=200, deadline=None)
@given(floats, floats)
def test_pow_interpreted_is_the_c_librarys(x, y):
    """Compiled and interpreted alike, where CPython's `**` raises (an overflow, 0 ** -1) or
    gives a complex number (a negative base to a fractional power) too."""
    from addt_dsl.kernel import _libm

    assert bits(kpow(x, y)) == bits(_pow(x, y)) == bits(_libm("pow")(x, y))


def test_pow_where_python_raises():
    assert kpow(1e200, 2.0) == math.inf and kpow(-1e200, 3.0) == -math.inf
    assert kpow(0.0, -1.0) == math.inf and kpow(-0.0, -1.0) == -math.inf
    assert math.isnan(kpow(-8.0, 0.5))


@kernel
def _divide(a, b):
    return a / b


def test_compiled_call_bound_and_interpreted_still_python():
    """Compiled, a kernel's calls go to its dispatcher (its class's `__call__`); within
    `interpreted()`, nested too, they run its Python (a division by zero raises), and after
    it the compiled code again."""
    assert _divide(1.0, 0.0) == math.inf
    assert type(_divide).__dict__["__call__"].__func__ is _divide._compiled
    with interpreted():
        with pytest.raises(ZeroDivisionError):
            _divide(1.0, 0.0)
        with interpreted():
            pass
        with pytest.raises(ZeroDivisionError):  # (the inner context left it interpreted)
            _divide(1.0, 0.0)
    assert _divide(1.0, 0.0) == math.inf
    assert type(_mix) is not type(_divide) and isinstance(_divide, Kernel)


# The C library's functions over arrays (`Libm.over`): numpy's ufuncs of these names take
# SIMD code on AVX-512 machines whose bits differ; these must give CPython's `math` bits
# (the C library's), and the C library's own answer where `math` raises.
LIBM_CASES = {"exp": math.exp, "log": math.log, "log2": math.log2, "atan": math.atan, "tan": math.tan}
edge_floats = any_float | st.sampled_from([0.0, -0.0, -1.0, 1000.0, -1000.0, 709.8, 1e-320])


def _c_answer(name: str, *args) -> float:
    try:
        return getattr(math, "atan2" if name == "atan2" else name)(*args)
    except (OverflowError, ValueError):
        return {"exp": math.inf, "tan": math.nan}.get(name) if name in ("exp", "tan") else \
            (-math.inf if args[0] == 0.0 else math.nan)


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(sorted(LIBM_CASES)), st.lists(edge_floats, min_size=1, max_size=30))
def test_libm_over_arrays_gives_the_c_librarys_bits(name, values):
    from addt_dsl import kernel as K

    fn = getattr(K, name)
    want = bits([_c_answer(name, v) for v in values])
    assert bits(fn.over(np.array(values))) == want
    with interpreted():
        assert bits(fn.over(np.array(values))) == want


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(edge_floats, edge_floats), min_size=1, max_size=30))
def test_atan2_and_pow_over_arrays(pairs):
    from addt_dsl import kernel as K

    y, x = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    assert bits(K.atan2.over(y, x)) == bits([math.atan2(a, b) for a, b in pairs])
    assert bits(K.pow.over(y, x)) == bits([K.pow.python(a, b) for a, b in pairs])


def test_over_keeps_numpys_shapes_and_differs_where_numpy_takes_simd_code():
    from addt_dsl import kernel as K

    grid = np.linspace(-3.0, 3.0, 12).reshape(3, 4)
    assert K.exp.over(grid).shape == (3, 4) and K.atan2.over(grid, 1.0).shape == (3, 4)
    assert isinstance(K.log.over(2.0), np.float64) and K.log.over(2.0) == math.log(2.0)
    x = np.random.default_rng(3).uniform(-10.0, 10.0, 20000)
    assert bits(K.exp.over(x)) == bits([math.exp(v) for v in x.tolist()])
    # (numpy's own exp gives the C library's bits only without AVX-512: nothing to assert here)
    # Arrays taken as they are (float64, C-contiguous, one shape) and arrays copied first
    # (strided, transposed, float32, lists, another shape broadcast) give the same values.
    m = np.random.default_rng(4).uniform(-5.0, 5.0, (6, 8))
    for a, b in ((m[:, ::2], m[:, 1::2]), (m.T, m.T[::-1]), (m.astype(np.float32), m), (m.tolist(), m[0])):
        want = [math.atan2(u, v) for u, v in zip(*(np.broadcast_arrays(np.asarray(a, dtype=np.float64),
                                                                        np.asarray(b, dtype=np.float64))[i].ravel()
                                                   for i in (0, 1)))]
        got = K.atan2.over(a, b)
        assert got.shape == np.broadcast_shapes(np.shape(a), np.shape(b)) and bits(got.ravel()) == bits(want)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 6), st.integers(0, 4), st.integers(1, 5), st.integers(0, 2**16))
def test_matmul_sums_in_one_order(n, k, m, seed):
    """Each element is the products summed from the first on (no fused multiply-add): an
    order any machine follows; compiled and interpreted alike; np.matmul's shapes."""
    from addt_dsl.kernel import matmul

    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(n, k)) * 10.0 ** rng.integers(-5, 5), rng.normal(size=(k, m))
    want = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            acc = a[i, 0] * b[0, j] if k else 0.0
            for q in range(1, k):
                acc = acc + a[i, q] * b[q, j]
            want[i, j] = acc
    got = matmul(a, b)
    assert bits(got) == bits(want)
    with interpreted():
        assert bits(matmul(a, b)) == bits(want)
    assert matmul(a[0], b).shape == (a[0] @ b).shape
    assert matmul(a, b[:, 0]).shape == (a @ b[:, 0]).shape
    if k:
        assert matmul(a[0], a[0]) == sum_in_order(a[0] * a[0])


def sum_in_order(values) -> float:
    acc = values[0]
    for v in values[1:]:
        acc = acc + v
    return float(acc)


def test_matmul_refuses_what_numpy_refuses():
    from addt_dsl.kernel import matmul

    with pytest.raises(ValueError):
        matmul(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError):
        matmul(np.zeros((2, 2)), np.zeros((2, 2, 2)))
    stack = np.arange(24.0).reshape(2, 4, 3)  # rows of a stack, as np.matmul takes them
    assert matmul(stack, np.eye(3)[:, :2]).shape == (2, 4, 2)
    assert np.array_equal(matmul(stack, np.eye(3)), stack)


def test_helpers_give_the_same_bits_before_numba_is_loaded(monkeypatch):
    """A compile-only process computes road geometry without loading numba: `over` and
    `matmul` then take numpy or Python, which must give the kernels' bits."""
    from addt_dsl import kernel as K

    rng = np.random.default_rng(11)
    x, y = rng.normal(size=300) * 5.0, rng.normal(size=300) * 5.0
    a, b = rng.normal(size=(40, 7)), rng.normal(size=(7, 3))
    K.maximum(1.0, 2.0)  # a kernel's call loads numba (the helpers do not load it themselves)
    assert K._numba_loaded()
    compiled = [K.exp.over(x), K.atan2.over(y, x), K.pow.over(np.abs(x), y), K.matmul(a, b), K.matmul(a[0], a[1])]
    monkeypatch.setattr(K, "_numba_loaded", lambda: False)
    plain = [K.exp.over(x), K.atan2.over(y, x), K.pow.over(np.abs(x), y), K.matmul(a, b), K.matmul(a[0], a[1])]
    for c, p in zip(compiled, plain):
        assert bits(c) == bits(p)
