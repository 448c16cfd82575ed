"""The window kernels against plain loops."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.runtime.oracles.windows import unbounded_until, until, window_reduce

arrays = st.integers(0, 60).flatmap(lambda n: st.lists(
    st.sampled_from([-3.0, -1.0, 0.0, 0.5, 2.0, np.inf, -np.inf]), min_size=n, max_size=n)).map(np.array)


def naive_window(x, lo, hi, op):
    n = len(x)
    hi = n - 1 if hi is None else hi
    ident = np.inf if op is np.minimum else -np.inf
    out = []
    for i in range(n):
        w = x[i + lo:min(i + hi, n - 1) + 1]
        out.append(op.reduce(w) if len(w) else ident)
    return np.array(out, dtype=float)


@settings(max_examples=300)
@given(arrays, st.integers(0, 70), st.one_of(st.none(), st.integers(0, 70)),
       st.sampled_from([np.minimum, np.maximum]))
def test_window_reduce(x, lo, width, op):
    hi = None if width is None else lo + width
    np.testing.assert_array_equal(window_reduce(x, lo, hi, op), naive_window(x, lo, hi, op))


@settings(max_examples=300)
@given(st.integers(0, 60).flatmap(lambda n: st.tuples(*(st.lists(
    st.sampled_from([-3.0, -1.0, 0.0, 0.5, 2.0]), min_size=n, max_size=n) for _ in range(2)))),
       st.integers(0, 8), st.one_of(st.none(), st.integers(0, 8)))
def test_until_kernel(pair, lo, width):
    phi, psi = map(np.array, pair)
    n = len(phi)
    # the textbook recurrence
    u, nxt = np.empty(n), -np.inf
    for i in range(n - 1, -1, -1):
        nxt = u[i] = max(psi[i], min(phi[i], nxt))
    np.testing.assert_array_equal(unbounded_until(phi, psi), u)
    hi = None if width is None else lo + width
    want = []
    for t in range(n):
        end = n - 1 if hi is None else min(t + hi, n - 1)
        want.append(max((min(psi[t1], min(phi[t:t1], default=np.inf)) for t1 in range(t + lo, end + 1)),
                        default=-np.inf))
    np.testing.assert_array_equal(until(phi, psi, lo, hi), np.array(want, dtype=float))


def test_long_trace_wide_window():
    rng = np.random.default_rng(0)
    x = rng.normal(size=4000)
    for lo, hi in [(0, 999), (17, 2500), (3999, 4200), (0, None), (250, None)]:
        np.testing.assert_array_equal(window_reduce(x, lo, hi, np.minimum), naive_window(x, lo, hi, np.minimum))
