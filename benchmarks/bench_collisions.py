"""The collisions phase (`collision.clearances_rows`, or `clearances_batch` in a tree
without it) per run-step, in two source trees.

Run: PYTHONPATH=. python benchmarks/bench_collisions.py [--before TREE] [--after TREE]
     [--agents 1,5,20,50,100] [--batch 1,16,64] [--rounds 3] [--json FILE]

Each run of a batch is the dense-traffic layout (`bench_dense.dense_source`): the ego and
`n` agents in three lanes 3.5 m apart, 25 m apart in each lane, with a little jitter in
station, offset and heading (seeded per run), so neighbours in adjacent lanes take the
exact box test. The items are built as each tree's `phases.collisions` builds them
(before: poses as lists of floats where the batch poses its agents one by one, fewer than
`ARRAY_MIN_AGENTS` in all, else arrays, and sizes as lists up to `ALL_PAIRS_MAX` actors;
after: the step's rows of the record and an array of sizes; with `clearances_rows`, the
batch's rows in one array as the batch's record block holds them). Each tree is timed in its own
process (`--child`), the trees alternate for `--rounds` rounds, and the least per-call time
of all rounds is kept, in CPU time of the process (the machine is shared: CPU time is the
steadier under load, which is printed). Prints us per run-step (one call's time / batch)
and the ratio before / after.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _figures as figures_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _arg(name: str, default: str) -> str:
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def items_for(n_agents: int, batch: int):
    """A batch's items for `clearances_batch`, as `phases.collisions` makes them."""
    import numpy as np

    from addt_dsl.runtime import agents as A
    from addt_dsl.runtime import collision as C

    arrays = n_agents * batch >= A.ARRAY_MIN_AGENTS
    few = getattr(C, "ALL_PAIRS_MAX", None)  # the tree before: sizes as lists up to it
    items = []
    for r in range(batch):
        rng = np.random.default_rng(1000 * n_agents + r)
        names = ["ego"] + [f"a{i}" for i in range(n_agents)]
        x = [20.0] + [60.0 + 25.0 * (i // 3) + rng.uniform(-3.0, 3.0) for i in range(n_agents)]
        y = [-5.25] + [-1.75 - 3.5 * (i % 3) + rng.uniform(-0.3, 0.3) for i in range(n_agents)]
        h = [0.0] + [rng.uniform(-0.03, 0.03) for _ in range(n_agents)]
        length = [4.6] + [12.0 if i % 7 == 3 else 4.6 for i in range(n_agents)]
        width = [1.9] + [2.5 if i % 7 == 3 else 1.9 for i in range(n_agents)]
        run = SimpleNamespace(contacts=set(), events=[])
        if few is None:  # the tree after: a step's rows of the record (x, y, heading first) and sizes
            rows = np.zeros((len(names), 11))
            rows[:, 0], rows[:, 1], rows[:, 2] = x, y, h
            items.append((rows, names, np.array([length, width]).T.copy(), run, 0.0))
            continue
        if arrays:
            x, y, h = np.array(x), np.array(y), np.array(h)
        if len(names) > few:
            length, width = np.array(length), np.array(width)
        items.append((np.zeros(len(names)), names, x, y, h, length, width, run, 0.0))
    return items


def phase_call(items):
    """The call `phases.collisions` makes for a batch's items in this tree: where the tree
    has `clearances_rows`, on the step's rows of the batch's record block (the runs' rows one
    after another, every run live), else `clearances_batch` of the items."""
    import numpy as np

    from addt_dsl.runtime import collision as C

    rows_of = getattr(C, "clearances_rows", None)
    if rows_of is None or len(items) < 2 or len(items[0]) != 5:
        return lambda: C.clearances_batch(items)
    rows = np.concatenate([item[0] for item in items])
    first = np.array([0, *np.cumsum([len(item[0]) for item in items])], dtype=np.int64)
    sizes = np.concatenate([item[2] for item in items])
    live = np.arange(len(items), dtype=np.int64)
    runs = [(item[1], item[3], item[4]) for item in items]
    return lambda: rows_of(rows, first, live, sizes, runs)


def child(cases, number_s: float = 0.2, repeat: int = 5) -> dict:
    """Least time per call [s] of the collisions phase's call (`phase_call`) per case (this
    process's tree)."""
    out = {}
    for n, b in cases:
        call = phase_call(items_for(n, b))
        call()  # compile / warm
        t0, number = time.process_time(), 0
        while time.process_time() - t0 < 0.02:
            call()
            number += 1
        number = max(1, int(number * number_s / 0.02 / repeat))
        best = float("inf")
        for _ in range(repeat):
            t0 = time.process_time()
            for _ in range(number):
                call()
            best = min(best, (time.process_time() - t0) / number)
        out[f"{n},{b}"] = best
    return out


def main() -> None:
    before = _arg("--before", None)  # another checkout to compare with (else this one alone)
    after = _arg("--after", str(ROOT))
    agents = [int(v) for v in _arg("--agents", "1,5,20,50,100").split(",")]
    batches = [int(v) for v in _arg("--batch", "1,16,64").split(",")]
    rounds = int(_arg("--rounds", "3"))
    cases = [(n, b) for n in agents for b in batches]
    best: dict[str, dict[str, float]] = {"before": {}, "after": {}}
    print(f"load before: {os.getloadavg()[0]:.2f}")
    for _ in range(rounds):
        for label, tree in (("before", before), ("after", after)):
            if tree is None:
                continue
            env = {**os.environ, "PYTHONPATH": tree}
            res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(cases)],
                                 env=env, cwd=tree, capture_output=True, text=True, check=True)
            for key, value in json.loads(res.stdout.strip().splitlines()[-1]).items():
                best[label][key] = min(best[label].get(key, float("inf")), value)
    print(f"load after: {os.getloadavg()[0]:.2f}")
    print(f"before: {before}\nafter:  {after}\nus per run-step (least of {rounds} rounds x 5 repeats)")
    print(f"{'agents':>6} {'batch':>5} {'before':>9} {'after':>9} {'ratio':>6}")
    for n, b in cases:
        key = f"{n},{b}"
        t0, t1 = best["before"].get(key, math.nan) / b * 1e6, best["after"][key] / b * 1e6
        print(f"{n:>6} {b:>5} {t0:>9.2f} {t1:>9.2f} {t0 / t1:>6.2f}")
    figures_json.write(_arg("--json", None), {"us_per_run_step": {
        label: {k: v / int(k.split(",")[1]) * 1e6 for k, v in values.items()} for label, values in best.items()}})


if __name__ == "__main__":
    if "--child" in sys.argv:
        sys.path.insert(0, os.getcwd())
        print(json.dumps(child([tuple(c) for c in json.loads(sys.argv[sys.argv.index("--child") + 1])])))
    else:
        main()
