"""`addtc shrink` and `addtc falsify`.

    addtc shrink FILE [--run-id ID] [--oracle NAME] [--max-simulations N] [--batch N] [--out DIR]
    addtc shrink --run-key SPEC.json [FILE]      a RunSpec as JSON
    addtc shrink --store DIR [--run-id ID]       a stored run (`addtc FILE --out DIR`)
    addtc falsify FILE [--budget-runs N] [--budget-seconds S] [--seed K] [--jobs J] [--out DIR]

Exit codes follow `addtc` (addt_dsl/errors.py): 0 nothing fails, 1 a failure was found (and
written), 2 usage or scenario error, 3 the tool could not complete.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from addt_dsl.console import compile_and_report
from addt_dsl.errors import EXIT_FAILED, EXIT_OK, EXIT_USAGE, nonneg_float, nonneg_int, positive_int
from addt_dsl.limits import DEFAULT
from addt_dsl.search.samplers import DEFAULT_SAMPLER, SAMPLERS

DEFAULT_OUT = ".addt-failures"
CACHE_NAME = "runs.sqlite"  # the search's run cache, in the output directory by default

# Falsify and shrink run their own budget of runs, never the file's sweep: only the
# per-run cost thresholds apply to them, not the sweep-wide ones (docs/limits.md).
SEARCH_LIMITS = DEFAULT.raised(runs=2 ** 62, sim_seconds=float("inf"), agent_steps=float("inf"),
                               wall_seconds=float("inf"))  # the sweep is not run: only per-run thresholds

# Candidates `addtc shrink` runs together by default (`--batch`): 1, because batches run
# ~40 % more runs for the same shrink and today's engine steps a batch barely faster than its
# runs one by one (benchmarks/bench_shrink.py: 0.85-0.94x wall time at batch 8 on one job).
DEFAULT_SHRINK_BATCH = 1


def add_commands(sub) -> None:
    shrink = sub.add_parser("shrink", help="shrink a failing run to a minimal replayable .addt file")
    shrink.add_argument("file", nargs="?", help="scenario; its first failing run is shrunk")
    shrink.add_argument("--run-id", help="shrink this run of the sweep (e.g. c002-r000)")
    shrink.add_argument("--run-key", metavar="SPEC_JSON",
                        help="shrink the RunSpec in this JSON file (RunSpec.model_dump_json)")
    shrink.add_argument("--store", metavar="RESULTS",
                        help="a results store (`addtc FILE --out DIR` writes DIR/results.sqlite): shrink its "
                             "run --run-id, else its first failing run")
    shrink.add_argument("--oracle", help="the failing oracle to keep (default: the earliest violation)")
    shrink.add_argument("--max-simulations", type=positive_int, default=300)
    shrink.add_argument("--limit", type=nonneg_int, default=0, help="look for a failure in the first N runs only")
    shrink.add_argument("--jobs", "-j", type=positive_int, default=1,
                        help="processes while looking for a failing run and for each batch of candidates")
    shrink.add_argument("--batch", type=positive_int, default=DEFAULT_SHRINK_BATCH, metavar="N",
                        help="candidates run together where one must be simulated: it and the next ones its "
                             "pass would try (the same shrink at any N; runs ahead count against "
                             f"--max-simulations; default {DEFAULT_SHRINK_BATCH}, see docs/falsify-and-shrink.md)")
    shrink.add_argument("--out", default=DEFAULT_OUT, help=f"output directory (default {DEFAULT_OUT})")
    shrink.add_argument("--cache", help=f"results store (SQLite) to keep runs in and reuse across invocations "
                                        f"(default OUT/{CACHE_NAME}: a killed shrink run again resumes)")
    shrink.add_argument("--no-animation", action="store_true")
    shrink.add_argument("--format", choices=("text", "json"), default="text")
    shrink.set_defaults(func=cmd_shrink)

    fal = sub.add_parser("falsify", help="search parameters and faults for oracle violations")
    fal.add_argument("file")
    fal.add_argument("--budget-runs", type=positive_int, default=200)
    fal.add_argument("--budget-seconds", type=nonneg_float, default=0.0, help="0: no time limit")
    fal.add_argument("--seed", type=int, default=0)
    fal.add_argument("--jobs", "-j", type=positive_int, default=1)
    fal.add_argument("--batch", type=positive_int, default=16,
                     help="candidates per generation (cem, random; bo runs --jobs at a time)")
    fal.add_argument("--sampler", choices=tuple(SAMPLERS), default=DEFAULT_SAMPLER,
                     help="; ".join(f"{s.name}: {s.summary}" for s in SAMPLERS.values())
                     + f" (default {DEFAULT_SAMPLER})")
    fal.add_argument("--shrink-simulations", type=nonneg_int, default=60,
                     help="per distinct failure, to find its origin (0: do not shrink)")
    fal.add_argument("--shrink-batch", type=positive_int, default=DEFAULT_SHRINK_BATCH, metavar="N",
                     help="candidates each shrink runs together, as `addtc shrink --batch` "
                          f"(default {DEFAULT_SHRINK_BATCH})")
    fal.add_argument("--out", default=DEFAULT_OUT, help="write each distinct failure's counterexample here")
    fal.add_argument("--no-write", action="store_true", help="report only (no counterexamples, no run cache "
                                                              "unless --cache is given)")
    fal.add_argument("--cache", help=f"results store (SQLite) to keep runs in (default OUT/{CACHE_NAME}: a killed "
                                     "search run again with the same seed resumes and ends with the same report)")
    fal.add_argument("--format", choices=("text", "json"), default="text")
    fal.set_defaults(func=cmd_falsify)


def _err(msg: str) -> None:
    print(f"error: {msg}", file=sys.stderr)


def _first_failing(plan, run_id: str | None, limit: int, jobs: int, cache):
    from addt_dsl.sweep import expand

    specs = expand(plan).specs
    if run_id:
        specs = [s for s in specs if s.run_id == run_id]
        if not specs:
            raise LookupError(f"no run '{run_id}' in the sweep")
    if limit:
        specs = specs[:limit]
    step = max(1, jobs)
    for i in range(0, len(specs), step):
        batch = specs[i:i + step]
        for spec, outcome in zip(batch, cache.get_many(batch, jobs)):
            if not outcome.passed:
                return spec
    return None


def _from_store(path: str, run_id: str | None):
    """(RunSpec, plan) of a stored run: `run_id`, else the first failing one; (None, plan) if none fails."""
    from addt_dsl.runtime.store import ResultStore

    p = Path(path)
    if p.is_dir():
        p = p / "results.sqlite"
    store = ResultStore(p, readonly=True)
    try:
        plan = store.plan()
        if run_id:
            record = next(store.records("run_id = ?", (run_id,), limit=1), None)
            if record is None:
                raise LookupError(f"no run '{run_id}' in {p}")
        else:
            record = next(store.failing(limit=1), None)
            if record is None:
                return None, plan
        return store.spec(record), plan
    finally:
        store.close()


def cmd_shrink(args) -> int:
    from addt_dsl.search import RunCache

    if not args.file and not args.run_key and not args.store:
        _err("give a scenario FILE, --run-key SPEC_JSON or --store RESULTS")
        return EXIT_USAGE
    plan = None
    if args.file:
        result = compile_and_report(args.file, "text", SEARCH_LIMITS)
        if not result.ok:
            return EXIT_USAGE
        plan = result.plan
    try:
        cache = RunCache(args.cache or Path(args.out) / CACHE_NAME)
    except ValueError as exc:
        _err(str(exc))
        return EXIT_USAGE
    try:
        return _shrink(args, plan, cache)
    finally:
        cache.close()


def _shrink(args, plan, cache) -> int:
    from addt_dsl.plan import RunSpec
    from addt_dsl.printer import check_spec
    from addt_dsl.search import NotFailing, Shrinker
    from addt_dsl.search.artifacts import ReplayMismatch, write_counterexample

    source = args.file or ""
    if args.store:
        try:
            spec, store_plan = _from_store(args.store, args.run_id)
        except (OSError, LookupError) as exc:
            _err(str(exc))
            return EXIT_USAGE
        if spec is None:
            print(f"no failing run in {args.store}: nothing to shrink")
            return EXIT_OK
        plan = plan or store_plan
        source = source or spec.plan.source_file
    elif args.run_key:
        try:
            spec = RunSpec.model_validate_json(Path(args.run_key).read_text())
        except (OSError, ValueError) as exc:
            detail = exc.errors()[0]["msg"] if hasattr(exc, "errors") else str(exc)  # pydantic: first error only
            _err(f"cannot read a RunSpec from {args.run_key}: {detail}")
            return EXIT_USAGE
        source = source or spec.plan.source_file
    if args.store or args.run_key:
        # Read from a file, it met no compiler: the limits and checks of a scenario first
        # (a RunSpec of 5000 agents ran for minutes; a duration of 1e308 s, a negative seed
        # or a NaN parameter were internal errors at the end).
        try:
            check_spec(spec, SEARCH_LIMITS)
        except ValueError as exc:
            _err(f"the run in {args.run_key or args.store} is not one a scenario can state: {exc}")
            return EXIT_USAGE
    else:
        try:
            spec = _first_failing(plan, args.run_id, args.limit, args.jobs, cache)
        except LookupError as exc:
            _err(str(exc))
            return EXIT_USAGE
        if spec is None:
            print("no failing run: nothing to shrink")
            return EXIT_OK
    log = (lambda m: print(m, file=sys.stderr)) if args.format == "text" else None
    try:
        shrinker = Shrinker(spec, nominal_plan=plan or spec.plan, oracle=args.oracle, cache=cache,
                            max_simulations=args.max_simulations, log=log, batch=args.batch, jobs=args.jobs)
    except NotFailing as exc:
        print(str(exc))
        return EXIT_OK
    result = shrinker.run()
    try:
        arts = write_counterexample(result, args.out, source, animate=not args.no_animation)
    except ReplayMismatch as exc:
        _err(str(exc))
        return EXIT_USAGE
    if args.format == "json":
        print(json.dumps(json.loads(arts.report.read_text()), indent=2))
    else:
        print_shrink_summary(result, arts)
    return EXIT_FAILED


def print_shrink_summary(result, arts) -> None:
    print(f"failure: {result.target.describe()}")
    print(f"shrunk: {len(result.original.faults)} -> {len(result.best.faults)} fault(s), "
          f"{len(result.original.plan.agents)} -> {len(result.best.plan.agents)} agent(s) in "
          f"{result.simulations} simulations ({result.cache_hits} cache hits, {result.rounds} rounds, "
          f"{result.seconds:.1f} s" + (f"; {result.ran_ahead} more run ahead in batches of {result.batch}"
                                       if result.batch > 1 else "")
          + ")" + (" [budget exhausted]" if result.budget_exhausted else ""))
    width = max(len(s.name) for s in result.stats)
    for s in result.stats:
        print(f"  {s.name:<{width}}  {s.candidates:4d} candidates {s.simulations:4d} simulated "
              f"{s.accepted:3d} accepted {s.seconds:6.2f} s"
              + (f" ({s.rejected} did not compile)" if s.rejected else ""))
    for line in result.changes:
        print(f"  {line}")
    print(f"wrote {arts.addt}  (replay: addtc {arts.addt})")
    for p in arts.files[1:]:
        print(f"      {p}")
    if arts.osi_note:
        print(f"      no OSI trace: {arts.osi_note}")


def cmd_falsify(args) -> int:
    result = compile_and_report(args.file, "text", SEARCH_LIMITS)
    if not result.ok:
        return EXIT_USAGE
    log = (lambda m: print(m, file=sys.stderr)) if args.format == "text" else None
    from addt_dsl.search import RunCache

    path = args.cache or (None if args.no_write else Path(args.out) / CACHE_NAME)
    try:
        cache = RunCache(path)
    except ValueError as exc:
        _err(str(exc))
        return EXIT_USAGE
    try:
        return _falsify(args, result, cache, log)
    finally:
        cache.close()


def _falsify(args, result, cache, log) -> int:
    from addt_dsl.search.falsify import Falsifier
    from addt_dsl.sweep import UnsatisfiableAssumptions

    try:
        fal = Falsifier(result.plan, seed=args.seed, batch=args.batch, jobs=args.jobs, sampler=args.sampler,
                        log=log, cache=cache, shrink_batch=args.shrink_batch)
    except UnsatisfiableAssumptions as exc:
        _err(str(exc))
        return EXIT_USAGE
    if log is not None and cache.path is not None and cache.path.exists() and len(cache.store):
        log(f"run cache {cache.path}: {len(cache.store)} run(s) kept from before are reused")
    report = fal.run(budget_runs=args.budget_runs, budget_seconds=args.budget_seconds,
                     shrink_simulations=args.shrink_simulations)
    written, notes = [], []
    if not args.no_write:
        from addt_dsl.search.artifacts import ReplayMismatch, write_counterexample

        for found in report.failures:
            if found.shrunk is None:
                continue
            try:
                arts = write_counterexample(found.shrunk, args.out, args.file, animate=False)
                written += [arts.addt] + ([arts.xosc] if arts.xosc else [])  # .xosc: docs/openscenario.md
                written += [arts.osi] if arts.osi else []  # .osi: docs/bridge.md
                if arts.osi_note and arts.osi_note not in notes:
                    notes.append(arts.osi_note)
            except ReplayMismatch as exc:
                _err(str(exc))
    if args.format == "json":
        data = report.to_json()
        data["written"] = [str(p) for p in written]
        print(json.dumps(data, indent=2))
    else:
        from addt_dsl.search.render import falsify_text

        print(falsify_text(report))
        for p in written:
            print(f"wrote {p}")
        for note in notes:
            print(f"no OSI trace: {note}")
    return EXIT_FAILED if report.failures else EXIT_OK
