"""`addtc`: compile, run and judge `.addt` scenarios.

    addtc FILE [--jobs N] [--out DIR]     compile and run the file's sweep, print verdicts
    addtc DIR|FILE... [--by PARAM]        a suite: each file's sweep, one combined table
        [--executor local|ray] [--address ADDR] [--store PATH] [--timeout auto|S|0] [--retries N]
        [--junit FILE]
        [--classify]                      also classify each run against its fault-free twin
    addtc report DIR                      HTML report, summary.json, runs.csv of a results dir
    addtc report DIR --salvage NEW        copy a damaged store's readable runs into a new store
    addtc trace DIR RUN_ID [--csv F] [--parquet F] [--plot F.png]   one run's signals and events
    addtc check FILE...                   compile only (diagnostics and the sweep's cost estimate)
    addtc plan FILE                       print the ScenarioPlan as JSON (the cost estimate on stderr)
        check, plan and run take [--allow-large] [--max NAME=N] (docs/limits.md)
    addtc schema [--write PATH]           the plan's JSON schema
    addtc shrink FILE | --run-key JSON    shrink a failing run to a minimal replayable .addt file
    addtc falsify FILE [--budget-runs N]  search parameters and faults for failures
    addtc study perception|classify|table ...  fault studies (perception errors by band, outcomes)
    addtc export FILE [--run ID | --params K=V ...] --to DIR   one run as OpenSCENARIO + OpenDRIVE
    addtc import FILE.xosc [-o FILE.addt] [--root DIR]          OpenSCENARIO to .addt (docs/openscenario.md)

Exit codes (addt_dsl/errors.py): 0 every run passed, 1 at least one run failed an oracle,
2 usage or scenario error, 3 the tool could not complete (runs crashed, timed out or were
lost after their retries, the store is unusable or in use, the disk is full, internal error).
Set ADDT_DEBUG=1 to see the traceback of an internal error.
"""

from __future__ import annotations

import argparse
import errno
import itertools
import json
import os
import sqlite3
import sys
import tempfile
import traceback
from pathlib import Path

from addt_dsl.console import compile_and_report, stack_option
from addt_dsl.diagnostics import render_json
from addt_dsl.errors import (EXIT_INCOMPLETE, EXIT_OK, EXIT_USAGE, ToolError, UsageError, nonneg_float,
                             nonneg_int, positive_int, time_bound, verdict_exit_code)
from addt_dsl.limits import DEFAULT, DEFAULT_ANIMATION_BUDGET_S, INPUT_LIMITS, parse_limit

SUBCOMMANDS = ("run", "check", "plan", "schema", "report", "trace", "shrink", "falsify", "study", "map", "export",
               "import")


def cmd_check(args) -> int:
    """Compile every file (one process: the grammar is built once). With `--format json`,
    one JSON array holds the diagnostics of all files (each names its file)."""
    from addt_dsl.compiler import compile_file

    failed = False
    collected = []
    limits = _limits(args)
    for path in args.files:
        if args.format == "json":
            result = compile_file(path, limits, args.stack, args.root)
            collected.extend(result.diagnostics)
        else:
            result = compile_and_report(path, args.format, limits, args.stack, args.root)
            if result.ok:
                print(f"ok: {path}")
                print("\n".join(result.estimate.lines()))
        failed |= not result.ok
    if args.format == "json":
        print(render_json(collected))
    return EXIT_USAGE if failed else EXIT_OK


def cmd_plan(args) -> int:
    result = compile_and_report(args.file, args.format, _limits(args), args.stack, args.root)
    if not result.ok:
        return EXIT_USAGE
    if args.format == "text":  # stdout stays the plan's JSON
        print("\n".join(result.estimate.lines()), file=sys.stderr)
    print(result.plan.model_dump_json(indent=2))
    return EXIT_OK


def cmd_schema(args) -> int:
    from addt_dsl.plan import plan_json_schema

    text = json.dumps(plan_json_schema(), indent=2) + "\n"
    if args.write:
        from addt_dsl.atomic import write_text

        if not Path(args.write).parent.is_dir():  # a mistyped path: said, not created
            raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), args.write)
        write_text(args.write, text)
        print(f"wrote {args.write}")
    else:
        print(text, end="")
    return EXIT_OK


