"""Latency summary for latency.json: percentiles from the per-run histograms, by-object e2e."""

import pytest

from addt_dsl.reporting.plots import LatencyStats
from addt_dsl.runtime.store import LATENCY_BIN_S


def test_percentiles_budget_share_and_objects():
    stats = LatencyStats()
    # 90 ticks in bin 10 (20-22 ms), 10 ticks in bin 55 (110-112 ms): p50 at 22 ms, p95 at the bin's
    # upper edge 112 ms, but never above the worst sample (110.5 ms).
    stats.add({"latency_hist": {"e2e": {"10": 90, "55": 10}}, "latency_max_s": {"e2e": 0.1105},
               "e2e_by_objects": {"3": [100, 3.1, 0.1105]}})
    stats.add({"latency_hist": {"perception": {"5": 4}}, "latency_max_s": {"perception": 0.0101}})
    s = stats.summary(budget_s=0.1)
    e2e = s["nodes"]["e2e"]
    assert e2e["p50_ms"] == pytest.approx(11 * LATENCY_BIN_S * 1e3)
    assert e2e["p95_ms"] == e2e["p99_ms"] == pytest.approx(110.5)
    assert e2e["share_at_or_over_budget"] == pytest.approx(0.1) and e2e["max_ms"] == pytest.approx(110.5)
    assert list(s["nodes"]) == ["perception", "e2e"]  # pipeline order
    assert s["e2e_by_objects"]["3"] == {"mean_ms": pytest.approx(31.0), "max_ms": pytest.approx(110.5), "ticks": 100}
