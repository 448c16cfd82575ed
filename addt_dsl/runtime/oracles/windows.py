"""Vectorised window kernels for the STL evaluator.

All kernels work on whole-sample windows over a finite trace of n samples and cut
windows off at the trace end (rtamt's discrete-time offline semantics): the window of
sample i is [i + lo, min(i + hi, n - 1)]; a window that starts past the end is empty
and yields the operator's identity (+inf for min, -inf for max).
"""

from __future__ import annotations

import numpy as np

_IDENTITY = {np.minimum: np.inf, np.maximum: -np.inf}


def window_reduce(x: np.ndarray, lo: int, hi: int | None, op: np.ufunc) -> np.ndarray:
    """y[i] = op over x[i+lo .. min(i+hi, n-1)]; hi None = to the end of the trace.

    O(n) per call whatever the window width (van Herk / Gil-Werman: block-wise prefix
    and suffix scans, each window is one prefix combined with one suffix).
    """
    n = x.shape[0]
    identity = _IDENTITY[op]
    if lo >= n:
        return np.full(n, identity)
    # Windows can't reach past n-1 from any i >= 0, so a longer hi changes nothing.
    hi = n - 1 if hi is None else min(hi, n - 1)
    if hi < lo:
        raise ValueError(f"empty window [{lo}, {hi}]")
    if hi == n - 1:  # every window runs to the end: one suffix scan
        suffix = op.accumulate(x[::-1])[::-1]
        return _shift(suffix, lo, identity)
    w = hi - lo + 1
    length = -(-(lo + n + w - 1) // w) * w  # room for every window, a multiple of w
    z = np.full(length, identity)
    z[:n] = x
    blocks = z.reshape(-1, w)
    prefix = op.accumulate(blocks, axis=1).ravel()
    suffix = op.accumulate(blocks[:, ::-1], axis=1)[:, ::-1].ravel()
    return op(suffix[lo:lo + n], prefix[lo + w - 1:lo + w - 1 + n])


def _shift(x: np.ndarray, k: int, fill: float) -> np.ndarray:
    """y[i] = x[i + k], `fill` past the end."""
    if k == 0:
        return x
    y = np.full_like(x, fill)
    if k < x.shape[0]:
        y[:x.shape[0] - k] = x[k:]
    return y


def unbounded_until(phi: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """u[i] = max_{j >= i} min(psi[j], min(phi[i:j])), i.e. the recurrence
    u[i] = max(psi[i], min(phi[i], u[i+1])), u[n] = -inf, without a Python loop.

    Each step is the map f_i(x) = max(psi_i, min(phi_i, x)); such maps are closed under
    composition ((P1,Q1) o (P2,Q2) = (max(P1, min(Q1, P2)), min(Q1, Q2))), so a
    Hillis-Steele suffix scan over the pairs takes log2(n) vector steps; u[i] is the
    composed map applied to -inf, which is its P.
    """
    n = phi.shape[0]
    p, q = psi.copy(), phi.copy()
    k = 1
    while k < n:
        head = n - k
        p[:head] = np.maximum(p[:head], np.minimum(q[:head], p[k:]))
        q[:head] = np.minimum(q[:head], q[k:])
        k *= 2
    return p


def until(phi: np.ndarray, psi: np.ndarray, lo: int, hi: int | None) -> np.ndarray:
    """Bounded until, rtamt's discrete-time definition:
    rho[t] = max_{t' in [t+lo, t+hi]} min(psi[t'], min_{t'' in [t, t')} phi[t'']).

    Split phi's span at t+lo: rho[t] = min(always[0, lo-1] phi (t), U[0, hi-lo](t+lo)),
    and U[0, c] = min(eventually[0, c] psi, unbounded until), exact in the (min, max)
    lattice: a witness of U beyond c is dominated by phi on [s, s+c], which covers the
    phi-span of the best psi inside the window.
    """
    n = phi.shape[0]
    u = unbounded_until(phi, psi)
    if hi is not None:
        u = np.minimum(window_reduce(psi, 0, hi - lo, np.maximum), u)
    u = _shift(u, lo, -np.inf)
    if lo == 0:
        return u
    return np.minimum(window_reduce(phi, 0, lo - 1, np.minimum), u) if n else u