def cmd_run(args) -> int:
    from addt_dsl.suite import SuiteError, expand_paths

    if getattr(args, "allow_host", None):  # the environment reaches every worker process the runs are made in
        from addt_dsl.stack.bridge import ALLOW_HOSTS_ENV

        os.environ[ALLOW_HOSTS_ENV] = ",".join(args.allow_host)
    try:
        paths = expand_paths(args.files)
    except SuiteError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if len(paths) == 1 and not args.by and not Path(args.files[0]).is_dir():
        return _run_file(args, paths[0], Path(args.out) if args.out else None)
    return _run_suite(args, paths)


def _run_suite(args, paths: list[Path]) -> int:
    """Each file as its own run (results in OUT/<stem>/), then one combined table."""
    import time

    from addt_dsl.suite import SuiteRow, collect_row, print_suite, write_summary

    if args.store:
        print("error: --store names one results file; a suite keeps one per file under --out", file=sys.stderr)
        return EXIT_USAGE
    out = Path(args.out) if args.out else None
    # Each file runs as usual, but JUnit goes to one file for the whole suite (below).
    per_file = argparse.Namespace(**{**vars(args), "junit": None, "in_suite": True})
    rows, junit_trees = [], []

    def collect(plan, store, row):
        collect_row(row, plan, store, args.by)
        if args.junit:
            from addt_dsl.reporting.junit import junit_tree

            junit_trees.append(junit_tree(plan, store.records()))

    for path in paths:
        row = SuiteRow(path)
        if args.format != "json":
            print(f"== {path}", file=sys.stderr)
        started = time.perf_counter()
        row.exit_code = _run_file(per_file, path, out / path.stem if out else None,
                                  collect=lambda plan, store, row=row: collect(plan, store, row))
        row.wall_s = time.perf_counter() - started
        rows.append(row)
    if args.by and not any(r.by for r in rows) and any(r.totals.get("runs") for r in rows):
        print(f"error: --by {args.by}: no file of the suite has a parameter of that name", file=sys.stderr)
        return max([EXIT_USAGE, *(r.exit_code for r in rows)])
    if out:
        write_summary(out, rows, args.by)
    if args.junit:
        from addt_dsl.reporting.junit import merge_junit, write_tree

        write_tree(args.junit, merge_junit(junit_trees))  # one <testsuite> per file that ran
    if args.format == "json":
        from addt_dsl.suite import suite_summary

        print(json.dumps(suite_summary(rows, args.by), indent=2))
    else:
        print_suite(rows, args.by)
    return max(r.exit_code for r in rows)


