"""Micro-benchmark of the STL evaluator: µs per formula on a 4000-sample trace.

Run: PYTHONPATH=. python benchmarks/bench_stl.py
"""

from __future__ import annotations

import argparse
import time

import _figures as figures_json
import numpy as np

from addt_dsl.compiler.formula import parse_formula
from addt_dsl.runtime.oracles import robustness_at_0, satisfied

N = 4000
PERIOD_S = 0.05  # 200 s of simulation

FORMULAS = [
    "always ttc(ego, lead) > 1 s",
    "eventually within 40 s ego.s > 900 m",
    "always during [2 s, 5 s] lane_offset(ego) < 1.8 m",
    "always (abs(lane_offset(ego)) < 1.8 m and ttc(ego, lead) > 2 s)",
    "always (ego.speed > 30 km/h implies eventually within 5 s ego.accel < 0 m/s^2)",
    "always within 60 s eventually during [1 s, 10 s] ego.speed < 10 km/h",
    "ego.speed < 50 km/h until within 10 s ego.s > 100 m",
    "always (ego.accel < -3 m/s^2 implies ego.speed > 1 m/s until within 2 s ttc(ego, lead) > 3 s)",
]


def trace(n: int = N, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * PERIOD_S
    speed = 20 + 5 * np.sin(t / 7) + rng.normal(0, 0.2, n)
    return {
        "speed(ego)": speed,
        "s(ego)": np.cumsum(speed) * PERIOD_S,
        "accel(ego)": np.gradient(speed, PERIOD_S),
        "ttc(ego,lead)": 3 + 2 * np.cos(t / 5) + rng.normal(0, 0.1, n),
        "lane_offset(ego)": 0.5 * np.sin(t / 3) + rng.normal(0, 0.05, n),
    }


def per_call_us(fn, min_time_s: float = 0.2) -> float:
    fn()  # warm up
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < min_time_s:
        fn()
        calls += 1
    return elapsed / calls * 1e6


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    figures = {}
    sig = trace()
    lists = {k: v.tolist() for k, v in sig.items()}
    print(f"{N} samples at {PERIOD_S} s; µs per call (expr: pre-parsed tree, text: parse_formula + robustness_at_0)")
    print(f"{'expr':>8} {'text':>8} {'verdict':>8}  formula")
    for text in FORMULAS:
        expr = parse_formula(text)
        t_expr = per_call_us(lambda: robustness_at_0(expr, sig, PERIOD_S))
        t_text = per_call_us(lambda: robustness_at_0(parse_formula(text), lists, PERIOD_S))
        t_sat = per_call_us(lambda: satisfied(expr, sig, PERIOD_S))
        print(f"{t_expr:8.0f} {t_text:8.0f} {t_sat:8.0f}  {text}")
        figures[text] = {"robustness_us": t_expr, "robustness_from_text_us": t_text, "verdict_us": t_sat}
    figures_json.write(args.json, {"samples": N, "per_formula": figures})


if __name__ == "__main__":
    main()
