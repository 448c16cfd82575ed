"""Compile time against input size (checks must grow linearly, n log n at worst).

    python benchmarks/bench_compile_scaling.py [--quick] [--json FILE]

For each dimension (params, agents, oracles, lanes of an imported map, roads of an
imported map, included volume) it generates a scenario at size n and at 10 n, compiles
each in-process (the grammar is built once beforehand) and prints the seconds and the
ratio t(10 n) / t(n): about 10 is linear, about 13 is n log n, 100 is quadratic. The
input limits of docs/limits.md are raised for the measurement (10 n may pass a default:
the point is how the checks grow), so every scenario compiles clean.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import _figures as figures_json  # benchmarks/ is on the path when run as a script

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

HEAD = """scenario scale {{
  duration 10 s
  step 50 ms
{roads}
  ego car on r lane -1 at 20 m speed 10 m/s
{body}
}}
"""
ROAD = """  road r {
    line length 20000 m
    lanes right 2 width 3.5 m
  }"""


def _scenario(body: str, roads: str = ROAD) -> str:
    return HEAD.format(roads=roads, body=body)


def params(n: int, _dir: Path) -> str:
    return _scenario("\n".join(f"  param p{i} = 1 m in [0 m, 2 m]" for i in range(n)))


def agents(n: int, _dir: Path) -> str:
    return _scenario("\n".join(f"  agent a{i} car on r lane -{1 + i % 2} at {40 + 9 * i} m speed 5 m/s"
                               for i in range(n)))


def oracles(n: int, _dir: Path) -> str:
    lines = [f"    o{i}: always speed(ego) < {100 + i} m/s" for i in range(n)]
    return _scenario("  expect {\n" + "\n".join(lines) + "\n  }")


def _xodr(roads: int, lanes: int) -> str:
    lane = '<lane id="-{k}" type="driving"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>'
    rights = "".join(lane.format(k=k) for k in range(1, lanes + 1))
    road = ('<road name="" length="500" id="{i}" junction="-1"><planView>'
            '<geometry s="0" x="0" y="{y}" hdg="0" length="500"><line/></geometry></planView>'
            '<lanes><laneSection s="0"><center><lane id="0" type="none"/></center>'
            '<right>' + rights + '</right></laneSection></lanes></road>\n')
    body = "".join(road.format(i=i + 1, y=10 * lanes * i) for i in range(roads))
    return f'<?xml version="1.0"?>\n<OpenDRIVE><header revMajor="1" revMinor="4"/>\n{body}</OpenDRIVE>\n'


def _import(directory: Path, text: str) -> str:
    (directory / "map.xodr").write_text(text)
    roads = '  road r import "map.xodr" road 1'
    return _scenario("", roads=roads)


def lanes(n: int, directory: Path) -> str:
    return _import(directory, _xodr(1, n))


def roads(n: int, directory: Path) -> str:
    return _import(directory, _xodr(n, 2))


def included(n: int, directory: Path) -> str:
    """n kB of included definitions, in files of at most 1 MB."""
    per_file = 900  # kB: under the 1,000,000-byte limit of one file
    files = max(1, n // per_file)
    line = "param q{f}_{i} = 1 m in [0 m, 2 m]\n"
    count = 0
    for f in range(files):
        size = min(per_file, n - f * per_file) * 1024
        text, i = [], 0
        length = 0
        while length < size:
            text.append(line.format(f=f, i=i))
            length += len(text[-1])
            i += 1
        count += i
        (directory / f"inc{f}.addt").write_text("".join(text))
    incs = "".join(f'include "inc{f}.addt"\n' for f in range(files))
    return incs + _scenario("")


DIMENSIONS = {  # name: (generator, n, unit)
    "params": (params, 2_000, "params"),
    "agents": (agents, 100, "agents"),
    "oracles": (oracles, 200, "oracles"),
    "lanes": (lanes, 40, "lanes in one section"),
    "roads": (roads, 500, "roads in one map"),
    "included": (included, 100, "kB included"),
}


def _time(gen, n: int) -> tuple[float, list[str]]:
    from addt_dsl.compiler import compile_file
    from addt_dsl.limits import DEFAULT, INPUT_LIMITS

    unlimited = DEFAULT.raised(allow_large=True, **{name: 10 ** 12 for name in INPUT_LIMITS})
    directory = Path(tempfile.mkdtemp(prefix="addt-scale-"))
    try:
        path = directory / "s.addt"
        path.write_text(gen(n, directory))
        t0 = time.perf_counter()
        result = compile_file(path, unlimited)
        elapsed = time.perf_counter() - t0
        errors = [f"{d.code} {d.message}" for d in result.diagnostics if d.is_error]
        return elapsed, errors
    finally:
        shutil.rmtree(directory, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="sizes divided by 4")
    ap.add_argument("--only", choices=sorted(DIMENSIONS))
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    from addt_dsl.compiler import compile_source

    compile_source("scenario warm { duration 1 s }")  # build the grammar outside the timings
    figures, worst = {}, 0.0
    print(f"{'dimension':<10} {'n':>8} {'t(n) s':>8} {'10 n':>8} {'t(10 n) s':>10} {'ratio':>6}")
    for name, (gen, n, unit) in DIMENSIONS.items():
        if args.only and name != args.only:
            continue
        n = max(1, n // 4) if args.quick else n
        small, err_small = _time(gen, n)
        large, err_large = _time(gen, 10 * n)
        ratio = large / max(small, 1e-9)
        worst = max(worst, ratio)
        print(f"{name:<10} {n:>8} {small:>8.3f} {10 * n:>8} {large:>10.3f} {ratio:>6.1f}   ({unit})")
        for err in (err_small + err_large)[:3]:
            print(f"    error: {err}")
        figures[name] = {"n": n, "t_n_s": small, "t_10n_s": large, "ratio": ratio,
                         "errors": len(err_small) + len(err_large)}
    print(f"worst ratio {worst:.1f} (linear about 10, n log n about 13, quadratic 100)")
    figures_json.write(args.json, figures)
    return 0


if __name__ == "__main__":
    sys.exit(main())
