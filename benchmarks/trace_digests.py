"""Trace digests of example and dense-traffic RunSpecs, one line each: compare two
checkouts' output to show a change keeps every run bit for bit.

Run: PYTHONPATH=. python benchmarks/trace_digests.py > digests.txt   (on each checkout; diff)
     [--arrays: agents posed as arrays whatever their count, as the loop does from
     `ARRAY_MIN_AGENTS` agents on: the digests must not change]
     [NAME ...: only the runs whose name contains one of these]
     [--json OUT: also write {name: "status digest | oracle:P oracle:F ..."} to OUT; compare two
     with --compare A B: digests, then verdicts (where both files have them)]
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
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
        for i, spec in enumerate(expand(plan).specs[:2]):  # the first two runs of each sweep
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


def compare(before: str, after: str) -> int:
    """Print every run whose digest differs or is missing, then every run whose verdicts
    differ (runs both files give verdicts for); the exit status says whether all match."""
    a, b = json.loads(Path(before).read_text()), json.loads(Path(after).read_text())
    digest = lambda v: None if v is None else v.split(" | ")[0]  # noqa: E731
    verdicts = lambda v: v.split(" | ", 1)[1] if v is not None and " | " in v else None  # noqa: E731
    bad = [k for k in sorted(set(a) | set(b)) if digest(a.get(k)) != digest(b.get(k))]
    for k in bad:
        print(f"{k:56s} {digest(a.get(k))!s:28s} -> {digest(b.get(k))}")
    print(f"identical {len(a) - len(bad)}/{len(a)}" + (f"; {len(b)} after" if len(b) != len(a) else ""))
    both = [k for k in sorted(set(a) & set(b)) if verdicts(a[k]) is not None and verdicts(b[k]) is not None]
    changed = [k for k in both if verdicts(a[k]) != verdicts(b[k])]
    for k in changed:
        print(f"verdicts {k}: {verdicts(a[k])} -> {verdicts(b[k])}")
    if both:
        print(f"verdicts identical {len(both) - len(changed)}/{len(both)}")
    return 1 if bad or changed else 0


def main() -> None:
    args = sys.argv[1:]
    if args[:1] == ["--compare"]:
        sys.exit(compare(args[1], args[2]))
    from addt_dsl.runtime.execute import execute

    if "--arrays" in args:
        try:
            from addt_dsl.runtime import agents as loop  # the agents' arrays (runtime/agents.py)
        except ImportError:  # a checkout before the phases split
            from addt_dsl.runtime import execute as loop
        loop.ARRAY_MIN_AGENTS = 1
        args.remove("--arrays")
    out = None
    if "--json" in args:
        i = args.index("--json")
        out = Path(args[i + 1])
        del args[i:i + 2]
    found = {}
    for name, spec in specs():
        if args and not any(o in name for o in args):
            continue
        t0 = time.perf_counter()
        r = execute(spec)
        passed = " ".join(f"{v.name}:{'P' if v.passed else 'F'}" for v in r.verdicts)
        found[name] = f"{r.status} {full_digest(r.trace)} | {passed}"
        print(f"{name:56s} {r.status:9s} {full_digest(r.trace)} {time.perf_counter() - t0:6.2f}s", flush=True)
        if out is not None:
            out.write_text(json.dumps(found, indent=1))


if __name__ == "__main__":
    main()
