"""Trace digests of example and dense-traffic RunSpecs, one line each: compare two
checkouts' output to show a change keeps every run bit for bit.

Run: PYTHONPATH=. python benchmarks/trace_digests.py > digests.txt   (on each checkout; diff)
     [--arrays: agents posed and stepped as arrays whatever their count, as the loop does
     from `ARRAY_MIN_AGENTS` / `STEP_MIN_AGENTS` agents on: the digests must not change]
     [NAME ...: only the runs whose name contains one of these]
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _families import PAPER_FAMILIES, family_spec  # noqa: E402
from bench_dense import dense_source  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def full_digest(trace) -> str:
    """trace.digest() plus what it leaves out: objects seen, every event, step and light states."""
    h = hashlib.sha256(trace.digest().encode())
    if trace.object_count is not None:
        h.update(trace.object_count.tobytes())
    h.update(repr([(e.time_s, e.kind, sorted(e.detail.items())) for e in trace.events]).encode())
    for group in (trace.steps, trace.lights, trace.red_margin):
        for k in sorted(group or {}):
            h.update(k.encode())
            h.update(group[k].tobytes())
    h.update(f"{trace.status}|{trace.error}".encode())
    return h.hexdigest()[:16]


def specs():
    from addt_dsl.compiler import compile_file, compile_source
    from addt_dsl.sweep import expand

    for path in sorted((ROOT / "examples").rglob("*.addt")):
        plan = compile_file(path).plan
        if plan is None:
            continue
        top = path.parent.name == "examples"  # nested (suites, search): the first RunSpec only
        for i, spec in enumerate(expand(plan).specs[:2 if top else 1]):
            yield f"{path.relative_to(ROOT / 'examples')}#{i}", spec
    for n in (5, 20, 50):
        for perception in ("ground_truth", "learned"):
            src = dense_source(n, perception=perception, duration=4.0 if n == 50 else 6.0)
            yield f"dense{n}-{perception}", expand(compile_source(src).plan).specs[0]
    yield "dense-ties", expand(compile_source(dense_source(12, ties=True, duration=6.0)).plan).specs[0]
    yield "dense-lanechange", expand(compile_source(dense_source(15, lane_changes=True, duration=8.0)).plan).specs[0]
    # The paper families with the learned detector (bench_stack.py's runs), and tensor faults on it.
    for family in PAPER_FAMILIES:
        yield f"family-{family}-learned", family_spec(family, "learned")
    site = "perception.backbone.conv0"
    for label, faults in (("activations-10hz", f"bitflip {site} tensor activations count 300"),
                          ("activations-last-second", f"during [29 s, 30 s] bitflip {site} tensor activations"),
                          ("weights-1hz", f"bitflip {site} tensor weights count 30"),
                          ("fine-activations-1hz", "bitflip perception.neck.fine tensor activations count 30")):
        yield f"family-following-learned-{label}", family_spec("following", "learned", faults=faults)


def main() -> None:
    from addt_dsl.runtime import execute as loop
    from addt_dsl.runtime.execute import execute

    if "--arrays" in sys.argv:
        loop.ARRAY_MIN_AGENTS = loop.STEP_MIN_AGENTS = 1
    only = [a for a in sys.argv[1:] if a != "--arrays"]
    for name, spec in specs():
        if only and not any(o in name for o in only):
            continue
        r = execute(spec)
        print(f"{name:56s} {r.status:9s} {full_digest(r.trace)}", flush=True)


if __name__ == "__main__":
    main()