def _run_file(args, path: Path, out: Path | None, collect=None) -> int:
    """Compile and run one file; `collect(plan, store)` sees the store before it closes."""
    result = compile_and_report(str(path), args.format, _limits(args), args.stack, args.root)
    if not result.ok:
        return EXIT_USAGE
    from addt_dsl.runtime.store import ResultStore, StoreMismatch
    from addt_dsl.sweep import SweepStream, UnsatisfiableAssumptions

    plan = result.plan
    stream = SweepStream(plan)
    try:
        if len(stream) == 0:
            next(iter(stream))  # raises: every candidate breaks an assumption
    except UnsatisfiableAssumptions as exc:
        print(f"error[E0501]: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        args.sweep_runs = len(stream)  # (the default batch size comes from it)
        executor = _executor(args)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    tmp = None
    if args.store:
        store_path = Path(args.store)
    elif out:
        store_path = out / "results.sqlite"
    else:
        tmp = tempfile.TemporaryDirectory(prefix="addtc-")
        store_path = Path(tmp.name) / "results.sqlite"
    try:
        store = ResultStore(store_path, plan, fresh=args.fresh)
    except StoreMismatch as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ToolError as exc:  # damaged, foreign, read-only or busy: this file fails, a suite goes on
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INCOMPLETE
    try:
        if args.classify:
            executor = _classifying(args, stream, store, executor)
        code = _run_and_report(args, plan, stream, store, executor, out)
        if collect is not None and code != 130:
            collect(plan, store)
        return code
    except UnsatisfiableAssumptions as exc:
        print(f"error[E0501]: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ToolError as exc:  # e.g. the disk filled up: committed runs stay, a resume goes on
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INCOMPLETE
    finally:
        store.close()
        if tmp is not None:
            tmp.cleanup()


def _executor(args):
    from addt_dsl.runtime.executor import default_batch

    inline = args.executor == "inline"  # one process: one worker's batches
    batch = getattr(args, "batch", None) or default_batch(getattr(args, "sweep_runs", 0),
                                                          1 if inline else getattr(args, "jobs", 1))
    if inline:
        from addt_dsl.runtime.executor import InlineExecutor

        return InlineExecutor(timeout_s=args.timeout, memory_limit_mb=args.memory_limit, batch=batch)
    if args.executor == "ray":
        from addt_dsl.runtime.ray_executor import RayExecutor, ray_available

        if not ray_available():
            raise UsageError("--executor ray needs the `ray` package (pip install 'addt-dsl[ray]')")
        return RayExecutor(address=args.address, jobs=args.jobs if args.jobs_given else None,
                           timeout_s=args.timeout, memory_limit_mb=args.memory_limit, retries=args.retries,
                           batch=batch)
    if args.address:
        raise UsageError("--address is for --executor ray")
    from addt_dsl.runtime.executor import LocalExecutor

    return LocalExecutor(args.jobs, timeout_s=args.timeout, memory_limit_mb=args.memory_limit,
                         max_tasks_per_child=args.max_tasks_per_child, retries=args.retries, batch=batch)


def _classifying(args, stream, store, executor):
    """`--classify`: run the golden (fault-free) twins the sweep still needs, kept in the
    store so a resumed sweep reuses them, then wrap the executor so every run it returns
    carries its outcome class (addt_dsl.runtime.outcome)."""
    from addt_dsl.runtime.outcome import ClassifyingExecutor, GoldenCache, prepare_goldens

    if not hasattr(executor, "run_fn"):
        raise UsageError(f"--classify runs on the local or inline executor, not {executor.name}")
    done = store.done(classified=True)  # stored runs without a class run again to get one
    specs = itertools.islice(stream, args.limit) if args.limit else stream
    pending = [s for s in specs if s.faults and (s.key(), s.run_id) not in done]
    if not stream.plan.faults and args.format != "json":
        print("note: the scenario has no faults: every run is its own golden run (masked if it "
              "passed, else twin_failed)", file=sys.stderr)
    ran = prepare_goldens(pending, cache=GoldenCache(store.path), executor=executor)
    if ran and args.format != "json":
        print(f"classify: ran {ran} golden run(s) (kept in {store.path})", file=sys.stderr)
    return ClassifyingExecutor(executor, store.path)


def _run_and_report(args, plan, stream, store, executor, out) -> int:
    from addt_dsl.reporting.summary import store_summary
    from addt_dsl.reporting.tables import print_verdicts, shown_records

    total = len(stream)
    limit = args.limit or None
    specs = itertools.islice(stream, limit) if limit else stream
    total = min(total, limit) if limit else total
    store.begin_session(" ".join(sys.argv), executor.name, min(executor.workers, total))  # no more ever start
    already = len(store)
    quiet = args.format == "json"
    if already and not quiet:
        print(f"resuming: {already} run(s) already in {store.path}", file=sys.stderr)
    try:
        if args.classify:
            classified = len(store.done(classified=True))
            if already > classified and not quiet:
                print(f"classify: {already - classified} stored run(s) have no outcome class; they run again "
                      "to get one (same RunSpec, same run)", file=sys.stderr)
            already = classified
        outcome = _sweep_with_progress(specs, store, executor, total, min(already, total), quiet,
                                       classified=args.classify)
    except KeyboardInterrupt:
        print(f"interrupted: {len(store)} run(s) are stored in {store.path}; "
              "run the same command again to resume", file=sys.stderr)
        return 130
    store.set_meta("rejected", dict(stream.rejected))
    store.set_meta("not_done", [r.run_id for r in outcome.lost])
    for text, n in stream.rejected.most_common():
        print(f"note: assumption `{text}` rejected {n} candidate run(s)", file=sys.stderr)
    totals = store_summary(store)
    if out:
        from addt_dsl.reporting import build_report, write_tables

        write_tables(out, store)
        if not args.no_report:
            build_report(store, out / "report.html", max_animations=args.animations,
                         animation_budget_s=args.animation_budget)
    if args.junit:
        from addt_dsl.reporting import write_junit

        write_junit(args.junit, plan, store.records())
    if getattr(args, "in_suite", False):
        if not quiet:  # one line per file; the suite prints the combined table
            failing = [f"{r.run_id} ({', '.join(r.failed_oracles) or r.status})" for r in store.failing(limit=5)]
            warned = f", {totals['warned']} with warnings" if totals.get("warned") else ""
            errors = f", {totals['errors']} error(s)" if totals.get("errors") else ""
            print(f"{plan.name}: {totals['passed']} passed, {totals['failed']} failed{errors}{warned}"
                  + (f"; e.g. {', '.join(failing)}" if failing else ""), file=sys.stderr)
    else:
        print_verdicts(plan, shown_records(store), totals, fmt=args.format)
    if not quiet and outcome.skipped:
        print(f"({outcome.skipped} run(s) taken from the store, {outcome.ran} executed now)", file=sys.stderr)
    if getattr(executor, "retried", 0) and not quiet:
        print(f"note: {executor.retried} run attempt(s) did not finish and were run again", file=sys.stderr)
    if outcome.lost:
        ids = ", ".join(r.run_id for r in outcome.lost[:5]) + (", ..." if len(outcome.lost) > 5 else "")
        print(f"error: {len(outcome.lost)} run(s) could not be completed ({ids}: "
              f"{outcome.lost[0].error.splitlines()[0]}); they are not stored: run the same command again "
              "to run them", file=sys.stderr)
        return EXIT_INCOMPLETE
    return verdict_exit_code(totals["statuses"], totals["failed"])


def _sweep_with_progress(specs, store, executor, total: int, done: int, quiet: bool, classified: bool = False):
    from addt_dsl.runtime.executor import run_sweep

    if quiet or total - done < 4:
        return run_sweep(specs, store, executor, classified=classified)
    if not sys.stderr.isatty():  # a log, not a terminal: plain lines a bar cannot give
        from addt_dsl.reporting.progress import ProgressLines

        return run_sweep(specs, store, executor, on_record=ProgressLines(total, done), classified=classified)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeRemainingColumn(), transient=True) as progress:
        task = progress.add_task("runs", total=total, completed=done)
        return run_sweep(specs, store, executor, on_record=lambda r: progress.advance(task), classified=classified)


def cmd_report(args) -> int:
    from addt_dsl.reporting import build_report, write_junit, write_tables
    from addt_dsl.reporting.summary import store_summary, write_csv, write_parquet

    target = Path(args.dir)
    if args.salvage:
        return _salvage(target, Path(args.salvage))
    out = Path(args.out) if args.out else (target.parent if target.is_file() else target)
    with _open_store(target) as store:
        totals = store_summary(store)
        write_tables(out, store)
        path = build_report(store, out / "report.html", max_animations=args.animations,
                         animation_budget_s=args.animation_budget)
        if args.junit:
            write_junit(args.junit, store.plan(), store.records())
        for export in args.export or ():
            if export.endswith(".parquet"):
                write_parquet(store, export)
            else:
                write_csv(store, export)
        print(f"wrote {path}")
    if totals.get("not_done"):
        print(f"error: {len(totals['not_done'])} run(s) of the sweep could not be completed and are not in "
              "the store: run the sweep's command again to run them", file=sys.stderr)
        return EXIT_INCOMPLETE
    return verdict_exit_code(totals["statuses"], totals["failed"])


def _store_path(target: Path) -> Path:
    store_path = target if target.is_file() else target / "results.sqlite"
    if not store_path.exists():
        raise UsageError(f"no results store at {store_path} (run `addtc FILE --out DIR` first)")
    return store_path


def _open_store(target: Path):
    """The results store of a directory written by `--out`, or a store file, read-only
    (readers never write it: a read-only store or one a sweep is writing both work)."""
    from addt_dsl.runtime.store import ResultStore

    return ResultStore(_store_path(target), readonly=True)


def _salvage(target: Path, into: Path) -> int:
    """`addtc report DIR --salvage NEW`: copy a damaged store's readable runs into NEW."""
    from addt_dsl.runtime.store import ResultStore

    copied, lost = ResultStore.salvage(_store_path(target), into)
    print(f"salvaged {copied} run(s) into {into}" + (f"; {lost} unreadable run(s) left out" if lost else "")
          + f"; resume the sweep with `addtc FILE --store {into}` (it runs the missing ones)")
    return EXIT_OK


# Input limits and cost thresholds out of the way: a stored run was made under the sweep's `--max`.
_ANY_SIZE = DEFAULT.raised(allow_large=True, **{name: type(getattr(DEFAULT, name))(2 ** 62) for name in INPUT_LIMITS})


def cmd_trace(args) -> int:
    """Execute a stored run again (its RunSpec determines it) and show its signals and events."""
    from addt_dsl.printer import check_spec
    from addt_dsl.reporting.trace_view import events_path, events_table, print_trace, rerun, signals_table

    if args.osi:  # before the run is executed again
        from addt_dsl import extras

        missing = extras.missing_message("osi3", "`--osi`")
        if missing:
            raise UsageError(missing)
        if Path(args.osi).suffix.lower() not in (".osi", ".mcap"):
            raise UsageError(f"--osi writes FILE.osi or FILE.mcap, not {args.osi!r}")
    with _open_store(Path(args.dir)) as store:
        record = next(store.records("run_id = ?", (args.run_id,), limit=1), None)
        if record is None:
            ids = [r.run_id for r in store.records(limit=5)]
            raise UsageError(f"no run {args.run_id!r} in {store.path} (runs are named like {', '.join(ids)})")
        try:  # the stored run met a compiler (with whatever --max the sweep had): its values still must
            check_spec(store.spec(record), _ANY_SIZE)
        except ValueError as exc:
            raise ToolError(f"{store.path}: run {args.run_id} is not one a scenario can state (the store was "
                            f"edited or damaged): {exc}") from None
        run = rerun(store, record)
    table, events = signals_table(run.spec, run.trace), events_table(run.trace)
    print_trace(run, table, events)
    for path, write in ((args.csv, "to_csv"), (args.parquet, "to_parquet")):
        if path:
            from addt_dsl.atomic import atomic_path

            for frame, target in ((table, path), (events, events_path(path))):
                with atomic_path(target) as tmp:
                    getattr(frame, write)(tmp, index=False)
            print(f"wrote {path} and {events_path(path)}")
    if args.osi:
        from addt_dsl.stack import osi_trace

        n = osi_trace.write(run.spec, run.trace, args.osi)
        print(f"wrote {args.osi} ({n} OSI SensorViews)")
    if args.plot:
        from addt_dsl.atomic import write_bytes
        from addt_dsl.reporting.plots import run_signals_png

        write_bytes(args.plot, run_signals_png(table, run.verdicts, f"{run.spec.plan.name} {record.run_id}",
                                               events))
        print(f"wrote {args.plot}")
    return EXIT_OK


def cmd_map(args) -> int:
    """Roads, lanes with direction, junction connections and signals of an OpenDRIVE file."""
    from addt_dsl.compiler.xodr_check import count_roads
    from addt_dsl.reporting.roadmap import describe, map_png
    from addt_dsl.road import XodrError, parse_xodr

    # The compiler's map limits (docs/limits.md), checked before anything is built.
    limits = _limits(args)
    try:
        size = Path(args.file).stat().st_size
        if size > limits.map_bytes:
            raise UsageError(f"{args.file}: {size:,} bytes, more than map_bytes = {limits.map_bytes:,} "
                             "(raise it with --max map_bytes=N)")
        with open(args.file, "rb") as fh:
            data = fh.read(limits.map_bytes + 1)
    except OSError as exc:
        raise UsageError(f"cannot read {args.file}: {exc.strerror or exc}") from None
    text = data.decode("utf-8", errors="replace")
    roads = count_roads(text)
    if roads > limits.roads_per_map:
        raise UsageError(f"{args.file}: {roads:,} roads, more than roads_per_map = {limits.roads_per_map:,} "
                         "(raise it with --max roads_per_map=N)")
    try:
        network = parse_xodr(data, str(args.file))
    except XodrError as exc:
        raise UsageError(f"cannot read {args.file}: {exc}") from None
    for road_id, road in network.roads.items():
        widest = max((len(section.lane_ids) for section in road.sections), default=0)
        if widest > limits.lanes_per_section:
            raise UsageError(f"{args.file}: road {road_id} has a lane section of {widest} lanes, more than "
                             f"lanes_per_section = {limits.lanes_per_section} "
                             "(raise it with --max lanes_per_section=N)")
    print(describe(network, Path(args.file).name), end="")
    if args.png:
        from addt_dsl.atomic import write_bytes

        write_bytes(args.png, map_png(network, Path(args.file).name))
        print(f"wrote {args.png}")
    return EXIT_OK


def _limits(args):
    """The input limits and cost thresholds of `--max` and `--allow-large` (docs/limits.md)."""
    limits = DEFAULT.raised(allow_large=getattr(args, "allow_large", False),
                            run_cap=getattr(args, "limit", 0) or 0)  # `run --limit N`: the first N runs
    for item in getattr(args, "max", None) or ():
        try:
            limits = parse_limit(item, limits)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    return limits


def _limit_options(parser) -> None:
    stack_option(parser)
    parser.add_argument("--root", metavar="DIR",
                        help="read includes and maps from anywhere under DIR, e.g. a repository's root (default: "
                             "the scenario's directory; DIR must hold the scenario)")
    parser.add_argument("--allow-large", action="store_true",
                        help="run a sweep whose cost estimate is beyond the thresholds (docs/limits.md)")
    parser.add_argument("--max", action="append", default=[], metavar="NAME=N",
                        help="raise one input limit or cost threshold, e.g. --max agents=5000 (docs/limits.md)")


ANIMATIONS_HELP = ("animate the N worst failing runs in report.html (default 0: none; each is re-run with its "
                   "trace and drawn, 5-15 s apiece)")
ANIMATION_BUDGET_HELP = (f"wall seconds the animations may take in all (default {DEFAULT_ANIMATION_BUDGET_S:g}); "
                         "failing runs left over are listed in the report, not drawn")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="addtc", description="Compile and run .addt driving scenarios.")
    sub = parser.add_subparsers(dest="command")
    run = sub.add_parser("run", help="compile and run a scenario (default)")
    run.add_argument("files", nargs="+", metavar="file",
                     help="scenario file(s); a directory stands for the .addt files in it (a suite)")
    run.add_argument("--by", metavar="PARAM",
                     help="suite table: success rate per value of this parameter (e.g. drop_rate)")
    run.add_argument("--jobs", "-j", type=positive_int, default=None,
                     help="worker processes (default: CPU count; Ray: the cluster's CPUs)")
    run.add_argument("--batch", type=positive_int, default=None, metavar="N",
                     help="runs a worker steps together (default: from the sweep's size, at most "
                          "16, each worker at least 4 batches; see docs/twin.md)")
    run.add_argument("--executor", choices=("local", "ray", "inline"), default="local",
                     help="local worker processes (default), a Ray cluster, or this process (debugging)")
    run.add_argument("--address", help="Ray cluster address (default: start a local Ray instance)")
    run.add_argument("--allow-host", action="append", default=[], metavar="HOST",
                     help="let `stack external` scenarios connect to HOST (default: loopback only; repeatable)")
    run.add_argument("--out", help="write summary.json, runs.csv, report.html and results.sqlite here")
    run.add_argument("--store", help="results store (SQLite) to commit runs to and resume from "
                                     "(default: OUT/results.sqlite, else a temporary file)")
    run.add_argument("--fresh", action="store_true", help="discard the store's results before running")
    run.add_argument("--junit", metavar="FILE", help="write JUnit XML (one testcase per run)")
    run.add_argument("--timeout", type=time_bound, default="auto", metavar="SECONDS",
                     help="wall-clock limit per run; a run past it is recorded as `timeout` (default auto: "
                          "60 s + 10 x the simulated duration; 0: no limit)")
    run.add_argument("--retries", type=nonneg_int, default=2, metavar="N",
                     help="run again a run that did not finish (its worker killed from outside: up to N "
                          "times; a crash or timeout: once); default 2")
    run.add_argument("--memory-limit", type=nonneg_float, default=4096, metavar="MB",
                     help="resident memory per worker; a run past it is recorded as `memory` (0: off)")
    run.add_argument("--max-tasks-per-child", type=positive_int, default=500, metavar="N",
                     help="replace a worker process after N runs")
    run.add_argument("--no-report", action="store_true", help="with --out: skip report.html")
    run.add_argument("--animations", type=nonneg_int, default=0, metavar="N",
                     help=ANIMATIONS_HELP)
    run.add_argument("--animation-budget", type=nonneg_float, default=DEFAULT_ANIMATION_BUDGET_S,
                     metavar="SECONDS", help=ANIMATION_BUDGET_HELP)
    run.add_argument("--limit", type=nonneg_int, default=0, help="run only the first N runs of the sweep")
    run.add_argument("--format", choices=("text", "json"), default="text")
    run.add_argument("--classify", action="store_true",
                     help="classify every run against its fault-free twin: masked, silent, detected, "
                          "hazard (or error); adds an outcome column and counts")
    _limit_options(run)
    run.set_defaults(func=cmd_run)
    report = sub.add_parser("report", help="write report.html (and tables) for a results directory")
    report.add_argument("dir", help="directory written by --out (or a results .sqlite file)")
    report.add_argument("--out", help="directory for report.html, summary.json, runs.csv (default: DIR)")
    report.add_argument("--junit", metavar="FILE", help="also write JUnit XML")
    report.add_argument("--export", action="append", metavar="FILE",
                        help="also export the runs table (.csv or .parquet); repeatable")
    report.add_argument("--animations", type=nonneg_int, default=0, metavar="N", help=ANIMATIONS_HELP)
    report.add_argument("--animation-budget", type=nonneg_float, default=DEFAULT_ANIMATION_BUDGET_S,
                        metavar="SECONDS", help=ANIMATION_BUDGET_HELP)
    report.add_argument("--salvage", metavar="NEW.sqlite",
                        help="copy the readable runs of a damaged store into a new store (then resume with "
                             "--store NEW.sqlite)")
    report.set_defaults(func=cmd_report)
    trace = sub.add_parser("trace", help="one stored run's signals and events (executes its RunSpec again)")
    trace.add_argument("dir", help="directory written by --out (or a results .sqlite file)")
    trace.add_argument("run_id", help="the run, e.g. c002-r000 (the `run` column of the verdict table)")
    trace.add_argument("--csv", metavar="FILE", help="write the signals (one row per sample) here, the events "
                                                     "beside it as FILE-events.csv")
    trace.add_argument("--parquet", metavar="FILE", help="the same as Parquet")
    trace.add_argument("--plot", metavar="FILE.png", help="plot speeds, gaps, TTC, lane offset and each "
                                                          "oracle's margin over time")
    trace.add_argument("--osi", metavar="FILE", help="write the run's ground truth as an ASAM OSI trace: "
                                                     "FILE.osi (binary, length-prefixed SensorViews) or FILE.mcap")
    trace.set_defaults(func=cmd_trace)
    check = sub.add_parser("check", help="compile only")
    check.add_argument("files", nargs="+")
    check.add_argument("--format", choices=("text", "json"), default="text")
    _limit_options(check)
    check.set_defaults(func=cmd_check)
    plan = sub.add_parser("plan", help="print the execution plan as JSON")
    plan.add_argument("file")
    plan.add_argument("--format", choices=("text", "json"), default="text")
    _limit_options(plan)
    plan.set_defaults(func=cmd_plan)
    schema = sub.add_parser("schema", help="print or write the plan's JSON schema")
    schema.add_argument("--write", help="file to write")
    schema.set_defaults(func=cmd_schema)
    road_map = sub.add_parser("map", help="list an OpenDRIVE file's roads, lanes, junctions and signals "
                                          "(ids for routes); --png draws it")
    road_map.add_argument("file", help="an .xodr file")
    road_map.add_argument("--png", help="write a map image with the ids drawn on it")
    road_map.add_argument("--max", action="append", metavar="NAME=N",
                          help="raise one of the compiler's map limits (map_bytes, roads_per_map, lanes_per_section)")
    road_map.set_defaults(func=cmd_map)
    from addt_dsl.search.commands import add_commands

    add_commands(sub)
    from addt_dsl.interop.commands import add_commands as add_interop_commands  # export, import

    add_interop_commands(sub)
    # Listed for `addtc --help` only: `main` hands every `addtc study ...` argument to the
    # studies' own parser (addt_dsl/studies.py), --help included.
    sub.add_parser("study", add_help=False,
                   help="fault studies: perception errors by distance band, outcome classes, "
                        "success tables (`addtc study --help`)")
    return parser


