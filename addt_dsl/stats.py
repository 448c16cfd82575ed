"""Interval estimates for the success and outcome rates that tables and studies report."""

from __future__ import annotations

import math

Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion k/n (NaNs for n = 0: no runs, no rate):
    sound near 0 and 1, where fault campaigns' rates usually are. The closed form, without
    continuity correction (scipy's `binomtest(...).proportion_ci(method="wilson")`)."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)
