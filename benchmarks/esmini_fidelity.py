"""How closely imported esmini scenarios move like esmini: per scenario and entity, the RMS and
maximum distance [m] between the twin's run and esmini 3.6's own trajectory
(tests/data/esmini-ref), and how many scenarios are within 0.5 m RMS for every entity.

    python benchmarks/esmini_fidelity.py [--ego stack|scripted] [--lenient] [NAME ...]
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from addt_dsl.interop.fidelity import TOLERANCE_M, scenario_fidelity  # noqa: E402

ESMINI = ROOT / "tests" / "data" / "esmini"
REF = ROOT / "tests" / "data" / "esmini-ref"


def references() -> list[dict]:
    with open(REF / "INDEX.csv", newline="") as fh:
        return [r for r in csv.DictReader(fh) if r["file"]]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--ego", choices=("stack", "scripted"), default="stack")
    ap.add_argument("--lenient", action="store_true", help="import what translates (W0801 for the rest)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    options = {"ego": args.ego, "lenient": args.lenient}
    all_ok = others_ok = total = 0
    for row in references():
        name = row["name"].split(".")[0]
        if args.names and name not in args.names:
            continue
        total += 1
        t0 = time.perf_counter()
        fid, names = scenario_fidelity(ESMINI / "xosc" / row["xosc"], ESMINI, REF / row["file"],
                                       float(row["t_end"]), **options)
        egos = {e for e, a in names.items() if a == "ego"}
        all_ok += fid.ok
        others_ok += fid.ok_except(egos)
        cells = " ".join(f"{e.entity}{'*' if e.entity in egos else ''}:{e.rms_m:.2f}/{e.max_m:.1f}"
                         for e in fid.errors) or fid.problem
        print(f"{name:30s} {'all' if fid.ok else '   '} {'others' if fid.ok_except(egos) else '      '} "
              f"{cells}  [{time.perf_counter() - t0:.1f} s]", flush=True)
    print(f"within {TOLERANCE_M} m RMS: every entity in {all_ok} of {total}; every entity but the ego (*) "
          f"in {others_ok} of {total}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