def cmd_study(argv: list[str]) -> int:
    from addt_dsl.studies import main as study_main

    return study_main(argv, prog="addtc study")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["study"]:  # its own parser sees every argument, --help included
        return guarded(cmd_study, argv[1:])
    if argv and argv[0] not in SUBCOMMANDS and not argv[0].startswith("-"):
        argv.insert(0, "run")
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "command", None) == "run":
        args.jobs_given = args.jobs is not None
        args.jobs = args.jobs if args.jobs is not None else max(1, os.cpu_count() or 1)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    return guarded(args.func, args)


def guarded(command, *args) -> int:
    """Run a command; map what escapes it onto the exit codes (addt_dsl/errors.py): a usage
    error is one line and exit 2; an unusable store, a disk error or any other exception
    is one line and exit 3 (never 1, which means a run failed), with the traceback only
    when ADDT_DEBUG is set."""
    try:
        code = command(*args)
        sys.stdout.flush()  # here, not at exit: a reader that went away is handled below
        return code
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `addtc map X | head`: the reader has what it wanted; end quietly
        _stdout_to_devnull()
        return EXIT_OK
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ToolError as exc:  # says what is wrong and what to do: no "internal error"
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INCOMPLETE
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError) as exc:  # a path the user gave
        print(f"error: {exc.strerror or exc}: {exc.filename}" if exc.filename else f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as exc:  # noqa: BLE001 - the tool failed: say so in one line, exit 3
        if os.environ.get("ADDT_DEBUG"):
            traceback.print_exc()
        print(f"error: {_incomplete_message(exc)}", file=sys.stderr)
        return EXIT_INCOMPLETE


def _stdout_to_devnull() -> None:
    """Point stdout at /dev/null so the interpreter's final flush of what is still
    buffered does not raise again (Python's documented recipe for SIGPIPE)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no file descriptor (captured in tests): nothing to flush to
        pass


def _incomplete_message(exc: Exception) -> str:
    first = (str(exc).splitlines() or [""])[0]
    if isinstance(exc, sqlite3.DatabaseError):
        return f"the results store is unusable ({first}); run again with a new --out or --store"
    if isinstance(exc, OSError):
        return f"{exc.strerror or first}" + (f": {exc.filename}" if exc.filename else "")
    return (f"internal error: {type(exc).__name__}: {first} "
            "(a bug in addtc; set ADDT_DEBUG=1 for the traceback)")


if __name__ == "__main__":
    sys.exit(main())
